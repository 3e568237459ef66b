"""Depth-ordered rendering of whole postures: part labels by z-buffer, visible part outlines,
and the d_S counts (eq. 4.1-4.4) of many postures touching only the pixels each covers.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from engine.render._raster.spans import (
    _INF,
    _axis,
    _axis_t,
    _cols,
    _front_depth,
    _in_body,
    _rows,
    _widen,
)


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
def edge_mask(label: np.ndarray, cov: np.ndarray, body: np.ndarray, out: np.ndarray) -> None:
    """Visible part outlines of a rasterised box into ``out`` (h, w) bool."""
    h, w = label.shape
    for rr in range(h):
        for cc in range(w):
            out[rr, cc] = _is_edge(label, cov, body, rr, cc)


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
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


@njit(cache=True, nogil=True)
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
            # row views (profile: the per-pixel 2D indexing of _is_edge was a large share)
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
