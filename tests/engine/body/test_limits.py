import math

import numpy as np
import pytest

from engine.body.kinematics import forward_kinematics, rotation_about_axis
from engine.body.limits import joint_angles, limit_violations, within_limits
from engine.body.shapes import BodyShape
from engine.body.skeleton import JOINT_LIMITS, PART_INDEX
from engine.errors import InvalidInput

KNEE = [j for j, *_ in JOINT_LIMITS].index("l_knee")
ELBOW = [j for j, *_ in JOINT_LIMITS].index("r_elbow")


def posture_with_bent_knee(bend_deg: float) -> np.ndarray:
    """Default posture with the left shin rotated about x by bend_deg (0 = straight)."""
    shape = BodyShape.default()
    R = np.broadcast_to(np.eye(3), (12, 3, 3)).copy()
    R[PART_INDEX["l_lower_leg"]] = rotation_about_axis(
        np.array([1.0, 0, 0]), math.radians(bend_deg)
    )
    return forward_kinematics(shape.offsets, np.zeros(3), R)


def test_default_posture_is_within_limits():
    j = posture_with_bent_knee(0.0)
    ang = joint_angles(j)
    assert ang.shape == (11,)
    assert ang[KNEE] == pytest.approx(math.pi)
    assert within_limits(j)


@pytest.mark.parametrize(
    ("bend", "broken"), [(90.0, False), (140.0, False), (150.0, True), (170.0, True)]
)
def test_hyper_bent_knee_flagged(bend, broken):
    j = posture_with_bent_knee(bend)
    ang = joint_angles(j)
    assert ang[KNEE] == pytest.approx(math.radians(180 - bend))  # ground truth by construction
    v = limit_violations(j)
    assert v[KNEE] == broken
    assert v.sum() == int(broken)
    assert within_limits(j) == (not broken)


def test_vectorised_over_batches():
    j = np.stack([posture_with_bent_knee(b) for b in (0, 150, 60, 170)]).reshape(2, 2, 17, 3)
    assert joint_angles(j).shape == (2, 2, 11)
    np.testing.assert_array_equal(within_limits(j), [[True, False], [True, False]])


def test_margin():
    j = posture_with_bent_knee(147.0)  # 33 deg < 35
    assert not within_limits(j)
    assert within_limits(j, margin_rad=math.radians(3))


def test_validation():
    with pytest.raises(InvalidInput, match=r"shape \(\.\.\., 17, 3\)"):
        joint_angles(np.zeros((16, 3)))
    with pytest.raises(InvalidInput, match="margin_rad must be a non-negative"):
        limit_violations(np.zeros((17, 3)), margin_rad=-1.0)
