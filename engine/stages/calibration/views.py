"""Stage 1 on the calibration frame: a camera per sampled view azimuth, scored by d_S, the
best few refined (thesis 4.2, plus azimuth), and the mirror hypothesis for the whole video.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput, RegistrationFailed
from engine.render import capsules
from engine.render.camera import Camera
from engine.stages.calibration.initial import keypoint_camera, pca_camera
from engine.stages.calibration.search import _keypoint_cost, _refine, _refine_above_ankles
from engine.stages.calibration.settings import CalibrationSettings
from engine.stages.perception import readings

ProgressFn = Callable[[str, float], None]

#: The default settings, one frozen instance (the argument default of :func:`calibrate`).
_DEFAULTS = CalibrationSettings()


def calibrate(
    joints: np.ndarray,
    shape: BodyShape,
    silhouette: np.ndarray,
    edges: np.ndarray,
    settings: CalibrationSettings = _DEFAULTS,
    *,
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
    facing: int = 0,
    on_progress: ProgressFn | None = None,
) -> tuple[Camera, dict]:
    """Calibrate the camera from one frame's body region (thesis 4.2, plus azimuth).

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
        Calibration posture B_0 (the reference posture the calibration frame shows).
    shape : BodyShape
    silhouette, edges : ndarray of bool, shape (H, W)
        Input body region of the calibration frame.
    settings : CalibrationSettings
    keypoints : (ndarray (17, 2), ndarray (17,)), optional
        The calibration frame's 2D keypoints and confidences (stage 0's perception); see
        ``settings.keypoint_weight``.
    facing : int
        +1 the pose model saw the face, -1 the back of the head, 0 unknown.
    on_progress : callable(stage, fraction), optional

    Returns
    -------
    camera : Camera
    report : dict
        ``{"azimuth_scores": {deg: d_S}, "d_S": best}``.

    Raises
    ------
    InvalidInput
        Bad shapes, or an empty calibration silhouette.
    RegistrationFailed
        No sampled azimuth gives a usable camera.
    """
    j, sil = _check_calibration_frame(joints, silhouette, edges, settings)
    kp = _usable_keypoints(keypoints, settings)
    frame = _CalibrationFrame(
        joints=j, shape=shape, silhouette=sil,
        target=capsules.Target.from_masks(sil, np.asarray(edges, dtype=bool)),
        keypoints=kp, readings=None if kp is None else readings(*kp), facing=facing,
    )  # fmt: skip
    scores, cams = _sample_azimuths(frame, settings, on_progress)
    if not scores:
        raise RegistrationFailed("the camera could not be calibrated from the first frame")
    d, cam = _refine_best(frame, scores, cams, settings)
    if settings.refine and settings.above_ankles:
        cam, _ = _refine_above_ankles(j, shape, sil, cam)
    if on_progress is not None:
        on_progress("calibration", 1.0)
    return cam, {"azimuth_scores": scores, "d_S": d}


@dataclass(frozen=True)
class _CalibrationFrame:
    """What stage 1 compares each view with: the posture and the calibration frame's evidence.

    Attributes
    ----------
    joints : ndarray, shape (17, 3)
        Calibration posture B_0.
    shape : BodyShape
    silhouette : ndarray of bool, shape (H, W)
        The frame's body region.
    target : capsules.Target
        The region (and its edges) prepared for d_S.
    keypoints : (ndarray (17, 2), ndarray (17,)) or None
        The frame's 2D keypoints and confidences, when usable (:func:`_usable_keypoints`).
    readings : (ndarray (2, 17, 2), ndarray (2, 17)) or None
        Their two readings for d_K (:func:`engine.stages.perception.readings`).
    facing : int
        +1 the pose model saw the face, -1 the back of the head, 0 unknown.
    """

    joints: np.ndarray
    shape: BodyShape
    silhouette: np.ndarray
    target: capsules.Target
    keypoints: tuple[np.ndarray, np.ndarray] | None
    readings: tuple[np.ndarray, np.ndarray] | None
    facing: int


def _check_calibration_frame(
    joints: np.ndarray, silhouette: np.ndarray, edges: np.ndarray, s: CalibrationSettings
) -> tuple[np.ndarray, np.ndarray]:
    """The posture (17, 3) as floats and the region (H, W) as bool, or InvalidInput naming
    the parameter."""
    j = np.asarray(joints, dtype=float)
    if j.shape != (17, 3) or not np.all(np.isfinite(j)):
        raise InvalidInput(f"joints must be a finite (17, 3) posture, got shape {j.shape}")
    sil = np.asarray(silhouette, dtype=bool)
    if sil.ndim != 2 or np.asarray(edges).shape != sil.shape:
        raise InvalidInput(
            f"silhouette and edges must be (H, W) masks of one shape, got {sil.shape} and "
            f"{np.asarray(edges).shape}"
        )
    if np.count_nonzero(sil) < 50:
        raise InvalidInput(
            "the calibration frame shows no body region (the performer must be visible in the "
            "first frame)"
        )
    if not s.azimuths_deg:
        raise InvalidInput("settings.azimuths_deg must name at least one azimuth")
    return j, sil


def _usable_keypoints(
    keypoints: tuple[np.ndarray, np.ndarray] | None, s: CalibrationSettings
) -> tuple[np.ndarray, np.ndarray] | None:
    """The keypoints (17, 2) and confidences (17,) when they are to be used: weighted, and
    at least three confident ones (fewer cannot place a similarity)."""
    if keypoints is None or not s.keypoint_weight > 0:
        return None
    if np.count_nonzero(keypoints[1] > 0) < 3:
        return None
    return keypoints


def _view_camera(frame: _CalibrationFrame, az_deg: float) -> Camera:
    """The first camera at one azimuth: from the keypoints when there are any, else the
    thesis' PCA (4.2). Raises InvalidInput when the posture cannot be placed in the image."""
    az = float(np.radians(az_deg))
    if frame.keypoints is not None:
        h, w = frame.silhouette.shape
        return keypoint_camera(frame.joints, *frame.keypoints, azimuth=az, width=w, height=h)
    return pca_camera(frame.joints, frame.shape, frame.silhouette, azimuth=az)


