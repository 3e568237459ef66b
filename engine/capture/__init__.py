"""Reference-free capture (seed 001): 3D motion from one video, with no reference.

A club without a motion-capture lab films its best player once and uses the capture as the
expert; a performer keeps their own motion as 3D. The steps, one module each:

1. :mod:`~engine.capture.pose2d`: the 2D pose of every frame from the learned landmarks of
   stage 0's perception step, left/right labels made continuous, gaps interpolated, smoothed
   without lag.
2. :mod:`~engine.capture.lifting`: each segment's depth from its foreshortening under scaled
   orthographic projection (seed 001 eq. 2.2); the depth signs chosen by Viterbi from the
   detector's depth hint, continuity, joint limits and the facing; questions where a sign
   stays uncertain.
3. :mod:`~engine.capture.motion`: the segments laid on the 17-joint body with constant bone
   lengths and root motion, in DESIGN.md's world frame.
4. :mod:`~engine.capture.export`: BVH (our skeleton or CMU's names) and a CSV of joint angles.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from engine.body.shapes import BodyShape
from engine.capture.lifting import FACING, Lifted, Question, lift
from engine.capture.motion import world_motion
from engine.capture.pose2d import Pose2D, faces_camera, pose_2d
from engine.capture.settings import CaptureSettings
from engine.errors import InvalidInput, RegistrationFailed
from engine.io.video import Video, VideoLimits, probe_video, read_video
from engine.stages.perception import Perception, PoseModel

__all__ = ["Capture", "CaptureSettings", "Question", "capture", "capture_video"]

ProgressFn = Callable[[str, float], None]


@dataclass(frozen=True)
class Capture:
    """A captured motion.

    Attributes
    ----------
    joints : ndarray, shape (T', 17, 3)
        The 17-joint body in DESIGN.md's world frame (y up, facing +z at frame 0), metres,
        one posture per video frame, root motion included.
    fps : float
    shape : BodyShape
        The body the motion is laid on (constant bone lengths).
    pose : Pose2D
        The 2D pose it was lifted from (working pixels).
    lifted : Lifted
        The segments in the camera frame, their depth signs and the questions left.
    model : str
        The pose model.
    timing_s : dict
    """

    joints: np.ndarray
    fps: float
    shape: BodyShape
    pose: Pose2D
    lifted: Lifted
    model: str
    timing_s: dict = field(default_factory=dict)

    @property
    def questions(self) -> tuple[Question, ...]:
        return self.lifted.questions

    def summary(self) -> dict:
        """JSON-ready facts: frames, questions, where the 2D came from, timings."""
        p = self.pose
        return {
            "frames": int(self.joints.shape[0]),
            "fps": self.fps,
            "model": self.model,
            "height_m": round(self.shape.height, 3),
            "questions": [q.to_dict(self.fps) for q in self.questions],
            "frames_interpolated": int((~p.reliable.any(1)).sum()),
            "points_interpolated_share": round(float(1 - p.reliable.mean()), 3),
            "label_swaps_corrected": int(p.swapped.sum()),
            "timing_s": {k: round(v, 3) for k, v in self.timing_s.items()},
        }


def capture(
    perception: Perception,
    fps: float,
    size: tuple[int, int],
    s: CaptureSettings | None = None,
    *,
    answers: dict[str, int] | None = None,
    signs: np.ndarray | None = None,
) -> Capture:
    """Capture the motion seen by a pose model.

    Parameters
    ----------
    perception : Perception
        With landmarks (:class:`engine.stages.perception.MediaPipePose` gives them).
    fps : float
    size : (width, height)
        The frames' size in pixels.
    s : CaptureSettings, optional
    answers : dict, optional
        Question id -> -1 (towards the camera) or +1 (away).
    signs : ndarray, shape (T', 12), optional
        Depth signs to impose (:func:`engine.capture.lifting.lift`).

    Raises
    ------
    InvalidInput
        The perception has no landmarks.
    RegistrationFailed
        No frame shows a person.
    """
    s = s or CaptureSettings()
    if perception.landmarks is None:
        raise InvalidInput(f"the pose model {perception.model!r} gives no landmarks to capture")
    t0 = time.perf_counter()
    pose, facing_q = _pose(perception, fps, s, answers or {})
    t1 = time.perf_counter()
    lifted = lift(pose, s, answers, signs)
    if facing_q is not None:
        lifted = dataclasses.replace(lifted, questions=(facing_q, *lifted.questions))
    t2 = time.perf_counter()
    shape = BodyShape.default(s.height_m)
    joints = world_motion(lifted, pose, shape, size[0], size[1], s.camera_distance_m, s.cutoff_hz)
    t3 = time.perf_counter()
    return Capture(
        joints=joints,
        fps=float(fps),
        shape=shape,
        pose=pose,
        lifted=lifted,
        model=perception.model,
        timing_s={"pose_2d": t1 - t0, "lifting": t2 - t1, "motion": t3 - t2},
    )


def _pose(
    perception: Perception, fps: float, s: CaptureSettings, answers: dict[str, int]
) -> tuple[Pose2D, Question | None]:
    """The 2D pose, and the front/back question when the model's labels were split; an
    answer to that question that contradicts the labels flips them."""
    lm = perception.landmarks
    assert lm is not None

    def read(flip: bool) -> Pose2D:
        return pose_2d(
            lm,
            perception.facing,
            fps,
            min_visibility=s.min_visibility,
            cutoff_hz=s.cutoff_hz,
            swap_cost=s.swap_cost,
            flip=flip,
        )

    pose = read(False)
    T = pose.n_frames
    front = faces_camera(pose.uv)
    qid = f"{FACING}@0-{T}"
    if qid in answers:
        want_front = answers[qid] < 0
        if want_front != front:
            pose = read(True)
        # the answer replaces the model's own front/back reading of every frame
        facing = np.full(T, 1 if want_front else -1, np.int8)
        return dataclasses.replace(pose, facing=facing), None
    seen = np.isfinite(pose.raw).all(-1).all(-1)
    split = float(pose.swapped[seen].mean()) if seen.any() else 0.0
    f = perception.facing[perception.detected]
    unsure = 1.0 - max(float(np.mean(f > 0)), float(np.mean(f < 0))) if f.size else 1.0
    doubt = max(split, unsure)
    if doubt <= s.facing_question_share:
        return pose, None
    return pose, Question(FACING, 0, T, -1 if front else 1, doubt)


def capture_video(
    path: str | os.PathLike,
    s: CaptureSettings | None = None,
    *,
    answers: dict[str, int] | None = None,
    model: PoseModel | None = None,
    limits: VideoLimits = VideoLimits(),
    on_progress: ProgressFn | None = None,
) -> Capture:
    """Decode a video, run the pose model and capture the motion (see :func:`capture`)."""
    s = s or CaptureSettings()
    t0 = time.perf_counter()
    rows = probe_video(path, limits).height  # never scale a small video up
    video = read_video(
        path, height=min(s.working_height, rows) if s.working_height else 0, limits=limits
    )
    t1 = time.perf_counter()
    perception = _perceive(video, model, on_progress)
    t2 = time.perf_counter()
    if not perception.detected.any():
        raise RegistrationFailed(
            "We could not find a person in this video. Film the whole body, from head to "
            "feet, in good light."
        )
    out = capture(perception, video.fps, (video.width, video.height), s, answers=answers)
    out.timing_s.update({"load": t1 - t0, "perception": t2 - t1})
    return out


def _perceive(video: Video, model: PoseModel | None, on_progress: ProgressFn | None) -> Perception:
    from engine.stages.perception import perceive  # mediapipe loads on use

    return perceive(video.frames, model, on_progress=on_progress)
