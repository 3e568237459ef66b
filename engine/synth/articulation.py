"""The performer's articulation errors (thesis 2.1.3 item 5, approach c): parts rotated about
their root joints in the wrong segments, ramping in and out (items 6-7, table 2.1).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.kinematics import bone_vectors, part_rotations, rotation_about_axis
from engine.body.skeleton import BONE_CHILD, BONE_PARENT, BONE_PART, N_PARTS, PART_PARENT, PARTS
from engine.synth.settings import SynthSettings
from engine.types import Segments

#: Parts that may be articulated by default: all but the abdomen (whose rotation is the
#: body's global orientation, set separately by ``yaw_deg``).
ARTICULABLE_PARTS: tuple[str, ...] = PARTS[1:]


# The bone whose direction an articulation of each part must change (the axis is chosen
# perpendicular to it): the neck for the upper chest, the part's only bone otherwise.
_PRIMARY_BONE = np.array([0, 7, 14, 15, 9, 10, 12, 13, 1, 2, 4, 5])


def _descendants(part: int) -> np.ndarray:
    """The part and every part below it in the part tree, as indices."""
    inside = np.zeros(N_PARTS, dtype=bool)
    inside[part] = True
    for p in range(N_PARTS):  # parents come before children in PARTS
        if PART_PARENT[p] >= 0 and inside[PART_PARENT[p]]:
            inside[p] = True
    return np.flatnonzero(inside)


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


def _random_axes(offsets: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """A random unit axis per part, perpendicular to its primary bone (no pure twist)."""
    d = offsets[_PRIMARY_BONE]
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    v = rng.standard_normal((N_PARTS, 3))
    v -= d * np.sum(v * d, axis=1, keepdims=True)
    return v / np.linalg.norm(v, axis=1, keepdims=True)


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
