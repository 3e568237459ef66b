"""The DP of stage 2 (thesis 4.5.2, eq. 4.11): the least-cost monotone path through the
correspondence matrix, inside a band around the diagonal, with an optional step cost.
"""

from __future__ import annotations

import numpy as np

from engine.errors import InvalidInput


def window_size(k: float, n_ref: int, n_video: int) -> int:
    """w = ceil(k L / L') (thesis 4.5.2), at least 1; L, L' are frame counts minus one."""
    L, Lv = max(n_ref - 1, 1), max(n_video - 1, 1)
    return max(1, int(np.ceil(k * L / Lv - 1e-9)))


def band_mask(
    n_video: int, n_ref: int, beta: float, *, start: int = 0, end: int | None = None
) -> np.ndarray:
    """Entries within ``beta`` reference frames of the straight diagonal (thesis fig. 4.4).

    Returns
    -------
    ndarray of bool, shape (T', T)
    """
    end = n_ref - 1 if end is None else end
    tv = np.arange(n_video)[:, None]
    diag = start + (end - start) * tv / max(n_video - 1, 1)
    return np.abs(np.arange(n_ref)[None, :] - diag) <= beta


def step_costs(window: int, mean_step: float, weight: float) -> np.ndarray:
    """Cost of a step of i = 0..window reference frames: weight * log((i + 1/2) / (r + 1/2))^2.

    Beyond the thesis: a prior on the local slope of C around the mean slope r = L / L'. The
    log makes halving and doubling the pace cost about the same; the 1/2 keeps i = 0 finite.

    Returns
    -------
    ndarray, shape (window + 1,)
    """
    i = np.arange(window + 1, dtype=float)
    return weight * np.log((i + 0.5) / (max(mean_step, 0.0) + 0.5)) ** 2


def dp_path(
    cost: np.ndarray,
    *,
    window: int,
    start: int = 0,
    end: int | None = None,
    float_start: int = 0,
    float_end: int = 0,
    min_step: int = 1,
    step_cost: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Least-cost monotone path (thesis 4.5.2, eq. 4.11), optionally with a step cost.

        D(t', t) = d(t', t) + min_{i = min_step..w} [D(t' - 1, t - i) + g(i)]

    Parameters
    ----------
    cost : ndarray, shape (T', T)
        d(t', t); ``inf`` marks forbidden entries (outside the band).
    window : int
        w: C(t') - C(t' - 1) in min_step..w.
    start : int
        C(0) (or the earliest C(0) with ``float_start``).
    end : int, optional
        C(L'); the last reference frame by default (or the latest C(L') with ``float_end``).
    float_start, float_end : int
        C(0) in [start, start + float_start], C(L') in [end - float_end, end] (thesis 6.3).
    min_step : int
        1 (thesis: one-to-one) or 0 (a reference frame may repeat).
    step_cost : ndarray, shape (window + 1,), optional
        g(i), added per step of i frames (see :func:`step_costs`); zero by default.

    Returns
    -------
    C : ndarray of int, shape (T',)
    total : float
        Sum of the costs along the path, step costs included.

    Raises
    ------
    InvalidInput
        Bad shapes or parameters, or no path satisfies the constraints (e.g. more video
        frames than reference frames between the pinned ends).
    """
    d, end, g = _checked(cost, window, start, end, float_start, float_end, min_step, step_cost)
    n_v, n_r = d.shape
    D, step = _accumulate(d, g, start, min(start + float_start, n_r - 1), window, min_step)
    e_lo = max(end - float_end, 0)
    last = D[-1, e_lo : end + 1]
    if not np.isfinite(last).any():
        raise InvalidInput(
            f"no monotone path of {n_v} video frames fits between reference frames {start} and "
            f"{end} with window {window} inside the band"
        )
    C = np.empty(n_v, dtype=int)
    C[-1] = e_lo + int(np.argmin(last))
    for tv in range(n_v - 1, 0, -1):
        C[tv - 1] = C[tv] - step[tv, C[tv]]
    return C, float(D[-1, C[-1]])


def _checked(
    cost: np.ndarray,
    window: int,
    start: int,
    end: int | None,
    float_start: int,
    float_end: int,
    min_step: int,
    step_cost: np.ndarray | None,
) -> tuple[np.ndarray, int, np.ndarray]:
    """:func:`dp_path`'s inputs checked: d (T', T) as floats, the last reference frame
    ``end`` and the step costs g (window + 1,); InvalidInput names the bad parameter."""
    d = np.asarray(cost, dtype=float)
    if d.ndim != 2 or d.shape[0] < 1 or d.shape[1] < 1:
        raise InvalidInput(f"cost must be a (T', T) matrix, got shape {d.shape}")
    n_r = d.shape[1]
    end = n_r - 1 if end is None else int(end)
    if not isinstance(window, int | np.integer) or window < 1:
        raise InvalidInput(f"window must be an integer >= 1, got {window!r}")
    if not (0 <= start <= end < n_r):
        raise InvalidInput(
            f"start and end must satisfy 0 <= start <= end < {n_r}, got {start}, {end}"
        )
    if min_step not in (0, 1):
        raise InvalidInput(f"min_step must be 0 or 1, got {min_step!r}")
    if float_start < 0 or float_end < 0:
        raise InvalidInput(
            f"float_start and float_end must be >= 0, got {float_start}, {float_end}"
        )
    if step_cost is None:
        return d, end, np.zeros(window + 1)
    g = np.asarray(step_cost, dtype=float)
    if g.shape != (window + 1,) or not np.all(np.isfinite(g)):
        raise InvalidInput(
            f"step_cost must be finite with shape ({window + 1},), got shape {g.shape}"
        )
    return d, end, g


def _accumulate(
    d: np.ndarray, g: np.ndarray, start: int, s_hi: int, window: int, min_step: int
) -> tuple[np.ndarray, np.ndarray]:
    """D(t', t) of eq. 4.11 with the step costs g (window + 1,), from C(0) in [start, s_hi],
    and the step i taken into each entry; both (T', T)."""
    n_v, n_r = d.shape
    D = np.full((n_v, n_r), np.inf)
    step = np.zeros((n_v, n_r), dtype=np.int32)
    D[0, start : s_hi + 1] = d[0, start : s_hi + 1]
    best = np.empty(n_r)
    cand = np.empty(n_r)
    for tv in range(1, n_v):
        best.fill(np.inf)
        arg = step[tv]
        prev = D[tv - 1]
        for i in range(min_step, window + 1):
            if i >= n_r:
                break
            cand[:i] = np.inf
            np.add(prev[: n_r - i], g[i], out=cand[i:])
            better = cand < best
            best[better] = cand[better]
            arg[better] = i
        D[tv] = d[tv] + best
    return D, step


def _dp_relaxing(cost: np.ndarray, *, min_step: int, **kw) -> tuple[np.ndarray, float, bool]:
    """:func:`dp_path`, retried with repeats allowed when no strictly increasing path fits."""
    try:
        C, total = dp_path(cost, min_step=min_step, **kw)
        return C, total, False
    except InvalidInput:
        if min_step == 0:
            raise
        C, total = dp_path(cost, min_step=0, **kw)
        return C, total, True
