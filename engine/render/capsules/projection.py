"""The capsule body in the image: which capsule ends are seams, each part's capsules, and the
projection of postures' capsules (thesis 4.3 with capsules instead of a mesh).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.shapes import (
    CAPSULE_A,
    CAPSULE_B,
    CAPSULE_PART,
    CAPSULE_T,
    N_CAPSULES,
    BodyShape,
)
from engine.body.skeleton import BONE_CHILD, BONE_PARENT, N_PARTS, PART_BONES
from engine.errors import InvalidInput
from engine.render.camera import Camera


def _seam_ends() -> np.ndarray:
    """Which capsule ends are seams with another part, shape (C, 2) bool (see module doc)."""
    bones = {(int(p), int(c)) for p, c in zip(BONE_PARENT, BONE_CHILD, strict=True)}
    part_joints = [
        {int(BONE_PARENT[b]) for b in PART_BONES[k]} | {int(BONE_CHILD[b]) for b in PART_BONES[k]}
        for k in range(N_PARTS)
    ]
    seam = np.zeros((N_CAPSULES, 2), dtype=bool)
    for c in range(N_CAPSULES):
        a, b, k = int(CAPSULE_A[c]), int(CAPSULE_B[c]), int(CAPSULE_PART[c])
        if (a, b) not in bones:
            continue  # pelvis and shoulder capsules: their caps are the body's outer shape
        for e, joint in ((0, a), (1, b)):
            t = CAPSULE_T[c, e]
            at_joint = (t == 0.0 and joint == a) or (t == 1.0 and joint == b)
            shared = any(joint in part_joints[j] for j in range(N_PARTS) if j != k)
            seam[c, e] = at_joint and shared
    seam.setflags(write=False)
    return seam


#: Capsule ends whose round cap is a seam inside a neighbouring part, shape (C, 2).
SEAM_END = _seam_ends()


#: Capsules of each part.
PART_CAPSULES: tuple[np.ndarray, ...] = tuple(
    np.flatnonzero(CAPSULE_PART == k).astype(np.int64) for k in range(N_PARTS)
)


_PART_I64 = np.ascontiguousarray(CAPSULE_PART, dtype=np.int64)


_ALL_CAPS = np.arange(N_CAPSULES, dtype=np.int64)


def _check_joints(joints: np.ndarray, name: str, batch: bool) -> np.ndarray:
    j = np.asarray(joints, dtype=float)
    want = "(N, 17, 3)" if batch else "(17, 3)"
    if j.ndim != (3 if batch else 2) or j.shape[-2:] != (17, 3):
        raise InvalidInput(f"{name} must have shape {want}, got {j.shape}")
    if not np.all(np.isfinite(j)):
        raise InvalidInput(f"{name} contains NaN or infinite values")
    return j


def _check_part(part: int) -> int:
    if not isinstance(part, int | np.integer) or not 0 <= int(part) < N_PARTS:
        raise InvalidInput(f"part must be an int in 0..{N_PARTS - 1}, got {part!r}")
    return int(part)


@dataclass(frozen=True)
class ProjectedCapsules:
    """Capsules of postures in the image.

    Attributes
    ----------
    ends_px : ndarray, shape (..., C, 2, 2)
        Axis ends (capsule, end, (u, v)), pixels.
    radius_px : ndarray, shape (C,)
        Radii in pixels (``radius_m * camera.scale``).
    depth : ndarray, shape (..., C, 2)
        Depth of the axis ends along the viewing direction, metres (larger is farther).
    radius_m : ndarray, shape (C,)
        Radii in metres (for surface depth).
    scale : float
        Pixels per metre.
    """

    ends_px: np.ndarray
    radius_px: np.ndarray
    depth: np.ndarray
    radius_m: np.ndarray
    scale: float


def project_capsules(joints: np.ndarray, shape: BodyShape, camera: Camera) -> ProjectedCapsules:
    """Project the capsule body of postures (thesis 4.3 with capsules instead of a mesh).

    Parameters
    ----------
    joints : ndarray, shape (..., 17, 3)
        World joint positions, metres.
    shape : BodyShape
    camera : Camera

    Returns
    -------
    ProjectedCapsules

    Raises
    ------
    InvalidInput
        If ``joints`` is not (..., 17, 3) or not finite.
    """
    j = np.asarray(joints, dtype=float)
    if j.ndim < 2 or j.shape[-2:] != (17, 3):
        raise InvalidInput(f"joints must have shape (..., 17, 3), got {j.shape}")
    if not np.all(np.isfinite(j)):
        raise InvalidInput("joints contains NaN or infinite values")
    return _project(j, shape, camera)


def _project(j: np.ndarray, shape: BodyShape, camera: Camera) -> ProjectedCapsules:
    a = j[..., CAPSULE_A, :]
    b = j[..., CAPSULE_B, :]
    ends = a[..., None, :] + CAPSULE_T[..., None] * (b - a)[..., None, :]  # (..., C, 2, 3)
    radius_m = np.asarray(shape.radii, dtype=float)
    return ProjectedCapsules(
        ends_px=np.ascontiguousarray(camera.project(ends)),
        radius_px=radius_m * float(camera.scale),
        depth=np.ascontiguousarray(camera.depth(ends)),
        radius_m=radius_m,
        scale=float(camera.scale),
    )
