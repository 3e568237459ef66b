"""Nonlinear synchronisation of two takes of one action (seed 002, section 3).

Take ``m`` is first stretched linearly to the length of the pattern ``n`` (eq. 7). Then a
disparity ``d(p)`` is found for every pattern frame ``p``: frame ``p`` of ``n`` shows the
posture of frame ``p + d(p)`` of the stretched ``m``. It minimises the DSI cost
``E(p, d) = |x_n(p) - x_m(p + d)|^2`` (eq. 14) plus ``mu |d(p+1) - d(p)|`` (eqs. 12, 15), with
``|d(p+1) - d(p)| <= 1`` so that time never runs backwards (eqs. 9, 13), and with both ends
pinned: ``d = 0`` at the first and last frames (eq. 9, ``tau(0) = 0``, ``tau(T) = T``).

Dynamic programming over the DSI trellis finds it exactly (eqs. 16-17). With ``mu = 0`` this is
dynamic time warping with steps of 0, 1 or 2 frames of ``m`` per frame of ``n``; the smoothness
term is what keeps the warp from jittering where the motion is slow and the cost flat.
Written by hand: DTW libraries (dtaidistance, tslearn) have no smoothness term on the
disparity, which is the point of seed 002.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from scipy.linalg import solveh_banded

from engine.errors import InvalidInput


@dataclass(frozen=True)
class Synchronisation:
    """Take ``m`` synchronised to pattern ``n`` (seed 002 eqs. 7, 12-18).

    Attributes
    ----------
    disparity : ndarray, shape (P,), int
        ``d(p)`` in frames of the linearly stretched ``m`` (eq. 17).
    alpha : float
        Linear rate ratio ``(F_m - 1) / (P - 1)`` of eq. 7.
    distance : float
        The synchronisation distance ``D_nm`` of eq. 12 (cost plus smoothness) per frame.
    cost : float
        Its first term alone (the matched postures' mean squared distance).
    mu : float
        Smoothness weight used (eq. 20's rule of thumb when none was given).
    """

    disparity: np.ndarray
    alpha: float
    distance: float
    cost: float
    mu: float
    refined: np.ndarray | None = None

    @property
    def positions(self) -> np.ndarray:
        """(P,) fractional frame of the original ``m`` shown at each pattern frame: the
        refined warp when there is one, else eq. 18 composed with eq. 7. What :func:`warp`
        samples."""
        if self.refined is not None:
            return self.refined
        p = np.arange(len(self.disparity), dtype=float)
        return (p + self.disparity) * self.alpha

    @property
    def roughness(self) -> float:
        """Sum of |second differences| of the warp, frames: 0 for a linear warp."""
        return float(np.abs(np.diff(self.positions, 2)).sum())


def stretch(x: np.ndarray, frames: int) -> np.ndarray:
    """Eq. 7: ``x`` (F, b) resampled linearly to ``frames`` frames over the same duration."""
    x = np.asarray(x, dtype=float)
    src = np.linspace(0.0, len(x) - 1.0, frames)
    return interpolate(x, src)


def interpolate(x: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """``x`` (F, ...) at fractional frames ``positions`` (P,), linearly -> (P, ...)."""
    positions = np.clip(np.asarray(positions, dtype=float), 0.0, len(x) - 1.0)
    i0 = np.minimum(np.floor(positions).astype(int), len(x) - 1)
    i1 = np.minimum(i0 + 1, len(x) - 1)
    w = (positions - i0).reshape((-1,) + (1,) * (x.ndim - 1))
    return (1.0 - w) * x[i0] + w * x[i1]


def dsi_costs(xn: np.ndarray, xm: np.ndarray, max_disparity: int) -> np.ndarray:
    """Eq. 14: the DSI matrix ``E[p, d + D] = |xn(p) - xm(p + d)|^2`` for ``|d| <= D`` and two
    sequences of one length P (``xm`` already stretched); inf where ``p + d`` falls outside.

    Returns
    -------
    E : ndarray, shape (P, 2D + 1)
    """
    P, D = len(xn), int(max_disparity)
    E = np.full((P, 2 * D + 1), np.inf)
    for k, d in enumerate(range(-D, D + 1)):  # one diagonal at a time: memory P x (2D + 1)
        lo, hi = max(0, -d), min(P, P - d)
        if lo < hi:
            diff = xn[lo:hi] - xm[lo + d : hi + d]
            E[lo:hi, k] = (diff * diff).sum(-1)
    return E


def rule_of_thumb_mu(E: np.ndarray, near: int = 1) -> float:
    """Eq. 20: mu = the mean DSI cost over a domain of the trellis.

    The domain is taken as the cells at most ``near`` frames off the linear synchronisation:
    the mean cost of being a frame out of step, which is what one step of disparity must
    buy back. Over the whole band the mean is dominated by postures of other phases of the
    motion; on warped copies of a golf swing that mu came out 2-3 times larger and the warp
    lagged behind the truth by 5-8 frames (benchmarks/README.md, synchronisation).
    """
    mid = E.shape[1] // 2
    cells = E[:, max(0, mid - near) : mid + near + 1]
    finite = cells[np.isfinite(cells)]
    return float(finite.mean()) if finite.size else 0.0


def optimal_disparity(E: np.ndarray, mu: float) -> tuple[np.ndarray, float]:
    """Eqs. 15-17: the path through the DSI trellis ``E`` (P, 2D + 1) minimising
    ``sum E(p, d(p)) + mu sum |d(p+1) - d(p)|`` with ``|d(p+1) - d(p)| <= 1`` and
    ``d(0) = d(P-1) = 0``.

    Seed 002 prints eq. 16's penalty as ``mu |d + k|``; eq. 15, which it solves, penalises the
    step ``|k|``, and so does this.

    Returns
    -------
    d : ndarray, shape (P,), int
    total : float
        The minimum of eq. 15.
    """
    P, width = E.shape
    zero = width // 2  # column of d = 0
    S = np.full(width, np.inf)
    S[zero] = E[0, zero]  # eq. 9: tau(0) = 0
    K = np.zeros((P, width), dtype=np.int8)  # eq. 17's look-up table of steps
    for p in range(1, P):
        stay = S
        down = np.concatenate([S[1:], [np.inf]]) + mu  # from d + 1
        up = np.concatenate([[np.inf], S[:-1]]) + mu  # from d - 1
        best = np.minimum(stay, np.minimum(down, up))
        K[p] = np.where(best == stay, 0, np.where(best == down, 1, -1))
        S = E[p] + best  # eq. 16
    total = float(S[zero])  # eq. 9: tau(T) = T
    if not np.isfinite(total):
        raise InvalidInput("no monotonic synchronisation path exists")
    d = np.empty(P, dtype=int)
    d[-1] = zero
    for p in range(P - 1, 0, -1):  # eq. 17, backwards
        d[p - 1] = d[p] + K[p, d[p]]
    return d - zero, total


def synchronise(
    xn: np.ndarray,
    xm: np.ndarray,
    *,
    mu: float | None = None,
    band: float = 0.1,
    refine: bool = True,
) -> Synchronisation:
    """Synchronise take ``m`` to pattern ``n`` (seed 002 section 3).

    Parameters
    ----------
    xn : ndarray, shape (P, b)
        The pattern, e.g. aSpace coordinates (:class:`ActionSpace`) of each frame.
    xm : ndarray, shape (F_m, b)
        The take to synchronise, any length.
    mu : float, optional
        Smoothness weight (eq. 12); eq. 20's rule of thumb when None; 0 gives DTW.
    band : float
        Largest disparity D as a share of P: the DSI's ``-D <= d <= D`` (section 3).
    refine : bool
        Follow the DP with :func:`refine_warp` (sub-frame, curvature-penalised; not with
        ``mu = 0``, which stays plain DTW).
    """
    xn, xm = np.asarray(xn, dtype=float), np.asarray(xm, dtype=float)
    if xn.ndim != 2 or xm.ndim != 2 or xn.shape[1] != xm.shape[1]:
        raise InvalidInput(f"takes must be (frames, dims) alike, got {xn.shape}, {xm.shape}")
    if len(xn) < 2 or len(xm) < 2:
        raise InvalidInput("each take needs at least two frames")
    if not 0.0 < band <= 1.0:
        raise InvalidInput(f"band must be in (0, 1], got {band}")
    P = len(xn)
    E = dsi_costs(xn, stretch(xm, P), max(1, int(np.ceil(band * (P - 1)))))
    mu = rule_of_thumb_mu(E) if mu is None else float(mu)
    if mu < 0:
        raise InvalidInput(f"mu must be >= 0, got {mu}")
    d, total = optimal_disparity(E, mu)
    cost = float(E[np.arange(P), d + E.shape[1] // 2].sum())
    sync = Synchronisation(
        disparity=d, alpha=(len(xm) - 1.0) / (P - 1.0), distance=total / P, cost=cost / P, mu=mu
    )
    if refine and mu > 0:
        sync = dataclasses.replace(sync, refined=refine_warp(xn, xm, sync.positions, 10.0 * mu))
    return sync


def refine_warp(
    xn: np.ndarray, xm: np.ndarray, positions: np.ndarray, weight: float, iterations: int = 20
) -> np.ndarray:
    """A sub-frame warp near the DP's: minimise ``sum |xn(p) - xm(tau(p))|^2 + weight sum
    |tau(p+1) - 2 tau(p) + tau(p-1)|^2`` by Gauss-Newton from ``positions``.

    Beyond seed 002: its penalty on ``|d(i+1) - d(i)|`` charges every change of disparity,
    so the DP cuts the corners of a warp whose rate varies and steps in whole frames (1.1-2.5
    frames off on warped golf swings, against 0.9 for DTW). Penalising the warp's curvature
    instead costs a smoothly varying rate nothing; started from the DP path, which is
    robust, it lands on the true warp (0.2-0.4 frames on the same swings, benchmarks/README).
    Where the posture does not move the data term vanishes and the warp is interpolated.

    Parameters
    ----------
    xn : ndarray, shape (P, b)
    xm : ndarray, shape (F_m, b)
    positions : ndarray, shape (P,)
        Start: fractional frames of ``xm`` (:attr:`Synchronisation.positions`).
    weight : float
        Of the curvature term, in units of the squared distance (10 x eq. 20's mu).

    Returns
    -------
    tau : ndarray, shape (P,)
        Non-decreasing, from 0 to F_m - 1 (eq. 9).
    """
    P, last = len(xn), len(xm) - 1.0
    tau = np.asarray(positions, dtype=float).copy()
    if P < 3:
        return tau
    # D2^T D2 (pentadiagonal) as the upper bands solveh_banded takes: rows are the 2nd, 1st
    # and main diagonals
    curv = np.zeros((3, P))
    curv[0, 2:] = 1.0
    curv[1, 1:] = -4.0
    curv[1, [1, -1]] = -2.0
    curv[2] = 6.0
    curv[2, [0, -1]] = 1.0
    curv[2, [1, -2]] = 5.0
    slope = np.gradient(xm, axis=0)  # (F_m, b) d xm / d frame
    for _ in range(iterations):
        g = interpolate(slope, tau)  # (P, b)
        r = interpolate(xm, tau) - xn
        bands = weight * curv
        bands[2] += (g * g).sum(1) + 1e-9
        d2 = np.diff(tau, 2)
        Ltau = np.zeros(P)
        Ltau[:-2] += d2
        Ltau[1:-1] -= 2.0 * d2
        Ltau[2:] += d2
        rhs = -(g * r).sum(1) - weight * Ltau
        step = np.clip(solveh_banded(bands, rhs), -1.0, 1.0)  # linearisation holds a frame
        tau = np.maximum.accumulate(np.clip(tau + step, 0.0, last))
        tau[0], tau[-1] = 0.0, last
    return tau


def warp(x: np.ndarray, sync: Synchronisation) -> np.ndarray:
    """Eq. 18: take ``x`` (F_m, ...) resampled on the pattern's frames -> (P, ...)."""
    return interpolate(np.asarray(x, dtype=float), sync.positions)
