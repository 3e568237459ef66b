"""The change of the d_S counts when one part moves over a fixed rest of the body (thesis
4.6.2), for :class:`engine.render.capsules.PartScorer`.
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
    # the three passes are inlined (inline="always"): as plain calls the kernel ran a few
    # per cent slower; inlined, as fast as before the split
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
                # test stays inline (as a helper function it cost most of the kernel's time)
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
