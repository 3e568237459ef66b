"""Registration stages (thesis chapter 4): 0 foreground, 1 calibration, 2 alignment.

:func:`run_stages_0_2` chains the first three: video frames in, body regions, camera and
approximate temporal correspondence out.
"""

from __future__ import annotations

import time
from collections.abc import Callable

from engine.errors import InvalidInput
from engine.stages.alignment import AlignmentResult, AlignmentSettings, align, dp_path
from engine.stages.calibration import CalibrationSettings, calibrate
from engine.stages.foreground import ForegroundResult, ForegroundSettings, extract_foreground

__all__ = [
    "AlignmentResult", "AlignmentSettings", "CalibrationSettings", "ForegroundResult",
    "ForegroundSettings", "align", "calibrate", "dp_path", "extract_foreground", "run_stages_0_2",
]  # fmt: skip


def run_stages_0_2(
    reference,
    video,
    foreground: ForegroundSettings = ForegroundSettings(),
    calibration: CalibrationSettings = CalibrationSettings(),
    alignment: AlignmentSettings = AlignmentSettings(),
    *,
    on_progress: Callable[[str, float], None] | None = None,
):
    """Stages 0-2 of the thesis (4.1, 4.2, 4.5) on a loaded reference and video.

    Parameters
    ----------
    reference : engine.io.bvh.Reference
        ``reference.motion.joints`` (T, 17, 3) and ``reference.shape``.
    video : engine.io.video.Video
        ``video.frames`` (T', H, W, 3) RGB uint8.
    foreground, calibration, alignment : settings of each stage
    on_progress : callable(stage, fraction), optional

    Returns
    -------
    fg : ForegroundResult
    camera : Camera
    result : AlignmentResult
    timing_s : dict
        Seconds per stage ("foreground", "calibration", "alignment").

    Raises
    ------
    InvalidInput
        The calibration frame is out of range (or any stage's own validation).
    RegistrationFailed
        The camera cannot be calibrated.
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
    fg = extract_foreground(video.frames, foreground, on_progress=on_progress)
    timing["foreground"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    k = calibration.video_frame
    camera, _ = calibrate(joints[c0], reference.shape, fg.silhouettes[k], fg.edges[k],
                          calibration, on_progress=on_progress)  # fmt: skip
    timing["calibration"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    result = align(joints, reference.shape, camera, fg.silhouettes, fg.skin, alignment,
                   start=c0, on_progress=on_progress)  # fmt: skip
    timing["alignment"] = time.perf_counter() - t0
    return fg, camera, result, timing
