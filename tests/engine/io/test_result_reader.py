"""The typed result reader: a written result reads back with every field and shape, older
results without the optional keys read as None / empty, and malformed documents are refused
with InvalidInput naming the JSON path (never a KeyError)."""

from __future__ import annotations

import copy
import dataclasses
import json

import numpy as np
import pytest

from engine.body.skeleton import BONE_NAMES, JOINTS
from engine.errors import InvalidInput
from engine.io.result import build_result, write_result
from engine.io.result_reader import (
    Fit,
    Result,
    ResultFrame,
    ResultSegment,
    as_result,
    read_result,
)
from engine.reference.domain import parse_domain
from engine.render.camera import Camera
from engine.stages.assessment import add_image_best, add_uncertainty
from engine.stages.selection import select_and_refine
from engine.types import Segments

BASE = np.array([
    [0, 1, 0], [0.1, 1, 0], [0.1, 0.55, 0], [0.1, 0.1, 0], [-0.1, 1, 0], [-0.1, 0.55, 0],
    [-0.1, 0.1, 0], [0, 1.2, 0], [0, 1.4, 0], [0.18, 1.45, 0], [0.45, 1.45, 0], [0.7, 1.45, 0],
    [-0.18, 1.45, 0], [-0.45, 1.45, 0], [-0.7, 1.45, 0], [0, 1.55, 0], [0, 1.75, 0],
], float)  # fmt: skip
CAMERA = Camera(scale=100.0, cx=160.0, cy=200.0)
N = 11  # video frames


@pytest.fixture
def doc(rng) -> dict:
    """A result as the engine writes it: stage 4's document with a domain, then the keys of
    engine.stages.assessment (image_best in one misfit frame, uncertainty, summary.fit)."""
    ang = np.linspace(0, np.pi / 2, 41)
    ref = np.repeat(BASE[None], 41, 0)
    for k, r in ((13, 0.27), (14, 0.52)):  # right arm swings up
        ref[:, k] = BASE[12] + r * np.stack([-np.cos(ang), np.sin(ang), 0 * ang], -1)
    C0 = np.arange(0, 41, 4)
    cands = [np.stack([ref[c], ref[c] + rng.normal(0, 0.05, (17, 3))]) for c in C0]
    sel = select_and_refine(cands, ref, Segments((0, 20), 40, ("a", "b")), C0, fps_ratio=4.0)
    d = build_result(
        reference_name="arm", reference_frames=42, reference_fps=120.0,
        video={"frames": N, "fps": 30.0, "width": 320, "height": 240}, camera=CAMERA,
        selection=sel, candidates=cands, timing_s={"selection": 0.01},
        domain=parse_domain({"segment_names": ["lift", "hold"], "default_tolerance_deg": 2}),
        reference_frame_offset=1,
    )  # fmt: skip
    for f in d["frames"]:
        f["flags"] = [x for x in f["flags"] if x != "image_misfit"]
    d["frames"][4]["flags"].append("image_misfit")
    d_s = [np.array([0.3, 0.1 + 0.01 * i]) for i in range(N)]
    add_image_best(d, cands, d_s, CAMERA)
    add_uncertainty(d, cands, d_s, ref[sel.C], margin=0.5)
    d["summary"]["fit"] = {  # as engine.stages.assessment.assess_fit writes it
        "region_mismatch_median": 0.12, "region_mismatch_per_frame": [0.1] * (N - 1) + [0.3],
        "poor_frames": 0, "keypoint_worst_per_frame": [0.05] * (N - 1) + [None],
        "keypoint_off_frames": 0,
    }  # fmt: skip
    d["analysis_id"] = "abc"
    return d


