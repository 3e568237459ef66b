"""Key frames chosen by the reference's motion, and the carried start between them (issue 25)."""

from __future__ import annotations

import numpy as np
import pytest

from engine.body.kinematics import bone_vectors, rot_y, rotation_about_axis
from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.stages.candidates import CandidateSettings
from engine.stages.candidates.key_frames import (
    carry_deviation,
    choose_key_frames,
    key_span,
    reference_motion_deg,
)
from tests.synthetic import swing_joints


@pytest.fixture(scope="module")
def swing() -> np.ndarray:
    return swing_joints(BodyShape.default(1.75), 60)


def test_a_still_reference_gets_a_key_frame_every_gap_frames(swing):
    still = np.repeat(swing[:1], 10, axis=0)
    np.testing.assert_allclose(reference_motion_deg(still), 0.0, atol=1e-4)
    assert np.flatnonzero(choose_key_frames(still, 3, 4.0)).tolist() == [0, 3, 6, 9]
    assert np.flatnonzero(choose_key_frames(still, 4, 4.0)).tolist() == [0, 4, 8, 9]
    assert choose_key_frames(still, 1, 4.0).all()  # the thesis: every frame


def test_key_frames_crowd_where_the_reference_moves_fast(swing):
    motion = reference_motion_deg(swing)
    keys = choose_key_frames(swing, 6, 2.0)
    fast, slow = motion > np.quantile(motion, 0.75), motion < np.quantile(motion, 0.25)
    assert keys[fast].mean() > keys[slow].mean()
    # between two key frames the reference moves by at most the threshold plus one frame
    idx = np.flatnonzero(keys)
    for a, b in zip(idx[:-1], idx[1:], strict=True):
        assert motion[a + 1 : b].sum() <= 2.0 and b - a <= 6


def test_the_span_reaches_the_key_frames_around_a_chunk():
    keys = np.zeros(12, bool)
    keys[[0, 3, 6, 9, 11]] = True
    assert key_span(range(4, 8), keys) == range(3, 10)
    assert key_span(range(3, 7), keys) == range(3, 7)  # already ends on key frames
    assert key_span(range(0, 12), keys) == range(0, 12)


def test_carrying_onto_the_same_reference_gives_the_posture_back(swing):
    reference = swing[10]
    posture = reference.copy()
    posture[11] = reference[10] + rot_y(0.4) @ (reference[11] - reference[10])  # l forearm
    np.testing.assert_allclose(carry_deviation(posture, reference, reference), posture, atol=1e-9)


def test_a_carried_posture_keeps_the_targets_bones_and_the_deviation(swing):
    ref_a, ref_b = swing[10], swing[14]
    # the performer's right forearm is turned by 30 deg against the expert's at the key frame
    posture = ref_a.copy()
    forearm = ref_a[14] - ref_a[13]
    axis = np.cross(forearm, [0.0, 0.0, 1.0])
    posture[14] = (
        ref_a[13] + rotation_about_axis(axis / np.linalg.norm(axis), np.radians(30)) @ forearm
    )
    carried = carry_deviation(posture + [0.1, 0.0, 0.0], ref_a, ref_b)
    np.testing.assert_allclose(
        np.linalg.norm(bone_vectors(carried), axis=-1), np.linalg.norm(bone_vectors(ref_b), axis=-1)
    )
    np.testing.assert_allclose(carried[0], ref_b[0] + [0.1, 0.0, 0.0])
    # the unchanged bones follow the target, the changed one keeps its deviation
    unchanged = [b for b in range(16) if b != 13]  # bone 13: r_elbow -> r_wrist
    np.testing.assert_allclose(bone_vectors(carried)[unchanged], bone_vectors(ref_b)[unchanged])
    a, b = (v / np.linalg.norm(v) for v in (bone_vectors(carried)[13], bone_vectors(ref_b)[13]))
    assert np.degrees(np.arccos(np.clip(a @ b, -1, 1))) == pytest.approx(30.0, abs=3.0)


@pytest.mark.parametrize(
    "field", [{"key_gap": 0}, {"key_motion_deg": 0.0}, {"between_step0_deg": float("nan")}]
)
def test_bad_key_frame_settings_are_refused(field):
    with pytest.raises(InvalidInput, match=next(iter(field))):
        CandidateSettings(**field).validate()


@pytest.mark.parametrize("keys", [[False, True, True], [True, True, False], [True, True]])
def test_a_chunk_refuses_keys_that_do_not_frame_it(keys):
    # a frame between key frames needs a key frame on each side within the chunk
    from engine.stages.candidates import estimate_candidates_chunk

    with pytest.raises(InvalidInput, match="keys must be 3 flags"):
        estimate_candidates_chunk(
            np.zeros((3, 8, 8), bool), np.zeros((3, 8, 8), bool),
            None,  # the keys are checked before anything is estimated
            BodyShape.default(1.75), np.zeros((3, 17, 3)),
            rng=np.random.default_rng(0), keys=np.asarray(keys),
        )  # fmt: skip
