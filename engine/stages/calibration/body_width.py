"""The performer's body width: capsule radius factors per part group fitted by d_A on the
calibration frame, the camera fixed (thesis 2.1.1: the body H of the performer).
"""

from __future__ import annotations

import numpy as np

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.render import capsules
from engine.render.camera import Camera

#: Part groups whose capsule radii :func:`fit_body_shape` scales together.
WIDTH_GROUPS: dict[str, tuple[str, ...]] = {
    "torso": ("abdomen", "lower_chest", "upper_chest"),
    "head": ("head",),
    "arms": ("l_upper_arm", "l_lower_arm", "r_upper_arm", "r_lower_arm"),
    "legs": ("l_upper_leg", "l_lower_leg", "r_upper_leg", "r_lower_leg"),
}


def _capsule_groups() -> np.ndarray:
    from engine.body.shapes import CAPSULE_PART
    from engine.body.skeleton import PART_INDEX

    g = np.full(len(CAPSULE_PART), -1)
    for i, parts in enumerate(WIDTH_GROUPS.values()):
        g[np.isin(CAPSULE_PART, [PART_INDEX[p] for p in parts])] = i
    return g


def fit_body_shape(
    joints: np.ndarray,
    shape: BodyShape,
    camera: Camera,
    silhouette: np.ndarray,
    *,
    bounds: tuple[float, float] = (0.7, 1.8),
) -> tuple[BodyShape, dict[str, float]]:
    """Fit the performer's body width: capsule radius factors per part group (thesis 2.1.1).

    The thesis retargets the reference to the performer's body; here the bone lengths come
    from the reference (scaled by the camera) and only the widths are unknown. With the
    camera fixed, a coordinate search over one radius factor per group of
    :data:`WIDTH_GROUPS` minimises d_A (eq. 4.1) between the rendered calibration posture and
    the calibration frame's body region. The camera stays fixed because scale and width
    trade off against each other when the region misses parts (dark shoes, hair).

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
        Calibration posture.
    shape : BodyShape
        The reference's body (its radii are the starting point).
    camera : Camera
        Calibrated camera (:func:`calibrate`).
    silhouette : ndarray of bool, shape (H, W)
        Body region of the calibration frame.
    bounds : (float, float)
        Smallest and largest factor.

    Returns
    -------
    shape : BodyShape
        ``shape`` with the fitted radii.
    factors : dict
        Factor per group name.

    Raises
    ------
    InvalidInput
        Bad shapes or bounds.
    """
    from dataclasses import replace

    j = np.asarray(joints, dtype=float)
    if j.shape != (17, 3) or not np.all(np.isfinite(j)):
        raise InvalidInput(f"joints must be a finite (17, 3) posture, got shape {j.shape}")
    sil = np.asarray(silhouette, dtype=bool)
    if sil.shape != (camera.height, camera.width):
        raise InvalidInput(
            f"silhouette must be ({camera.height}, {camera.width}) like the camera's image, "
            f"got {sil.shape}"
        )
    lo, hi = bounds
    if not 0 < lo <= 1 <= hi:
        raise InvalidInput(f"bounds must satisfy 0 < low <= 1 <= high, got {bounds}")
    groups = _capsule_groups()
    base = np.asarray(shape.radii, dtype=float)
    target = capsules.Target.from_masks(sil, np.zeros_like(sil))

    def make(f: np.ndarray) -> BodyShape:
        return replace(shape, radii=base * np.where(groups >= 0, f[np.maximum(groups, 0)], 1.0))

    def score(f: np.ndarray) -> float:
        return float(capsules.d_A_batch(j[None], target, make(f), camera)[0])

    f = np.ones(len(WIDTH_GROUPS))
    best = score(f)
    for step in (0.16, 0.08, 0.04, 0.02):
        improved = True
        while improved:
            improved = False
            for g in range(len(f)):
                for sign in (1.0, -1.0):
                    cand = f.copy()
                    cand[g] = np.clip(cand[g] * (1 + sign * step), lo, hi)
                    d = score(cand)
                    if d < best - 1e-9:
                        f, best, improved = cand, d, True
    return make(f), {name: float(v) for name, v in zip(WIDTH_GROUPS, f, strict=True)}
