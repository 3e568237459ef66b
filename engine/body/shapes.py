"""Part shapes: the body as a union of capsules (thesis 2.1.1 item 1, 4.3).

Each rigid part is one or more capsules (points within a radius of a segment) whose ends sit
on the part's own joints, so they move rigidly with the part. A capsule's scaled orthographic
projection is exactly a 2D capsule, which is what makes the analytic rasteriser possible.

Default proportions come from seed 001, tables 3.1-3.2 (ratios to a 175 cm body). Table 3.2
names them radii but they match body *widths* (a 40 cm torso, 20 cm head), so half of each is
used; the torso width is spread over a pelvis capsule, two spine capsules and a shoulder
capsule, and forearms and shins taper to 80 %.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.skeleton import JOINT_INDEX, N_BONES, PART_INDEX

_H0 = 1.75  # the seed's reference height, metres

# (part, joint a, joint b, t0, t1, width ratio of seed 001 table 3.2, factor)
# Capsule ends are a + t * (b - a). Radius = factor * ratio * height / 2.
_CAPSULES: tuple[tuple[str, str, str, float, float, float, float], ...] = (
    ("abdomen", "l_hip", "r_hip", 0.0, 1.0, 40 / 175, 0.45),
    ("abdomen", "hip", "lower_chest", 0.0, 1.0, 40 / 175, 0.6),
    ("lower_chest", "lower_chest", "upper_chest", 0.0, 1.0, 40 / 175, 0.6),
    ("upper_chest", "upper_chest", "neck", 0.0, 0.35, 40 / 175, 0.6),
    ("upper_chest", "l_shoulder", "r_shoulder", 0.0, 1.0, 40 / 175, 0.35),
    ("upper_chest", "upper_chest", "neck", 0.0, 1.0, 20 / 175, 0.45),
    ("head", "neck", "head_top", 0.45, 0.62, 20 / 175, 0.9),
    ("l_upper_arm", "l_shoulder", "l_elbow", 0.0, 1.0, 10 / 175, 1.0),
    ("l_lower_arm", "l_elbow", "l_wrist", 0.0, 1.15, 10 / 175, 0.8),
    ("r_upper_arm", "r_shoulder", "r_elbow", 0.0, 1.0, 10 / 175, 1.0),
    ("r_lower_arm", "r_elbow", "r_wrist", 0.0, 1.15, 10 / 175, 0.8),
    ("l_upper_leg", "l_hip", "l_knee", 0.0, 1.0, 20 / 175, 0.8),
    ("l_lower_leg", "l_knee", "l_ankle", 0.0, 1.0, 20 / 175, 0.6),
    ("r_upper_leg", "r_hip", "r_knee", 0.0, 1.0, 20 / 175, 0.8),
    ("r_lower_leg", "r_knee", "r_ankle", 0.0, 1.0, 20 / 175, 0.6),
)


def _ro(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


#: Part of each capsule, shape (C,).
CAPSULE_PART = _ro(np.array([PART_INDEX[c[0]] for c in _CAPSULES]))
#: Joints the capsule ends are interpolated between, shape (C,) each.
CAPSULE_A = _ro(np.array([JOINT_INDEX[c[1]] for c in _CAPSULES]))
CAPSULE_B = _ro(np.array([JOINT_INDEX[c[2]] for c in _CAPSULES]))
#: Interpolation parameters of the two ends, shape (C, 2).
CAPSULE_T = _ro(np.array([[c[3], c[4]] for c in _CAPSULES]))
N_CAPSULES = len(_CAPSULES)

# Default-posture bone directions (thesis fig. 2.1 d: x to the body's left, y up, z front),
# a T-pose: legs down, spine up, arms out to the sides.
_DEFAULT_DIRS = np.array(
    [
        [1, -0.35, 0], [0, -1, 0], [0, -1, 0],  # hip->l_hip, l thigh, l shin
        [-1, -0.35, 0], [0, -1, 0], [0, -1, 0],  # hip->r_hip, r thigh, r shin
        [0, 1, 0], [0, 1, 0],  # spine
        [1, 0.25, 0], [1, 0, 0], [1, 0, 0],  # l clavicle, l upper arm, l forearm
        [-1, 0.25, 0], [-1, 0, 0], [-1, 0, 0],  # r clavicle, r upper arm, r forearm
        [0, 1, 0], [0, 1, 0],  # neck, head
    ],
    dtype=float,
)
_DEFAULT_DIRS /= np.linalg.norm(_DEFAULT_DIRS, axis=1, keepdims=True)
# Bone lengths of a 1.75 m body, from seed 001 table 3.1 where it gives them (upper/lower
# arm and leg, head) and anthropometric proportions for the rest.
_DEFAULT_LENGTHS_175 = np.array(
    [0.10, 0.46, 0.44, 0.10, 0.46, 0.44, 0.22, 0.20, 0.19, 0.28, 0.26, 0.19, 0.28, 0.26, 0.10, 0.20]
)


@dataclass(frozen=True)
class BodyShape:
    """Sizes of one body: its default-posture skeleton and capsule radii.

    Attributes
    ----------
    offsets : ndarray, shape (16, 3)
        Default-posture bone vectors, metres (child joint minus parent joint).
    radii : ndarray, shape (C,)
        Radius of each capsule of :data:`CAPSULE_PART`, metres.
    """

    offsets: np.ndarray
    radii: np.ndarray

    @property
    def lengths(self) -> np.ndarray:
        """Bone lengths, shape (16,)."""
        return np.linalg.norm(self.offsets, axis=1)

    @property
    def height(self) -> float:
        """Standing height in the default posture (ankle to head top), metres."""
        from engine.body.kinematics import forward_kinematics

        j = forward_kinematics(self.offsets, np.zeros(3), np.broadcast_to(np.eye(3), (12, 3, 3)))
        return float(j[:, 1].max() - j[:, 1].min())

    @classmethod
    def default(cls, height: float = 1.75) -> BodyShape:
        """The seed-001 body scaled to ``height`` metres."""
        if not np.isfinite(height) or not 0.5 <= height <= 2.5:
            from engine.errors import InvalidInput

            raise InvalidInput(f"height must be between 0.5 and 2.5 m, got {height!r}")
        k = height / _H0
        offsets = _DEFAULT_DIRS * (_DEFAULT_LENGTHS_175 * k)[:, None]
        return cls(offsets=offsets, radii=default_radii(height))

    @classmethod
    def from_rest_joints(cls, rest_joints: np.ndarray, height: float | None = None) -> BodyShape:
        """A body whose default posture is the given joint positions (e.g. a BVH T-pose).

        Parameters
        ----------
        rest_joints : ndarray, shape (17, 3)
        height : float, optional
            Height used to size the capsules; measured from ``rest_joints`` when omitted
            (head top to lowest ankle, plus 4 % for the feet).
        """
        from engine.body.kinematics import bone_vectors

        rest = np.asarray(rest_joints, dtype=float)
        if height is None:
            height = float(rest[:, 1].max() - rest[:, 1].min()) * 1.04
        return cls(offsets=bone_vectors(rest), radii=default_radii(height))


def default_radii(height: float) -> np.ndarray:
    """Capsule radii of a body of ``height`` metres, shape (C,)."""
    return np.array([c[5] * c[6] * height / 2.0 for c in _CAPSULES])


def capsule_endpoints(joints: np.ndarray) -> np.ndarray:
    """Capsule axis endpoints for postures.

    Parameters
    ----------
    joints : ndarray, shape (..., 17, 3)

    Returns
    -------
    ends : ndarray, shape (..., C, 2, 3)
    """
    a = joints[..., CAPSULE_A, :]
    b = joints[..., CAPSULE_B, :]
    t = CAPSULE_T[..., None]  # (C, 2, 1)
    return a[..., None, :] + t * (b - a)[..., None, :]


assert len(_DEFAULT_LENGTHS_175) == N_BONES  # table sanity at import, not an input check
