"""Angles a golf or strength coach reads against the room, not between two bones: the
spine's tilt from the vertical (forward and sideways) and the turn of the shoulders and of
the hips about the vertical, since the first frame.

Bends (:func:`engine.body.limits.joint_angles_deg`) say how a joint is folded; these say how
the body stands: a golfer's spine angle at address and its loss at impact, the shoulder and
hip turn at the top of the backswing and their difference (the "X-factor"). Frame of
DESIGN.md's world: y up. "Forward" and "left" are the body's own at the first frame, from
its hip line, so the figures do not depend on where the camera or the motion's file put the
body.
"""

from __future__ import annotations

import numpy as np

from engine.body.skeleton import JOINT_INDEX
from engine.errors import InvalidInput

#: What :func:`posture_angles_deg` returns, in its column order.
POSTURE_ANGLES: tuple[str, ...] = (
    "spine forward tilt", "spine side tilt", "shoulder turn", "hip turn",
)  # fmt: skip

_UP = np.array([0.0, 1.0, 0.0])
_J = JOINT_INDEX


def _flat(v: np.ndarray) -> np.ndarray:
    """Vectors (..., 3) laid on the ground plane and normalised (zero where vertical)."""
    h = v * np.array([1.0, 0.0, 1.0])
    n = np.linalg.norm(h, axis=-1, keepdims=True)
    return np.divide(h, n, out=np.zeros_like(h), where=n > 1e-9)


def _turn_deg(line: np.ndarray, start: np.ndarray) -> np.ndarray:
    """Signed angle (deg) about +y from the ground direction ``start`` (3,) to each of
    ``line`` (T, 3), in (-180, 180]: positive turns the body's left side backwards."""
    a, b = _flat(line), _flat(start[None])[0]
    cross_y = b[2] * a[:, 0] - b[0] * a[:, 2]  # (b x a) . y
    return np.degrees(np.arctan2(cross_y, a @ b))


def posture_angles_deg(joints: np.ndarray) -> np.ndarray:
    """Postures (T, 17, 3) -> (T, 4) degrees, the columns of :data:`POSTURE_ANGLES`:

    - spine forward / side tilt: the hip -> neck line's angle from the vertical, towards the
      body's front / its left (negative: backwards / to its right), in the first frame's
      body directions;
    - shoulder / hip turn: the left-to-right shoulder (hip) line's turn about the vertical
      since the first frame.

    Raises
    ------
    InvalidInput
        Not (T, 17, 3) with T >= 1.
    """
    j = np.asarray(joints, float)
    if j.ndim != 3 or j.shape[1:] != (17, 3) or len(j) == 0:
        raise InvalidInput(f"postures must be (T, 17, 3) with T >= 1, got {j.shape}")
    hips = j[:, _J["l_hip"]] - j[:, _J["r_hip"]]
    shoulders = j[:, _J["l_shoulder"]] - j[:, _J["r_shoulder"]]
    left = _flat(hips[:1])[0]
    forward = np.cross(left, _UP)  # facing +z with the left side at +x: forward is +z
    trunk = j[:, _J["neck"]] - j[:, _J["hip"]]
    up = trunk @ _UP
    return np.stack([
        np.degrees(np.arctan2(trunk @ forward, up)),
        np.degrees(np.arctan2(trunk @ left, up)),
        _turn_deg(shoulders, shoulders[0]),
        _turn_deg(hips, hips[0]),
    ], axis=1)  # fmt: skip
