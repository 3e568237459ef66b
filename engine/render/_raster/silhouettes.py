"""Silhouettes without depth: their size and overlap with a target, counted from row spans
with no image (d_A, eq. 4.1), and silhouette images of many postures.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from engine.render._raster.spans import _INF, _ceil, _cols, _floor, _insert_span, _rows, row_span


@njit(cache=True, nogil=True)
def sil_counts(ends: np.ndarray, rad: np.ndarray, prefix: np.ndarray, out: np.ndarray) -> None:
    """Silhouette size and overlap with a target for many postures, without any image.

    Per row, the spans of all capsules are sorted, merged and counted; the target's pixels
    in a span come from its row prefix sums. Cost is O(rows x capsules), not O(pixels).

    Parameters
    ----------
    ends : (N, C, 2, 2) float64
    rad : (C,) float64, pixels
    prefix : (H, W + 1) int32, row prefix sums of the target silhouette
    out : (N, 2) int64, receives (|A|, |A and A'|)
    """
    N, C = ends.shape[0], ends.shape[1]
    H, W = prefix.shape[0], prefix.shape[1] - 1
    lo = np.empty(C)
    hi = np.empty(C)
    rlo = np.empty(C, np.int64)
    rhi = np.empty(C, np.int64)
    for n in range(N):
        e = ends[n]
        vmin = H
        vmax = -1
        for c in range(C):
            rlo[c], rhi[c] = _rows(e[c, 0, 1], e[c, 1, 1], rad[c], 0, H - 1)
            vmin = min(vmin, rlo[c])
            vmax = max(vmax, rhi[c])
        area = 0
        inter = 0
        for v in range(vmin, vmax + 1):
            m = 0
            for c in range(C):
                if rlo[c] <= v <= rhi[c]:
                    i0, i1 = _cols(
                        e[c, 0, 0], e[c, 0, 1], e[c, 1, 0], e[c, 1, 1], rad[c], v, 0, W - 1
                    )
                    if i0 <= i1:
                        m = _insert_span(lo, hi, m, i0, i1)
            a, i, _ = _union_counts(lo, hi, m, prefix[v])
            area += a
            inter += i
        out[n, 0] = area
        out[n, 1] = inter


@njit(cache=True, inline="always")
def _merge_spans(lo: np.ndarray, hi: np.ndarray, m: int) -> int:
    """Merge the first ``m`` column spans (sorted by start) in place into disjoint ones,
    touching spans joined; returns how many are left."""
    if m == 0:
        return 0
    k = 0
    for j in range(1, m):
        if lo[j] <= hi[k] + 1:
            hi[k] = max(hi[k], hi[j])
        else:
            k += 1
            lo[k] = lo[j]
            hi[k] = hi[j]
    return k + 1


@njit(cache=True, inline="always")
def _union_counts(lo: np.ndarray, hi: np.ndarray, m: int, pr: np.ndarray) -> tuple:
    """Pixels of one row in the union of the first ``m`` column spans (sorted by start;
    merged in place), and how many of them are target pixels (``pr``: the row's prefix
    sums, (W + 1,)). Returns (pixels, target pixels, spans left after merging)."""
    m = _merge_spans(lo, hi, m)
    area = 0
    inter = 0
    for j in range(m):
        s = int(lo[j])
        t = int(hi[j])
        area += t - s + 1
        inter += pr[t + 1] - pr[s]
    return area, inter, m


@njit(cache=True, nogil=True)
def row_unions(
    ends: np.ndarray,
    rad: np.ndarray,
    caps: np.ndarray,
    prefix: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    n_row: np.ndarray,
    row_counts: np.ndarray,
) -> tuple:
    """Each row's union of the column spans of capsules ``caps`` of one posture, as
    disjoint spans: the fixed body that :func:`part_sil_counts` adds a moving part to.

    Parameters
    ----------
    ends : (C, 2, 2) float64; rad : (C,) float64, pixels
    prefix : (H, W + 1) int32, row prefix sums of the target silhouette
    lo, hi : (H, len(caps)) float64 receive each row's spans, sorted and disjoint; n_row :
    (H,) int64, zeroed by the caller, receives their number; row_counts : (H, 2) int64
    receives each row's (pixels, target pixels)

    Returns (|A|, |A and A'|) of the whole union.
    """
    H, W = prefix.shape[0], prefix.shape[1] - 1
    area = 0
    inter = 0
    for k in range(caps.shape[0]):
        c = caps[k]
        v0, v1 = _rows(ends[c, 0, 1], ends[c, 1, 1], rad[c], 0, H - 1)
        for v in range(v0, v1 + 1):
            i0, i1 = _cols(ends[c, 0, 0], ends[c, 0, 1], ends[c, 1, 0], ends[c, 1, 1], rad[c],
                           v, 0, W - 1)  # fmt: skip
            if i0 <= i1:
                n_row[v] = _insert_span(lo[v], hi[v], n_row[v], i0, i1)
    for v in range(H):
        m = n_row[v]
        if m == 0:
            continue
        # the merged spans are kept: fewer to merge again per moving sample
        a, i, n_row[v] = _union_counts(lo[v], hi[v], m, prefix[v])
        row_counts[v, 0] = a
        row_counts[v, 1] = i
        area += a
        inter += i
    return area, inter


@njit(cache=True, nogil=True)
def part_sil_counts(
    ends: np.ndarray,
    rad: np.ndarray,
    caps: np.ndarray,
    prefix: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    n_row: np.ndarray,
    row_counts: np.ndarray,
    area0: int,
    inter0: int,
    out: np.ndarray,
) -> None:
    """(|A|, |A and A'|) of samples of the capsules ``caps`` joining a fixed body, from row
    spans (d_A of :class:`~engine.render.capsules.PartScorer` without d_E).

    Only the rows a sample's capsules meet are merged again with the fixed spans: O(moving
    rows x spans) per sample, no image. Counts the same pixels as :func:`sil_counts` of the
    whole posture.

    Parameters
    ----------
    ends : (S, C, 2, 2) float64; only rows ``caps`` are read
    rad : (C,) float64, pixels
    lo, hi, n_row, row_counts : the fixed body, from :func:`row_unions`
    area0, inter0 : its totals
    out : (S, 2) int64 receives (|A|, |A and A'|)
    """
    S = ends.shape[0]
    H, W = prefix.shape[0], prefix.shape[1] - 1
    nc = caps.shape[0]
    K = lo.shape[1] + nc
    blo = np.empty(K)
    bhi = np.empty(K)
    rlo = np.empty(nc, np.int64)
    rhi = np.empty(nc, np.int64)
    for n in range(S):
        e = ends[n]
        vmin = H
        vmax = -1
        for k in range(nc):
            c = caps[k]
            rlo[k], rhi[k] = _rows(e[c, 0, 1], e[c, 1, 1], rad[c], 0, H - 1)
            vmin = min(vmin, rlo[k])
            vmax = max(vmax, rhi[k])
        add_a = 0
        add_i = 0
        for v in range(vmin, vmax + 1):
            m0 = n_row[v]
            for j in range(m0):
                blo[j] = lo[v, j]
                bhi[j] = hi[v, j]
            m = m0
            for k in range(nc):
                if rlo[k] <= v <= rhi[k]:
                    c = caps[k]
                    i0, i1 = _cols(e[c, 0, 0], e[c, 0, 1], e[c, 1, 0], e[c, 1, 1], rad[c], v,
                                   0, W - 1)  # fmt: skip
                    if i0 <= i1:
                        m = _insert_span(blo, bhi, m, i0, i1)
            if m == m0:
                continue
            a, i, _ = _union_counts(blo, bhi, m, prefix[v])
            add_a += a - row_counts[v, 0]
            add_i += i - row_counts[v, 1]
        out[n, 0] = area0 + add_a
        out[n, 1] = inter0 + add_i


@njit(cache=True, inline="always")
def _prefix_at(pr: np.ndarray, x: float) -> float:
    """Target pixels of a row left of column position ``x``, pixels as unit boxes.

    ``pr`` is the row's prefix sum (W + 1,); pixel u covers [u - 1/2, u + 1/2], so the count
    is piecewise linear in ``x`` (0 at -1/2, |row| at W - 1/2).
    """
    y = min(max(x + 0.5, 0.0), pr.shape[0] - 1.0)
    i = min(int(math.floor(y)), pr.shape[0] - 2)
    return pr[i] + (y - i) * (pr[i + 1] - pr[i])


@njit(cache=True, nogil=True)
def sil_counts_smooth(
    ends: np.ndarray, rad: np.ndarray, prefix: np.ndarray, sub: int, out: np.ndarray
) -> None:
    """Area of the capsule body and its overlap with the target, sub-pixel (continuous).

    Like :func:`sil_counts`, but each pixel row is sampled at ``sub`` sub-rows and the spans
    are kept as real intervals (clipped to the image), the target's pixels counted as unit
    boxes: area and overlap change continuously as a capsule moves by a fraction of a pixel,
    where the pixel-centre counts only change when a centre is crossed.

    Parameters
    ----------
    ends : (N, C, 2, 2) float64
    rad : (C,) float64, pixels
    prefix : (H, W + 1) int32, row prefix sums of the target silhouette
    sub : int >= 1
    out : (N, 2) float64, receives (|A|, |A and A'|) in pixels
    """
    N, C = ends.shape[0], ends.shape[1]
    H, W = prefix.shape[0], prefix.shape[1] - 1
    lo = np.empty(C)
    hi = np.empty(C)
    xmin = -0.5
    xmax = W - 0.5
    w = 1.0 / sub
    for n in range(N):
        e = ends[n]
        area = 0.0
        inter = 0.0
        ymin = _INF
        ymax = -_INF
        for c in range(C):
            ymin = min(ymin, min(e[c, 0, 1], e[c, 1, 1]) - rad[c])
            ymax = max(ymax, max(e[c, 0, 1], e[c, 1, 1]) + rad[c])
        k0 = max(_floor((ymin + 0.5) * sub), 0)
        k1 = min(_ceil((ymax + 0.5) * sub), H * sub - 1)
        for k in range(k0, k1 + 1):
            y = (k + 0.5) * w - 0.5  # centre of sub-row k
            v = min(max(int(math.floor(y + 0.5)), 0), H - 1)
            m = 0
            for c in range(C):
                a0, a1 = row_span(e[c, 0, 0], e[c, 0, 1], e[c, 1, 0], e[c, 1, 1], rad[c], y)
                a0 = max(a0, xmin)
                a1 = min(a1, xmax)
                if a0 < a1:
                    m = _insert_span(lo, hi, m, a0, a1)
            if m == 0:
                continue
            s = lo[0]
            t = hi[0]
            pr = prefix[v]
            for j in range(1, m + 1):
                if j < m and lo[j] <= t:
                    t = max(t, hi[j])
                    continue
                area += (t - s) * w
                inter += (_prefix_at(pr, t) - _prefix_at(pr, s)) * w
                if j < m:
                    s = lo[j]
                    t = hi[j]
        out[n, 0] = area
        out[n, 1] = inter


@njit(cache=True, nogil=True)
def fill_silhouettes(ends: np.ndarray, rad: np.ndarray, out: np.ndarray) -> None:
    """Write the silhouettes of many postures into ``out`` (N, H, W) bool (zeroed by caller)."""
    N, C = ends.shape[0], ends.shape[1]
    H, W = out.shape[1], out.shape[2]
    for n in range(N):
        e = ends[n]
        for c in range(C):
            r = rad[c]
            v0, v1 = _rows(e[c, 0, 1], e[c, 1, 1], r, 0, H - 1)
            for v in range(v0, v1 + 1):
                i0, i1 = _cols(e[c, 0, 0], e[c, 0, 1], e[c, 1, 0], e[c, 1, 1], r, v, 0, W - 1)
                for u in range(i0, i1 + 1):
                    out[n, v, u] = True
