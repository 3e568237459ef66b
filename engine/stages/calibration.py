"""Stage 1: calibrate the scaled orthographic camera from the first frame (thesis 4.2).

The thesis compares the principal axes (PCA of the pixel positions) of the input body region
at t' = 0 with those of the projected calibration posture B_0 (it assumes B'_0 = B_0): the
ratio of principal lengths gives the scale s, the angle between principal directions the
in-plane angle theta_z, and the centres the position (c_x, c_y).

Beyond the thesis, the view azimuth about the vertical is estimated by sampling: the
calibration posture is projected at each sampled azimuth, PCA-calibrated as above, rendered,
and the azimuth with the smallest d_S (eq. 4.4) against the input region is kept, so face-on
and down-the-line (side) videos both work. Front and back views (azimuth a and a + 180 deg)
give mirror-image silhouettes that differ only in the internal edges; both are sampled.

Optionally (``above_ankles``) the last refinement fits scale and position by d_A over the
rows above the ankles only (:func:`_refine_above_ankles`): planted shoes print into a
static-camera background model, and a whole-body fit then shrinks the scale to end the legs
where the region does.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from engine.body.shapes import BodyShape
from engine.body.skeleton import JOINT_INDEX
from engine.errors import InvalidInput, RegistrationFailed
from engine.measures import LAMBDA_A, LAMBDA_E
from engine.render import capsules
from engine.render.camera import Camera
from engine.stages.perception import MIRROR, readings

ProgressFn = Callable[[str, float], None]


@dataclass(frozen=True)
class CalibrationSettings:
    """Settings of stage 1 (thesis 4.2).

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
        (:func:`_refine_above_ankles`): P1 scale -3.1 % -> -2.1 % (-1.1 % measured once with
        another GrabCut initialisation; over GrabCut seeds 0-6 it ranged -2.6 ... +1.9 %, the
        plain camera -3.1 ... +1.4 %), P2 -5.5 % -> -1.7 %. Off by default for now: stage 2
        compares whole silhouettes that lack the shoes in every frame, and the shorter (wrong)
        camera matches them better (P1 temporal error 0.83 -> 0.91 video frames with it on; P2
        1.84 -> 1.80).
    fit_width : bool
        After the camera, fit the performer's capsule radii per part group
        (:func:`fit_body_shape`; used by :func:`engine.pipeline.run_stages_0_2`).
    refine_top : int
        Azimuths (the best by the PCA fit's d_S) refined; the best refined fit wins. The PCA
        ranking alone is fragile: on a synthetic case (``coach synth 64_29 --seed 3``) -15 deg
        beat the true 0 deg before refinement (d_S 0.73 against 0.77) and lost after it (0.49
        against 0.38).
    check_mirror : bool
        Let the whole video choose between the best azimuth and the best one facing the
        other way (:func:`mirror_azimuth`; used by :func:`engine.pipeline.run_stages_0_2`).
        One frame's silhouette hardly tells a front view from a back view: on P2 the refined
        fits score 0.485 (front) and 0.466 (back), and the back view wins. Stage 2's mean cost
        E_C over the whole video separates them clearly (P2 0.38 front / 0.56 back, P1 0.32 /
        0.73), for one extra stage-2 run (~3 s for 150 frames).
    refine_frames : int
        After stage 2, polish scale, position and in-plane angle once more on this many
        frames spread over the video, each showing the reference posture stage 2 matched to
        it (:func:`refine_on_frames`; 0 keeps the one-frame camera). Beyond the thesis: one
        frame's region carries that frame's faults (on P2 part of a prop, on a synthetic case
        a missed band of trousers), which many frames average out. Camera error against the
        truth (scale %, cy px, in-plane deg), one frame -> 15 frames: P2 -6.1 / -8.3 / 2.5 ->
        -4.2 / -6.8 / 1.5; ``coach synth 64_30 --seed 4`` +1.4 / +1.5 / 0.1 -> +0.4 / 0.0 /
        0.1; P1 and three other synthetic cases unchanged. Stages 3-4 see the new camera;
        stage 2 keeps the one it ran with.
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


@dataclass(frozen=True)
class PrincipalAxes:
    """Principal axes of a pixel region (thesis 4.2 steps 3-4).

    Attributes
    ----------
    centre : ndarray, shape (2,)
        Mean (u, v) pixel position.
    direction : ndarray, shape (2,)
        First eigenvector (u, v), unit, oriented with v decreasing (pointing "up" the body).
    length : float
        Extent of the region along ``direction``, pixels.
    """

    centre: np.ndarray
    direction: np.ndarray
    length: float

    @property
    def angle(self) -> float:
        """Angle of ``direction`` in the image, radians (atan2(v, u))."""
        return float(np.arctan2(self.direction[1], self.direction[0]))


def principal_axes(mask: np.ndarray) -> PrincipalAxes:
    """PCA of the pixel positions of a region (thesis 4.2 step 3).

    Parameters
    ----------
    mask : ndarray of bool, shape (H, W)

    Returns
    -------
    PrincipalAxes

    Raises
    ------
    InvalidInput
        If the mask has fewer than 3 pixels.
    """
    rows, cols = np.nonzero(mask)
    if rows.size < 3:
        raise InvalidInput(f"mask must contain a body region, got {rows.size} pixel(s)")
    uv = np.stack([cols, rows], axis=1).astype(float)
    centre = uv.mean(0)
    cov = np.cov((uv - centre).T)
    w, v = np.linalg.eigh(cov)
    d = v[:, np.argmax(w)]
    if d[1] > 0:
        d = -d
    proj = (uv - centre) @ d
    return PrincipalAxes(centre, d, float(proj.max() - proj.min() + 1.0))


def _wrap_half_turn(a: float) -> float:
    """Wrap an axis angle to (-pi/2, pi/2] (a principal axis has no sign)."""
    return float((a + np.pi / 2) % np.pi - np.pi / 2)


def pca_camera(
    joints: np.ndarray, shape: BodyShape, target: np.ndarray, *, azimuth: float = 0.0
) -> Camera:
    """Camera by the thesis' PCA calibration at one azimuth (4.2 steps 1-7).

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
        Calibration posture, world frame.
    shape : BodyShape
    target : ndarray of bool, shape (H, W)
        Input body region of the calibration frame.
    azimuth : float
        View azimuth, radians.

    Returns
    -------
    Camera
    """
    h, w = target.shape
    tgt = principal_axes(target)
    # default camera: a scale that fits the body comfortably, world origin mid-image
    height_m = max(float(np.ptp(joints[:, 1])), 0.3)
    s0 = 0.6 * h / height_m
    mid = joints.mean(0)
    cam0 = Camera(scale=s0, theta_z=0.0, cx=0.0, cy=0.0, azimuth=azimuth, width=w, height=h)
    off = np.array([w / 2, h / 2]) - cam0.project(mid)
    cam0 = cam0.with_(cx=float(off[0]), cy=float(off[1]))
    proj = principal_axes(capsules.silhouettes(joints[None], shape, cam0)[0])
    s = s0 * tgt.length / proj.length
    theta = _wrap_half_turn(tgt.angle - proj.angle)
    # centroid of the projection relative to the world origin, in metres of image plane
    q = (proj.centre - np.array([cam0.cx, cam0.cy])) / s0
    c, si = np.cos(theta), np.sin(theta)
    c_xy = tgt.centre - s * (np.array([[c, -si], [si, c]]) @ q)
    return Camera(
        scale=float(s), theta_z=theta, cx=float(c_xy[0]), cy=float(c_xy[1]),
        azimuth=azimuth, width=w, height=h,
    )  # fmt: skip


def keypoint_camera(
    joints: np.ndarray,
    keypoints: np.ndarray,
    confidence: np.ndarray,
    *,
    azimuth: float,
    width: int,
    height: int,
) -> Camera:
    """Camera at one azimuth that best puts the posture's joints on 2D keypoints.

    The weighted least-squares similarity (scale, in-plane angle, translation) from the
    posture's orthographic view at ``azimuth`` to the keypoints, in closed form (Umeyama
    1991), on the labels as given and on their mirror (a pose model swaps left and right);
    the better fit wins. Beyond the thesis' PCA (4.2), which only sees the region's axes.

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
    keypoints : ndarray, shape (17, 2)
        NaN where there is none.
    confidence : ndarray, shape (17,)
    azimuth : float
        Radians.
    width, height : int

    Raises
    ------
    InvalidInput
        Fewer than three keypoints carry weight.
    """
    ok = np.isfinite(keypoints).all(-1) & (confidence > 0)
    if ok.sum() < 3:
        raise InvalidInput("at least three 2D keypoints are needed to place the camera")
    base = Camera(scale=1.0, azimuth=azimuth, width=width, height=height)
    p = base.project(joints)
    fits = []
    for idx in (np.arange(len(joints)), MIRROR):
        k, w = np.nan_to_num(keypoints[idx]), np.where(ok[idx], confidence[idx], 0.0)
        pm, km = (w[:, None] * p).sum(0) / w.sum(), (w[:, None] * k).sum(0) / w.sum()
        a, b = p - pm, k - km
        h00 = (w * a[:, 0] * b[:, 0]).sum() + (w * a[:, 1] * b[:, 1]).sum()
        h01 = (w * a[:, 0] * b[:, 1]).sum() - (w * a[:, 1] * b[:, 0]).sum()
        theta = float(np.arctan2(h01, h00))
        scale = float(np.hypot(h00, h01) / max((w * (a**2).sum(1)).sum(), 1e-12))
        c, si = np.cos(theta), np.sin(theta)
        t = km - scale * (np.array([[c, -si], [si, c]]) @ pm)
        r = scale * (a @ np.array([[c, si], [-si, c]])) - b
        fits.append(((w * (r**2).sum(1)).sum(), scale, theta, t))
    _, scale, theta, t = min(fits, key=lambda f: f[0])
    return Camera(scale=max(scale, 1e-6), theta_z=theta, cx=float(t[0]), cy=float(t[1]),
                  azimuth=azimuth, width=width, height=height)  # fmt: skip


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


def _facing_cost(azimuth_deg: float, facing: int, penalty: float) -> float:
    """``penalty`` when a view at ``azimuth_deg`` contradicts the facing (+1 front, -1 back);
    views within 15 deg of a side view contradict neither."""
    off = abs((azimuth_deg + 180.0) % 360.0 - 180.0)  # 0 front, 180 back
    if (facing > 0 and off > 105.0) or (facing < 0 and off < 75.0):
        return penalty
    return 0.0


def _refine_above_ankles(
    joints: np.ndarray, shape: BodyShape, silhouette: np.ndarray, cam: Camera
) -> tuple[Camera, float]:
    """Coordinate search on scale and position minimising d_A (eq. 4.1) over the image rows
    above the higher projected ankle only.

    The feet are the part of the body a static-camera background model loses first: shoes
    that stay planted for most of the video print into the background, and a d_S over the
    whole body then shrinks the scale until the capsule legs end where the silhouette does
    (measured: -3 % on P1, -5.5 % on P2). Head to ankles is the stretch both the region
    and the capsule body show faithfully, so the fit uses only that.
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
    in excess: a synthetic case with part of a leg missing started 3.5 deg off, and the
    position then settled 6 px from the truth (d_S 0.58; 0.36 at the true camera).
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


def calibrate(
    joints: np.ndarray,
    shape: BodyShape,
    silhouette: np.ndarray,
    edges: np.ndarray,
    settings: CalibrationSettings = CalibrationSettings(),
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


def refine_on_frames(
    camera: Camera,
    postures: np.ndarray,
    shape: BodyShape,
    silhouettes: np.ndarray,
    edges: np.ndarray,
    settings: CalibrationSettings = CalibrationSettings(),
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


#: Part groups whose capsule radii :func:`fit_body_shape` scales together.
WIDTH_GROUPS: dict[str, tuple[str, ...]] = {
    "torso": ("abdomen", "lower_chest", "upper_chest"),
    "head": ("head",),
    "arms": ("l_upper_arm", "l_lower_arm", "r_upper_arm", "r_lower_arm"),
    "legs": ("l_upper_leg", "l_lower_leg", "r_upper_leg", "r_lower_leg"),
}


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
