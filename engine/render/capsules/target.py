"""The input body region prepared for comparison, and d_A and d_S of many postures against it
(thesis 4.4.1, eq. 4.1-4.4), with no image allocated.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.measures import LAMBDA_A, LAMBDA_E, SIGMA_PX, XI, edge_cost_map
from engine.render import _raster
from engine.render.camera import Camera
from engine.render.capsules.full import Render
from engine.render.capsules.projection import (
    _PART_I64,
    SEAM_END,
    ProjectedCapsules,
    _check_joints,
    _project,
)


@dataclass(frozen=True)
class Target:
    """The input body region S' prepared for fast comparison (thesis 4.4.1).

    Attributes
    ----------
    silhouette : ndarray of bool, shape (H, W)
        Input silhouette A'.
    edges : ndarray of bool, shape (H, W)
        Input edges E'.
    cost : ndarray of float64, shape (H, W)
        min(D^2 / sigma^2, xi), D = distance to the nearest pixel of E' (eq. 4.3).
    prefix : ndarray of int32, shape (H, W + 1)
        Row prefix sums of ``silhouette`` (overlap of a column span in O(1)).
    area : int
        |A'|.
    sigma_px, xi : float
        Parameters of eq. 4.3.
    """

    silhouette: np.ndarray
    edges: np.ndarray
    cost: np.ndarray
    prefix: np.ndarray
    area: int
    sigma_px: float
    xi: float

    @classmethod
    def from_masks(
        cls,
        silhouette: np.ndarray,
        edges: np.ndarray,
        *,
        sigma_px: float = SIGMA_PX,
        xi: float = XI,
    ) -> Target:
        """Precompute the truncated squared edge distance map and the silhouette sums.

        Parameters
        ----------
        silhouette, edges : ndarray of bool, shape (H, W)
        sigma_px : float
            sigma of eq. 4.3, pixels (default :data:`engine.measures.SIGMA_PX`).
        xi : float
            Truncation xi of eq. 4.3 (default :data:`engine.measures.XI`).

        Raises
        ------
        InvalidInput
            Masks not 2D, of different shapes, or non-positive ``sigma_px`` / ``xi``.
        """
        sil = np.asarray(silhouette)
        edg = np.asarray(edges)
        if sil.ndim != 2 or sil.shape[0] < 1 or sil.shape[1] < 1:
            raise InvalidInput(f"silhouette must be a 2D (H, W) mask, got shape {sil.shape}")
        if edg.shape != sil.shape:
            raise InvalidInput(
                f"edges must have the silhouette's shape {sil.shape}, got {edg.shape}"
            )
        sil = np.ascontiguousarray(sil.astype(bool))
        edg = np.ascontiguousarray(edg.astype(bool))
        cost = edge_cost_map(edg, sigma_px=sigma_px, xi=xi)
        prefix = np.zeros((sil.shape[0], sil.shape[1] + 1), dtype=np.int32)
        np.cumsum(sil, axis=1, out=prefix[:, 1:])
        return cls(sil, edg, cost, prefix, int(np.count_nonzero(sil)), float(sigma_px), float(xi))

    @classmethod
    def from_render(cls, r: Render, **kwargs: float) -> Target:
        """A target from a rendered body (identity tests, synthetic cases)."""
        return cls.from_masks(r.silhouette, r.edges, **kwargs)


def _check_camera_target(camera: Camera, target: Target) -> None:
    if target.silhouette.shape != (camera.height, camera.width):
        raise InvalidInput(
            f"target is {target.silhouette.shape} (H, W) but the camera renders "
            f"({camera.height}, {camera.width})"
        )


def _d_A(area: np.ndarray, inter: np.ndarray, target_area: int) -> np.ndarray:
    total = area + target_area
    return np.where(total > 0, 1.0 - 2.0 * inter / np.maximum(total, 1), 0.0)


def _d_E(sum_cost: np.ndarray, count: np.ndarray, xi: float) -> np.ndarray:
    # normalised by the number of rendered edge pixels so postures with long and short
    # outlines are comparable; no rendered edge at all scores the worst value xi
    return np.where(count > 0, sum_cost / np.maximum(count, 1), xi)


def _project_batch(
    joints: np.ndarray, target: Target, shape: BodyShape, camera: Camera
) -> ProjectedCapsules:
    """Checked ``joints`` (N, 17, 3) and ``target`` of a batch measure, projected."""
    j = _check_joints(joints, "joints", batch=True)
    _check_camera_target(camera, target)
    return _project(j, shape, camera)


def d_A_batch(
    joints: np.ndarray,
    target: Target,
    shape: BodyShape,
    camera: Camera,
    *,
    subpixel_rows: int = 0,
) -> np.ndarray:
    """Silhouette difference d_A (thesis eq. 4.1) of many postures, no image allocated.

    By default a pixel is in the body when its centre is (as in :func:`render`). With
    ``subpixel_rows`` > 0 (beyond the thesis) the body's area is measured continuously: that
    many sub-rows per pixel row with exact column spans, the target's pixels as unit boxes,
    so d_A changes smoothly when a part moves by a fraction of a pixel instead of only when
    a pixel centre is crossed. Measured to change little in stage 3
    (``CandidateSettings.subpixel_rows``).

    Parameters
    ----------
    joints : ndarray, shape (N, 17, 3)
    target : Target
    shape : BodyShape
    camera : Camera
    subpixel_rows : int
        0 (pixel centres) or the sub-rows per pixel row.

    Returns
    -------
    d : ndarray, shape (N,)

    Raises
    ------
    InvalidInput
        Bad ``joints`` or ``subpixel_rows``, or a target whose size differs from the camera's
        image.
    """
    if not isinstance(subpixel_rows, int | np.integer) or subpixel_rows < 0:
        raise InvalidInput(f"subpixel_rows must be an integer >= 0, got {subpixel_rows!r}")
    pc = _project_batch(joints, target, shape, camera)
    if subpixel_rows:
        smooth = np.empty((pc.ends_px.shape[0], 2))
        _raster.sil_counts_smooth(
            pc.ends_px, pc.radius_px, target.prefix, int(subpixel_rows), smooth
        )
        return _d_A(smooth[:, 0], smooth[:, 1], target.area)
    out = np.empty((pc.ends_px.shape[0], 2), dtype=np.int64)
    _raster.sil_counts(pc.ends_px, pc.radius_px, target.prefix, out)
    return _d_A(out[:, 0], out[:, 1], target.area)


def d_S_batch(
    joints: np.ndarray,
    target: Target,
    shape: BodyShape,
    camera: Camera,
    *,
    lambda_A: float = LAMBDA_A,
    lambda_E: float = LAMBDA_E,
) -> np.ndarray:
    """Region difference d_S = lambda_A d_A + lambda_E d_E of many postures (thesis eq. 4.4).

    d_A is eq. 4.1; d_E is eq. 4.2-4.3 divided by the number of rendered edge pixels (a mean
    truncated chamfer distance in [0, xi], comparable across postures). Each posture is
    rasterised only inside its own bounding box; with ``lambda_E`` 0 nothing is rasterised
    (:func:`d_A_batch`).

    Parameters
    ----------
    joints : ndarray, shape (N, 17, 3)
    target : Target
    shape : BodyShape
    camera : Camera
    lambda_A, lambda_E : float
        Weights of eq. 4.4 (defaults in :mod:`engine.measures`).

    Returns
    -------
    d : ndarray, shape (N,)

    Raises
    ------
    InvalidInput
        Bad ``joints``, or a target whose size differs from the camera's image.
    """
    if lambda_E == 0.0:  # d_A alone: counted from row spans, the same pixels as a render
        # (profile of stage 3: a sixth of the time of the per-pixel depth render)
        return lambda_A * d_A_batch(joints, target, shape, camera)
    pc = _project_batch(joints, target, shape, camera)
    n = pc.ends_px.shape[0]
    out_i = np.empty((n, 3), dtype=np.int64)
    out_f = np.empty(n)
    _raster.full_counts(
        pc.ends_px, pc.depth, pc.radius_px, pc.radius_m, _PART_I64, SEAM_END, pc.scale,
        target.silhouette, target.cost, out_i, out_f,
    )  # fmt: skip
    dA = _d_A(out_i[:, 0], out_i[:, 1], target.area)
    dE = _d_E(out_f, out_i[:, 2], target.xi)
    return lambda_A * dA + lambda_E * dE
