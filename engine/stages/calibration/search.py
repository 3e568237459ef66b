"""Polishing a camera by greedy coordinate search (beyond the thesis): on the calibration
frame by d_S (and d_K), above the ankles by d_A, or on many frames at once.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from engine.body.shapes import BodyShape
from engine.body.skeleton import JOINT_INDEX
from engine.errors import InvalidInput
from engine.render import capsules
from engine.render.camera import Camera
from engine.stages.calibration.settings import CalibrationSettings

#: The default settings, one frozen instance (the argument default of :func:`refine_on_frames`).
_DEFAULTS = CalibrationSettings()


def _keypoint_cost(
    joints: np.ndarray, keypoints: np.ndarray, confidence: np.ndarray, cam: Camera, tau: float
) -> float:
    """d_K of one posture (17, 3) at a camera against a detection's readings (R, 17, 2),
    (R, 17), saturating at ``tau`` of the posture's height."""
    from engine.measures import d_K

    tau_px = tau * cam.scale * max(float(np.ptp(joints[:, 1])), 0.3)
    return float(d_K(cam.project(joints)[None], keypoints, confidence, tau_px=tau_px)[0])


def _refine(
    joints: np.ndarray,
    shape: BodyShape,
    target: capsules.Target,
    cam: Camera,
    s: CalibrationSettings,
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[Camera, float]:
    """Coordinate search on scale and position minimising d_S (+ the keypoint term, over
    the detection's readings (R, 17, 2), (R, 17))."""

    def score(c: Camera) -> float:
        d = float(
            capsules.d_S_batch(joints[None], target, shape, c, lambda_A=s.lambda_A,
                               lambda_E=s.lambda_E)[0]
        )  # fmt: skip
        if keypoints is not None and s.keypoint_weight > 0:
            d += s.keypoint_weight * _keypoint_cost(joints, *keypoints, c, s.keypoint_tau)
        return d

    return _coordinate_search(cam, score)


def _refine_above_ankles(
    joints: np.ndarray, shape: BodyShape, silhouette: np.ndarray, cam: Camera
) -> tuple[Camera, float]:
    """Coordinate search on scale and position minimising d_A (eq. 4.1) over the image rows
    above the higher projected ankle only.

    The feet are the part of the body a static-camera background model loses first: shoes
    that stay planted for most of the video print into the background, and a d_S over the
    whole body then shrinks the scale until the capsule legs end where the silhouette does
    (on P1 and P2 by a few per cent). Head to ankles is the stretch both the region and the
    capsule body show faithfully, so the fit uses only that.
    """
    a = [JOINT_INDEX["l_ankle"], JOINT_INDEX["r_ankle"]]

    def score(c: Camera) -> float:
        cut = int(np.floor(c.project(joints[a])[:, 1].min()))
        if cut <= 0:
            return 1.0
        m = capsules.silhouettes(joints[None], shape, c)[0][:cut]
        t = silhouette[:cut]
        inter = np.count_nonzero(m & t)
        return 1.0 - 2.0 * inter / max(int(np.count_nonzero(m) + np.count_nonzero(t)), 1)

    return _coordinate_search(cam, score)


def _coordinate_search(
    cam: Camera, score: Callable[[Camera], float], *, perspective: bool = False
) -> tuple[Camera, float]:
    """Greedy search on position (steps of 4, 2, 1, 0.5 px), scale (the same in %) and the
    in-plane angle (half of it in degrees); with ``perspective``, also the perspective
    strength 1 / distance (steps of 0.02 per metre per pixel step, from 0 = orthographic up
    to 1 / 1.5 m).

    At each step size, moves to the best of the eight neighbours while it lowers ``score``.
    The angle is searched too because PCA's is biased by whatever the region lacks or has
    in excess: on a synthetic case with part of a leg missing it started degrees off, and
    with the angle fixed the position then settled pixels from the truth.
    """
    best = score(cam)
    for step_px in (4.0, 2.0, 1.0, 0.5):
        step_rad = np.radians(step_px / 2)
        improved = True
        while improved:
            improved = False
            cands = [
                cam.with_(cx=cam.cx + step_px), cam.with_(cx=cam.cx - step_px),
                cam.with_(cy=cam.cy + step_px), cam.with_(cy=cam.cy - step_px),
                _rescale(cam, 1 + step_px / 100), _rescale(cam, 1 - step_px / 100),
                cam.with_(theta_z=cam.theta_z + step_rad),
                cam.with_(theta_z=cam.theta_z - step_rad),
            ]  # fmt: skip
            if perspective:
                rho = 1.0 / cam.distance if cam.distance > 0 else 0.0
                for r in (rho + 0.02 * step_px, rho - 0.02 * step_px):
                    if r <= 1e-9:
                        cands.append(cam.with_(distance=0.0))
                    elif r <= 1.0 / 1.5:
                        cands.append(cam.with_(distance=1.0 / r))
            scores = [score(c) for c in cands]
            k = int(np.argmin(scores))
            if scores[k] < best - 1e-9:
                cam, best, improved = cands[k], scores[k], True
    return cam, best


def _rescale(cam: Camera, k: float) -> Camera:
    """Scale about the feet-ish image point: keep (cx, cy) -- the world origin is near the
    floor under the body in heading-normalised references -- and change the scale."""
    return cam.with_(scale=cam.scale * k)


def refine_on_frames(
    camera: Camera,
    postures: np.ndarray,
    shape: BodyShape,
    silhouettes: np.ndarray,
    edges: np.ndarray,
    settings: CalibrationSettings = _DEFAULTS,
    *,
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[Camera, float]:
    """Polish a camera on several frames: minimise the mean d_S of their postures.

    Parameters
    ----------
    camera : Camera
        Start (the one-frame calibration).
    postures : ndarray, shape (N, 17, 3)
        The posture each frame shows (stage 2: the reference at C(t'), turned by T_t').
    shape : BodyShape
    silhouettes, edges : ndarray of bool, shape (N, H, W)
        The frames' body regions.
    keypoints : (ndarray (N, R, 17, 2), ndarray (N, R, 17)), optional
        The readings of the frames' 2D keypoints and their confidences
        (:func:`engine.stages.perception.readings`): d_K joins d_S as in :func:`calibrate`.

    Returns
    -------
    camera : Camera
    d_S : float
        Mean d_S over the frames at the returned camera.
    """
    j = np.asarray(postures, dtype=float)
    if j.ndim != 3 or j.shape[1:] != (17, 3) or not len(j) == len(silhouettes) == len(edges):
        raise InvalidInput(
            f"postures (N, 17, 3), silhouettes and edges (N, H, W) must agree, got {j.shape}, "
            f"{np.shape(silhouettes)}, {np.shape(edges)}"
        )
    targets = [
        capsules.Target.from_masks(np.asarray(m, bool), np.asarray(e, bool))
        for m, e in zip(silhouettes, edges, strict=True)
    ]

    use_kp = keypoints is not None and settings.keypoint_weight > 0

    def score(c: Camera) -> float:
        d = [
            capsules.d_S_batch(p[None], t, shape, c, lambda_A=settings.lambda_A,
                               lambda_E=settings.lambda_E)[0]
            for p, t in zip(j, targets, strict=True)
        ]  # fmt: skip
        if use_kp:
            kp, conf = keypoints  # type: ignore[misc]
            d = [di + settings.keypoint_weight
                 * _keypoint_cost(p, kp[i], conf[i], c, settings.keypoint_tau)
                 for i, (di, p) in enumerate(zip(d, j, strict=True))]  # fmt: skip
        return float(np.mean(d))

    return _coordinate_search(camera, score, perspective=settings.perspective)
