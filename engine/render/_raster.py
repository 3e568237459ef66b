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
            r = rad[c]
            a = min(e[c, 0, 1], e[c, 1, 1])
            b = max(e[c, 0, 1], e[c, 1, 1])
            rlo[c] = max(_ceil(a - r), 0)
            rhi[c] = min(_floor(b + r), H - 1)
            vmin = min(vmin, rlo[c])
            vmax = max(vmax, rhi[c])
        area = 0
        inter = 0
        for v in range(vmin, vmax + 1):
            m = 0
            for c in range(C):
                if rlo[c] <= v <= rhi[c]:
                    a0, a1 = row_span(e[c, 0, 0], e[c, 0, 1], e[c, 1, 0], e[c, 1, 1], rad[c], v)
                    if not a0 <= a1:
                        continue
                    i0 = max(_ceil(a0), 0)
                    i1 = min(_floor(a1), W - 1)
                    if i0 <= i1:
                        # insertion sort by start column
                        j = m
                        while j > 0 and lo[j - 1] > i0:
                            lo[j] = lo[j - 1]
                            hi[j] = hi[j - 1]
                            j -= 1
                        lo[j] = i0
                        hi[j] = i1
                        m += 1
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


@njit(cache=True)
def fill_silhouettes(ends: np.ndarray, rad: np.ndarray, out: np.ndarray) -> None:
    """Write the silhouettes of many postures into ``out`` (N, H, W) bool (zeroed by caller)."""
    N, C = ends.shape[0], ends.shape[1]
    H, W = out.shape[1], out.shape[2]
    for n in range(N):
        e = ends[n]
        for c in range(C):
            r = rad[c]
            v0 = max(_ceil(min(e[c, 0, 1], e[c, 1, 1]) - r), 0)
            v1 = min(_floor(max(e[c, 0, 1], e[c, 1, 1]) + r), H - 1)
            for v in range(v0, v1 + 1):
                a0, a1 = row_span(e[c, 0, 0], e[c, 0, 1], e[c, 1, 0], e[c, 1, 1], r, v)
                if not a0 <= a1:
                    continue
                i0 = max(_ceil(a0), 0)
                i1 = min(_floor(a1), W - 1)
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
        dx = bx - ax
        dy = by - ay
        l2 = dx * dx + dy * dy
        inv_l2 = 1.0 / l2 if l2 > 0.0 else 0.0
        bit = np.uint16(1 << part[c])
        s0 = seam[c, 0]
        s1 = seam[c, 1]
        pk = np.int8(part[c])
        v0 = max(_ceil(min(ay, by) - r), r0)
        v1 = min(_floor(max(ay, by) + r), r0 + h - 1)
        for v in range(v0, v1 + 1):
            a0, a1 = row_span(ax, ay, bx, by, r, v)
            if not a0 <= a1:
                continue
            i0 = max(_ceil(a0), c0)
            i1 = min(_floor(a1), c0 + w - 1)
            rr = v - r0
            for u in range(i0, i1 + 1):
                tr = ((u - ax) * dx + (v - ay) * dy) * inv_l2
                t = min(max(tr, 0.0), 1.0)
                px = u - (ax + t * dx)
                py = v - (ay + t * dy)
                d2 = (px * px + py * py) * inv_s2
                zs = za + t * (zb - za) - math.sqrt(max(rm2 - d2, 0.0))
                cc = u - c0
                cov[rr, cc] |= bit
                if not ((tr < 0.0 and s0) or (tr > 1.0 and s1)):
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
    """Counts for d_S of many whole-body postures, each rasterised only inside its box.

    Parameters
    ----------
    ends : (N, C, 2, 2); zends : (N, C, 2)
    target : (H, W) bool target silhouette; dt : (H, W) float64 truncated edge distances
    out_i : (N, 3) int64 receives (|A|, |A and A'|, |E|); out_f : (N,) receives sum of dt on E
    """
    N, C = ends.shape[0], ends.shape[1]
    H, W = target.shape
    caps = np.arange(C)
    zb = np.empty((H, W))
    lb = np.empty((H, W), np.int8)
    cb = np.empty((H, W), np.uint16)
    bb = np.empty((H, W), np.uint16)
    for n in range(N):
        # one pixel of margin so the outline test sees uncovered neighbours inside the box
        r0, r1, c0, c1 = _bbox(ends[n], rad_px, caps, H, W, 1)
        h = r1 - r0
        w = c1 - c0
        z = zb[:h, :w]
        label = lb[:h, :w]
        cov = cb[:h, :w]
        body = bb[:h, :w]
        z[:] = _INF
        label[:] = -1
        cov[:] = 0
        body[:] = 0
        raster_parts(ends[n], zends[n], rad_px, rad_m, part, seam, caps, scale, r0, c0,
                     z, label, cov, body)  # fmt: skip
        area = 0
        inter = 0
        ne = 0
        se = 0.0
        for rr in range(h):
            for cc in range(w):
                if label[rr, cc] < 0:
                    continue
                area += 1
                if target[r0 + rr, c0 + cc]:
                    inter += 1
                # the box has a one-pixel margin or ends at the image border, outside which
                # nothing is covered, exactly as in the full render
                if _is_edge(label, cov, body, rr, cc):
                    ne += 1
                    se += dt[r0 + rr, c0 + cc]
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
    fixed_sil: np.ndarray,
    fixed_z: np.ndarray,
    fixed_edge: np.ndarray,
    target: np.ndarray,
    dt: np.ndarray,
    out_i: np.ndarray,
    out_f: np.ndarray,
) -> None:
    """Changes of the d_S counts when one part (capsules ``caps``) joins a fixed body.

    For each sample n: added silhouette pixels, added overlap, visible outline pixels of the
    moving part, and fixed outline pixels it hides (with their dt sums). Only the moving
    part's box (plus one pixel for the outline test) is touched. Same geometry as
    :func:`raster_parts` specialised to one part: one flag byte per pixel (bit 0 covered,
    bit 1 covered outside a seam cap), the z-buffer written on first cover, and per-row
    column extents so the counting pass skips uncovered pixels (profile: the generic path
    spent most of its time initialising and scanning the four full box buffers).

    Parameters
    ----------
    ends : (S, C, 2, 2); zends : (S, C, 2); only rows ``caps`` are read
    fixed_sil, fixed_edge : (H, W) bool; fixed_z : (H, W) float64 (inf = empty)
    out_i : (S, 4) int64 (added area, added overlap, moving edges, hidden fixed edges)
    out_f : (S, 2) float64 (dt sum on moving edges, dt sum on hidden fixed edges)
    """
    S = ends.shape[0]
    H, W = target.shape
    zb = np.empty((H, W))
    fb = np.zeros((H, W), np.uint8)
    rlo = np.empty(H, np.int64)
    rhi = np.empty(H, np.int64)
    inv_s2 = 1.0 / (scale * scale)
    for n in range(S):
        r0, r1, c0, c1 = _bbox(ends[n], rad_px, caps, H, W, 1)
        h = r1 - r0
        w = c1 - c0
        for rr in range(h):
            rlo[rr] = w
            rhi[rr] = -1
            for cc in range(w):
                fb[rr, cc] = 0
        for i in range(caps.shape[0]):
            c = caps[i]
            ax, ay = ends[n, c, 0, 0], ends[n, c, 0, 1]
            bx, by = ends[n, c, 1, 0], ends[n, c, 1, 1]
            za, zbb = zends[n, c, 0], zends[n, c, 1]
            r = rad_px[c]
            rm2 = rad_m[c] * rad_m[c]
            dx = bx - ax
            dy = by - ay
            l2 = dx * dx + dy * dy
            inv_l2 = 1.0 / l2 if l2 > 0.0 else 0.0
            s0 = seam[c, 0]
            s1 = seam[c, 1]
            v0 = max(_ceil(min(ay, by) - r), r0)
            v1 = min(_floor(max(ay, by) + r), r1 - 1)
            for v in range(v0, v1 + 1):
                a0, a1 = row_span(ax, ay, bx, by, r, v)
                if not a0 <= a1:
                    continue
                i0 = max(_ceil(a0), c0)
                i1 = min(_floor(a1), c1 - 1)
                if i0 > i1:
                    continue
                rr = v - r0
                rlo[rr] = min(rlo[rr], i0 - c0)
                rhi[rr] = max(rhi[rr], i1 - c0)
                for u in range(i0, i1 + 1):
                    tr = ((u - ax) * dx + (v - ay) * dy) * inv_l2
                    cc = u - c0
                    f = fb[rr, cc]
                    if fixed_z[v, u] == _INF:
                        # nothing fixed here: visible whatever its depth, skip the sqrt
                        zb[rr, cc] = -_INF
                    else:
                        t = min(max(tr, 0.0), 1.0)
                        px = u - (ax + t * dx)
                        py = v - (ay + t * dy)
                        d2 = (px * px + py * py) * inv_s2
                        zs = za + t * (zbb - za) - math.sqrt(max(rm2 - d2, 0.0))
                        if f == 0 or zs < zb[rr, cc]:
                            zb[rr, cc] = zs
                    f |= 1
                    if not ((tr < 0.0 and s0) or (tr > 1.0 and s1)):
                        f |= 2
                    fb[rr, cc] = f
        add_a = 0
        add_i = 0
        ne = 0
        nh = 0
        se = 0.0
        sh = 0.0
        for rr in range(h):
            y = r0 + rr
            for cc in range(rlo[rr], rhi[rr] + 1):
                f = fb[rr, cc]
                if f == 0:
                    continue
                x = c0 + cc
                if not fixed_sil[y, x]:
                    add_a += 1
                    if target[y, x]:
                        add_i += 1
                if zb[rr, cc] < fixed_z[y, x]:
                    if fixed_edge[y, x]:
                        nh += 1
                        sh += dt[y, x]
                    if f & 2 and (
                        rr == 0 or rr == h - 1 or cc == 0 or cc == w - 1
                        or not (fb[rr - 1, cc] & 1) or not (fb[rr + 1, cc] & 1)
                        or not (fb[rr, cc - 1] & 1) or not (fb[rr, cc + 1] & 1)
                    ):  # fmt: skip
                        ne += 1
                        se += dt[y, x]
        out_i[n, 0] = add_a
        out_i[n, 1] = add_i
        out_i[n, 2] = ne
        out_i[n, 3] = nh
        out_f[n, 0] = se
        out_f[n, 1] = sh
