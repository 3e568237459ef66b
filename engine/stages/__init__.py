"""Registration stages (thesis chapter 4): 0 foreground, 1 calibration, 2 alignment.

:func:`run_stages_0_2` chains the first three: video frames in, body regions, camera and
approximate temporal correspondence out.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput, RegistrationFailed
from engine.render.camera import Camera
from engine.stages.alignment import AlignmentResult, AlignmentSettings, align, dp_path
from engine.stages.calibration import (
    CalibrationSettings,
    calibrate,
    fit_body_shape,
    mirror_azimuth,
    refine_on_frames,
)
from engine.stages.foreground import (
    ForegroundResult,
    ForegroundSettings,
    extract_foreground,
    outline,
)
from engine.stages.perception import Perception, keypoint_offsets, readings

__all__ = [
    "AlignmentResult", "AlignmentSettings", "CalibrationSettings", "ForegroundResult",
    "ForegroundSettings", "Stages02", "align", "calibrate", "dp_path", "extract_foreground",
    "check_person_found", "fit_body_shape", "run_stages_0_2", "run_stages_0_2_full",
]  # fmt: skip


@dataclass(frozen=True)
class Stages02:
    """Output of stages 0-2.

    Attributes
    ----------
    foreground : ForegroundResult
        Body regions per video frame (stage 0).
    camera : Camera
        Calibrated scaled orthographic camera (stage 1; polished after stage 2 on frames
        spread over the video with ``CalibrationSettings.refine_frames``).
    shape : BodyShape
        The performer's body: the reference's bones with capsule radii fitted to the
        calibration frame (:func:`fit_body_shape`); the reference's own shape when the
        fit is off.
    width_factors : dict
        Fitted radius factor per part group (empty when the fit is off).
    alignment : AlignmentResult
        Approximate temporal correspondence and global rotations (stage 2).
    timing_s : dict
        Seconds per stage ("foreground", "calibration", "alignment").
    view_costs : dict
        Stage 2's mean cost E_C per view azimuth tried (degrees -> E_C): the calibrated one
        and, with ``CalibrationSettings.check_mirror``, the best one facing the other way.
    keypoint_offsets : ndarray, shape (17, 2)
        The pose model's offset from each joint in pixels, measured on the first frames
        (:func:`engine.stages.perception.keypoint_offsets`); zeros without perception.
    """

    foreground: ForegroundResult
    camera: Camera
    shape: BodyShape
    width_factors: dict
    alignment: AlignmentResult
    timing_s: dict
    view_costs: dict = field(default_factory=dict)
    keypoint_offsets: np.ndarray = field(default_factory=lambda: np.zeros((17, 2)))


def run_stages_0_2(
    reference,
    video,
    foreground: ForegroundSettings = ForegroundSettings(),
    calibration: CalibrationSettings = CalibrationSettings(),
    alignment: AlignmentSettings = AlignmentSettings(),
    *,
    on_progress: Callable[[str, float], None] | None = None,
):
    """Stages 0-2 as a tuple ``(foreground, camera, alignment, timing_s)``.

    Kept for callers written before :func:`run_stages_0_2_full` (which also returns the
    fitted body shape); same parameters and errors.
    """
    r = run_stages_0_2_full(reference, video, foreground, calibration, alignment,
                            on_progress=on_progress)  # fmt: skip
    return r.foreground, r.camera, r.alignment, r.timing_s


def run_stages_0_2_full(
    reference,
    video,
    foreground: ForegroundSettings = ForegroundSettings(),
    calibration: CalibrationSettings = CalibrationSettings(),
    alignment: AlignmentSettings = AlignmentSettings(),
    *,
    align_with_fitted_shape: bool = False,
    perception: Perception | None = None,
    min_person_fraction: float = 0.0,
    on_progress: Callable[[str, float], None] | None = None,
) -> Stages02:
    """Stages 0-2 of the thesis (4.1, 4.2, 4.5) on a loaded reference and video.

    With ``calibration.check_mirror`` stage 2 runs for the calibrated view and for the best
    view facing the other way, and the one with the lower mean cost E_C is kept (one frame
    hardly tells front from back; the whole motion does). The camera is then polished on
    frames spread over the video and, with ``alignment.realign``, stage 2 runs once more
    with it and the performer's fitted body.

    Parameters
    ----------
    reference : engine.io.bvh.Reference
        ``reference.motion.joints`` (T, 17, 3) and ``reference.shape``.
    video : engine.io.video.Video
        ``video.frames`` (T', H, W, 3) RGB uint8.
    foreground, calibration, alignment : settings of each stage
    align_with_fitted_shape : bool
        Compare stage 2's first pass with a body fitted for the calibration-frame camera
        instead of the reference's. Off: measured slightly worse on the public cases (0.87 ->
        1.12 and 1.90 -> 2.07 video frames), because the fit absorbs foreground errors of one
        frame. The second pass (``alignment.realign``) uses the body fitted for the polished
        camera.
    on_progress : callable(stage, fraction), optional

    Returns
    -------
    Stages02

    Raises
    ------
    InvalidInput
        The calibration frame is out of range (or any stage's own validation).
    RegistrationFailed
        Nobody is found in the video (:func:`check_person_found`), or the camera cannot be
        calibrated.
    """
    joints = reference.motion.joints
    c0 = calibration.reference_frame
    c0 = reference.motion.first_motion_frame if c0 is None else int(c0)
    if not 0 <= c0 < len(joints):
        raise InvalidInput(
            f"calibration.reference_frame must be 0..{len(joints) - 1}, got {c0}"
        )
    if not 0 <= calibration.video_frame < video.frames.shape[0]:
        raise InvalidInput(
            f"calibration.video_frame must be 0..{video.frames.shape[0] - 1}, "
            f"got {calibration.video_frame}"
        )
    timing = {}
    t0 = time.perf_counter()
    fg = extract_foreground(video.frames, foreground,
                            learned=None if perception is None else perception.mask,
                            on_progress=on_progress)  # fmt: skip
    timing["foreground"] = time.perf_counter() - t0
    check_person_found(fg.flags, perception, min_person_fraction)
    t0 = time.perf_counter()
    k = calibration.video_frame
    # the outline only: interior image edges (ForegroundSettings.interior_edges) are for
    # stage 3's per-part fit; the calibration's capsule body has no clothing seams
    edges_k = outline(fg.silhouettes[k], fg.skin[k])
    kp_k, facing = _calibration_keypoints(perception, k, foreground.learned_max_gap)
    camera, report = calibrate(joints[c0], reference.shape, fg.silhouettes[k], edges_k,
                               calibration, keypoints=kp_k, facing=facing,
                               on_progress=on_progress)  # fmt: skip
    cameras = [camera]
    alt = None
    if calibration.check_mirror:
        alt = mirror_azimuth(report["azimuth_scores"], float(np.degrees(camera.azimuth)))
    if alt is not None:
        mirrored = dataclasses.replace(calibration, azimuths_deg=(alt,))
        cameras.append(calibrate(joints[c0], reference.shape, fg.silhouettes[k], edges_k,
                                 mirrored, keypoints=kp_k)[0])  # fmt: skip
    timing["calibration"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    def keypoints_for(cam: Camera) -> tuple[np.ndarray, tuple | None]:
        """The detector's offsets as seen through ``cam``, and the readings stages 1-2 use
        (without the offsets unless ``alignment.keypoint_offsets``)."""
        if perception is None:
            return np.zeros((17, 2)), None
        off = _keypoint_offsets(perception, cam, joints[c0], calibration.offset_frames)
        used = off if alignment.keypoint_offsets else np.zeros((17, 2))
        return off, readings(perception.keypoints, perception.confidence, used)

    results = []
    passes = len(cameras) + int(alignment.realign and calibration.refine_frames > 0)
    for i, cam in enumerate(cameras):
        shape: BodyShape = reference.shape
        if align_with_fitted_shape and calibration.fit_width:
            shape, _ = fit_body_shape(joints[c0], reference.shape, cam, fg.silhouettes[k])
        progress = None if on_progress is None else _share(on_progress, i, passes)
        aligned = align(joints, shape, cam, fg.silhouettes, fg.skin, alignment, start=c0,
                        keypoints=keypoints_for(cam)[1], on_progress=progress)  # fmt: skip
        results.append((aligned.E_C, i, cam, aligned))
    # the camera whose view explains the whole video best (CalibrationSettings.check_mirror)
    _, _, camera, result = min(results, key=lambda r: (r[0], r[1]))
    timing["alignment"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if calibration.refine_frames > 0:
        camera = _refine_camera(camera, reference, fg, result, calibration,
                                keypoints_for(camera)[1])  # fmt: skip
    offsets, kp_all = keypoints_for(camera)
    factors: dict[str, float] = {}
    shape = reference.shape
    if calibration.fit_width:  # the performer's widths, for the final camera
        shape, factors = fit_body_shape(joints[c0], reference.shape, camera, fg.silhouettes[k])
    timing["calibration"] += time.perf_counter() - t0
    if passes > len(cameras):  # AlignmentSettings.realign: C again with the polished camera
        t0 = time.perf_counter()
        progress = None if on_progress is None else _share(on_progress, passes - 1, passes)
        result = align(joints, shape, camera, fg.silhouettes, fg.skin, alignment, start=c0,
                       keypoints=kp_all, on_progress=progress)  # fmt: skip
        timing["alignment"] += time.perf_counter() - t0
    views = {round(float(np.degrees(r[2].azimuth)), 6): float(r[0]) for r in results}
    return Stages02(fg, camera, shape, factors, result, timing, views, offsets)


def check_person_found(
    flags: Sequence[Sequence[str]], perception: Perception | None, min_fraction: float
) -> None:
    """Refuse a video where nobody is found, rather than fit the reference to nothing.

    A frame shows a person when the pose model detected one there or stage 0's region is not
    flagged ``no_person`` (a pose model trained on photographs may miss a rendered or
    unusual figure that the background difference still finds; what is then found but is not
    a body ends ``poor_fit``, :func:`assess_fit`).

    Raises
    ------
    RegistrationFailed
        Fewer than ``min_fraction`` of the frames show a person.
    """
    seen = np.array(["no_person" not in f for f in flags], bool)
    if perception is not None:
        seen |= np.asarray(perception.detected, bool)
    found = float(seen.mean())
    if found < min_fraction:
        raise RegistrationFailed(
            f"We could not find a person in this video (only {100 * found:.0f} % of the "
            "frames show one). Film the whole body, from head to feet, in good light, "
            "standing out from the background."
        )


def _refine_camera(
    camera: Camera,
    reference,
    fg: ForegroundResult,
    aligned: AlignmentResult,
    calibration: CalibrationSettings,
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
) -> Camera:
    """The camera polished on frames spread over the video.

    Each frame shows the reference at stage 2's C(t') turned by T_t' about the hip
    (``CalibrationSettings.refine_frames``).
    """
    n = len(aligned.C)
    idx = np.unique(np.linspace(0, n - 1, min(calibration.refine_frames, n)).round().astype(int))
    ref = reference.motion.joints[aligned.C[idx]]
    hip = ref[:, :1]
    posed = np.einsum("nij,nkj->nki", aligned.rotations[idx], ref - hip) + hip
    outlines = np.array([outline(fg.silhouettes[i], fg.skin[i]) for i in idx])
    kp = None if keypoints is None else (keypoints[0][idx], keypoints[1][idx])
    camera, _ = refine_on_frames(
        camera, posed, reference.shape, fg.silhouettes[idx], outlines, calibration, keypoints=kp
    )
    return camera


def _keypoint_offsets(
    perception: Perception, camera: Camera, posture: np.ndarray, n_frames: int
) -> np.ndarray:
    """The detector's offsets on the first ``n_frames`` frames, which show ``posture`` (17, 3)
    by stage 1's assumption; zeros when fewer than two of them have a detection."""
    idx = np.flatnonzero(perception.detected[:n_frames])
    if idx.size < 2:
        return np.zeros((17, 2))
    pred = np.broadcast_to(camera.project(posture), (idx.size, 17, 2))
    return keypoint_offsets(perception.keypoints[idx], perception.confidence[idx], pred)


def _calibration_keypoints(
    perception: Perception | None, k: int, max_gap: int
) -> tuple[tuple[np.ndarray, np.ndarray] | None, int]:
    """Keypoints and confidences (17, 2), (17,) for calibration frame k, and the facing.

    Where the pose model lost the person in frame k, the nearest frame that has him within
    ``max_gap`` frames stands in (a performer starts still, in the reference's first
    posture). The facing is the majority of the frames up to ``max_gap`` after k.
    """
    if perception is None:
        return None, 0
    found = np.flatnonzero(perception.detected)
    if found.size == 0:
        return None, 0
    j = int(found[np.argmin(np.abs(found - k))])
    if abs(j - k) > max_gap:
        return None, 0
    window = perception.facing[k : k + max_gap + 1][perception.detected[k : k + max_gap + 1]]
    facing = int(np.sign(window.sum())) if window.size else 0
    return (perception.keypoints[j], perception.confidence[j]), facing


def _share(
    on_progress: Callable[[str, float], None], i: int, n: int
) -> Callable[[str, float], None]:
    """Progress of the i-th of n runs of a stage as a share of the stage's whole progress."""
    return lambda stage, f: on_progress(stage, (i + f) / n)