def _view_score(
    frame: _CalibrationFrame, cam: Camera, az_deg: float, s: CalibrationSettings
) -> float:
    """d_S (eq. 4.4) of the posture at ``cam``, plus the facing penalty and the keypoint
    term (beyond the thesis)."""
    d = float(
        capsules.d_S_batch(frame.joints[None], frame.target, frame.shape, cam,
                           lambda_A=s.lambda_A, lambda_E=s.lambda_E)[0]
    ) + _facing_cost(float(az_deg), frame.facing, s.facing_penalty)  # fmt: skip
    if frame.readings is not None:
        d += s.keypoint_weight * _keypoint_cost(
            frame.joints, frame.readings[0], frame.readings[1], cam, s.keypoint_tau
        )
    return d


def _facing_cost(azimuth_deg: float, facing: int, penalty: float) -> float:
    """``penalty`` when a view at ``azimuth_deg`` contradicts the facing (+1 front, -1 back);
    views within 15 deg of a side view contradict neither."""
    off = abs((azimuth_deg + 180.0) % 360.0 - 180.0)  # 0 front, 180 back
    if (facing > 0 and off > 105.0) or (facing < 0 and off < 75.0):
        return penalty
    return 0.0


def _sample_azimuths(
    frame: _CalibrationFrame, s: CalibrationSettings, on_progress: ProgressFn | None
) -> tuple[dict[float, float], dict[float, Camera]]:
    """Score and camera per sampled azimuth (degrees), skipping those where the posture
    cannot be placed (beyond the thesis, which has only the front view)."""
    scores: dict[float, float] = {}
    cams: dict[float, Camera] = {}
    for i, az in enumerate(s.azimuths_deg):
        try:
            cam = _view_camera(frame, az)
        except InvalidInput:  # the posture projects outside the image at this azimuth
            continue
        scores[float(az)] = _view_score(frame, cam, az, s)
        cams[float(az)] = cam
        if on_progress is not None:
            on_progress("calibration", (i + 1) / (len(s.azimuths_deg) + 1))
    return scores, cams


def _refine_best(
    frame: _CalibrationFrame,
    scores: dict[float, float],
    cams: dict[float, Camera],
    s: CalibrationSettings,
) -> tuple[float, Camera]:
    """The best camera and its score after refining the ``s.refine_top`` best azimuths.

    The first scores rank the azimuths roughly; the refined fit decides among the best few
    (ties go to the smaller azimuth).
    """
    n_top = max(1, s.refine_top) if s.refine else 1
    top = sorted(scores, key=lambda az: scores[az])[:n_top]
    fits = []
    for az in top:
        cam, d = cams[az], scores[az]
        if s.refine:
            cam, d = _refine(frame.joints, frame.shape, frame.target, cam, s, frame.readings)
            d += _facing_cost(az, frame.facing, s.facing_penalty)
        fits.append((d, az, cam))
    d, _, cam = min(fits, key=lambda f: (f[0], f[1]))
    return d, cam


def mirror_azimuth(scores: dict[float, float], chosen_deg: float) -> float | None:
    """Best-scoring sampled azimuth facing away from ``chosen_deg`` (more than 90 deg off).

    ``scores`` is :func:`calibrate`'s ``azimuth_scores`` (degrees -> d_S). The front and back
    views of a posture (and the left and right side views) give near mirror-image silhouettes
    that differ only in the internal edges; this is the other hypothesis to test.
    """
    away = {
        az: d for az, d in scores.items()
        if abs((az - chosen_deg + 180.0) % 360.0 - 180.0) > 90.0
    }  # fmt: skip
    return min(away, key=lambda az: away[az]) if away else None
