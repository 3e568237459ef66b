import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from engine.body.kinematics import bone_directions, forward_kinematics
from engine.body.retarget import retarget, retarget_shape
from engine.body.shapes import BodyShape
from engine.body.skeleton import PARENTS
from engine.errors import InvalidInput
from engine.types import Motion


@pytest.fixture
def motion(rng):
    shape = BodyShape.default(1.8)
    R = Rotation.random(10 * 12, random_state=rng).as_matrix().reshape(10, 12, 3, 3)
    root = np.cumsum(rng.normal(scale=0.05, size=(10, 3)), axis=0) + [0, 1.0, 0]
    return Motion(forward_kinematics(shape.offsets, root, R), 30.0, first_motion_frame=1), shape


def test_height_scales_every_bone(motion):
    m, shape = motion
    out, new = retarget(m, shape, 1.5)
    assert new.height * 1.04 == pytest.approx(1.5)
    np.testing.assert_allclose(new.lengths / shape.lengths, new.lengths[0] / shape.lengths[0])
    np.testing.assert_allclose(bone_directions(out.joints), bone_directions(m.joints), atol=1e-9)
    np.testing.assert_allclose(
        np.linalg.norm(out.joints[:, 1:] - out.joints[:, PARENTS[1:]], axis=-1),
        np.broadcast_to(new.lengths, (10, 16)),
        atol=1e-9,
    )
    assert out.fps == 30.0 and out.first_motion_frame == 1


def test_given_limb_lengths(motion):
    m, shape = motion
    out, new = retarget(m, shape, 1.8, bone_lengths={"l_elbow": 0.31, "r_shoulder->r_elbow": 0.25})
    assert new.lengths[9] == pytest.approx(0.31)
    assert new.lengths[12] == pytest.approx(0.25)
    np.testing.assert_allclose(np.linalg.norm(out.joints[:, 10] - out.joints[:, 9], axis=-1), 0.31)
    np.testing.assert_allclose(bone_directions(out.joints), bone_directions(m.joints), atol=1e-9)


def test_same_height_is_identity(motion):
    m, shape = motion
    out, _ = retarget(m, shape, shape.height * 1.04)
    np.testing.assert_allclose(out.joints, m.joints, atol=1e-9)


def test_validation():
    shape = BodyShape.default()
    with pytest.raises(InvalidInput, match="height must be between"):
        retarget_shape(shape, 3.0)
    with pytest.raises(InvalidInput, match="unknown bone 'forearm'"):
        retarget_shape(shape, 1.7, {"forearm": 0.3})
    with pytest.raises(InvalidInput, match="must be positive"):
        retarget_shape(shape, 1.7, {"l_wrist": -0.3})
