"""Fast analytic rasteriser of the capsule body and the image measures d_A, d_E, d_S on it.

Thesis 4.3 renders the posed mesh with OpenGL and 4.4.1 compares the rendered region with the
input region (d_A eq. 4.1, d_E eq. 4.2-4.3, d_S eq. 4.4). The body here is a union of capsules
(:mod:`engine.body.shapes`), whose scaled orthographic projection is *exactly* a 2D capsule:
the points within ``radius_m * camera.scale`` pixels of the projected axis segment. So
coverage is computed analytically, row by row, with no mesh and no OpenGL; the silhouette
overlap of a posture needs O(rows x capsules) work and never an image.

What the rendered region contains
---------------------------------
silhouette
    pixels (u, v) (centres at integers; row = v, col = u) within the radius of any capsule.
labels
    the part of the nearest capsule surface at the pixel (see depth in
    :mod:`engine.render._raster`).
edges
    the *visible outline of every part*: pixels where part k is the nearest surface and that
    have a 4-neighbour not covered by part k. This is the silhouette boundary plus the
    internal boundaries where a nearer part overlaps a farther one (an arm in front of the
    torso), and no edges inside a part (its capsules are merged first). Seams at joints are
    removed by one local rule: a capsule running along a bone does not contribute the round
    cap at an end that sits on a joint shared with another part (``SEAM_END``), since that
    cap lies inside the neighbouring part. Consequence (an approximation of a real image's
    edges, not of the render): on the outside of a strongly bent joint the short arc of that
    cap that sticks out is not an edge. Because every part's outline depends only on its own
    capsules and the depth order, the incremental :class:`PartScorer` is exact.

Thesis 4.6.2: in belief propagation one part moves while the others keep their poses from the
previous iteration, so :class:`PartScorer` caches the others' rendering and scores many poses
of the moving part touching only that part's bounding box.

    projection   seam ends, each part's capsules, postures' capsules in the image
    full         the whole render of one posture; silhouettes of many
    target       the input region prepared for comparison; d_A and d_S of many postures
    part_scorer  PartScorer: d_S with one part moving over the cached rest (4.6.2)
"""

from engine.render.capsules.full import Render, render, silhouettes
from engine.render.capsules.part_scorer import PartScorer
from engine.render.capsules.projection import (
    PART_CAPSULES,
    SEAM_END,
    ProjectedCapsules,
    project_capsules,
)
from engine.render.capsules.target import Target, d_A_batch, d_S_batch

__all__ = [
    "PART_CAPSULES",
    "SEAM_END",
    "PartScorer",
    "ProjectedCapsules",
    "Render",
    "Target",
    "d_A_batch",
    "d_S_batch",
    "project_capsules",
    "render",
    "silhouettes",
]
