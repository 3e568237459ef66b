"""Numba kernels of the analytic capsule rasteriser (private; see :mod:`engine.render.capsules`).

Why numba: the work is per image row and per pixel of small, data-dependent boxes (one box
per posture sample), which numpy can only express with large temporary arrays per sample; a
profile of the numpy version spent nearly all its time allocating and masking those
temporaries. Every kernel here is a plain loop over rows and pixels. The kernels called from
Python are compiled ``nogil``: stage 2 scores its video frames on threads (:mod:`engine.threads`).

    spans        where a row meets a capsule, depth of its front surface (inlined helpers)
    silhouettes  silhouette size and overlap from row spans, no image (d_A), of whole postures
                 or of one part joining a fixed body; silhouette images
    depth        depth-ordered render: part labels, visible outlines, d_S counts of postures
    incremental  the change of the d_S counts when one part moves (PartScorer)

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

from engine.render._raster.depth import edge_mask, full_counts, raster_parts, render_image
from engine.render._raster.incremental import part_counts
from engine.render._raster.silhouettes import (
    fill_silhouettes,
    part_sil_counts,
    row_unions,
    sil_counts,
    sil_counts_smooth,
)
from engine.render._raster.spans import row_span

__all__ = [
    "edge_mask",
    "fill_silhouettes",
    "full_counts",
    "part_counts",
    "part_sil_counts",
    "raster_parts",
    "render_image",
    "row_span",
    "row_unions",
    "sil_counts",
    "sil_counts_smooth",
]