def test_a_written_result_reads_back_with_every_field_and_shape(doc, tmp_path):
    r = read_result(write_result(doc, tmp_path / "result.json"))
    assert (r.version, r.reference.name, r.reference.frames, r.reference.fps) == (
        1,
        "arm",
        42,
        120.0,
    )
    assert (r.video.frames, r.video.fps, r.video.width, r.video.height) == (N, 30.0, 320, 240)
    assert r.joints == JOINTS and r.bones == BONE_NAMES
    assert r.camera == CAMERA
    assert r.analysis_id == "abc" and r.domain is not None
    assert r.timing_s["total"] == pytest.approx(0.01)
    assert len(r.frames) == N and all(isinstance(f, ResultFrame) for f in r.frames)
    assert r.joints_3d.shape == (N, 17, 3) and r.joints_2d.shape == (N, 17, 2)
    assert r.bone_errors_deg.shape == (N, 16) and r.posture_error_deg.shape == (N,)
    assert r.score_deg is not None and r.score_deg.shape == (N,)
    np.testing.assert_array_equal(r.t, np.arange(N))
    assert r.reference_frame[0] == 1 and r.reference_frame[-1] == 41  # T-pose offset
    assert r.frame_index == {t: t for t in range(N)}
    f = r.frames[4]
    assert f.candidates.shape == (2, 17, 3) and f.selected in (0, 1)
    assert f.bone_error_range_deg is not None and f.bone_error_range_deg.shape == (16, 2)
    assert "image_misfit" in f.flags and f.image_best == 1
    assert f.image_best_joints_2d is not None and f.image_best_joints_2d.shape == (17, 2)
    assert r.frames[3].image_best is None and r.frames[3].image_best_joints_2d is None
    assert [s.name for s in r.segments] == ["lift", "hold"]
    s = r.segments[0]
    assert isinstance(s, ResultSegment) and s.bone_mean_errors_deg.shape == (16,)
    assert s.status == "ok" and s.tempo is not None and s.worst_frame is not None
    assert len(s.worst_bones) == 3 and s.boundary_found is not None and s.score_deg is not None
    assert s.bone_uncertainty_deg is not None and s.bone_uncertainty_deg.shape == (16,)
    assert r.summary.status == "ok" and r.summary.score_deg is not None
    fit = r.summary.fit
    assert isinstance(fit, Fit) and fit.region_mismatch_per_frame.shape == (N,)
    assert fit.keypoint_worst_per_frame is not None
    assert np.isnan(fit.keypoint_worst_per_frame[-1])  # JSON null: no confident keypoint
    assert fit.keypoint_off_frames == 0 and fit.poor_frames == 0


def test_every_value_equals_the_documents(doc):
    r = Result.from_dict(doc)
    assert r.doc is doc  # passed on unchanged
    for f, d in zip(r.frames, doc["frames"], strict=True):
        assert (f.t, f.reference_frame, f.selected) == (d["t"], d["reference_frame"], d["selected"])
        assert f.posture_error_deg == d["posture_error_deg"] and f.score_deg == d["score_deg"]
        for key in ("joints_3d", "joints_2d", "candidates", "bone_errors_deg",
                    "bone_error_range_deg"):  # fmt: skip
            assert getattr(f, key).tolist() == d[key], key
        assert f.flags == tuple(d["flags"])
    for s, d in zip(r.segments, doc["segments"], strict=True):
        for key, value in d.items():
            got = getattr(s, key)
            assert (got.tolist() if isinstance(got, np.ndarray) else got) == (
                tuple(value) if isinstance(value, list) and key == "worst_bones" else value
            ), key
    assert r.summary.messages == tuple(doc["summary"]["messages"])
    assert r.summary.mean_error_deg == doc["summary"]["mean_error_deg"]
    assert dict(r.timing_s) == doc["timing_s"]
    np.testing.assert_array_equal(r.joints_3d, [f["joints_3d"] for f in doc["frames"]])


def test_the_result_is_read_only(doc):
    r = Result.from_dict(doc)
    for a in (r.joints_3d, r.bone_errors_deg, r.frames[0].joints_3d, r.frames[0].candidates):
        assert not a.flags.writeable
    with pytest.raises(dataclasses.FrozenInstanceError):
        r.frames[0].t = 3  # type: ignore[misc]


def test_as_result_reads_a_document_once(doc):
    r = as_result(doc)
    assert as_result(r) is r and r.doc is doc


