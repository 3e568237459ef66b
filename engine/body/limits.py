"""Joint-angle limits of the 17-joint body (thesis appendix A, table A.1).

The limit of a joint is on the angle *at* that joint between the bone towards its parent and
the bone towards its child (180 deg = straight, e.g. a straight knee); table A.1 gives the
smallest allowed angle, e.g. 35 deg for a knee, so a knee folded tighter than that is
impossible. The table itself is :data:`engine.body.skeleton.JOINT_LIMITS` (11 limited joints,
:data:`~engine.body.skeleton.LIMIT_JOINT` order); the end effectors and the root have none.
"""

from __future__ import annotations

import numpy as np

from engine.body.skeleton import (
    BEND_LABELS,
    BONE_CHILD,
    BONE_NAMES,
    BONE_PARENT,
    LIMIT_A,
    LIMIT_B,
    LIMIT_JOINT,
    LIMIT_MIN_RAD,
    column_name,
)
from engine.errors import InvalidInput


def _check(joints: np.ndarray) -> np.ndarray:
    j = np.asarray(joints, dtype=float)
    if j.ndim < 2 or j.shape[-2:] != (17, 3):
        raise InvalidInput(f"joints must have shape (..., 17, 3), got {j.shape}")
    return j


def joint_angles(joints: np.ndarray) -> np.ndarray:
    """Angle at each limited joint between its parent-side and child-side bones.

    Parameters
    ----------
    joints : ndarray, shape (..., 17, 3)

    Returns
    -------
    angles : ndarray, shape (..., 11)
        Radians in [0, pi], in :data:`~engine.body.skeleton.JOINT_LIMITS` order
        (thesis table A.1: alpha_ij between connected bones).

    Raises
    ------
    InvalidInput
        When ``joints`` is not (..., 17, 3).
    """
    j = _check(joints)
    a = j[..., LIMIT_A, :] - j[..., LIMIT_JOINT, :]
    b = j[..., LIMIT_B, :] - j[..., LIMIT_JOINT, :]
    na = np.linalg.norm(a, axis=-1)
    nb = np.linalg.norm(b, axis=-1)
    cos = np.sum(a * b, axis=-1) / np.maximum(na * nb, 1e-12)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def limit_violations(joints: np.ndarray, *, margin_rad: float = 0.0) -> np.ndarray:
    """Which joint-angle limits (appendix A) a posture breaks.

    Parameters
    ----------
    joints : ndarray, shape (..., 17, 3)
    margin_rad : float
        Tolerance: a limit is broken only when the angle is below ``min - margin_rad``
        (useful for noisy measured postures).

    Returns
    -------
    violated : ndarray of bool, shape (..., 11)

    Raises
    ------
    InvalidInput
        When ``joints`` is not (..., 17, 3) or ``margin_rad`` is negative or not finite.
    """
    if not np.isfinite(margin_rad) or margin_rad < 0:
        raise InvalidInput(f"margin_rad must be a non-negative number, got {margin_rad!r}")
    return joint_angles(joints) < LIMIT_MIN_RAD - margin_rad


def within_limits(joints: np.ndarray, *, margin_rad: float = 0.0) -> np.ndarray:
    """Whether postures respect every joint-angle limit (appendix A).

    Parameters
    ----------
    joints : ndarray, shape (..., 17, 3)
    margin_rad : float
        See :func:`limit_violations`.

    Returns
    -------
    ok : ndarray of bool, shape (...)
    """
    return ~np.any(limit_violations(joints, margin_rad=margin_rad), axis=-1)


#: CSV columns of the angle between each pair of consecutive bones: (name, parent bone, bone),
#: named by the bend a coach sees (``angle_deg_left_knee``; the upper chest's three angles get
#: three names). Every joint angle, not only the limited ones (the export's and the capture's
#: CSV).
JOINT_ANGLES: tuple[tuple[str, int, int], ...] = tuple(
    (f"angle_deg_{column_name(str(BEND_LABELS[b]))}", pb, b)
    for b in range(len(BONE_NAMES))
    for pb in range(len(BONE_NAMES))
    if int(BONE_CHILD[pb]) == int(BONE_PARENT[b])
)


def joint_angles_deg(joints: np.ndarray) -> np.ndarray:
    """Angles (deg) between consecutive bones of postures (T, 17, 3) -> (T, len(JOINT_ANGLES))."""
    j = np.asarray(joints, float)
    d = j[:, BONE_CHILD] - j[:, BONE_PARENT]
    d = d / np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-12)
    pb = [a[1] for a in JOINT_ANGLES]
    b = [a[2] for a in JOINT_ANGLES]
    cos = np.clip((d[:, pb] * d[:, b]).sum(-1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))
