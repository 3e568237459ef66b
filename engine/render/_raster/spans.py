"""Geometry shared by the rasteriser's kernels: where an image row meets a capsule, the
axis parameter and front-surface depth of a pixel, span bookkeeping (the conventions are in
:mod:`engine.render._raster`).

All are small ``inline="always"`` functions: as plain calls they cost the kernels a few
per cent.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_INF = np.inf


@njit(cache=True, inline="always")
def _ceil(x: float) -> int:
    """ceil as int, clamped so that far off-screen or infinite values cannot overflow."""
    return int(math.ceil(min(max(x, -1e9), 1e9)))


@njit(cache=True, inline="always")
def _floor(x: float) -> int:
    """floor as int, clamped like :func:`_ceil`."""
    return int(math.floor(min(max(x, -1e9), 1e9)))


@njit(cache=True, inline="always")
def row_span(ax: float, ay: float, bx: float, by: float, r: float, v: float) -> tuple:
    """Columns (lo, hi) as floats where row ``v`` meets the capsule; lo > hi when empty."""
    lo = _INF
    hi = -_INF
    dy = v - ay
    h2 = r * r - dy * dy
    if h2 >= 0.0:
        h = math.sqrt(h2)
        lo = min(lo, ax - h)
        hi = max(hi, ax + h)
    dy = v - by
    h2 = r * r - dy * dy
    if h2 >= 0.0:
        h = math.sqrt(h2)
        lo = min(lo, bx - h)
        hi = max(hi, bx + h)
    dx = bx - ax
    dyb = by - ay
    l2 = dx * dx + dyb * dyb
    if l2 > 0.0:
        # the band: 0 <= (p - a).d <= |d|^2 and |(p - a) x d| <= r |d|, linear in u
        ulo = -_INF
        uhi = _INF
        ok = True
        k = (v - ay) * dyb
        if dx != 0.0:
            t1 = -k / dx + ax
            t2 = (l2 - k) / dx + ax
            ulo = max(ulo, min(t1, t2))
            uhi = min(uhi, max(t1, t2))
        elif k < 0.0 or k > l2:
            ok = False
        k2 = -(v - ay) * dx
        rl = r * math.sqrt(l2)
        if dyb != 0.0:
            t1 = (-rl - k2) / dyb + ax
            t2 = (rl - k2) / dyb + ax
            ulo = max(ulo, min(t1, t2))
            uhi = min(uhi, max(t1, t2))
        elif abs(k2) > rl:
            ok = False
        if ok and ulo <= uhi:
            lo = min(lo, ulo)
            hi = max(hi, uhi)
    return lo, hi


@njit(cache=True, inline="always")
def _rows(ay: float, by: float, r: float, lo: int, hi: int) -> tuple:
    """Rows (v0, v1) in [lo, hi] that a capsule with end rows ``ay``, ``by``, radius ``r`` spans."""
    return max(_ceil(min(ay, by) - r), lo), min(_floor(max(ay, by) + r), hi)


@njit(cache=True, inline="always")
def _cols(ax: float, ay: float, bx: float, by: float, r: float, v: int, lo: int, hi: int) -> tuple:
    """Pixel columns (i0, i1) where row ``v`` meets the capsule, in [lo, hi]; i0 > i1 when none."""
    a0, a1 = row_span(ax, ay, bx, by, r, v)
    if not a0 <= a1:
        return lo, lo - 1
    return max(_ceil(a0), lo), min(_floor(a1), hi)


@njit(cache=True, inline="always")
def _axis(ax: float, ay: float, bx: float, by: float) -> tuple:
    """Axis direction (dx, dy) and 1 / its squared length (0 for a point capsule)."""
    dx = bx - ax
    dy = by - ay
    l2 = dx * dx + dy * dy
    return dx, dy, 1.0 / l2 if l2 > 0.0 else 0.0


@njit(cache=True, inline="always")
def _axis_t(u: int, v: int, ax: float, ay: float, dx: float, dy: float, inv_l2: float) -> float:
    """Unclamped axis parameter of the pixel's projection (< 0 before end a, > 1 past end b)."""
    return ((u - ax) * dx + (v - ay) * dy) * inv_l2


@njit(cache=True, inline="always")
def _front_depth(
    u: int, v: int, tr: float, ax: float, ay: float, dx: float, dy: float,
    za: float, zb: float, rm2: float, inv_s2: float,
) -> float:  # fmt: skip
    """Depth of the capsule's front surface at the pixel (see the module doc)."""
    t = min(max(tr, 0.0), 1.0)
    px = u - (ax + t * dx)
    py = v - (ay + t * dy)
    d2 = (px * px + py * py) * inv_s2
    return za + t * (zb - za) - math.sqrt(max(rm2 - d2, 0.0))


@njit(cache=True, inline="always")
def _in_body(tr: float, s0: bool, s1: bool) -> bool:
    """Whether axis parameter ``tr`` is outside the round caps at seam ends (a ``body`` pixel)."""
    return not ((tr < 0.0 and s0) or (tr > 1.0 and s1))


@njit(cache=True, inline="always")
def _widen(
    rlo: np.ndarray, rhi: np.ndarray, v: int, i0: int, i1: int, vmin: int, vmax: int
) -> tuple:
    """Widen row ``v``'s written extent to [i0, i1]; returns the widened rows (vmin, vmax)."""
    rlo[v] = min(rlo[v], i0)
    rhi[v] = max(rhi[v], i1)
    return min(vmin, v), max(vmax, v)


@njit(cache=True, inline="always")
def _insert_span(lo: np.ndarray, hi: np.ndarray, m: int, a: float, b: float) -> int:
    """Insert span [a, b] into the first ``m`` spans, kept sorted by start; returns m + 1."""
    j = m
    while j > 0 and lo[j - 1] > a:
        lo[j] = lo[j - 1]
        hi[j] = hi[j - 1]
        j -= 1
    lo[j] = a
    hi[j] = b
    return m + 1