def test_an_old_result_without_the_optional_keys(doc):
    old = copy.deepcopy(doc)
    for key in ("summary", "domain", "bones", "analysis_id"):
        old.pop(key)
    for f in old["frames"]:
        for key in ("score_deg", "image_best", "image_best_joints_2d", "bone_error_range_deg"):
            f.pop(key, None)
    required = {"reference_start", "reference_end", "performer_start", "performer_end",
                "mean_error_deg", "bone_mean_errors_deg"}  # fmt: skip
    old["segments"] = [{k: v for k, v in s.items() if k in required} for s in old["segments"]]
    old["camera"] = {k: old["camera"][k] for k in ("scale", "theta_z_deg", "cx", "cy")}
    r = Result.from_dict(old)
    assert r.summary.status is None and r.summary.messages == () and r.summary.fit is None
    assert r.summary.mean_error_deg is None
    assert r.domain is None and r.bones is None and r.analysis_id is None
    assert r.score_deg is None
    f = r.frames[4]
    assert f.score_deg is None and f.image_best is None and f.image_best_joints_2d is None
    assert f.bone_error_range_deg is None
    s = r.segments[0]
    assert s.name is None and s.status is None and s.tempo is None and s.worst_frame is None
    assert s.worst_bones == () and s.bone_uncertainty_deg is None and s.score_deg is None
    assert (r.camera.width, r.camera.height, r.camera.azimuth) == (320, 240, 0.0)  # defaults


def test_a_result_without_a_fits_keypoints_or_a_segments_frames(doc):
    doc["summary"]["fit"] = {k: doc["summary"]["fit"][k] for k in
                             ("region_mismatch_median", "region_mismatch_per_frame",
                              "poor_frames")}  # fmt: skip
    doc["segments"][1]["bone_uncertainty_deg"] = []  # a segment that owns no frame
    r = Result.from_dict(doc)
    assert r.summary.fit is not None and r.summary.fit.keypoint_worst_per_frame is None
    assert r.summary.fit.keypoint_off_frames is None
    assert r.segments[1].bone_uncertainty_deg is None


def test_a_result_without_frames_has_empty_arrays(doc):
    doc["frames"], doc["segments"] = [], []
    r = Result.from_dict(doc)
    assert r.joints_3d.shape == (0, 17, 3) and r.bone_errors_deg.shape == (0, 16)
    assert r.posture_error_deg.shape == (0,) and r.score_deg is None


