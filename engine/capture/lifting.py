"""Capture step 2: 3D from one view (seed 001, 2.3 and 3.1.5).

Under scaled orthographic projection a segment of length L whose image is (du, dv) at image
scale s has a depth difference dz = +-sqrt(L^2 - (du^2 + dv^2) / s^2) between its ends
(seed 001 eq. 2.2, after Taylor 2000). The magnitude comes from the foreshortening; the sign
is the classic ambiguity, one per segment and frame. Seed 001 asked the user for it (59-60
inputs per video). Here it is chosen for whole chains of segments at once by Viterbi over
the frames, from
- the detector's own relative depth (a hint, not trusted alone);
- continuity: a sign can flip only where the segment passes through the image plane, since
  elsewhere a flip turns the bone by a large angle between two frames;
- joint limits (thesis appendix A, table A.1) and the knee's hinge, which bends one way only;
- the facing the face landmarks show.
Spans where the chosen sign still wins by a small margin are returned as questions.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import product

import numpy as np

from engine.capture.pose2d import P, Pose2D, viterbi, zero_phase
from engine.capture.settings import CaptureSettings

#: Lifted segments: (name, parent point, child point, length of a 1.75 m adult in metres).
#: Pelvis and shoulders run right to left through their mid-point. The lengths are between
#: the pose model's landmarks (hip joints, acromions, ears' mid-point), which differ a little
#: from a mocap skeleton's: each is only a floor, raised where the video shows it longer.
SEGMENTS: tuple[tuple[str, str, str, float], ...] = (
    ("pelvis", "r_hip", "l_hip", 0.20),
    ("trunk", "hip", "neck", 0.50),
    ("shoulders", "r_shoulder", "l_shoulder", 0.33),
    ("l_thigh", "l_hip", "l_knee", 0.43),
    ("l_shin", "l_knee", "l_ankle", 0.42),
    ("r_thigh", "r_hip", "r_knee", 0.43),
    ("r_shin", "r_knee", "r_ankle", 0.42),
    ("l_upper_arm", "l_shoulder", "l_elbow", 0.28),
    ("l_forearm", "l_elbow", "l_wrist", 0.25),
    ("r_upper_arm", "r_shoulder", "r_elbow", 0.28),
    ("r_forearm", "r_elbow", "r_wrist", 0.25),
    ("head", "neck", "head", 0.20),
)
SEGMENT_NAMES: tuple[str, ...] = tuple(s[0] for s in SEGMENTS)
S = {n: i for i, n in enumerate(SEGMENT_NAMES)}
_A = np.array([P[s[1]] for s in SEGMENTS])
_B = np.array([P[s[2]] for s in SEGMENTS])
_PRIOR_175 = np.array([s[3] for s in SEGMENTS])
#: Segments long enough, and often enough in the image plane, to set the image scale.
_SCALE_SEGMENTS = np.array(
    [
        S[n]
        for n in ("trunk", "l_thigh", "l_shin", "r_thigh", "r_shin", "l_upper_arm", "r_upper_arm")
    ]
)
#: Chains whose signs are chosen together, in this order (limbs after the body they hang on).
CHAINS: tuple[tuple[str, ...], ...] = (
    ("pelvis", "trunk", "shoulders"),
    ("l_thigh", "l_shin"),
    ("r_thigh", "r_shin"),
    ("l_upper_arm", "l_forearm"),
    ("r_upper_arm", "r_forearm"),
    ("head",),
)
#: Plain words for questions.
SEGMENT_WORDS = {
    "pelvis": "the hips' line (left hip)",
    "trunk": "the trunk (shoulders)",
    "shoulders": "the shoulders' line (left shoulder)",
    "l_thigh": "the left thigh (knee)",
    "l_shin": "the left shin (ankle)",
    "r_thigh": "the right thigh (knee)",
    "r_shin": "the right shin (ankle)",
    "l_upper_arm": "the left upper arm (elbow)",
    "l_forearm": "the left forearm (wrist)",
    "r_upper_arm": "the right upper arm (elbow)",
    "r_forearm": "the right forearm (wrist)",
    "head": "the head",
}


#: The question about the whole body's orientation (front or back to the camera), which no
#: image cue settles under orthographic projection: the body with left and right exchanged and
#: depths mirrored casts the same picture. Its ``sign`` is -1 facing the camera, +1 the back;
#: its ``margin`` the share of frames whose labels the pose model had the other way.
FACING = "facing"


@dataclass(frozen=True)
class Question:
    """A span of frames where a segment's depth sign stays uncertain.

    ``sign`` is the one chosen: -1 the segment's far end (``child``) is nearer the camera
    than its start, +1 farther. ``margin`` is how much better (nats) the chosen sign explains
    the span than the other.
    """

    segment: str
    start: int
    end: int
    sign: int
    margin: float

    @property
    def id(self) -> str:
        return f"{self.segment}@{self.start}-{self.end}"

    def text(self, fps: float) -> str:
        a, b = self.start / fps, (self.end - 1) / fps
        if self.segment == FACING:
            return (
                "Does the performer face the camera for most of the video? (we took "
                f"{'yes' if self.sign < 0 else 'no'}; the pose model was unsure in "
                f"{self.margin:.0%} of the frames)"
            )
        return (
            f"Is {SEGMENT_WORDS[self.segment]} towards or away from the camera from "
            f"{a:.1f} s to {b:.1f} s? (we took it {'towards' if self.sign < 0 else 'away'})"
        )

    def to_dict(self, fps: float) -> dict:
        return {
            "id": self.id,
            "segment": self.segment,
            "frames": [self.start, self.end],
            "chosen": "towards" if self.sign < 0 else "away",
            "margin": round(float(self.margin), 2),
            "text": self.text(fps),
        }


@dataclass(frozen=True)
class Lifted:
    """Segments in 3D, camera frame (x right, y down, z away from the camera), metres.

    Attributes
    ----------
    vectors : ndarray, shape (T', 12, 3)
        Each segment, child minus parent point (:data:`SEGMENTS` order).
    lengths : ndarray, shape (12,)
        Metres.
    scale : ndarray, shape (T',)
        Image pixels per metre in each frame.
    signs : ndarray of int8, shape (T', 12)
        The depth sign chosen (+1 away, -1 towards the camera; meaningless where depth ~0).
    questions : tuple of Question
    """

    vectors: np.ndarray
    lengths: np.ndarray
    scale: np.ndarray
    signs: np.ndarray
    questions: tuple[Question, ...] = field(default=())


def image_scale(pose: Pose2D, height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The image scale of every frame (px per metre) and the segment lengths (m).

    A segment's image length is at most s L. Per frame the scale is read from the few long
    segments nearest the image plane (the median of the three largest ratios, robust to one
    misplaced landmark); over time it is the 90th percentile in a one-second window (a body
    always has segments in depth), smoothed. Lengths are the 95th percentile of what the video
    shows, kept within 0.75-1.3 times the table's: a body whose hips the camera sees wider than
    the table's must not have its hips pushed into depth, and a length well above the bone's
    (the trunk of a short-waisted body, the table's forearm) tilts it in depth wherever it lies
    in the image plane.

    Returns
    -------
    scale : ndarray, shape (T',)
    lengths : ndarray, shape (12,)
    """
    prior = _PRIOR_175 * height_m / 1.75
    l2d = _image_lengths(pose)
    ratio = np.sort(l2d[:, _SCALE_SEGMENTS] / prior[_SCALE_SEGMENTS], axis=1)[:, -3:]
    per_frame = np.median(ratio, axis=1)
    half = max(1, int(round(pose.fps / 2)))
    T = per_frame.shape[0]
    windowed = np.array(
        [np.percentile(per_frame[max(0, t - half) : t + half + 1], 90) for t in range(T)]
    )
    scale = np.maximum(zero_phase(windowed, pose.fps, 0.5), 1e-6)
    seen = np.percentile(l2d / scale[:, None], 95, axis=0)
    lengths = np.clip(seen, 0.75 * prior, 1.3 * prior)
    return scale, lengths


def _image_lengths(pose: Pose2D) -> np.ndarray:
    """Each segment's length in the image (T', 12), pixels."""
    return np.linalg.norm(pose.uv[:, _B] - pose.uv[:, _A], axis=-1)


def depth_magnitudes(pose: Pose2D, scale: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """|dz| of every segment (T', 12), metres (seed 001 eq. 2.2); 0 where the image length
    exceeds the bone's (noise, or a wrong length)."""
    l2d = _image_lengths(pose) / scale[:, None]
    return np.sqrt(np.maximum(lengths[None] ** 2 - l2d**2, 0.0))


def depth_hints(pose: Pose2D, scale: np.ndarray) -> np.ndarray:
    """The detector's dz of every segment (T', 12), metres; NaN where it gave none."""
    return (pose.z[:, _B] - pose.z[:, _A]) / scale[:, None]


def _vectors(pose: Pose2D, scale: np.ndarray, mag: np.ndarray, signs: np.ndarray) -> np.ndarray:
    """Segment vectors (..., 3) in metres for per-segment ``signs`` broadcast against (T', 12)."""
    extra = (1,) * (signs.ndim - 2)  # state axes between frames and segments
    d = ((pose.uv[:, _B] - pose.uv[:, _A]) / scale[:, None, None]).reshape(
        (pose.n_frames, *extra, len(SEGMENTS), 2)
    )
    dz = signs * mag.reshape((pose.n_frames, *extra, len(SEGMENTS)))
    return np.concatenate([np.broadcast_to(d, signs.shape + (2,)), dz[..., None]], axis=-1)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-9)


def _softplus(x: np.ndarray) -> np.ndarray:
    return np.logaddexp(0.0, x)


def _angle_deficit(a: np.ndarray, b: np.ndarray, min_deg: float) -> np.ndarray:
    """How far (radians) the angle between bones a (towards the parent) and b (towards the
    child) at a joint falls below ``min_deg`` (table A.1); 0 when within the limit."""
    cos = np.sum(_unit(a) * _unit(b), axis=-1)
    return np.maximum(np.radians(min_deg) - np.arccos(np.clip(cos, -1, 1)), 0.0)


class _Chain:
    """The states of one chain (every sign combination of its segments) and their costs."""

    def __init__(
        self,
        names: tuple[str, ...],
        pose: Pose2D,
        scale: np.ndarray,
        mag: np.ndarray,
        hint: np.ndarray,
        s: CaptureSettings,
    ) -> None:
        self.seg = np.array([S[n] for n in names])
        self.states = np.array(list(product((-1, 1), repeat=len(names))), np.int8)  # (K, n)
        T = pose.n_frames
        signs = np.broadcast_to(self.states[None], (T,) + self.states.shape)  # (T, K, n)
        full = np.zeros((T, len(self.states), len(SEGMENTS)), np.int8)
        full[..., self.seg] = signs
        # (T, K, n, 3): this chain's segment vectors in each state
        self.vec = _vectors(pose, scale, mag, full)[..., self.seg, :]
        h = np.nan_to_num(hint[:, self.seg])  # (T, n); NaN -> no evidence
        self.unary = _softplus(-signs * h[:, None] / s.hint_sigma_m).sum(-1)  # (T, K)
        dirs = _unit(self.vec)
        self.pair = s.continuity_weight * (1.0 - np.einsum("tind,tjnd->tij", dirs[:-1], dirs[1:]))

    def solve(self, forced: np.ndarray | None) -> np.ndarray:
        """The state of each frame (T,), with ``forced`` (T, n) signs (0 = free) imposed."""
        u = self.unary.copy()
        if forced is not None:
            clash = (forced[:, None, :] != 0) & (forced[:, None, :] != self.states[None])
            u += 1e6 * clash.any(-1)
        return viterbi(u, self.pair)

    def cost(self, path: np.ndarray) -> float:
        t = np.arange(len(path))
        return float(self.unary[t, path].sum() + self.pair[t[:-1], path[:-1], path[1:]].sum())


def _body_costs(chain: _Chain, pose: Pose2D, s: CaptureSettings) -> None:
    """Facing and twist terms of the pelvis-trunk-shoulders chain (added to its unary)."""
    pel, trunk, sh = chain.vec[..., 0, :], chain.vec[..., 1, :], chain.vec[..., 2, :]
    forward = _unit(np.cross(pel, trunk))  # DESIGN.md: facing = cross(l_hip - r_hip, up)
    # facing +1 = towards the camera = forward with negative z (camera z points away)
    face = pose.facing.astype(float)[:, None]
    chain.unary += s.facing_weight * np.maximum(face * forward[..., 2], 0.0)
    # the shoulders turn against the hips by well under 90 deg (a golf backswing ~45-60)
    up = _unit(trunk)
    lat_h = _unit(pel - np.sum(pel * up, -1, keepdims=True) * up)
    lat_s = _unit(sh - np.sum(sh * up, -1, keepdims=True) * up)
    chain.unary += s.limit_weight * np.maximum(
        np.cos(np.radians(75)) - np.sum(lat_h * lat_s, -1), 0
    )


def _leg_costs(chain: _Chain, side: str, body: np.ndarray, s: CaptureSettings) -> None:
    """Hip and knee limits (table A.1) and the knee's hinge, given the chosen body vectors."""
    thigh, shin = chain.vec[..., 0, :], chain.vec[..., 1, :]
    pel = body[:, None, S["pelvis"]]
    to_hip = pel * (0.5 if side == "l" else -0.5)  # hip mid-point -> this hip
    dev = _angle_deficit(-to_hip, thigh, 20.0) + _angle_deficit(-thigh, shin, 35.0)
    # the knee bends backwards only: cross(thigh, shin) points to the body's left (measured on
    # the CMU squat 64_17 and swing 63_01: cos > 0.37 in 95 % of frames bent over 20 deg)
    bend = np.cross(_unit(thigh), _unit(shin))
    wrong = np.maximum(-np.sum(bend * _unit(pel), -1), 0.0)  # |sin| of the bend, wrong way
    chain.unary += s.limit_weight * (dev + wrong)


def _arm_costs(chain: _Chain, body: np.ndarray, s: CaptureSettings) -> None:
    """The elbow's limit (table A.1: at least 40 deg)."""
    upper, fore = chain.vec[..., 0, :], chain.vec[..., 1, :]
    chain.unary += s.limit_weight * _angle_deficit(-upper, fore, 40.0)


def _head_costs(chain: _Chain, body: np.ndarray, s: CaptureSettings) -> None:
    """The neck's limit (table A.1: 100 deg between the trunk and the head)."""
    trunk = body[:, None, S["trunk"]]
    chain.unary += s.limit_weight * _angle_deficit(-trunk, chain.vec[..., 0, :], 100.0)


def lift(
    pose: Pose2D,
    s: CaptureSettings,
    answers: dict[str, int] | None = None,
    signs: np.ndarray | None = None,
) -> Lifted:
    """Lift a 2D pose to 3D segments, choosing depth signs chain by chain.

    Parameters
    ----------
    pose : Pose2D
    s : CaptureSettings
    answers : dict, optional
        Question id (:attr:`Question.id`) -> sign (-1 towards the camera, +1 away): the
        user's answers, imposed over their spans.
    signs : ndarray of int, shape (T', 12), optional
        Signs to impose everywhere they are non-zero (``benchmarks/capture.py`` imposes the
        truth's, to measure what the sign choice costs).
    """
    scale, lengths = image_scale(pose, s.height_m)
    mag = depth_magnitudes(pose, scale, lengths)
    hint = depth_hints(pose, scale)
    forced = _forced(answers or {}, pose.n_frames)
    if signs is not None:
        forced = np.where(np.asarray(signs) != 0, np.sign(signs), forced).astype(np.int8)
    T = pose.n_frames
    chosen = np.ones((T, len(SEGMENTS)), np.int8)
    body = np.zeros((T, len(SEGMENTS), 3))  # the body chain's vectors, once chosen
    questions: list[Question] = []
    for names in CHAINS:  # the body chain first: the limbs' costs need its vectors
        chain = _Chain(names, pose, scale, mag, hint, s)
        if names[0] == "pelvis":
            _body_costs(chain, pose, s)
        elif names[0].endswith("thigh"):
            _leg_costs(chain, names[0][0], body, s)
        elif names[0].endswith("upper_arm"):
            _arm_costs(chain, body, s)
        else:
            _head_costs(chain, body, s)
        f = forced[:, chain.seg]
        path = chain.solve(f if f.any() else None)
        chosen[:, chain.seg] = chain.states[path]
        questions += _questions(chain, path, mag, lengths, f, pose.fps, s)
        if names[0] == "pelvis":
            body = _vectors(pose, scale, mag, chosen)
    signs = chosen
    vectors = _vectors(pose, scale, mag, signs)
    return Lifted(
        vectors=vectors, lengths=lengths, scale=scale, signs=signs, questions=tuple(questions)
    )


def _forced(answers: dict[str, int], T: int) -> np.ndarray:
    """Answers -> imposed signs (T, 12), 0 where free; unknown ids are ignored (a question
    that no longer arises)."""
    out = np.zeros((T, len(SEGMENTS)), np.int8)
    for qid, sign in answers.items():
        name, _, span = qid.partition("@")
        a, _, b = span.partition("-")
        if name in S and a.isdigit() and b.isdigit():
            out[int(a) : int(b), S[name]] = 1 if sign > 0 else -1
    return out


def _questions(
    chain: _Chain,
    path: np.ndarray,
    mag: np.ndarray,
    lengths: np.ndarray,
    forced: np.ndarray,
    fps: float,
    s: CaptureSettings,
) -> list[Question]:
    """Spans where a segment is well out of the image plane (|dz| > 35 % of its length, about
    20 deg), its sign constant, and the other sign nearly as good."""
    out = []
    min_len = max(2, int(round(s.min_question_s * fps)))
    base = chain.cost(path)
    for k, g in enumerate(chain.seg):
        deep = mag[:, g] > 0.35 * lengths[g]
        sign = chain.states[path, k]
        for a, b in _runs(deep, sign):
            if b - a < min_len or (forced[a:b, k] != 0).any():
                continue
            flipped = path.copy()
            want = chain.states[path[a:b]].copy()
            want[:, k] *= -1
            flipped[a:b] = [int(np.flatnonzero((chain.states == w).all(1))[0]) for w in want]
            margin = chain.cost(flipped) - base
            if margin < s.question_margin:
                out.append(Question(SEGMENT_NAMES[g], a, b, int(sign[a]), float(margin)))
    return out


def _runs(mask: np.ndarray, value: np.ndarray) -> list[tuple[int, int]]:
    """Maximal runs [a, b) where ``mask`` holds and ``value`` is constant."""
    runs, a = [], None
    for t in range(len(mask) + 1):
        inside = t < len(mask) and mask[t] and (a is None or value[t] == value[a])
        if a is not None and not inside:
            runs.append((a, t))
            a = None
        if a is None and t < len(mask) and mask[t]:
            a = t
    return runs
