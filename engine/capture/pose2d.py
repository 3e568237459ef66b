"""Capture step 1: the performer's 2D pose in every frame, from the pose model's landmarks.

Seed 001 fits a stick model to the silhouette (3.1.4); here the learned landmarks of stage 0's
perception step give the 2D joints, which the seed's ideas then make reliable over a whole
video: left/right labels made continuous (its crossed-legs and swap handling, 3.1.4), frames
the model misses or is unsure of interpolated from their neighbours (4.1, key frames), and a
zero-phase low-pass, which smooths without the lag of a causal filter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.signal import butter, filtfilt

from engine.errors import RegistrationFailed

#: The points the capture lifts: BlazePose landmark indices averaged into each.
POINTS: tuple[tuple[str, tuple[int, ...]], ...] = (
    ("hip", (23, 24)),
    ("l_hip", (23,)),
    ("r_hip", (24,)),
    ("l_knee", (25,)),
    ("r_knee", (26,)),
    ("l_ankle", (27,)),
    ("r_ankle", (28,)),
    ("neck", (11, 12)),
    ("l_shoulder", (11,)),
    ("r_shoulder", (12,)),
    ("l_elbow", (13,)),
    ("r_elbow", (14,)),
    ("l_wrist", (15,)),
    ("r_wrist", (16,)),
    ("head", (7, 8)),
)
POINT_NAMES: tuple[str, ...] = tuple(n for n, _ in POINTS)
P = {n: i for i, n in enumerate(POINT_NAMES)}
#: Point index -> its left/right mirror, shape (15,).
POINT_MIRROR = np.array(
    [
        P[
            n.replace("l_", "r_", 1)
            if n.startswith("l_")
            else n.replace("r_", "l_", 1)
            if n.startswith("r_")
            else n
        ]
        for n in POINT_NAMES
    ]
)
_SIDED = np.array([i for i, n in enumerate(POINT_NAMES) if n[:2] in ("l_", "r_")])


@dataclass(frozen=True)
class Pose2D:
    """The performer's landmarks over a video.

    Attributes
    ----------
    uv : ndarray, shape (T', 15, 2)
        Pixels, :data:`POINT_NAMES` order; finite everywhere (gaps interpolated).
    z : ndarray, shape (T', 15)
        The model's relative depth of each point (pixels, larger = farther), NaN where the
        model gave none (no detection, or a gap).
    reliable : ndarray of bool, shape (T', 15)
        The point was seen in this frame (detected, visible enough); False where it was
        interpolated.
    facing : ndarray of int8, shape (T',)
        +1 faces the camera, -1 turns away, 0 unknown (the perception step's reading).
    swapped : ndarray of bool, shape (T',)
        Frames whose left/right labels were read against the model's.
    fps : float
    raw : ndarray, shape (T', 15, 2)
        The model's points as it gave them (its labels, NaN without a detection).
    """

    uv: np.ndarray
    z: np.ndarray
    reliable: np.ndarray
    facing: np.ndarray
    swapped: np.ndarray
    fps: float
    raw: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(self.uv.shape[0])


def points_from_landmarks(landmarks: np.ndarray) -> np.ndarray:
    """BlazePose landmarks (T', 33, 4) [u, v, z, visibility] -> points (T', 15, 4), each the
    mean of its landmarks (the visibility their minimum)."""
    lm = np.asarray(landmarks, float)
    out = np.empty(lm.shape[:-2] + (len(POINTS), 4))
    for i, (_, idx) in enumerate(POINTS):
        out[..., i, :3] = lm[..., idx, :3].mean(axis=-2)
        out[..., i, 3] = lm[..., idx, 3].min(axis=-1)
    return out


def resolve_label_swaps(
    uv: np.ndarray, seen: np.ndarray, torso_px: float, cost: float
) -> np.ndarray:
    """Frames whose left/right labels should be read mirrored, by Viterbi over two states.

    The model now and then swaps left and right for a frame or a few (a front/back confusion).
    Between two frames each labelling's cost is how far the sided points move, in torso
    lengths; reading a frame against the model costs ``cost``. The whole video's majority
    labelling is the model's, so a body seen consistently from behind stays as the model has it
    (which of the two the body really is, is the depth question that the lifting answers).

    Parameters
    ----------
    uv : ndarray, shape (T', 15, 2)
    seen : ndarray of bool, shape (T',)
        Frames with a detection; the others carry no evidence and keep the state.
    torso_px : float
    cost : float

    Returns
    -------
    ndarray of bool, shape (T',)
    """
    T = uv.shape[0]
    if T == 0:
        return np.zeros(0, bool)
    both = np.stack([uv, uv[:, POINT_MIRROR]], axis=1)[:, :, _SIDED]  # (T', 2, S, 2)
    unary = np.where(seen[:, None], np.array([0.0, cost])[None], 0.0)
    d = np.linalg.norm(both[1:, None] - both[:-1, :, None], axis=-1).mean(-1) / torso_px
    # d[t, i, j]: state i at t, state j at t + 1
    pair = np.where((seen[1:] & seen[:-1])[:, None, None], d, 0.0)
    path = viterbi(unary, pair)
    return path.astype(bool)


def viterbi(unary: np.ndarray, pair: np.ndarray) -> np.ndarray:
    """Minimum-cost state path.

    Parameters
    ----------
    unary : ndarray, shape (T, K)
    pair : ndarray, shape (T - 1, K, K)
        ``pair[t, i, j]``: state i at t followed by state j at t + 1.

    Returns
    -------
    ndarray of int, shape (T,)
    """
    T, K = unary.shape
    acc = unary[0].copy()
    back = np.zeros((T, K), int)
    for t in range(1, T):
        total = acc[:, None] + pair[t - 1]
        back[t] = np.argmin(total, axis=0)
        acc = total[back[t], np.arange(K)] + unary[t]
    path = np.empty(T, int)
    path[-1] = int(np.argmin(acc))
    for t in range(T - 1, 0, -1):
        path[t - 1] = back[t, path[t]]
    return path


def fill_gaps(values: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Linear interpolation over time where ``ok`` is False, per channel; ends held.

    Parameters
    ----------
    values : ndarray, shape (T', ...)
    ok : ndarray of bool, shape (T', ...) matching ``values`` up to its trailing axes
    """
    v = np.array(values, float)
    flat = v.reshape(v.shape[0], -1)
    okf = np.broadcast_to(ok.reshape(ok.shape + (1,) * (v.ndim - ok.ndim)), v.shape)
    okf = okf.reshape(v.shape[0], -1) & np.isfinite(flat)
    t = np.arange(v.shape[0])
    for c in range(flat.shape[1]):
        good = okf[:, c]
        if good.any() and not good.all():
            flat[:, c] = np.interp(t, t[good], flat[good, c])
    return flat.reshape(v.shape)


def zero_phase(values: np.ndarray, fps: float, cutoff_hz: float) -> np.ndarray:
    """Butterworth low-pass run forwards and backwards along axis 0 (no lag); unchanged when
    the video is too short for the filter or the cut-off is above Nyquist."""
    v = np.asarray(values, float)
    nyq = 0.5 * fps
    if cutoff_hz <= 0 or cutoff_hz >= 0.95 * nyq or v.shape[0] < 10:
        return v
    b, a = butter(2, cutoff_hz / nyq)
    return filtfilt(b, a, v, axis=0, padlen=min(v.shape[0] - 1, 3 * max(len(a), len(b))))


def faces_camera(uv: np.ndarray) -> bool:
    """Whether the labelled 2D pose (T', 15, 2) shows the front of the body in most frames:
    the left hip on the image's right of the right hip, seen upright, counted over the frames
    whose hips are clearly apart (a quarter of the torso); True when none are.

    A majority, not the first frame: the model's labels are often wrong for the first frames
    (P1, P4), before continuity has more frames to go on.
    """
    lat = uv[:, P["l_hip"]] - uv[:, P["r_hip"]]
    down = uv[:, P["hip"]] - uv[:, P["neck"]]  # neck to hip, in image (u, v)
    torso = np.linalg.norm(down, axis=-1)
    # forward = cross(lat, up) in the camera frame (x right, y down, z away) points towards
    # the camera (z < 0) for a front view; up = -down, so that is cross(lat, down)_z > 0
    front = lat[:, 0] * down[:, 1] - lat[:, 1] * down[:, 0]
    apart = np.abs(lat[:, 0]) > 0.25 * np.maximum(torso, 1e-6)
    return bool(np.sum(np.sign(front[apart])) >= 0)


def pose_2d(
    landmarks: np.ndarray,
    facing: np.ndarray,
    fps: float,
    *,
    min_visibility: float,
    cutoff_hz: float,
    swap_cost: float,
    flip: bool = False,
) -> Pose2D:
    """The 2D pose of every frame from the pose model's landmarks.

    Parameters
    ----------
    landmarks : ndarray, shape (T', 33, 4)
        :attr:`engine.stages.perception.Perception.landmarks` (NaN without a detection).
    facing : ndarray, shape (T',)
    fps : float
    flip : bool
        Read every frame against the labels continuity chose: the user said the body faces
        the other way (the front/back question).

    Raises
    ------
    RegistrationFailed
        No frame shows a person.
    """
    pts = points_from_landmarks(landmarks)
    seen = np.isfinite(pts[..., :2]).all(-1).all(-1)  # a model may give no depth
    if not seen.any():
        raise RegistrationFailed(
            "We could not find a person in this video. Film the whole body, from head to "
            "feet, in good light."
        )
    raw = np.where(seen[:, None, None], pts[..., :2], np.nan)
    uv = fill_gaps(pts[..., :2], np.broadcast_to(seen[:, None], pts.shape[:2]))
    torso = float(np.nanmedian(np.linalg.norm(uv[seen, P["neck"]] - uv[seen, P["hip"]], axis=-1)))
    swapped = resolve_label_swaps(uv, seen, max(torso, 1.0), swap_cost) ^ flip
    # A swap exchanges only the labels: the model's depth of each point (and so its facing,
    # nose against ears) goes with the point, not with its name. Negating the depths of the
    # relabelled frames as well (the body "mirrored in depth") lowered the depth signs'
    # agreement with the truth on the public cases (P1 0.83 -> 0.75, P4 0.86 -> 0.81).
    pts = np.where(swapped[:, None, None], pts[:, POINT_MIRROR], pts)
    face = np.asarray(facing, np.int8)
    ok = seen[:, None] & (np.nan_to_num(pts[..., 3]) >= min_visibility)
    uv = zero_phase(fill_gaps(pts[..., :2], ok), fps, cutoff_hz)
    z = np.where(ok, pts[..., 2], np.nan)
    return Pose2D(
        uv=uv,
        z=z,
        reliable=ok,
        facing=face.astype(np.int8),
        swapped=swapped,
        fps=float(fps),
        raw=raw,
    )
