import numpy as np
import pytest

from engine.body.skeleton import JOINT_INDEX
from engine.errors import InvalidInput
from engine.reference import direction_change, reference_boundaries, segments_from_list
from engine.types import Motion

FPS = 120.0
RW = JOINT_INDEX["r_wrist"]


def wrist_motion(
    turns: list[int], T: int = 600, first: int = 0, angle_deg: float = 180.0
) -> Motion:
    """The right wrist moves at 0.5 m/s and turns by angle_deg at each frame of ``turns``."""
    d = np.array([1.0, 0.0, 0.0])
    vel = np.empty((T, 3))
    a = np.radians(angle_deg)
    R = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    for t in range(T):
        if t in turns:
            d = R @ d
        vel[t] = d * 0.5 / FPS
    path = np.cumsum(vel, axis=0)
    joints = np.zeros((T, 17, 3))
    joints[:, RW] = path
    if first:
        joints[:first, RW] = [5.0, 5.0, 5.0]  # a T-pose far away must not matter
    return Motion(joints, FPS, first_motion_frame=first)


def test_reversals_found_within_two_frames():
    turns = [150, 320, 450]
    seg = reference_boundaries(wrist_motion(turns))
    assert seg.starts[0] == 0 and seg.end == 599
    assert len(seg.starts) == 4
    np.testing.assert_allclose(seg.starts[1:], turns, atol=2)


def test_threshold_separates_turn_angles():
    m = wrist_motion([200, 400], angle_deg=90.0)
    assert len(reference_boundaries(m, threshold_deg=60).starts) == 3
    assert len(reference_boundaries(m, threshold_deg=120).starts) == 1


def test_still_joint_and_first_frame():
    m = wrist_motion([300], first=1)
    joints = m.joints.copy()
    joints[100:200, RW] = joints[100, RW]  # stands still: direction is noise, no boundary
    joints[100:200, RW] += np.random.default_rng(0).normal(scale=1e-5, size=(100, 3))
    m = Motion(joints, FPS, first_motion_frame=1)
    seg = reference_boundaries(m)
    assert seg.starts[0] == 1
    assert seg.starts[1:] == pytest.approx([300], abs=2)
    speed, change = direction_change(m)
    assert speed[0] == 0 and change.shape == (600,)


def test_min_segment_keeps_sharpest():
    m = wrist_motion([200, 230], angle_deg=100.0)
    seg = reference_boundaries(m, min_segment_s=0.5)
    assert len(seg.starts) == 2  # 30 frames apart: only one survives
    seg = reference_boundaries(m, min_segment_s=0.1)
    assert len(seg.starts) == 3


def test_cmu_defaults(cmu_bvh):
    from engine.io import load_reference

    seg = reference_boundaries(load_reference(cmu_bvh).motion)
    assert seg.starts == (1, 274, 473)


def test_validation():
    m = wrist_motion([100], T=200)
    with pytest.raises(InvalidInput, match="joint must be one of"):
        reference_boundaries(m, joint="wrist")
    with pytest.raises(InvalidInput, match=r"threshold_deg must lie in \(0, 180\)"):
        reference_boundaries(m, threshold_deg=200)
    with pytest.raises(InvalidInput, match="step must be a positive whole"):
        reference_boundaries(m, step=0)
    with pytest.raises(InvalidInput, match="smooth_s must be"):
        reference_boundaries(m, smooth_s=-1)
    with pytest.raises(InvalidInput, match="min_speed must be"):
        reference_boundaries(m, min_speed=-1)
    with pytest.raises(InvalidInput, match="min_segment_s must be"):
        reference_boundaries(m, min_segment_s=np.nan)


def test_segments_from_list():
    m = wrist_motion([100], T=200)
    seg = segments_from_list([1, 50, 120], m, names=["address", "swing", "finish"])
    assert seg.bounds() == [(1, 50), (50, 120), (120, 199)]
    assert seg.names == ("address", "swing", "finish")
    with pytest.raises(InvalidInput, match="at least one"):
        segments_from_list([], m)
    with pytest.raises(InvalidInput, match="whole frame numbers"):
        segments_from_list([1, 2.5], m)
    with pytest.raises(InvalidInput, match="strictly increasing"):
        segments_from_list([1, 50, 50], m)
    with pytest.raises(InvalidInput, match=r"lie in \[0, 199\]"):
        segments_from_list([1, 250], m)
    with pytest.raises(InvalidInput, match="one name per segment"):
        segments_from_list([1, 50], m, names=["a"])
