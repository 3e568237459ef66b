"""A whole render of one posture (silhouette, part labels, visible outlines, depth) and the
silhouettes of many postures (thesis 4.3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.render import _raster
from engine.render.camera import Camera
from engine.render.capsules.projection import (
    _ALL_CAPS,
    _PART_I64,
    SEAM_END,
    ProjectedCapsules,
    _check_joints,
    _project,
)


@dataclass(frozen=True)
class Render:
    """A rendered capsule body over an image box.

    Attributes
    ----------
    silhouette : ndarray of bool, shape (H, W)
    labels : ndarray of int8, shape (H, W)
        Visible part index 0..11, -1 for background.
    edges : ndarray of bool, shape (H, W)
        Visible part outlines (see the module docstring).
    depth : ndarray of float64, shape (H, W)
        Depth of the visible surface, metres; inf on the background.
    box : tuple of int
        (row0, row1, col0, col1), half-open, of the image window rendered.
    """

    silhouette: np.ndarray
    labels: np.ndarray
    edges: np.ndarray
    depth: np.ndarray
    box: tuple[int, int, int, int]


def _raster_box(
    pc: ProjectedCapsules, caps: np.ndarray, box: tuple[int, int, int, int]
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    r0, r1, c0, c1 = box
    z = np.full((r1 - r0, c1 - c0), np.inf)
    label = np.full(z.shape, -1, dtype=np.int8)
    cov = np.zeros(z.shape, dtype=np.uint16)
    body = np.zeros(z.shape, dtype=np.uint16)
    _raster.raster_parts(
        pc.ends_px, pc.depth, pc.radius_px, pc.radius_m, _PART_I64, SEAM_END, caps,
        pc.scale, r0, c0, z, label, cov, body,
    )  # fmt: skip
    return z, label, cov, body


def _render_caps(
    pc: ProjectedCapsules, caps: np.ndarray, camera: Camera, box: tuple[int, int, int, int]
) -> Render:
    r0, r1, c0, c1 = box
    # one pixel more on each side (inside the image) so outlines at the box border are right
    g = (max(r0 - 1, 0), min(r1 + 1, camera.height), max(c0 - 1, 0), min(c1 + 1, camera.width))
    z, label, cov, body = _raster_box(pc, caps, g)
    edges = np.empty(z.shape, dtype=bool)
    _raster.edge_mask(label, cov, body, edges)
    crop = np.s_[r0 - g[0] : r1 - g[0], c0 - g[2] : c1 - g[2]]
    return Render(
        silhouette=label[crop] >= 0,
        labels=label[crop].copy(),
        edges=edges[crop].copy(),
        depth=z[crop].copy(),
        box=box,
    )


def _check_box(box: tuple[int, int, int, int] | None, camera: Camera) -> tuple[int, int, int, int]:
    if box is None:
        return (0, camera.height, 0, camera.width)
    try:
        r0, r1, c0, c1 = (int(x) for x in box)
    except (TypeError, ValueError) as exc:
        raise InvalidInput(f"box must be (row0, row1, col0, col1), got {box!r}") from exc
    if not (0 <= r0 <= r1 <= camera.height and 0 <= c0 <= c1 <= camera.width):
        raise InvalidInput(f"box {box!r} must lie inside the {camera.height}x{camera.width} image")
    return (r0, r1, c0, c1)


def render(
    joints: np.ndarray,
    shape: BodyShape,
    camera: Camera,
    *,
    box: tuple[int, int, int, int] | None = None,
) -> Render:
    """Render one posture's capsule body: silhouette, part labels, edges (thesis 4.3).

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
    shape : BodyShape
    camera : Camera
        Image size is ``(camera.height, camera.width)``.
    box : (row0, row1, col0, col1), optional
        Half-open image window to render; the whole image by default. The result is the
        crop of the whole-image render (edges at the window border included correctly).

    Returns
    -------
    Render

    Raises
    ------
    InvalidInput
        Bad ``joints`` shape or values, or ``box`` outside the image.
    """
    j = _check_joints(joints, "joints", batch=False)
    b = _check_box(box, camera)
    return _render_caps(_project(j, shape, camera), _ALL_CAPS, camera, b)


def silhouettes(joints: np.ndarray, shape: BodyShape, camera: Camera) -> np.ndarray:
    """Silhouettes of many postures, shape (N, H, W) bool.

    Raises
    ------
    InvalidInput
        If ``joints`` is not (N, 17, 3) or not finite.
    """
    j = _check_joints(joints, "joints", batch=True)
    pc = _project(j, shape, camera)
    out = np.zeros((j.shape[0], camera.height, camera.width), dtype=bool)
    _raster.fill_silhouettes(pc.ends_px, pc.radius_px, out)
    return out
