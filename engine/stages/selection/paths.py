"""The per-segment DP of thesis 4.7.2 (eq. 4.24-4.30): the refined C and the selected
candidate of every video frame.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from numba import njit

from engine.stages.selection.boundaries import _Segmentation
from engine.stages.selection.evidence import _angles, _Evidence
from engine.stages.selection.settings import SelectionSettings

ProgressFn = Callable[[str, float], None]


def refine_segment(
    d_c: np.ndarray, *, window: int, band: int, min_step: int = 1
) -> tuple[np.ndarray, np.ndarray, float]:
    """Least-cost path over (t', t, l) in one segment (thesis 4.7.2, eq. 4.24-4.30).

    The path starts at (0, 0, l) and ends at (n'-1, n-1, l): C(t'_b) = t_b and C(t'_e) = t_e.
    The predecessor of (t', t, l) is (t'-1, t-i, k) with i in [min_step, window] (constraint B;
    the thesis' i = 1..w+1), and only t within ``band`` of the segment's diagonal is searched.
    Cost per step d_c(t', t, l) + (d_c(t', t, l) - d_c(t'-1, s, k))^2 (eq. 4.25, 4.26).
    Complexity O(w beta L'_B N_B^2).

    Parameters
    ----------
    d_c : ndarray, shape (n', n, K)
        Posture error of candidate l at t' against reference frame t (radians); ``inf`` marks
        absent candidates.
    window : int
        w >= 1.
    band : int
        beta, reference frames either side of the diagonal.
    min_step : int
        0 lets C hold still (slower performer than the reference's frame rate allows).

    Returns
    -------
    C : ndarray of int, shape (n',)
        Reference frame per video frame, relative to the segment start.
    ell : ndarray of int, shape (n',)
        Selected candidate.
    cost : float
        Sum of the step costs (E_F times n'); ``inf`` when no path exists.
    """
    n_v, n_r, k = d_c.shape
    if n_v == 1:
        l0 = int(np.argmin(d_c[0, 0]))
        return np.zeros(1, dtype=int), np.array([l0]), float(d_c[0, 0, l0])
    diag = np.linspace(0.0, n_r - 1, n_v)
    D, back_i, back_k = _dp_table(np.ascontiguousarray(d_c, dtype=np.float64), diag,
                                  int(window), float(band), int(min_step))  # fmt: skip
    l_end = int(np.argmin(D[n_r - 1]))
    cost = float(D[n_r - 1, l_end])
    C = np.empty(n_v, dtype=int)
    ell = np.empty(n_v, dtype=int)
    C[-1], ell[-1] = n_r - 1, l_end
    for tp in range(n_v - 1, 0, -1):
        i, kk = back_i[tp, C[tp], ell[tp]], back_k[tp, C[tp], ell[tp]]
        C[tp - 1], ell[tp - 1] = C[tp] - i, kk
    return C, ell, cost


@njit(cache=True)
def _dp_table(
    d_c: np.ndarray, diag: np.ndarray, window: int, band: float, min_step: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The DP of :func:`refine_segment`: the last row's cumulated costs D (n, K) and the
    back pointers (step i, candidate k), each (n', n, K).

    Compiled: the profile of stage 4 (benchmarks/profile.py) put 90 % of its time in this
    loop as numpy, which built (n, K, K) arrays for every step i and every reference frame,
    inside the band or not. Here only the band's frames are visited. Ties go to the smallest
    step, then the smallest k, as numpy's argmin did.
    """
    n_v, n_r, k = d_c.shape
    D = np.full((n_r, k), np.inf)
    D[0] = d_c[0, 0]
    back_i = np.zeros((n_v, n_r, k), dtype=np.int32)
    back_k = np.zeros((n_v, n_r, k), dtype=np.int32)
    for tp in range(1, n_v):
        new = np.full((n_r, k), np.inf)
        lo, hi = max(0, int(np.ceil(diag[tp] - band))), min(n_r - 1, int(np.floor(diag[tp] + band)))
        if tp == n_v - 1:  # the path ends at the segment's last reference frame
            lo = hi = n_r - 1
        for t in range(lo, hi + 1):
            for ll in range(k):
                cur = d_c[tp, t, ll]
                best, bi, bk = np.inf, 0, 0
                for i in range(min_step, min(window, n_r - 1) + 1):
                    if t - i < 0:
                        break
                    for kk in range(k):
                        diff = cur - d_c[tp - 1, t - i, kk]
                        if not np.isfinite(diff):
                            continue
                        tot = D[t - i, kk] + diff * diff
                        if tot < best:
                            best, bi, bk = tot, i, kk
                new[t, ll] = best + cur
                back_i[tp, t, ll], back_k[tp, t, ll] = bi, bk
        D = new
    return D, back_i, back_k


def _segment_table(ref_dirs: np.ndarray, cand_dirs: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """d_c(t', t, l) for one segment, shape (n', n, K) (eq. 4.25)."""
    out = np.empty((cand_dirs.shape[0], ref_dirs.shape[0], cand_dirs.shape[1]))
    for i in range(cand_dirs.shape[0]):
        out[i] = _angles(ref_dirs[:, None], cand_dirs[i][None]).mean(-1)
    return np.where(valid[:, None, :], out, np.inf)


def _segment_path(
    ev: _Evidence,
    span: tuple[int, int],
    bound: tuple[int, int],
    fps_ratio: float,
    s: SelectionSettings,
) -> tuple[np.ndarray, np.ndarray, float]:
    """C (n',) relative to the reference start, candidates l (n',) and the path cost of one
    segment (thesis 4.7.2), the performer's frames ``span`` against the reference's ``bound``.

    The cost table is d_c of eq. 4.25 plus the image evidence and the anchor to stage 2's C
    (beyond the thesis, see :class:`SelectionSettings`).
    """
    (ps, pe), (rs, re) = span, bound
    n_seg_v, n_seg_r = pe - ps + 1, re - rs + 1
    table = _segment_table(
        ev.ref_dirs[rs : re + 1], ev.cand_dirs[ps : pe + 1], ev.valid[ps : pe + 1]
    )
    table = table + ev.image[ps : pe + 1, None, :]
    if s.anchor_deg_per_frame > 0:
        off = np.abs(np.arange(n_seg_r)[None, :] - (ev.C0[ps : pe + 1, None] - rs))
        table = table + np.radians(s.anchor_deg_per_frame) * (off / fps_ratio)[..., None]
    min_step = 1 if n_seg_r >= n_seg_v else 0
    window = max(1, int(np.ceil(s.window_k * n_seg_r / max(n_seg_v, 1))))
    band = max(window, int(np.ceil(s.band * n_seg_r)))
    c_loc, l_loc, cost = refine_segment(table, window=window, band=band, min_step=min_step)
    if not np.isfinite(cost):  # band too narrow for this segment: search the whole segment
        c_loc, l_loc, cost = refine_segment(table, window=n_seg_r, band=n_seg_r, min_step=0)
    return c_loc, l_loc, cost


def _refine_segments(
    ev: _Evidence,
    seg: _Segmentation,
    fps_ratio: float,
    s: SelectionSettings,
    on_progress: ProgressFn | None,
) -> tuple[np.ndarray, np.ndarray, list[float]]:
    """The DP of thesis 4.7.2 per segment: C (T',), selected candidates l (T',) and each
    segment's mean step cost E_F (eq. 4.24)."""
    C = np.zeros(ev.n_frames, dtype=int)
    ell = np.zeros(ev.n_frames, dtype=int)
    costs = []
    for i, ((ps, pe), (rs, re)) in enumerate(zip(seg.spans, seg.bounds, strict=True)):
        c_loc, l_loc, cost = _segment_path(ev, (ps, pe), (rs, re), fps_ratio, s)
        # boundary frames are shared by two segments: the later segment's start wins
        C[ps : pe + 1] = rs + c_loc
        ell[ps : pe + 1] = l_loc
        costs.append(cost / (pe - ps + 1))
        if on_progress:
            on_progress("selection", 0.2 + 0.8 * (i + 1) / len(seg.bounds))
    return C, ell, costs