def test_a_frame_without_candidates(doc):
    doc["frames"][0]["candidates"] = []
    assert Result.from_dict(doc).frames[0].candidates.shape == (0, 17, 3)


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d.pop("frames"), r"^result \(root\): missing key 'frames'$"),
        (lambda d: d.pop("camera"), r"^result \(root\): missing key 'camera'$"),
        (lambda d: d["frames"][2].pop("joints_3d"), r"^result frames/2: missing key 'joints_3d'$"),
        (lambda d: d["frames"][2]["joints_3d"].pop(),
         r"^result frames/2/joints_3d: expected shape \(17, 3\), got \(16, 3\)$"),
        (lambda d: d["frames"][0].update(t="0"), r"frames/0/t: expected an integer, got str '0'"),
        (lambda d: d["frames"][0].update(t=True), r"frames/0/t: expected an integer"),
        (lambda d: d["frames"][1].update(posture_error_deg=None),
         r"frames/1/posture_error_deg: expected a number, got NoneType None"),
        (lambda d: d["frames"][0].update(selected=5),
         r"frames/0/selected: 5 is not an index into 2 candidates"),
        (lambda d: d["frames"][4].update(image_best=-1), r"frames/4/image_best: -1 is not an"),
        (lambda d: d["frames"][0]["candidates"][1].pop(),
         r"frames/0/candidates: expected numbers of shape \(K, 17, 3\)"),
        (lambda d: d["frames"][0]["bone_errors_deg"].__setitem__(3, None),
         r"frames/0/bone_errors_deg: expected numbers of shape \(16,\)"),
        (lambda d: d["frames"][0].update(joints_2d="none"), r"frames/0/joints_2d: expected a list"),
        (lambda d: d["frames"][0].update(flags="image_misfit"), r"frames/0/flags: expected a list"),
        (lambda d: d["frames"][0]["flags"].append(3), r"frames/0/flags/\d+: expected a string"),
        (lambda d: d["frames"][4]["image_best_joints_2d"].pop(),
         r"frames/4/image_best_joints_2d: expected shape \(17, 2\), got \(16, 2\)"),
        (lambda d: d["frames"][4]["bone_error_range_deg"].pop(),
         r"frames/4/bone_error_range_deg: expected shape \(16, 2\)"),
        (lambda d: d["segments"][1].update(bone_mean_errors_deg=[1.0] * 15),
         r"segments/1/bone_mean_errors_deg: expected shape \(16,\), got \(15,\)"),
        (lambda d: d["segments"][0].pop("performer_end"),
         r"segments/0: missing key 'performer_end'"),
        (lambda d: d["segments"][0].update(name=3), r"segments/0/name: expected a string"),
        (lambda d: d["segments"][0].update(boundary_found="yes"),
         r"segments/0/boundary_found: expected true or false"),
        (lambda d: d["video"].update(fps="30"), r"video/fps: expected a number, got str '30'"),
        (lambda d: d["reference"].pop("name"), r"reference: missing key 'name'"),
        (lambda d: d["camera"].pop("scale"), r"camera: missing key 'scale'"),
        (lambda d: d.update(version=2), r"version: expected 1, got 2"),
        (lambda d: d["joints"].reverse(), r"joints: expected \['hip'"),
        (lambda d: d["timing_s"].update(stage="x"), r"timing_s/stage: expected a number"),
        (lambda d: d.update(segments={}), r"segments: expected a list, got dict"),
        (lambda d: d.update(summary=[]), r"summary: expected an object, got list"),
        (lambda d: d["summary"].update(messages=[None]), r"summary/messages/0: expected a str"),
        (lambda d: d["summary"]["fit"].pop("poor_frames"),
         r"summary/fit: missing key 'poor_frames'"),
        (lambda d: d["summary"]["fit"]["keypoint_worst_per_frame"].__setitem__(0, "far"),
         r"summary/fit/keypoint_worst_per_frame: expected numbers"),
    ],
)  # fmt: skip
def test_malformed_documents_are_refused_naming_the_key(doc, mutate, match):
    bad = copy.deepcopy(doc)
    mutate(bad)
    with pytest.raises(InvalidInput, match=match):
        Result.from_dict(bad)


def test_read_result_refuses_what_is_not_a_result(tmp_path):
    with pytest.raises(InvalidInput, match="does not exist"):
        read_result(tmp_path / "nope.json")
    (tmp_path / "bad.json").write_text("[")
    with pytest.raises(InvalidInput, match="not valid JSON"):
        read_result(tmp_path / "bad.json")
    (tmp_path / "list.json").write_text(json.dumps([1, 2]))
    with pytest.raises(InvalidInput, match=r"result \(root\): expected an object, got list"):
        read_result(tmp_path / "list.json")


@pytest.mark.slow
def test_the_engines_own_result_reads_back(tmp_path, cmu_bvh):
    """The whole pipeline (fast preset, 12 frames) and the reader agree on every key."""
    from engine.io.encode import write_video
    from engine.io.video import read_video
    from engine.pipeline import analyze
    from engine.settings import Settings
    from tests.conftest import BENCH_CASES

    source = BENCH_CASES / "P1_warp_64_29" / "video.mp4"
    if not source.exists():
        pytest.skip("../shared/bench/cases is not beside the clone")
    v = read_video(source, height=0, max_frames=60)
    clip = tmp_path / "clip.mp4"
    write_video(clip, v.frames[::5], v.fps / 5)
    doc = analyze(cmu_bvh, clip, Settings.from_dict({"preset": "fast"}))
    r = read_result(write_result(doc, tmp_path / "result.json"))
    n = len(doc["frames"])
    assert r.joints_3d.shape == (n, 17, 3) and r.joints_2d.shape == (n, 17, 2)
    assert r.bone_errors_deg.shape == (n, 16) and r.camera.height == v.frames.shape[1]
    assert all(f.bone_error_range_deg is not None for f in r.frames)
    assert all((f.image_best is None) == (f.image_best_joints_2d is None) for f in r.frames)
    assert any(s.bone_uncertainty_deg is not None for s in r.segments)
    fit = r.summary.fit
    assert fit is not None and fit.region_mismatch_per_frame.shape == (n,)
    assert r.summary.status == doc["summary"]["status"]
