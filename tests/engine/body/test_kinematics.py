import numpy as np
import pytest

from engine.body.kinematics import (
    forward_kinematics,
    kabsch,
    part_rotations,
    rotation_about_axis,
    rotation_between,
)
from engine.body.shapes import BodyShape
from engine.body.skeleton import BONE_PART, PART_BONES


def random_rotations(rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
    q = rng.normal(size=shape + (4,))
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    w, x, y, z = np.moveaxis(q, -1, 0)
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
            np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
            np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def test_identity_posture_reproduces_offsets():
    shape = BodyShape.default(1.8)
    j = forward_kinematics(shape.offsets, np.zeros(3), np.broadcast_to(np.eye(3), (12, 3, 3)))
    assert j.shape == (17, 3)
    np.testing.assert_allclose(j[1] - j[0], shape.offsets[0])
    assert 1.6 < shape.height < 1.9


@pytest.mark.parametrize("batch", [(), (5,), (2, 3)])
def test_fk_then_ik_round_trip(rng, batch):
    shape = BodyShape.default()
    R = random_rotations(rng, batch + (12,))
    root = rng.normal(size=batch + (3,))
    joints = forward_kinematics(shape.offsets, root, R)
    R2 = part_rotations(joints, shape.offsets)
    again = forward_kinematics(shape.offsets, root, R2)
    np.testing.assert_allclose(again, joints, atol=1e-9)
    # multi-bone parts are recovered exactly, single-bone ones up to twist about the bone
    for p, bones in enumerate(PART_BONES):
        if len(bones) > 1:
            np.testing.assert_allclose(R2[..., p, :, :], R[..., p, :, :], atol=1e-9)
    assert BONE_PART.shape == (16,)


def test_rotation_between_antiparallel_and_parallel():
    a = np.array([[0, 1.0, 0], [0, 1.0, 0], [1.0, 0, 0]])
    b = np.array([[0, -2.0, 0], [0, 3.0, 0], [0, 0, 1.0]])
    R = rotation_between(a, b)
    out = np.einsum("nij,nj->ni", R, a)
    np.testing.assert_allclose(out, b / np.linalg.norm(b, axis=1, keepdims=True), atol=1e-12)
    np.testing.assert_allclose(np.linalg.det(R), 1.0)


def test_kabsch_recovers_rotation(rng):
    R = rotation_about_axis(np.array([1.0, 2.0, 3.0]), 0.7)
    src = rng.normal(size=(4, 3))
    np.testing.assert_allclose(kabsch(src, src @ R.T), R, atol=1e-12)
