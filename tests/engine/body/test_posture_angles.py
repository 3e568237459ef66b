"""Spine tilt and shoulder / hip turn against the room (engine.body.posture_angles)."""

from __future__ import annotations

import numpy as np
import pytest

from engine.body.kinematics import forward_kinematics, rotation_about_axis
from engine.body.posture_angles import POSTURE_ANGLES, posture_angles_deg
from engine.body.shapes import BodyShape
from engine.body.skeleton import JOINT_INDEX
from engine.errors import InvalidInput

J = JOINT_INDEX


def _standing() -> np.ndarray:
    """The default body standing upright, facing +z, its left at +x (DESIGN.md's world)."""
    shape = BodyShape.default(1.75)
    rest = np.broadcast_to(np.eye(3), (1, 12, 3, 3))
    return forward_kinematics(shape.offsets, np.array([[0.0, 0.95, 0.0]]), rest)[0]


def _about(axis, deg, joints, centre):
    R = rotation_about_axis(np.asarray(axis, float), np.radians(deg))
    return (joints - centre) @ R.T + centre


def test_upright_and_unturned_reads_zero():
    a = posture_angles_deg(_standing()[None])
    assert a.shape == (1, len(POSTURE_ANGLES))
    np.testing.assert_allclose(a, 0.0, atol=1.0)


def test_a_forward_bend_a_side_bend_and_a_turn_read_as_themselves():
    body = _standing()
    hip = body[J["hip"]]
    upper = [J[n] for n in ("lower_chest", "upper_chest", "l_shoulder", "l_elbow", "l_wrist",
                            "r_shoulder", "r_elbow", "r_wrist", "neck", "head_top")]  # fmt: skip
    bent, side, turned = body.copy(), body.copy(), body.copy()
    left = body[J["l_hip"]] - body[J["r_hip"]]
    left /= np.linalg.norm(left)
    bent[upper] = _about(left, 30, body[upper], hip)  # the trunk tips forward
    side[upper] = _about([0, 0, 1.0], -20, body[upper], hip)  # the trunk leans to its left (+x)
    turned[upper] = _about([0, 1.0, 0], 80, body[upper], hip)  # shoulders turn, hips stay
    a = posture_angles_deg(np.stack([body, bent, side, turned]))
    base = a[0]
    assert a[1, 0] - base[0] == pytest.approx(30, abs=0.5)
    assert a[2, 1] - base[1] == pytest.approx(20, abs=0.5)
    assert abs(a[3, 2]) == pytest.approx(80, abs=0.5) and a[3, 3] == pytest.approx(0, abs=1e-6)


def test_the_figures_do_not_depend_on_where_the_body_faces():
    body = _standing()
    seq = np.stack([body, _about([0, 1.0, 0], 50, body, body[J["hip"]])])
    facing_x = _about([0, 1.0, 0], 90, seq.reshape(-1, 3), np.zeros(3)).reshape(seq.shape)
    np.testing.assert_allclose(posture_angles_deg(seq), posture_angles_deg(facing_x), atol=1e-6)


def test_bad_shapes_are_refused():
    with pytest.raises(InvalidInput, match=r"\(T, 17, 3\)"):
        posture_angles_deg(np.zeros((0, 17, 3)))
