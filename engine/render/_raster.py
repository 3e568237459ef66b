"""Numba kernels of the analytic capsule rasteriser (private; see :mod:`engine.render.capsules`).

Why numba: the work is per image row and per pixel of small, data-dependent boxes (one box
per posture sample), which numpy can only express with large temporary arrays per sample; a
profile of the numpy version spent > 90 % of its time allocating and masking those
temporaries. Every kernel here is a plain loop over rows and pixels.

Conventions shared by all kernels:

- ``ends`` has shape (..., C, 2, 2): capsule, end (0, 1), (u, v) in pixels;
  pixel centres are at integers, row = v, col = u.
- A pixel is inside a capsule when its distance to the 2D segment is <= the radius.
  A capsule (stadium) is convex, so each image row meets it in one interval of columns,
  computed analytically in :func:`row_span` (no per-pixel distance test for coverage).
- ``zends`` (C, 2) are the depths (metres, larger is farther) of the capsule ends; the depth
  of the capsule's front surface at a pixel is the axis depth at the closest axis point minus
  sqrt(r^2 - d^2): exact on the spherical caps and for axes parallel to the image plane, an
  approximation (error < r (1 - cos tilt)) for axes tilted in depth.
- Part bits: ``cov`` has bit k set where part k covers the pixel; ``body`` has bit k set where
  the pixel is covered by part k outside the round caps at its seam ends (see
  ``SEAM_END`` in :mod:`engine.render.capsules`); the outline of part k is the set of
  ``body``-pixels of k with a 4-neighbour not covered by k.
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


@njit(cache=True)
def _bbox(ends: np.ndarray, rad: np.ndarray, caps: np.ndarray, H: int, W: int, margin: int):
    """Pixel box (r0, r1, c0, c1), half-open, of capsules ``caps`` grown by ``margin``."""
    umin = _INF
    umax = -_INF
    vmin = _INF
    vmax = -_INF
    for i in range(caps.shape[0]):
        c = caps[i]
        r = rad[c]
        for e in range(2):
            umin = min(umin, ends[c, e, 0] - r)
            umax = max(umax, ends[c, e, 0] + r)
            vmin = min(vmin, ends[c, e, 1] - r)
            vmax = max(vmax, ends[c, e, 1] + r)
    r0 = max(_ceil(vmin) - margin, 0)
    r1 = min(_floor(vmax) + 1 + margin, H)
    c0 = max(_ceil(umin) - margin, 0)
    c1 = min(_floor(umax) + 1 + margin, W)
    if r1 < r0:
        r1 = r0
    if c1 < c0:
        c1 = c0
    return r0, r1, c0, c1


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


@njit(cache=True)
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
            if m == 0:
                continue
            s = int(lo[0])
            t = int(hi[0])
            pr = prefix[v]
            for j in range(1, m + 1):
                if j < m and lo[j] <= t + 1:
                    t = max(t, int(hi[j]))
                    continue
                area += t - s + 1
                inter += pr[t + 1] - pr[s]
                if j < m:
                    s = int(lo[j])
                    t = int(hi[j])
        out[n, 0] = area
        out[n, 1] = inter


@njit(cache=True, inline="always")
def _prefix_at(pr: np.ndarray, x: float) -> float:
    """Target pixels of a row left of column position ``x``, pixels as unit boxes.

    ``pr`` is the row's prefix sum (W + 1,); pixel u covers [u - 1/2, u + 1/2], so the count
    is piecewise linear in ``x`` (0 at -1/2, |row| at W - 1/2).
    """
    y = min(max(x + 0.5, 0.0), pr.shape[0] - 1.0)
    i = min(int(math.floor(y)), pr.shape[0] - 2)
    return pr[i] + (y - i) * (pr[i + 1] - pr[i])


@njit(cache=True)
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


@njit(cache=True)
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


@njit(cache=True)
def raster_parts(
    ends: np.ndarray,
    zends: np.ndarray,
    rad_px: np.ndarray,
    rad_m: np.ndarray,
    part: np.ndarray,
    seam: np.ndarray,
    caps: np.ndarray,
    scale: float,
    r0: int,
    c0: int,
    z: np.ndarray,
    label: np.ndarray,
    cov: np.ndarray,
    body: np.ndarray,
) -> None:
    """Rasterise capsules ``caps`` of one posture into a box with origin (r0, c0).

    ``z`` (h, w) float64 is the z-buffer (inf = empty), ``label`` (h, w) int8 the nearest
    part (-1 = empty), ``cov``/``body`` (h, w) uint16 the part bits; all are updated in place
    (the caller initialises them). A pixel takes a capsule's part when strictly nearer, so on
    exact depth ties the capsule drawn first wins.
    """
    h, w = z.shape
    for i in range(caps.shape[0]):
        c = caps[i]
        ax, ay = ends[c, 0, 0], ends[c, 0, 1]
        bx, by = ends[c, 1, 0], ends[c, 1, 1]
        za, zb = zends[c, 0], zends[c, 1]
        r = rad_px[c]
        rm2 = rad_m[c] * rad_m[c]
        inv_s2 = 1.0 / (scale * scale)
        dx, dy, inv_l2 = _axis(ax, ay, bx, by)
        bit = np.uint16(1 << part[c])
        s0 = seam[c, 0]
        s1 = seam[c, 1]
        pk = np.int8(part[c])
        v0, v1 = _rows(ay, by, r, r0, r0 + h - 1)
        for v in range(v0, v1 + 1):
            i0, i1 = _cols(ax, ay, bx, by, r, v, c0, c0 + w - 1)
            rr = v - r0
            for u in range(i0, i1 + 1):
                tr = _axis_t(u, v, ax, ay, dx, dy, inv_l2)
                zs = _front_depth(u, v, tr, ax, ay, dx, dy, za, zb, rm2, inv_s2)
                cc = u - c0
                cov[rr, cc] |= bit
                if _in_body(tr, s0, s1):
                    body[rr, cc] |= bit
                if zs < z[rr, cc]:
                    z[rr, cc] = zs
                    label[rr, cc] = pk


@njit(cache=True, inline="always")
def _is_edge(label: np.ndarray, cov: np.ndarray, body: np.ndarray, rr: int, cc: int) -> bool:
    """Whether the box pixel is on the visible outline of its part (outside the box = empty)."""
    k = label[rr, cc]
    if k < 0:
        return False
    bit = np.uint16(1 << k)
    if not (body[rr, cc] & bit):
        return False
    h, w = label.shape
    if rr == 0 or not (cov[rr - 1, cc] & bit):
        return True
    if rr == h - 1 or not (cov[rr + 1, cc] & bit):
        return True
    if cc == 0 or not (cov[rr, cc - 1] & bit):
        return True
    if cc == w - 1 or not (cov[rr, cc + 1] & bit):
        return True
    return False


@njit(cache=True)
def edge_mask(label: np.ndarray, cov: np.ndarray, body: np.ndarray, out: np.ndarray) -> None:
    """Visible part outlines of a rasterised box into ``out`` (h, w) bool."""
    h, w = label.shape
    for rr in range(h):
        for cc in range(w):
            out[rr, cc] = _is_edge(label, cov, body, rr, cc)


@njit(cache=True)
def _raster_image(
    ends: np.ndarray,
    zends: np.ndarray,
    rad_px: np.ndarray,
    rad_m: np.ndarray,
    part: np.ndarray,
    seam: np.ndarray,
    caps: np.ndarray,
    inv_s2: float,
    z: np.ndarray,
    label: np.ndarray,
    cov: np.ndarray,
    body: np.ndarray,
    rlo: np.ndarray,
    rhi: np.ndarray,
) -> tuple:
    """:func:`raster_parts` into whole-image buffers, widening the per-row extents written.

    ``rlo``/``rhi`` (H,) are the first and last column written per row (W and -1 when none);
    returns the first and last row written (H, -1 when none).
    """
    H, W = z.shape
    vmin = H
    vmax = -1
    for i in range(caps.shape[0]):
        c = caps[i]
        ax, ay = ends[c, 0, 0], ends[c, 0, 1]
        bx, by = ends[c, 1, 0], ends[c, 1, 1]
        za, zb = zends[c, 0], zends[c, 1]
        r = rad_px[c]
        rm2 = rad_m[c] * rad_m[c]
        dx, dy, inv_l2 = _axis(ax, ay, bx, by)
        bit = np.uint16(1 << part[c])
        s0 = seam[c, 0]
        s1 = seam[c, 1]
        pk = np.int8(part[c])
        v0, v1 = _rows(ay, by, r, 0, H - 1)
        for v in range(v0, v1 + 1):
            i0, i1 = _cols(ax, ay, bx, by, r, v, 0, W - 1)
            if i0 > i1:
                continue
            vmin, vmax = _widen(rlo, rhi, v, i0, i1, vmin, vmax)
            zr = z[v]
            lr = label[v]
            cr = cov[v]
            br = body[v]
            for u in range(i0, i1 + 1):
                tr = _axis_t(u, v, ax, ay, dx, dy, inv_l2)
                zs = _front_depth(u, v, tr, ax, ay, dx, dy, za, zb, rm2, inv_s2)
                cr[u] |= bit
                if _in_body(tr, s0, s1):
                    br[u] |= bit
                if zs < zr[u]:
                    zr[u] = zs
                    lr[u] = pk
    return vmin, vmax


@njit(cache=True)
def render_image(
    ends: np.ndarray,
    zends: np.ndarray,
    rad_px: np.ndarray,
    rad_m: np.ndarray,
    part: np.ndarray,
    seam: np.ndarray,
    caps: np.ndarray,
    scale: float,
    target: np.ndarray,
    z: np.ndarray,
    sil: np.ndarray,
    edge: np.ndarray,
    flags: np.ndarray,
    out_i: np.ndarray,
) -> None:
    """Whole-image render of capsules ``caps`` of one posture, touching only covered rows.

    Equal to :func:`raster_parts` over the whole image followed by :func:`edge_mask`, without
    scanning the background (profile: the edge pass over the whole image was most of the
    cost of :class:`~engine.render.capsules.PartScorer`'s fixed-part cache).

    Parameters
    ----------
    target : (H, W) bool
    z : (H, W) float64 receives the depth (inf = empty); sil, edge : (H, W) bool, zeroed by
    the caller, receive the silhouette and the visible part outlines
    flags : (H, W) uint8, zeroed by the caller, receives what :func:`part_counts` reads per
    pixel in one byte: bit 0 covered, bit 1 target and not covered, bit 2 outline
    out_i : (3,) int64 receives (|A|, |A and target|, |E|)
    """
    H, W = z.shape
    z[:] = _INF
    label = np.full((H, W), -1, np.int8)
    cov = np.zeros((H, W), np.uint16)
    body = np.zeros((H, W), np.uint16)
    rlo = np.full(H, W, np.int64)
    rhi = np.full(H, -1, np.int64)
    vmin, vmax = _raster_image(ends, zends, rad_px, rad_m, part, seam, caps,
                               1.0 / (scale * scale), z, label, cov, body, rlo, rhi)  # fmt: skip
    for v in range(H):
        for u in range(W):
            if target[v, u]:
                flags[v, u] = 2
    area = 0
    inter = 0
    ne = 0
    for v in range(vmin, vmax + 1):
        for u in range(rlo[v], rhi[v] + 1):
            if label[v, u] < 0:
                continue
            sil[v, u] = True
            f = 1
            area += 1
            if target[v, u]:
                inter += 1
            if _is_edge(label, cov, body, v, u):
                edge[v, u] = True
                f |= 4
                ne += 1
            flags[v, u] = f
    out_i[0] = area
    out_i[1] = inter
    out_i[2] = ne


@njit(cache=True)
def full_counts(
    ends: np.ndarray,
    zends: np.ndarray,
    rad_px: np.ndarray,
    rad_m: np.ndarray,
    part: np.ndarray,
    seam: np.ndarray,
    scale: float,
    target: np.ndarray,
    dt: np.ndarray,
    out_i: np.ndarray,
    out_f: np.ndarray,
) -> None:
    """Counts for d_S of many whole-body postures, each touching only the pixels it covers.

    Same geometry and depth order as :func:`raster_parts` (capsules in order, strictly nearer
    wins). The buffers span the whole image and are cleared once; each posture records per
    row the column extent it wrote, counts only inside those extents and clears them again
    afterwards, instead of clearing and scanning its whole bounding box.

    Parameters
    ----------
    ends : (N, C, 2, 2); zends : (N, C, 2)
    target : (H, W) bool target silhouette; dt : (H, W) float64 truncated edge distances
    out_i : (N, 3) int64 receives (|A|, |A and A'|, |E|); out_f : (N,) receives sum of dt on E
    """
    N, C = ends.shape[0], ends.shape[1]
    H, W = target.shape
    caps = np.arange(C)
    z = np.full((H, W), _INF)
    label = np.full((H, W), -1, np.int8)
    # one pixel of border all round, never covered: the outline test reads the 4-neighbours
    # without bounds checks, and outside the image nothing is covered, as in the full render
    cov_b = np.zeros((H + 2, W + 2), np.uint16)
    cov = cov_b[1 : H + 1, 1 : W + 1]
    body = np.zeros((H, W), np.uint16)
    rlo = np.full(H, W, np.int64)
    rhi = np.full(H, -1, np.int64)
    inv_s2 = 1.0 / (scale * scale)
    for n in range(N):
        vmin, vmax = _raster_image(ends[n], zends[n], rad_px, rad_m, part, seam, caps, inv_s2,
                                   z, label, cov, body, rlo, rhi)  # fmt: skip
        area = 0
        inter = 0
        ne = 0
        se = 0.0
        for v in range(vmin, vmax + 1):
            # row views (profile: the per-pixel 2D indexing of _is_edge was 30 % of the time)
            lr, br, tr, dr = label[v], body[v], target[v], dt[v]
            up, cr, dn = cov_b[v], cov_b[v + 1], cov_b[v + 2]
            for u in range(rlo[v], rhi[v] + 1):
                k = lr[u]
                if k < 0:
                    continue
                area += 1
                if tr[u]:
                    inter += 1
                bit = np.uint16(1 << k)
                # _is_edge: a body pixel of its part with a 4-neighbour the part does not cover
                if br[u] & bit and not (up[u + 1] & dn[u + 1] & cr[u] & cr[u + 2] & bit):
                    ne += 1
                    se += dr[u]
        for v in range(vmin, vmax + 1):
            for u in range(rlo[v], rhi[v] + 1):
                z[v, u] = _INF
                label[v, u] = -1
                cov[v, u] = 0
                body[v, u] = 0
            rlo[v] = W
            rhi[v] = -1
        out_i[n, 0] = area
        out_i[n, 1] = inter
        out_i[n, 2] = ne
        out_f[n] = se


@njit(cache=True)
def part_counts(
    ends: np.ndarray,
    zends: np.ndarray,
    rad_px: np.ndarray,
    rad_m: np.ndarray,
    seam: np.ndarray,
    caps: np.ndarray,
    scale: float,
    fixed_flags: np.ndarray,
    fixed_z: np.ndarray,
    dt: np.ndarray,
    out_i: np.ndarray,
    out_f: np.ndarray,
) -> None:
    """Changes of the d_S counts when one part (capsules ``caps``) joins a fixed body.

    For each sample n: added silhouette pixels, added overlap, visible outline pixels of the
    moving part, and fixed outline pixels it hides (with their dt sums). Only the pixels the
    moving part covers (and their 4-neighbours) are touched. Same geometry as
    :func:`raster_parts` specialised to one part: one flag byte per pixel (bit 0 covered,
    bit 1 covered outside a seam cap), the z-buffer written on first cover, per-row column
    extents so the counting pass skips uncovered rows and columns, and the extents cleared
    after counting instead of clearing the whole box (profile: the generic path spent most
    of its time initialising and scanning the four full box buffers). The fixed body comes
    as one byte per pixel too (see :func:`render_image`), one read instead of three.

    Parameters
    ----------
    ends : (S, C, 2, 2); zends : (S, C, 2); only rows ``caps`` are read
    fixed_flags : (H, W) uint8 from :func:`render_image`; fixed_z : (H, W) float64 (inf = empty)
    out_i : (S, 4) int64 (added area, added overlap, moving edges, hidden fixed edges)
    out_f : (S, 2) float64 (dt sum on moving edges, dt sum on hidden fixed edges)
    """
    S = ends.shape[0]
    H, W = fixed_z.shape
    # one pixel of border all round, never written, so the outline test needs no bounds checks
    zb = np.empty((H + 2, W + 2))
    fb = np.zeros((H + 2, W + 2), np.uint8)
    rlo = np.full(H, W, np.int64)
    rhi = np.full(H, -1, np.int64)
    inv_s2 = 1.0 / (scale * scale)
    # the three passes are inlined (inline="always"): as plain calls the kernel ran 2-5 %
    # slower (48 calls of 40 samples at 320 x 240: 17.4 ms inlined, as before the split)
    for n in range(S):
        vmin, vmax = _raster_part(ends[n], zends[n], rad_px, rad_m, seam, caps, inv_s2,
                                  fixed_flags, zb, fb, rlo, rhi)  # fmt: skip
        add_a, add_i, ne, nh, se, sh = _count_part(fb, zb, fixed_flags, fixed_z, dt, rlo, rhi,
                                                   vmin, vmax)  # fmt: skip
        _clear_part(fb, rlo, rhi, vmin, vmax)
        out_i[n, 0] = add_a
        out_i[n, 1] = add_i
        out_i[n, 2] = ne
        out_i[n, 3] = nh
        out_f[n, 0] = se
        out_f[n, 1] = sh


@njit(cache=True, inline="always")
def _raster_part(
    ends: np.ndarray,
    zends: np.ndarray,
    rad_px: np.ndarray,
    rad_m: np.ndarray,
    seam: np.ndarray,
    caps: np.ndarray,
    inv_s2: float,
    fixed_flags: np.ndarray,
    zb: np.ndarray,
    fb: np.ndarray,
    rlo: np.ndarray,
    rhi: np.ndarray,
) -> tuple:
    """Write pass of :func:`part_counts` for one sample: flag byte and depth per pixel.

    ``ends`` (C, 2, 2) and ``zends`` (C, 2) are the sample's; ``zb``, ``fb`` (H + 2, W + 2)
    the bordered depth and flag buffers (bit 0 covered, bit 1 outside a seam cap),
    ``rlo``/``rhi`` (H,) the per-row extents widened as written. Returns the first and last
    row written (H, -1 when none).
    """
    H, W = fixed_flags.shape
    vmin = H
    vmax = -1
    for i in range(caps.shape[0]):
        c = caps[i]
        ax, ay = ends[c, 0, 0], ends[c, 0, 1]
        bx, by = ends[c, 1, 0], ends[c, 1, 1]
        za, zbb = zends[c, 0], zends[c, 1]
        r = rad_px[c]
        rm2 = rad_m[c] * rad_m[c]
        dx, dy, inv_l2 = _axis(ax, ay, bx, by)
        s0 = seam[c, 0]
        s1 = seam[c, 1]
        v0, v1 = _rows(ay, by, r, 0, H - 1)
        for v in range(v0, v1 + 1):
            i0, i1 = _cols(ax, ay, bx, by, r, v, 0, W - 1)
            if i0 > i1:
                continue
            vmin, vmax = _widen(rlo, rhi, v, i0, i1, vmin, vmax)
            fr = fb[v + 1]
            zr = zb[v + 1]
            xr = fixed_flags[v]
            for u in range(i0, i1 + 1):
                tr = _axis_t(u, v, ax, ay, dx, dy, inv_l2)
                f = fr[u + 1]
                if not xr[u] & 1:
                    # nothing fixed here: visible whatever its depth, skip the sqrt
                    zr[u + 1] = -_INF
                else:
                    zs = _front_depth(u, v, tr, ax, ay, dx, dy, za, zbb, rm2, inv_s2)
                    if f == 0 or zs < zr[u + 1]:
                        zr[u + 1] = zs
                f |= 1
                if _in_body(tr, s0, s1):
                    f |= 2
                fr[u + 1] = f
    return vmin, vmax


@njit(cache=True, inline="always")
def _count_part(
    fb: np.ndarray,
    zb: np.ndarray,
    fixed_flags: np.ndarray,
    fixed_z: np.ndarray,
    dt: np.ndarray,
    rlo: np.ndarray,
    rhi: np.ndarray,
    vmin: int,
    vmax: int,
) -> tuple:
    """Counting pass of :func:`part_counts` over the extents one sample wrote.

    ``fixed_flags`` (H, W): bit 0 covered, bit 1 target and not covered, bit 2 outline.
    Returns (added area, added overlap, moving edges, hidden fixed edges, dt sum on moving
    edges, dt sum on hidden fixed edges) (eq. 4.1-4.3 counts).
    """
    H, W = fixed_z.shape
    add_a = 0
    add_i = 0
    ne = 0
    nh = 0
    se = 0.0
    sh = 0.0
    for v in range(vmin, vmax + 1):
        fr = fb[v + 1]
        up = fb[v]
        dn = fb[v + 2]
        zr = zb[v + 1]
        xr = fixed_flags[v]
        fzr = fixed_z[v]
        for u in range(rlo[v], rhi[v] + 1):
            f = fr[u + 1]
            if f == 0:
                continue
            x = xr[u]
            if not x & 1:
                add_a += 1
                if x & 2:
                    add_i += 1
            if zr[u + 1] < fzr[u]:
                if x & 4:
                    nh += 1
                    sh += dt[v, u]
                # outside the image nothing is covered, exactly as in the full render; the
                # test stays inline (as a helper function it cost 60 % of the kernel's time)
                if f & 2 and (
                    v == 0 or v == H - 1 or u == 0 or u == W - 1
                    or not (up[u + 1] & 1) or not (dn[u + 1] & 1)
                    or not (fr[u] & 1) or not (fr[u + 2] & 1)
                ):  # fmt: skip
                    ne += 1
                    se += dt[v, u]
    return add_a, add_i, ne, nh, se, sh


@njit(cache=True, inline="always")
def _clear_part(fb: np.ndarray, rlo: np.ndarray, rhi: np.ndarray, vmin: int, vmax: int) -> None:
    """Clear the flags (H + 2, W + 2) one sample wrote and reset its row extents (H,)."""
    W = fb.shape[1] - 2
    for v in range(vmin, vmax + 1):
        fr = fb[v + 1]
        for u in range(rlo[v], rhi[v] + 1):
            fr[u + 1] = 0
        rlo[v] = W
        rhi[v] = -1


# ----------------------------------------------------------------------------- width-robust


@njit(cache=True, inline="always")
def _sample_sd(sd: np.ndarray, u: float, v: float) -> float:
    """Bilinear signed distance at (u, v); beyond the image, the border value minus the way out."""
    H, W = sd.shape
    uc = min(max(u, 0.0), W - 1.0)
    vc = min(max(v, 0.0), H - 1.0)
    away = math.hypot(u - uc, v - vc)
    c0 = min(int(uc), W - 2) if W > 1 else 0
    r0 = min(int(vc), H - 2) if H > 1 else 0
    fu = uc - c0
    fv = vc - r0
    c1 = min(c0 + 1, W - 1)
    r1 = min(r0 + 1, H - 1)
    val = (1 - fv) * ((1 - fu) * sd[r0, c0] + fu * sd[r0, c1]) + fv * (
        (1 - fu) * sd[r1, c0] + fu * sd[r1, c1]
    )
    return val - away


@njit(cache=True)
def width_costs(
    ends: np.ndarray,
    rad: np.ndarray,
    cap_part: np.ndarray,
    n_parts: int,
    sd: np.ndarray,
    deep_k: float,
    sigma_out: float,
    out_cap: float,
    n_pts: int,
    cover: np.ndarray,
    inflate: float,
    inflate_px: float,
    tau: float,
    out_center: np.ndarray,
    out_cover: np.ndarray,
    out_part: np.ndarray,
) -> None:
    """Centreline and coverage terms of the width-robust likelihood (see capsules.py).

    ends (N, C, 2, 2) capsule axis ends (u, v) px; rad (C,) px; sd (H, W) signed distance to
    the silhouette contour (+ inside); cover (M, 2) silhouette points (u, v). Writes
    out_center (N,), out_cover (N,), out_part (N, n_parts).
    """
    N = ends.shape[0]
    C = ends.shape[1]
    M = cover.shape[0]
    psum = np.zeros(n_parts)
    pcnt = np.zeros(n_parts)
    for n in range(N):
        psum[:] = 0.0
        pcnt[:] = 0.0
        for c in range(C):
            ax = ends[n, c, 0, 0]
            ay = ends[n, c, 0, 1]
            bx = ends[n, c, 1, 0]
            by = ends[n, c, 1, 1]
            deep = max(deep_k * rad[c], 0.5)
            p = cap_part[c]
            for i in range(n_pts):
                t = i / (n_pts - 1.0) if n_pts > 1 else 0.5
                s = _sample_sd(sd, ax + t * (bx - ax), ay + t * (by - ay))
                if s >= deep:
                    cost = 0.0
                elif s >= 0.0:
                    cost = 1.0 - s / deep
                else:
                    cost = min(1.0 - s / sigma_out, out_cap)
                psum[p] += cost
                pcnt[p] += 1.0
        tot = 0.0
        k = 0
        for p in range(n_parts):
            if pcnt[p] > 0:
                out_part[n, p] = psum[p] / pcnt[p]
                tot += out_part[n, p]
                k += 1
        out_center[n] = tot / max(k, 1)
        miss = 0.0
        for m in range(M):
            qx = cover[m, 0]
            qy = cover[m, 1]
            best = _INF
            for c in range(C):
                ax = ends[n, c, 0, 0]
                ay = ends[n, c, 0, 1]
                dx = ends[n, c, 1, 0] - ax
                dy = ends[n, c, 1, 1] - ay
                ll = dx * dx + dy * dy
                t = ((qx - ax) * dx + (qy - ay) * dy) / ll if ll > 1e-12 else 0.0
                t = min(max(t, 0.0), 1.0)
                d = math.hypot(qx - ax - t * dx, qy - ay - t * dy) - (inflate * rad[c] + inflate_px)
                if d < best:
                    best = d
                    if best <= 0.0:
                        break
            if best > 0.0:
                miss += min(best / tau, 1.0)
        out_cover[n] = miss / max(M, 1)
