"""Domain files (thesis 6.8): validation and the score they change."""

from __future__ import annotations

import json

import numpy as np
import pytest

from engine.errors import InvalidInput
from engine.reference.domain import (
    GOLF_SEGMENT_NAMES,
    Domain,
    domain_path,
    find_domain,
    load_domain,
    parse_domain,
    reference_segments,
)


def test_golf_file_round_trip(tmp_path):
    bvh = tmp_path / "swing.bvh"
    doc = {
        "sport": "golf",
        "segment_names": list(GOLF_SEGMENT_NAMES),
        "bone_weights": {"hip->lower_chest": 3, "l_elbow": 2},
        "tolerances_deg": {"l_knee": 15},
        "boundary": {"joints": ["r_wrist"], "direction_change_deg": 120},
    }
    assert domain_path(bvh).name == "swing.domain.json"
    assert find_domain(bvh) is None
    domain_path(bvh).write_text(json.dumps(doc))
    d = find_domain(bvh, n_segments=6)
    assert d is not None and d.segment_names == GOLF_SEGMENT_NAMES
    assert d.bone_weights[6] == 3 and d.bone_weights[9] == 2 and d.bone_weights[0] == 1
    assert np.degrees(d.tolerances[1]) == pytest.approx(15)
    assert d.boundary_joints == ("r_wrist",) and d.direction_change_deg == 120


def test_score_changes_but_raw_errors_do_not():
    errors = np.radians(np.full((3, 16), 10.0))
    raw = errors.copy()
    plain = Domain()
    assert np.degrees(plain.score(errors)) == pytest.approx([10, 10, 10])
    lenient = parse_domain({"default_tolerance_deg": 8})
    assert np.degrees(lenient.score(errors)) == pytest.approx([2, 2, 2])
    heavy = parse_domain({"bone_weights": {"l_knee": 0}, "tolerances_deg": {"l_knee": 30}})
    errors2 = errors.copy()
    errors2[:, 1] = np.radians(90)  # a large error on a bone that does not count
    assert np.degrees(heavy.score(errors2)) == pytest.approx([10, 10, 10])
    np.testing.assert_array_equal(errors, raw)


@pytest.mark.parametrize(
    ("doc", "match"),
    [
        ([], "expected a JSON object"),
        ({"colour": 1}, "unknown keys"),
        ({"version": 2}, "version"),
        ({"segment_names": "top"}, "segment_names"),
        ({"segment_names": ["a", "b"]}, "3 segments, got 2"),
        ({"bone_weights": {"tail": 1}}, "unknown bone 'tail'"),
        ({"bone_weights": {"l_knee": -1}}, r"bone_weights.l_knee: expected a number >= 0"),
        ({"bone_weights": {b: 0 for b in ("hip->l_hip",)} | {"x": 0}}, "unknown bone"),
        ({"tolerances_deg": {"l_knee": "a lot"}}, "expected a number"),
        ({"tolerances_deg": {"l_knee": 200}}, "at most 180"),
        ({"boundary": {"joints": ["tail"]}}, "boundary.joints"),
        ({"boundary": {"direction_change_deg": 500}}, "direction_change_deg"),
        ({"sport": 3}, "sport"),
        ({"segments": [1, "top"]}, "segments: expected the reference frames"),
        ({"segments": [5, 5]}, "increasing"),
        ({"segments": [-1, 5]}, "segments"),
        ({"segments": [1, 50], "segment_names": ["a", "b", "c"]}, "2 segments start"),
        ({"key_position_names": ["address", ""]}, "key_position_names: expected a list"),
        ({"key_position_names": ["address", "top", "end"]}, "3 segments have 4 key positions"),
        ({"segments": [1, 50], "key_position_names": ["a", "b"]}, "2 segments have 3"),
    ],
)
def test_invalid_documents_are_refused(doc, match):
    with pytest.raises(InvalidInput, match=match):
        parse_domain(doc, n_segments=3)


def test_key_positions_are_named_one_per_segment_start_and_one_for_the_end():
    d = parse_domain({"key_position_names": ["address", "top", "impact", "finish"]}, n_segments=3)
    assert d.key_position_names == ("address", "top", "impact", "finish")
    assert d.to_dict()["key_position_names"] == list(d.key_position_names)
    assert parse_domain({}).key_position_names == ()


def test_all_zero_weights_refused():
    from engine.body.skeleton import BONE_NAMES

    with pytest.raises(InvalidInput, match="at least one weight"):
        parse_domain({"bone_weights": {b: 0 for b in BONE_NAMES}})


def test_file_errors(tmp_path):
    with pytest.raises(InvalidInput, match="does not exist"):
        load_domain(tmp_path / "none.domain.json")
    bad = tmp_path / "bad.domain.json"
    bad.write_text("{not json")
    with pytest.raises(InvalidInput, match="not valid JSON"):
        load_domain(bad)


def test_the_coach_sets_the_segments_or_they_are_detected(tmp_path, cmu_bvh):
    """Every analysis takes its reference segments from here (engine.pipeline)."""
    from engine.io.bvh import load_reference
    from engine.reference.boundaries import reference_boundaries

    bvh = tmp_path / "swing.bvh"
    bvh.write_bytes(cmu_bvh.read_bytes())
    motion = load_reference(bvh).motion
    detected = reference_boundaries(motion)
    assert len(detected.starts) > 1
    assert reference_segments(motion, None) == detected
    names = [f"part {i}" for i in range(len(detected.starts))]
    named = reference_segments(motion, parse_domain({"segment_names": names}))
    assert named.starts == detected.starts and named.names == tuple(names)
    # names that do not match the detected count are not forced onto them
    assert reference_segments(motion, parse_domain({"segment_names": ["x"]})).names[0] == ""
    doc = {"segments": [1, 100, 300], "segment_names": ["a", "b", "c"]}
    domain_path(bvh).write_text(json.dumps(doc))
    own = reference_segments(load_reference(bvh).motion, find_domain(bvh))
    assert own.starts == (1, 100, 300) and own.end == motion.frames - 1
    assert own.names == ("a", "b", "c")
    with pytest.raises(InvalidInput, match="domain segments"):
        reference_segments(motion, parse_domain({"segments": [1, motion.frames]}))
