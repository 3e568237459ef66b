"""Synthetic performers with exact ground truth (thesis 2.1.2-2.1.3, table 2.1; 5.2.1).

A performer is made from a reference motion the way the thesis describes how performers differ
from the expert:

- *timing* (2.1.3 item 3): a smooth, strictly monotone time warp C(t') whose speed differs per
  reference segment, pinned to the first and last reference frames (2.1.3 item 4);
- *articulation* (2.1.3 item 5, approach c: B'_t' = A_t'(T_t'(B_C(t')))): in some segments the
  performer is right, in others chosen parts are rotated about their root joint by a given
  amplitude; errors of different segments are independent (item 7, table 2.1) and change
  smoothly (item 6), ramping in and out at the segment's ends;
- an optional global yaw T_t' about the vertical through the hip;
- a fixed scaled orthographic camera (2.1.3 item 1) framing the body at ~80 % of the image
  height, a textured static background and Gaussian sensor noise.

The reference at the fractional frame C(t') is :func:`engine.io.bvh.sample_reference`
(slerp of the file's local rotations), the same sampling the truth's bone errors are
measured against. Every random choice comes from the ``rng`` passed in.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.interpolate import PchipInterpolator

from engine.body.kinematics import bone_vectors, part_rotations, rot_y, rotation_about_axis
from engine.body.shapes import BodyShape, capsule_endpoints
from engine.body.skeleton import (
    BONE_CHILD,
    BONE_NAMES,
    BONE_PARENT,
    BONE_PART,
    BONES,
    JOINTS,
    N_PARTS,
    PART_INDEX,
    PART_PARENT,
    PART_ROOT_JOINT,
    PARTS,
)
from engine.errors import InvalidInput
from engine.measures import bone_angles
from engine.render.camera import Camera
from engine.types import Motion, Segments

#: Parts that may be articulated by default: all but the abdomen (whose rotation is the
#: body's global orientation, set separately by ``yaw_deg``).
ARTICULABLE_PARTS: tuple[str, ...] = PARTS[1:]

# The bone whose direction an articulation of each part must change (the axis is chosen
# perpendicular to it): the neck for the upper chest, the part's only bone otherwise.
_PRIMARY_BONE = np.array([0, 7, 14, 15, 9, 10, 12, 13, 1, 2, 4, 5])


class ReferenceLike(Protocol):
    """What :func:`synthesize` needs of a reference (e.g. :class:`engine.io.bvh.Reference`)."""

    # read-only: a frozen dataclass (engine.io.bvh.Reference) must satisfy the protocol
    @property
    def motion(self) -> Motion: ...

    @property
    def shape(self) -> BodyShape: ...


@dataclass(frozen=True)
class SynthSettings:
    """How a synthetic performer differs from the reference, and how it is filmed.

    Attributes
    ----------
    fps : float
        Video frame rate (thesis: 25-30 typical, 12.5 in 5.4); at most the reference's.
    width, height : int
        Image size in pixels (even, for yuv420p video).
    warp_strength : float
        Standard deviation of the log speed of each segment relative to the reference
        (0 = same timing, only the frame rate changes).
    error_deg : float
        Articulation amplitude of a wrong segment, degrees (thesis 5.2.2 uses up to 20).
    n_wrong : int
        Number of wrong segments (table 2.1: any subset may be wrong).
    parts_per_wrong : int
        Parts articulated in each wrong segment.
    error_parts : tuple of str, optional
        Parts that may be articulated, by part name or root joint name (``"l_elbow"`` means
        the left lower arm); all but the abdomen when omitted.
    yaw_deg : float
        Global rotation of the performer about the vertical through the hip, degrees.
    azimuth_deg : float
        Camera azimuth (0 = facing the body's front, 90 = its left side), degrees.
    theta_z_deg : float
        In-plane camera rotation, degrees.
    noise_sigma : float
        Standard deviation of the Gaussian sensor noise, grey levels (0-255).
    fill : float
        Fraction of the image height the body's extent over the whole motion spans.
    ramp : float
        Fraction of a wrong segment over which its error ramps in (and out), smoothly.
    n_segments : int
        Equal segments to use when the reference comes without segment boundaries and
        :mod:`engine.reference.boundaries` is not available.
    max_frames : int, optional
        Keep only the first ``max_frames`` video frames (the video then ends before the
        reference does; the truth says so in ``notes``).
    background : bool
        Textured wall and floor (True) or plain grey.
    """

    fps: float = 30.0
    width: int = 320
    height: int = 240
    warp_strength: float = 0.25
    error_deg: float = 20.0
    n_wrong: int = 2
    parts_per_wrong: int = 3
    error_parts: tuple[str, ...] | None = None
    yaw_deg: float = 0.0
    azimuth_deg: float = 0.0
    theta_z_deg: float = 0.0
    noise_sigma: float = 2.0
    fill: float = 0.8
    ramp: float = 0.2
    n_segments: int = 4
    max_frames: int | None = None
    background: bool = True

    def __post_init__(self) -> None:
        _check(np.isfinite(self.fps) and self.fps > 0, "fps", "> 0", self.fps)
        for name in ("width", "height"):
            v = getattr(self, name)
            _check(int(v) == v and v >= 16 and v % 2 == 0, name, "an even integer >= 16", v)
        _check(self.warp_strength >= 0, "warp_strength", ">= 0", self.warp_strength)
        _check(0 <= self.error_deg <= 180, "error_deg", "in [0, 180]", self.error_deg)
        _check(self.n_wrong >= 0, "n_wrong", ">= 0", self.n_wrong)
        _check(self.parts_per_wrong >= 1, "parts_per_wrong", ">= 1", self.parts_per_wrong)
        _check(
            np.isfinite(self.noise_sigma) and self.noise_sigma >= 0,
            "noise_sigma",
            ">= 0",
            self.noise_sigma,
        )
        _check(0 < self.fill <= 1, "fill", "in (0, 1]", self.fill)
        _check(0 < self.ramp <= 0.5, "ramp", "in (0, 0.5]", self.ramp)
        _check(self.n_segments >= 1, "n_segments", ">= 1", self.n_segments)
        _check(
            self.max_frames is None or self.max_frames >= 2, "max_frames", ">= 2", self.max_frames
        )
        for name in ("yaw_deg", "azimuth_deg", "theta_z_deg"):
            _check(np.isfinite(getattr(self, name)), name, "finite", getattr(self, name))
        if self.error_parts is not None:
            resolve_parts(self.error_parts)


@dataclass(frozen=True)
class SynthCase:
    """A synthetic performer video with its ground truth.

    Attributes
    ----------
    frames : ndarray of uint8, shape (T', H, W, 3)
        RGB video frames.
    masks : ndarray of bool, shape (T', H, W)
        True body silhouettes S'_t'.
    joints_3d : ndarray, shape (T', 17, 3)
        True performer postures B'_t', world frame, metres.
    warp : ndarray, shape (T',)
        True C(t'), fractional reference frames.
    camera : Camera
    fps : float
    truth : dict
        ``truth.json`` content (DESIGN.md "Synthetic cases").
    """

    frames: np.ndarray
    masks: np.ndarray
    joints_3d: np.ndarray
    warp: np.ndarray
    camera: Camera
    fps: float
    truth: dict = field(repr=False)


def _check(ok: bool, name: str, expected: str, got: object) -> None:
    if not ok:
        raise InvalidInput(f"{name} must be {expected}, got {got!r}")


def resolve_parts(names: tuple[str, ...] | list[str]) -> tuple[int, ...]:
    """Part indices from part names or root joint names.

    Raises
    ------
    InvalidInput
        A name that is neither, naming it and the valid choices.
    """
    root_of = {JOINTS[int(j)]: p for p, j in enumerate(PART_ROOT_JOINT)}
    out = []
    for n in names:
        if n in PART_INDEX:
            out.append(PART_INDEX[n])
        elif n in root_of:
            out.append(root_of[n])
        else:
            raise InvalidInput(
                f"error_parts: unknown part or joint {n!r}; choose from {', '.join(PARTS)} "
                f"or the joints {', '.join(sorted(root_of))}"
            )
    return tuple(out)


def _descendants(part: int) -> np.ndarray:
    """The part and every part below it in the part tree, as indices."""
    inside = np.zeros(N_PARTS, dtype=bool)
    inside[part] = True
    for p in range(N_PARTS):  # parents come before children in PARTS
        if PART_PARENT[p] >= 0 and inside[PART_PARENT[p]]:
            inside[p] = True
    return np.flatnonzero(inside)


def _default_segments(motion: Motion, n: int) -> Segments:
    first, last = motion.first_motion_frame, motion.frames - 1
    n = max(1, min(n, (last - first) // 2))
    starts = np.round(np.linspace(first, last, n + 1)[:-1]).astype(int)
    return Segments(starts=tuple(int(s) for s in starts), end=int(last))


def reference_segments(motion: Motion, n_segments: int = 4) -> Segments:
    """Segments of a reference: :func:`engine.reference.boundaries.reference_boundaries`
    when that module is available, else ``n_segments`` equal ones from the first motion frame.
    """
    try:
        from engine.reference.boundaries import reference_boundaries
    except ImportError:
        return _default_segments(motion, n_segments)
    return reference_boundaries(motion)


def time_warp(
    segments: Segments,
    reference_fps: float,
    fps: float,
    strength: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A smooth, strictly monotone time warp with a random speed per segment (thesis 2.1.3).

    Parameters
    ----------
    segments : Segments
        Reference segments; the warp runs from ``starts[0]`` to ``end``.
    reference_fps, fps : float
        Frame rates of the reference and the video.
    strength : float
        Standard deviation of each segment's log speed.
    rng : numpy.random.Generator

    Returns
    -------
    warp : ndarray, shape (T',)
        C(t') for t' = 0..L', with C(0) = starts[0] and C(L') = end exactly.
    knots_video : ndarray, shape (n_segments + 1,)
        Video time (fractional frames) of each reference boundary and of the end.
    speeds : ndarray, shape (n_segments,)
        Performer speed relative to the reference in each segment.
    """
    knots_ref = np.array([*segments.starts, segments.end], dtype=float)
    if np.any(np.diff(knots_ref) <= 0):
        raise InvalidInput(f"segments must be strictly increasing, got {knots_ref.tolist()}")
    speeds = np.exp(np.clip(strength * rng.standard_normal(len(segments.starts)), -1.0, 1.0))
    durations = np.diff(knots_ref) / reference_fps * fps / speeds
    knots_video = np.concatenate([[0.0], np.cumsum(durations)])
    L = max(1, int(round(knots_video[-1])))
    knots_video *= L / knots_video[-1]
    # PCHIP keeps the warp monotone and C1: speeds blend across boundaries instead of jumping
    warp = PchipInterpolator(knots_video, knots_ref)(np.arange(L + 1, dtype=float))
    warp[0], warp[-1] = knots_ref[0], knots_ref[-1]
    return np.clip(warp, knots_ref[0], knots_ref[-1]), knots_video, speeds


def _ramp_window(u: np.ndarray, ramp: float) -> np.ndarray:
    """1 inside a segment, smoothly 0 at its ends; u is the position in it, in [0, 1]."""
    a = np.clip(u / ramp, 0.0, 1.0)
    b = np.clip((1.0 - u) / ramp, 0.0, 1.0)
    s = lambda x: x * x * (3.0 - 2.0 * x)  # noqa: E731  (smoothstep)
    return s(a) * s(b) * ((u >= 0) & (u <= 1))


def _joints_from_bones(root: np.ndarray, vec: np.ndarray) -> np.ndarray:
    """(N, 3) roots and (N, 16, 3) bone vectors -> (N, 17, 3) joints."""
    joints = np.empty(vec.shape[:-2] + (17, 3))
    joints[..., 0, :] = root
    for b in range(16):  # topological order
        joints[..., BONE_CHILD[b], :] = joints[..., BONE_PARENT[b], :] + vec[..., b, :]
    return joints


def articulate(
    reference: np.ndarray, offsets: np.ndarray, angles: np.ndarray, axes_local: np.ndarray
) -> np.ndarray:
    """Rotate parts about their root joints, carrying their descendants (thesis 2.1.3 item 5).

    Parameters
    ----------
    reference : ndarray, shape (N, 17, 3)
        Reference postures B_C(t').
    offsets : ndarray, shape (16, 3)
        Default-posture bone vectors of the body.
    angles : ndarray, shape (N, 12)
        Rotation of each part, radians (0 leaves it as in the reference).
    axes_local : ndarray, shape (12, 3)
        Rotation axis of each part in its default-posture frame.

    Returns
    -------
    joints : ndarray, shape (N, 17, 3)
        Equal to ``reference`` wherever all angles are 0.
    """
    vec = bone_vectors(reference).copy()
    R_world_part = part_rotations(reference, offsets)
    for p in range(N_PARTS - 1, -1, -1):  # leaves first: a parent's turn carries the child's
        if not np.any(angles[:, p]):
            continue
        axis = np.einsum("nij,j->ni", R_world_part[:, p], axes_local[p])
        E = rotation_about_axis(axis, angles[:, p])  # (N, 3, 3)
        bones = np.isin(BONE_PART, _descendants(p))
        vec[:, bones] = np.einsum("nij,nbj->nbi", E, vec[:, bones])
    return _joints_from_bones(reference[:, 0], vec)


def fit_camera(joints: np.ndarray, shape: BodyShape, settings: SynthSettings) -> Camera:
    """Camera framing the whole motion at ``settings.fill`` of the image height, centred.

    Parameters
    ----------
    joints : ndarray, shape (T', 17, 3)
    shape : BodyShape
    settings : SynthSettings
    """
    cam1 = Camera(
        scale=1.0,
        theta_z=np.radians(settings.theta_z_deg),
        azimuth=np.radians(settings.azimuth_deg),
        width=settings.width,
        height=settings.height,
    )
    ends = cam1.project(capsule_endpoints(joints))  # (T', C, 2, 2)
    r = np.asarray(shape.radii)[None, :, None, None]
    lo = (ends - r).min(axis=(0, 1, 2))
    hi = (ends + r).max(axis=(0, 1, 2))
    ext = np.maximum(hi - lo, 1e-6)
    scale = min(settings.fill * settings.height / ext[1], 0.95 * settings.width / ext[0])
    mid = (lo + hi) / 2.0
    return cam1.with_(
        scale=float(scale),
        cx=float(settings.width / 2.0 - 0.5 - scale * mid[0]),
        cy=float(settings.height / 2.0 - 0.5 - scale * mid[1]),
    )


def _random_axes(offsets: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A random unit axis per part, perpendicular to its primary bone (no pure twist)."""
    d = offsets[_PRIMARY_BONE]
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    v = rng.standard_normal((N_PARTS, 3))
    v -= d * np.sum(v * d, axis=1, keepdims=True)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def synthesize(
    reference: ReferenceLike,
    *,
    settings: SynthSettings,
    rng: np.random.Generator,
    segments: Segments | None = None,
) -> SynthCase:
    """Make a performer video of a reference motion with exact ground truth.

    Parameters
    ----------
    reference : Reference
        ``.motion`` (joints (T, 17, 3), fps, first_motion_frame) and ``.shape``.
    settings : SynthSettings
    rng : numpy.random.Generator
        Source of every random choice (warp, wrong segments, parts, axes, background, noise).
    segments : Segments, optional
        Reference segments; :func:`reference_segments` when omitted.

    Returns
    -------
    SynthCase

    Raises
    ------
    InvalidInput
        A reference that is too short, segments outside it, fps above the reference's.
    """
    motion, shape = reference.motion, reference.shape
    segments = _checked_segments(motion, settings, segments)
    allowed = resolve_parts(
        settings.error_parts if settings.error_parts is not None else ARTICULABLE_PARTS
    )
    warp, knots_video, speeds = time_warp(
        segments, motion.fps, settings.fps, settings.warp_strength, rng
    )
    truncated = settings.max_frames is not None and len(warp) > settings.max_frames
    if truncated:
        warp = warp[: settings.max_frames]
    ref = _reference_at(reference, warp)
    art = _wrong_segments(warp, segments, shape.offsets, allowed, settings, rng)
    joints = articulate(ref, shape.offsets, art.angles, art.axes)
    if settings.yaw_deg:
        vec = np.einsum("ij,nbj->nbi", rot_y(np.radians(settings.yaw_deg)), bone_vectors(joints))
        joints = _joints_from_bones(joints[:, 0], vec)
    camera = fit_camera(joints, shape, settings)
    frames, masks = _film(joints, shape, camera, settings, rng)
    truth = _truth(
        motion, settings, segments, warp, knots_video, speeds, ref, joints, camera,
        art.wrong, art.seg_parts, art.seg_of, truncated,
    )  # fmt: skip
    return SynthCase(
        frames=frames,
        masks=masks,
        joints_3d=joints,
        warp=warp,
        camera=camera,
        fps=float(settings.fps),
        truth=truth,
    )


def _checked_segments(
    motion: Motion, settings: SynthSettings, segments: Segments | None
) -> Segments:
    """The reference segments to warp (:func:`reference_segments` when omitted), after
    checking the reference's joints (T >= 3, 17, 3) and frame rate against ``settings``."""
    if motion.joints.ndim != 3 or motion.joints.shape[1:] != (17, 3) or motion.frames < 3:
        raise InvalidInput(f"reference joints must be (T >= 3, 17, 3), got {motion.joints.shape}")
    _check(settings.fps <= motion.fps, "fps", f"<= the reference's {motion.fps:g}", settings.fps)
    if segments is None:
        segments = reference_segments(motion, settings.n_segments)
    if segments.starts[0] < 0 or segments.end > motion.frames - 1:
        raise InvalidInput(
            f"segments {segments.starts}..{segments.end} lie outside the reference's "
            f"{motion.frames} frames"
        )
    return segments


def _reference_at(reference: ReferenceLike, warp: np.ndarray) -> np.ndarray:
    """The reference postures B_C(t'), shape (T', 17, 3), at the fractional frames ``warp``."""
    from engine.io.bvh import Reference, sample_at, sample_reference

    # the file's own rotations interpolated, as the public truth does (rigid-part slerp
    # would bend CMU's spine and hips by up to 20 deg)
    if isinstance(reference, Reference):
        return sample_reference(reference, warp)
    # a reference built in memory (no file): interpolate on the 17-joint body
    return sample_at(reference.motion, reference.shape, warp)


@dataclass(frozen=True)
class _Articulation:
    """Which segments the performer gets wrong, and how (thesis table 2.1, 2.1.3 item 5).

    Attributes
    ----------
    angles : ndarray, shape (T', 12)
        Rotation of each part per video frame, radians (0 where the performer is right).
    axes : ndarray, shape (12, 3)
        Rotation axis of each part in its default-posture frame.
    wrong : ndarray of bool, shape (n_segments,)
    seg_parts : list of list of int
        The parts articulated in each segment, sorted (empty when it is right).
    seg_of : ndarray of int, shape (T',)
        The reference segment each video frame falls in.
    """

    angles: np.ndarray
    axes: np.ndarray
    wrong: np.ndarray
    seg_parts: list[list[int]]
    seg_of: np.ndarray


def _wrong_segments(
    warp: np.ndarray,
    segments: Segments,
    offsets: np.ndarray,
    allowed: tuple[int, ...],
    settings: SynthSettings,
    rng: np.random.Generator,
) -> _Articulation:
    """Choose ``settings.n_wrong`` wrong segments and, in each, parts among ``allowed`` to
    rotate by +-``error_deg``, ramping in and out (2.1.3 items 6-7; errors of different
    segments are independent). ``warp`` (T',) is C(t'); ``offsets`` (16, 3) the body's."""
    n_seg = len(segments.starts)
    knots_ref = np.array([*segments.starts, segments.end], dtype=float)
    seg_of = np.clip(np.searchsorted(knots_ref, warp, side="right") - 1, 0, n_seg - 1)
    wrong = np.zeros(n_seg, dtype=bool)
    wrong[rng.choice(n_seg, size=min(settings.n_wrong, n_seg), replace=False)] = True
    axes = _random_axes(offsets, rng)
    angles = np.zeros((len(warp), N_PARTS))
    seg_parts: list[list[int]] = [[] for _ in range(n_seg)]
    amp = np.radians(settings.error_deg)
    for k in np.flatnonzero(wrong):
        size = min(settings.parts_per_wrong, len(allowed))
        parts = [int(p) for p in rng.choice(allowed, size=size, replace=False)]
        seg_parts[k] = sorted(parts)
        u = (warp - knots_ref[k]) / (knots_ref[k + 1] - knots_ref[k])
        w = _ramp_window(u, settings.ramp) * (seg_of == k)
        for p in parts:
            angles[:, p] += rng.choice([-1.0, 1.0]) * amp * w
    return _Articulation(angles, axes, wrong, seg_parts, seg_of)


def _film(
    joints: np.ndarray,
    shape: BodyShape,
    camera: Camera,
    settings: SynthSettings,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """Render the postures (T', 17, 3) as the mesh body: RGB frames (T', H, W, 3) uint8 over
    the background, with sensor noise, and the true silhouettes (T', H, W)."""
    from engine.render.mesh import MeshRenderer, textured_background

    H, W = settings.height, settings.width
    # the horizon (wall meets floor) lies 15 % of the image above the lowest ankle (joints 3, 6)
    floor_v = float(camera.project(joints[:, [3, 6]]).max(axis=(0, 1))[1])
    bg = (
        textured_background(H, W, rng, horizon=min(floor_v - 0.15 * H, H - 2.0))
        if settings.background
        else np.full((H, W, 3), 128, dtype=np.uint8)
    )
    frames = np.empty((len(joints), H, W, 3), dtype=np.uint8)
    masks = np.empty((len(joints), H, W), dtype=bool)
    with MeshRenderer(W, H) as renderer:
        for i in range(len(joints)):
            img, masks[i] = renderer.render(joints[i], shape, camera, background=bg)
            if settings.noise_sigma > 0:
                noisy = img + rng.normal(0.0, settings.noise_sigma, img.shape)
                img = np.clip(np.rint(noisy), 0, 255).astype(np.uint8)
            frames[i] = img
    return frames, masks


def _truth(
    motion: Motion,
    settings: SynthSettings,
    segments: Segments,
    warp: np.ndarray,
    knots_video: np.ndarray,
    speeds: np.ndarray,
    ref: np.ndarray,
    joints: np.ndarray,
    camera: Camera,
    wrong: np.ndarray,
    seg_parts: list[list[int]],
    seg_of: np.ndarray,
    truncated: bool,
) -> dict:
    """The DESIGN.md truth.json dictionary (plus the public cases' extra fields)."""
    err = np.degrees(bone_angles(joints, ref))  # (T', 16)
    uv = camera.project(joints)
    cam = camera.to_dict()
    cam.update(
        type="orthographic",
        R_cam_world=camera.R_cam_world.tolist(),
        pixel_convention="pixel centres at integer (u, v); u right, v down (OpenCV)",
        projection="u = cx + scale * (A_u . X), v = cy + scale * (A_v . X): engine Camera",
        fill_fraction_of_height=settings.fill,
    )
    frames = [
        {
            "t": i,
            "reference_frame": round(float(warp[i]), 6),
            "joints_3d": np.round(joints[i], 6).tolist(),
            "joints_2d": np.round(uv[i], 4).tolist(),
            "bone_errors_deg": np.round(err[i], 4).tolist(),
            "posture_error_deg": round(float(err[i].mean()), 4),
            "reference_segment": int(seg_of[i]),
        }
        for i in range(len(warp))
    ]
    bounds = [*segments.starts, segments.end]
    segs = [
        {
            "reference_start": int(bounds[k]),
            "reference_end": int(bounds[k + 1]),
            "performer_start": round(float(knots_video[k]), 3),
            "performer_end": round(float(knots_video[k + 1]), 3),
            "speed": round(float(speeds[k]), 4),
            "wrong": bool(wrong[k]),
            "amplitude_deg": float(settings.error_deg) if wrong[k] else 0.0,
            "articulated_parts": [PARTS[p] for p in seg_parts[k]],
            "articulated_joints": [JOINTS[int(PART_ROOT_JOINT[p])] for p in seg_parts[k]],
            "yaw_deg": float(settings.yaw_deg),
        }
        for k in range(len(segments.starts))
    ]
    notes = (
        f"synthetic performer of {motion.name or 'the reference'} by engine.synth: smooth "
        f"monotone warp (PCHIP through segment boundaries, per-segment speeds), "
        f"{int(wrong.sum())} wrong segment(s) with parts rotated {settings.error_deg:g} deg "
        f"about their root joints (smooth ramp {settings.ramp:g} of the segment), yaw "
        f"{settings.yaw_deg:g} deg. World frame = the reference's (metres, y up, facing +z at "
        f"reference frame 0). reference_frame = true fractional C(t'); bone_errors_deg = "
        "angle to the reference sampled at that frame (engine.io.bvh.sample_reference, "
        "slerp of the file's rotations). "
        f"joints_2d = exact projection of joints_3d by the camera (pixel centres on integers). "
        f"Video frame 0 is pinned to reference frame {bounds[0]} (the first motion frame)."
    )
    if truncated:
        notes += (
            f" Truncated to {len(warp)} video frames (max_frames): the video ends at "
            f"reference frame {warp[-1]:.2f}, before the reference's end {bounds[-1]}."
        )
    return {
        "version": 1,
        "fps": float(settings.fps),
        "reference_fps": float(motion.fps),
        "joints": list(JOINTS),
        "bones": [list(b) for b in BONES],
        "bone_names": list(BONE_NAMES),
        "camera": cam,
        "frames": frames,
        "warp": [round(float(w), 6) for w in warp],
        "segments": segs,
        "reference": {
            "name": motion.name,
            "frames": motion.frames,
            "fps": float(motion.fps),
            "first_motion_frame": motion.first_motion_frame,
        },
        "video": {
            "frames": len(warp),
            "fps": float(settings.fps),
            "width": camera.width,
            "height": camera.height,
        },
        "settings": {
            k: (list(v) if isinstance(v, tuple) else v) for k, v in settings.__dict__.items()
        },
        "notes": notes,
    }


__all__ = [
    "ARTICULABLE_PARTS",
    "ReferenceLike",
    "SynthCase",
    "SynthSettings",
    "articulate",
    "fit_camera",
    "reference_segments",
    "resolve_parts",
    "synthesize",
    "time_warp",
]
