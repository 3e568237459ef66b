"""Stage 0, learned part: a person mask, 2D keypoints and the facing of every video frame.

Beyond the thesis (whose stage 0 is background differencing, 4.1): a pose model trained on
photographs of people separates a performer from a wall of his clothes' colour, which no
background model can when he never leaves his spot, and it sees in-plane limb angles and arms
in front of the torso, which a silhouette cannot. It is a strong cue, never trusted alone: it
swaps left and right in many frames and loses the person in some. Stage 0 fuses its mask with
the thesis' evidence (:mod:`engine.stages.foreground`); stages 1-3 use its keypoints through
swap-invariant, confidence-weighted, robust terms (:mod:`engine.measures`).

The model sits behind :class:`PoseModel`, so another one can replace it. The default,
:class:`MediaPipePose`, is MediaPipe's legacy pose solution, whose two TFLite models
(``pose_detection.tflite``, ``pose_landmark_full.tflite``) ship inside its PyPI wheel
(pinned in ``pyproject.toml``): nothing is fetched at run time.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from engine.body.skeleton import JOINTS
from engine.errors import InvalidInput, RegistrationFailed
from engine.render.camera import Camera

ProgressFn = Callable[[str, float], None]

#: Our joints (DESIGN.md order) -> MediaPipe pose landmark index (BlazePose topology); -1 for
#: a joint the model has no landmark for (``hip``, ``neck`` are built from two landmarks).
_MP_INDEX = {
    "l_hip": 23, "l_knee": 25, "l_ankle": 27, "r_hip": 24, "r_knee": 26, "r_ankle": 28,
    "l_shoulder": 11, "l_elbow": 13, "l_wrist": 15, "r_shoulder": 12, "r_elbow": 14,
    "r_wrist": 16,
}  # fmt: skip
_NOSE, _L_EAR, _R_EAR = 0, 7, 8

#: Joints a keypoint detector measures on the body's surface landmarks the way our skeleton
#: defines them; the spine joints and the head's top have no landmark.
KEYPOINT_JOINTS: tuple[int, ...] = tuple(
    JOINTS.index(n) for n in ("hip", *_MP_INDEX)
)

#: Joint index -> the index of its mirror image (left <-> right), identity elsewhere.
MIRROR: np.ndarray = np.array(
    [JOINTS.index(n.replace("l_", "r_", 1) if n.startswith("l_")
                  else n.replace("r_", "l_", 1) if n.startswith("r_") else n)
     for n in JOINTS]
)  # fmt: skip


@dataclass(frozen=True)
class PerceptionSettings:
    """Settings of the learned perception step.

    Attributes
    ----------
    enabled : bool
        Run the pose model (the ``thesis`` preset turns it off: stage 0 is then the thesis'
        alone and no stage has keypoints).
    min_detection_confidence : float
        The person detector's threshold (MediaPipe's default).
    min_detected_fraction : float
        With fewer frames than this showing a person (to the pose model, or to the thesis'
        region), the analysis fails with a message saying so rather than fit nothing.
    """

    enabled: bool = True
    min_detection_confidence: float = 0.5
    min_detected_fraction: float = 0.25


@dataclass(frozen=True)
class Perception:
    """What the pose model saw in each video frame.

    Attributes
    ----------
    mask : ndarray of uint8, shape (T', H, W)
        Person probability x 255 (0 everywhere in a frame without a detection).
    keypoints : ndarray, shape (T', 17, 2)
        (u, v) pixels per joint in DESIGN.md order; NaN where the model has no landmark.
    confidence : ndarray, shape (T', 17)
        The model's visibility of each keypoint in [0, 1]; 0 where there is none.
    facing : ndarray of int8, shape (T',)
        +1 the performer faces the camera, -1 turns his back to it, 0 side-on or unknown
        (from the face landmarks' depth against the ears').
    detected : ndarray of bool, shape (T',)
        The model found a person in the frame.
    model : str
        Name and version of the model, stored with the analysis.
    landmarks : ndarray, shape (T', 33, 4), optional
        The model's own landmarks (BlazePose topology): (u, v) pixels, its relative depth z
        (pixels, larger = farther from the camera, 0 at the hips' mid-point) and visibility;
        NaN in frames without a detection. Reference-free capture reads its depth hint and
        head landmarks; None for a model (or a stored stage) without them.
    """

    mask: np.ndarray
    keypoints: np.ndarray
    confidence: np.ndarray
    facing: np.ndarray
    detected: np.ndarray
    model: str
    landmarks: np.ndarray | None = None

    @property
    def n_frames(self) -> int:
        return int(self.detected.shape[0])

    def person(self, threshold: float = 0.5) -> np.ndarray:
        """The learned person mask as bool, shape (T', H, W)."""
        return self.mask > int(round(255 * threshold))

    def to_arrays(self) -> dict[str, np.ndarray]:
        """Arrays for :func:`engine.io.stagefiles.save_arrays` (the mask stays uint8)."""
        out = {
            "perception_mask": self.mask, "perception_keypoints": self.keypoints,
            "perception_confidence": self.confidence, "perception_facing": self.facing,
            "perception_detected": self.detected, "perception_model": np.array(self.model),
        }  # fmt: skip
        if self.landmarks is not None:
            out["perception_landmarks"] = self.landmarks
        return out

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> Perception | None:
        """Inverse of :meth:`to_arrays`; None when the arrays hold no perception."""
        if "perception_keypoints" not in a:
            return None
        return cls(
            np.asarray(a["perception_mask"]), np.asarray(a["perception_keypoints"]),
            np.asarray(a["perception_confidence"]), np.asarray(a["perception_facing"]),
            np.asarray(a["perception_detected"]), str(a["perception_model"]),
            np.asarray(a["perception_landmarks"]) if "perception_landmarks" in a else None,
        )  # fmt: skip

    def cut(self, start: int, end: int) -> Perception:
        """Frames ``start``..``end - 1`` only."""
        sl = slice(start, end)
        lm = None if self.landmarks is None else self.landmarks[sl]
        return Perception(self.mask[sl], self.keypoints[sl], self.confidence[sl],
                          self.facing[sl], self.detected[sl], self.model, lm)  # fmt: skip

    def scaled(self, factor: float) -> Perception:
        """Keypoints in an image scaled by ``factor`` (the mask is left as it is)."""
        lm = None
        if self.landmarks is not None:
            lm = self.landmarks * np.array([factor, factor, factor, 1.0])
        return Perception(self.mask, self.keypoints * factor, self.confidence, self.facing,
                          self.detected, self.model, lm)  # fmt: skip


class PoseModel(Protocol):
    """A learned person detector: RGB frames (T', H, W, 3) uint8 in, :class:`Perception` out."""

    name: str

    def __call__(
        self, frames: np.ndarray, *, on_progress: ProgressFn | None = None
    ) -> Perception: ...


def landmarks_to_joints(
    landmarks: np.ndarray, visibility: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """BlazePose landmarks -> our 17 joints.

    Parameters
    ----------
    landmarks : ndarray, shape (33, 2)
        (u, v) pixels.
    visibility : ndarray, shape (33,)

    Returns
    -------
    keypoints : ndarray, shape (17, 2)
        ``hip`` is the mid-point of the hips, ``neck`` of the shoulders; lower/upper chest and
        head top have no landmark (NaN).
    confidence : ndarray, shape (17,)
    """
    kp = np.full((len(JOINTS), 2), np.nan)
    conf = np.zeros(len(JOINTS))
    for name, i in _MP_INDEX.items():
        kp[JOINTS.index(name)] = landmarks[i]
        conf[JOINTS.index(name)] = visibility[i]
    for name, (a, b) in {"hip": (23, 24), "neck": (11, 12)}.items():
        kp[JOINTS.index(name)] = 0.5 * (landmarks[a] + landmarks[b])
        conf[JOINTS.index(name)] = min(visibility[a], visibility[b])
    # the neck is the shoulders' mid-point only roughly (BVH Neck1 sits higher): no weight
    conf[JOINTS.index("neck")] = 0.0
    return kp, np.clip(conf, 0.0, 1.0)


def facing_from_depths(nose_z: float, ears_z: float, torso_px: float) -> int:
    """+1 when the nose is nearer the camera than the ears (the face is seen), -1 when
    farther, 0 when the difference is under 15 % of the torso's length in the image (the
    head side-on, or the depths unsure)."""
    d = (ears_z - nose_z) / max(torso_px, 1e-6)
    return 1 if d > 0.15 else -1 if d < -0.15 else 0


class MediaPipePose:
    """MediaPipe's legacy pose solution (BlazePose full, with segmentation), run in video
    mode so that it tracks the person between frames.

    Parameters
    ----------
    min_detection_confidence : float
        The person detector's threshold (MediaPipe's default 0.5).
    """

    def __init__(self, *, min_detection_confidence: float = 0.5) -> None:
        self.min_detection_confidence = min_detection_confidence
        self.name = f"mediapipe-pose-full-{_mediapipe_version()}"

    def __call__(
        self, frames: np.ndarray, *, on_progress: ProgressFn | None = None
    ) -> Perception:
        f = np.asarray(frames)
        if f.ndim != 4 or f.shape[-1] != 3 or f.dtype != np.uint8:
            raise InvalidInput(
                f"frames must be uint8 of shape (T', H, W, 3), got {f.dtype} {f.shape}"
            )
        from mediapipe.python.solutions import pose as mp_pose  # heavy: import on use

        n, h, w = f.shape[:3]
        mask = np.zeros((n, h, w), np.uint8)
        kps = np.full((n, len(JOINTS), 2), np.nan)
        conf = np.zeros((n, len(JOINTS)))
        facing = np.zeros(n, np.int8)
        detected = np.zeros(n, bool)
        landmarks = np.full((n, 33, 4), np.nan)
        out = (mask, kps, conf, facing, detected, landmarks)
        # Forward, then backward over the frames still without a person: the landmark model
        # tracks a person from frame to frame far more reliably than the detector finds one
        # (P3, grey on a grey wall: 58 % of the frames forward, 83 % backward, all together;
        # P6 77 % / 98 %), so a person found late is followed back to the start.
        for order, share in ((range(n), 0.5), (range(n - 1, -1, -1), 0.5)):
            if order.step < 0 and detected.all():
                break
            missing = ~detected.copy()
            with mp_pose.Pose(
                static_image_mode=False, model_complexity=1, smooth_landmarks=True,
                enable_segmentation=True, smooth_segmentation=True,
                min_detection_confidence=self.min_detection_confidence,
            ) as model:  # fmt: skip
                for done, i in enumerate(order):
                    r = model.process(np.ascontiguousarray(f[i]))
                    if missing[i]:
                        _store(r, i, out, (h, w))
                    if on_progress is not None:
                        on_progress("perception", (0.0 if order.step > 0 else share)
                                    + share * (done + 1) / n)  # fmt: skip
        if on_progress is not None:
            on_progress("perception", 1.0)
        return Perception(mask, kps, conf, facing, detected, self.name, landmarks)


def _store(result, i: int, out: tuple, size: tuple[int, int]) -> None:
    """Write one MediaPipe result into frame i of ``out`` (mask, keypoints, confidence,
    facing, detected, landmarks)."""
    if result.pose_landmarks is None:
        return
    mask, kps, conf, facing, detected, landmarks = out
    h, w = size
    lm = np.array([(p.x * w, p.y * h, p.z * w, p.visibility)
                   for p in result.pose_landmarks.landmark])  # fmt: skip
    kps[i], conf[i] = landmarks_to_joints(lm[:, :2], lm[:, 3])
    landmarks[i] = lm
    torso = float(np.linalg.norm(lm[11, :2] + lm[12, :2] - lm[23, :2] - lm[24, :2]) / 2)
    facing[i] = facing_from_depths(lm[_NOSE, 2], 0.5 * (lm[_L_EAR, 2] + lm[_R_EAR, 2]), torso)
    if result.segmentation_mask is not None:
        mask[i] = np.clip(result.segmentation_mask * 255.0 + 0.5, 0, 255).astype(np.uint8)
    detected[i] = True


def _mediapipe_version() -> str:
    try:
        import mediapipe
    except ImportError as e:  # the perception extra is not installed
        raise InvalidInput(
            "the learned perception step needs the 'perception' extra (pip install "
            "'motion-coach[perception]'); use the 'thesis' preset to run without it"
        ) from e
    return str(mediapipe.__version__)


def perceive(
    frames: np.ndarray, model: PoseModel | None = None, *, on_progress: ProgressFn | None = None
) -> Perception:
    """Run a pose model over a video (the default: :class:`MediaPipePose`).

    Parameters
    ----------
    frames : ndarray of uint8, shape (T', H, W, 3)
        RGB frames.
    model : PoseModel, optional

    Raises
    ------
    InvalidInput
        Bad frames, or the default model's package is not installed.
    """
    return (model or MediaPipePose())(frames, on_progress=on_progress)


def readings(
    keypoints: np.ndarray, confidence: np.ndarray, offsets: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """The two readings of a detection, labels as given and mirrored, for :func:`d_K`.

    Parameters
    ----------
    keypoints : ndarray, shape (..., 17, 2)
    confidence : ndarray, shape (..., 17)
    offsets : ndarray, shape (17, 2), optional
        The detector's offset from each joint (:func:`keypoint_offsets`), removed from both
        readings once the labels are read.

    Returns
    -------
    keypoints : ndarray, shape (..., 2, 17, 2)
    confidence : ndarray, shape (..., 2, 17)
    """
    kp = np.asarray(keypoints, float)
    off = np.zeros((17, 2)) if offsets is None else np.asarray(offsets, float)
    both = np.stack([kp - off, kp[..., MIRROR, :] - off], axis=-3)
    c = np.asarray(confidence, float)
    return both, np.stack([c, c[..., MIRROR]], axis=-2)


def keypoint_offsets(
    keypoints: np.ndarray, confidence: np.ndarray, predicted: np.ndarray
) -> np.ndarray:
    """The detector's own offset from each of our joints, where the posture is known.

    A pose model puts a hip or a wrist where its training data did, not where a motion
    capture skeleton has the joint, and loose clothes or a club move it further: on the
    public cases its keypoints are 4 px (median) from the truth's joints, 2.6-3.3 px once a
    constant offset per joint, measured on the first five frames, is removed
    (``benchmarks/perception.py``). Stage 1 assumes the first frames show the reference's
    first posture (thesis 4.2, B'_0 = B_0), which is what makes the offset measurable.

    Parameters
    ----------
    keypoints : ndarray, shape (N, 17, 2)
    confidence : ndarray, shape (N, 17)
    predicted : ndarray, shape (N, 17, 2)
        Where the joints are in those frames (the known posture through the camera).

    Returns
    -------
    offsets : ndarray, shape (17, 2)
        Median of keypoint - joint per joint after resolving left/right per frame; 0 for a
        joint seen in fewer than two frames.
    """
    kp = np.asarray(keypoints, float)
    swap = resolve_swaps(kp, predicted, confidence)
    kp = np.where(swap[:, None, None], kp[:, MIRROR], kp)
    conf = np.where(swap[:, None], np.asarray(confidence)[:, MIRROR], confidence)
    res = np.where(((conf > 0) & np.isfinite(kp).all(-1))[..., None], kp - predicted, np.nan)
    seen = np.isfinite(res).all(-1).sum(0) >= 2
    out = np.zeros((17, 2))
    if seen.any():
        out[seen] = np.nanmedian(res[:, seen], axis=0)
    return out


def resolve_swaps(
    keypoints: np.ndarray, predicted: np.ndarray, confidence: np.ndarray
) -> np.ndarray:
    """Whether each frame's detection is left/right swapped against a prediction.

    Parameters
    ----------
    keypoints, predicted : ndarray, shape (N, 17, 2)
        Detected keypoints and the projection of the postures they should match.
    confidence : ndarray, shape (N, 17)

    Returns
    -------
    ndarray of bool, shape (N,)
        True where the mirrored labels (:data:`MIRROR`) fit the prediction better.
    """
    ok = np.isfinite(keypoints).all(-1) & (confidence > 0)
    d = np.where(ok, np.linalg.norm(np.nan_to_num(keypoints) - predicted, axis=-1), 0.0)
    dm = np.where(ok[:, MIRROR], np.linalg.norm(np.nan_to_num(keypoints[:, MIRROR]) - predicted,
                                                 axis=-1), 0.0)  # fmt: skip
    w = confidence
    return (dm * w[:, MIRROR]).sum(1) < (d * w).sum(1)


def check_person_found(
    flags: Sequence[Sequence[str]], perception: Perception | None, min_fraction: float
) -> None:
    """Refuse a video where nobody is found, rather than fit the reference to nothing.

    A frame shows a person when the pose model detected one there or stage 0's region is not
    flagged ``no_person`` (a pose model trained on photographs may miss a rendered or
    unusual figure that the background difference still finds; what is then found but is not
    a body ends ``poor_fit``, :func:`engine.stages.assessment.assess_fit`).

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


def offsets_on_first_frames(
    perception: Perception, camera: Camera, posture: np.ndarray, n_frames: int
) -> np.ndarray:
    """The detector's offsets (17, 2) on the first ``n_frames`` frames, which show
    ``posture`` (17, 3) by stage 1's assumption; zeros when fewer than two of them have a
    detection."""
    idx = np.flatnonzero(perception.detected[:n_frames])
    if idx.size < 2:
        return np.zeros((17, 2))
    pred = np.broadcast_to(camera.project(posture), (idx.size, 17, 2))
    return keypoint_offsets(perception.keypoints[idx], perception.confidence[idx], pred)


def calibration_keypoints(
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
