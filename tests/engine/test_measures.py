import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from engine.body.kinematics import forward_kinematics, rotation_about_axis
from engine.body.shapes import BodyShape
from engine.body.skeleton import PART_INDEX
from engine.measures import bone_angles, d_B


@pytest.fixture
def postures(rng):
    shape = BodyShape.default()
    R = Rotation.random(2 * 5 * 12, random_state=rng).as_matrix().reshape(2, 5, 12, 3, 3)
    root = rng.normal(size=(2, 5, 3))
    return forward_kinematics(shape.offsets, root, R)  # (2, 5, 17, 3)


def test_zero_on_equal_postures(postures):
    np.testing.assert_allclose(d_B(postures[0], postures[0]), 0.0, atol=1e-6)


def test_symmetric(postures):
    np.testing.assert_allclose(d_B(postures[0], postures[1]), d_B(postures[1], postures[0]))
    assert np.all(d_B(postures[0], postures[1]) > 0.1)


def test_translation_invariant(postures, rng):
    moved = postures[1] + rng.normal(size=(5, 1, 3))
    np.testing.assert_allclose(d_B(postures[0], moved), d_B(postures[0], postures[1]), atol=1e-12)


def test_exact_on_known_rotation_of_one_bone():
    shape = BodyShape.default()
    R = np.broadcast_to(np.eye(3), (12, 3, 3)).copy()
    a = forward_kinematics(shape.offsets, np.zeros(3), R)
    R[PART_INDEX["l_lower_arm"]] = rotation_about_axis(np.array([0.0, 1.0, 0.0]), math.radians(30))
    b = forward_kinematics(shape.offsets, np.zeros(3), R)
    ang = bone_angles(a, b)
    assert ang[10] == pytest.approx(math.radians(30))  # bone 10 = l_elbow->l_wrist
    assert np.count_nonzero(ang > 1e-9) == 1
    assert d_B(a, b) == pytest.approx(math.radians(30) / 16)
    w = np.zeros(16)
    w[10] = 1.0
    assert d_B(a, b, weights=w) == pytest.approx(math.radians(30))


def test_global_orientation_included(postures):
    turned = postures[0] @ Rotation.from_euler("y", 90, degrees=True).as_matrix().T
    assert np.all(d_B(postures[0], turned) > 0.3)
