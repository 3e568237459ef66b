"""Settings of reference-free capture (seed 001): one frozen dataclass, documented defaults."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class CaptureSettings:
    """Tuning of :func:`engine.capture.capture`.

    Attributes
    ----------
    height_m : float
        The performer's height: bone lengths are the default adult body's scaled to it
        (seed 001, table 3.1). The depth of a bone comes from its foreshortening against
        this length, so a wrong height tilts bones in depth, it does not break the capture.
    working_height : int
        Pixels the video is scaled to before the pose model (0: as filmed).
    min_visibility : float
        Landmarks the model rates less visible than this are treated as missing and
        interpolated from the neighbouring frames (seed 001 4.1: key frames and interpolation
        where frames are unreliable).
    cutoff_hz : float
        Cut-off of the zero-phase low-pass (Butterworth, run forwards and backwards: no lag)
        applied to the 2D landmarks and to the lifted bone directions.
    swap_cost : float
        Cost (in units of the body's torso length moved between frames) of reading a frame's
        left/right labels against the model's. Small: the model flips its front/back reading
        for stretches of many frames (a third of the frames on some public cases), and only
        continuity sees it; the whole video's majority still sets the labels.
    hint_sigma_m : float
        Scale of the detector's relative-depth hint: a hint of this many metres in favour of
        one depth sign weighs about one nat.
    continuity_weight : float
        Cost of turning a bone's 3D direction between two frames, per (1 - cos): a depth sign
        can only flip where the bone passes through the image plane.
    facing_weight : float
        Cost of a body orientation that faces away from what the face landmarks say.
    limit_weight : float
        Cost of a joint-limit (appendix A, table A.1) or knee-hinge violation, per radian (for
        the hinge, per unit of the sine of a knee bent the wrong way): anatomy outweighs the
        detector's depth hint wherever a joint is clearly bent (50: 25 nats for a knee bent
        30 deg backwards, against about 6 for a hint of 0.3 m).
    question_margin : float
        A span of frames whose depth sign wins by less than this (nats, against the opposite
        sign over the span) is left as a question for the user.
    min_question_s : float
        Spans shorter than this are never asked about (their frames are few and move little).
    facing_question_share : float
        When the pose model's left/right labels disagree with the continuous reading, or its
        face landmarks with its own majority front/back reading, in more than this share of
        the frames, whether the body faces the camera is asked (the model judges front and
        back from appearance, and a faceless or back-lit figure fools it).
    camera_distance_m : float
        Assumed camera distance for root motion in depth (from the change of the body's
        image scale); the image-plane root motion needs no assumption.
    """

    height_m: float = 1.75
    working_height: int = 480
    min_visibility: float = 0.3
    cutoff_hz: float = 6.0
    swap_cost: float = 0.02
    hint_sigma_m: float = 0.05
    continuity_weight: float = 20.0
    facing_weight: float = 3.0
    limit_weight: float = 50.0
    question_margin: float = 3.0
    min_question_s: float = 0.2
    facing_question_share: float = 0.2
    camera_distance_m: float = 4.0
