"""The tuning of stage 1 (thesis 4.2): one frozen settings object."""

from __future__ import annotations

from dataclasses import dataclass

from engine.measures import LAMBDA_A, LAMBDA_E


@dataclass(frozen=True)
class CalibrationSettings:
    """Settings of stage 1 (thesis 4.2).

    The benchmark figures behind the defaults beyond the thesis are in
    ``benchmarks/README.md`` ("Design figures", stage 1).

    Attributes
    ----------
    azimuths_deg : tuple of float
        View azimuths sampled (0 = the body's front; 90 = its left side). The thesis has
        only 0.
    reference_frame : int or None
        Reference frame shown by video frame 0 (the calibration posture, B'_0 = B_0).
        ``None`` means the reference's first motion frame (frame 1 of a CMU file whose frame
        0 is the conversion T-pose; the public cases pin video frame 0 there).
    video_frame : int
        Video frame used as the calibration image.
    lambda_A, lambda_E : float
        Weights of d_S (eq. 4.4) used to pick the azimuth.
    refine : bool
        After PCA, polish scale and position by a small d_S grid search (beyond the thesis:
        PCA lengths are biased by a mesh body wider than the capsules).
    above_ankles : bool
        Finish with a d_A fit over the rows above the ankles only
        (:func:`~engine.stages.calibration.search._refine_above_ankles`): the scale comes
        closer to the truth on P1 and P2. Off by default for now: stage 2 compares whole
        silhouettes that lack the shoes in every frame, and the shorter (wrong) camera
        matches them better (P1's temporal error grew with it on).
    fit_width : bool
        After the camera, fit the performer's capsule radii per part group
        (:func:`fit_body_shape`; used by :func:`engine.pipeline.run_stages_0_2`).
    refine_top : int
        Azimuths (the best by the PCA fit's d_S) refined; the best refined fit wins. The PCA
        ranking alone is fragile: on a synthetic case a wrong azimuth beat the true one
        before refinement and lost after it.
    check_mirror : bool
        Let the whole video choose between the best azimuth and the best one facing the
        other way (:func:`mirror_azimuth`; used by :func:`engine.pipeline.run_stages_0_2`).
        One frame's silhouette hardly tells a front view from a back view: on P2 the back
        view's refined fit scores a little better, and wins. Stage 2's mean cost E_C over the
        whole video separates them clearly, for one extra stage-2 run.
    refine_frames : int
        After stage 2, polish scale, position and in-plane angle once more on this many
        frames spread over the video, each showing the reference posture stage 2 matched to
        it (:func:`refine_on_frames`; 0 keeps the one-frame camera). Beyond the thesis: one
        frame's region carries that frame's faults (on P2 part of a prop, on a synthetic case
        a missed band of trousers), which many frames average out: the camera came closer to
        the truth on those cases and stayed where it was on the others. Stages 3-4 see the
        new camera; stage 2 keeps the one it ran with.
    keypoint_weight : float
        With 2D keypoints (:mod:`engine.stages.perception`), each azimuth's camera starts
        from the keypoints instead of PCA (:func:`keypoint_camera`: scale, centre and roll
        from the hips, shoulders, knees, ankles...), and every fit minimises d_S +
        ``keypoint_weight`` d_K (:func:`engine.measures.d_K`). Beyond the thesis: a body
        region that lacks the legs (a wall of the trousers' colour) gave a camera a third too
        small; the keypoints do not depend on the background.
    offset_frames : int
        Video frames from the first on which the pose model's offset from each joint is
        measured (:func:`engine.stages.perception.keypoint_offsets`); 0 trusts the
        keypoints as they come.
    keypoint_tau : float
        d_K's saturation distance as a fraction of the body's height in the image.
    perspective : bool
        Let :func:`refine_on_frames` also fit the camera's distance (a pinhole camera,
        :class:`~engine.render.camera.Camera`), which frames of postures at different depths
        (a bend towards the camera) tell apart; one upright frame does not, so stage 1's
        first calibration stays orthographic. Beyond the thesis: a phone 3.5 m away at 35 deg
        (P4) sees the near side of the body larger.
    facing_penalty : float
        Added to the score of an azimuth that contradicts the facing the pose model saw
        (the face seen: not a view from behind; the back of the head: not one from the front).
    """

    azimuths_deg: tuple[float, ...] = tuple(float(a) for a in range(-180, 180, 15))
    reference_frame: int | None = None
    video_frame: int = 0
    lambda_A: float = LAMBDA_A
    lambda_E: float = LAMBDA_E
    refine: bool = True
    above_ankles: bool = False
    fit_width: bool = True
    check_mirror: bool = True
    refine_top: int = 3
    refine_frames: int = 15
    offset_frames: int = 5
    keypoint_weight: float = 1.0
    keypoint_tau: float = 0.1
    facing_penalty: float = 0.1
    perspective: bool = True
