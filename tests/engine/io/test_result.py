"""The result JSON: built from stage 4, valid against the schema, and invalid ones refused."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from engine.errors import InvalidInput
from engine.io.result import build_result, read_result_doc, validate_result, write_result
from engine.reference.domain import parse_domain
from engine.render.camera import Camera
from engine.stages.selection import select_and_refine
from engine.types import Segments

BASE = np.array([
    [0, 1, 0], [0.1, 1, 0], [0.1, 0.55, 0], [0.1, 0.1, 0], [-0.1, 1, 0], [-0.1, 0.55, 0],
    [-0.1, 0.1, 0], [0, 1.2, 0], [0, 1.4, 0], [0.18, 1.45, 0], [0.45, 1.45, 0], [0.7, 1.45, 0],
    [-0.18, 1.45, 0], [-0.45, 1.45, 0], [-0.7, 1.45, 0], [0, 1.55, 0], [0, 1.75, 0],
], float)  # fmt: skip


def _reference(n: int = 41) -> np.ndarray:
    ang = np.linspace(0, np.pi / 2, n)
    ref = np.repeat(BASE[None], n, 0)
    for k, r in ((13, 0.27), (14, 0.52)):  # right arm swings up
        ref[:, k] = BASE[12] + r * np.stack([-np.cos(ang), np.sin(ang), 0 * ang], -1)
    return ref


@pytest.fixture
def result_doc(rng) -> dict:
    ref = _reference()
    C0 = np.arange(0, 41, 4)
    cands = [np.stack([ref[c], ref[c] + rng.normal(0, 0.02, (17, 3))]) for c in C0]
    sel = select_and_refine(cands, ref, Segments((0, 20), 40, ("a", "b")), C0, fps_ratio=4.0)
    cam = Camera(scale=100.0, cx=160.0, cy=200.0)
    return build_result(
        reference_name="arm", reference_frames=42, reference_fps=120.0,
        video={"frames": 11, "fps": 30.0, "width": 320, "height": 240}, camera=cam,
        selection=sel, candidates=cands, timing_s={"selection": 0.01},
        domain=parse_domain({"segment_names": ["lift", "hold"], "default_tolerance_deg": 2}),
        reference_frame_offset=1,
    )  # fmt: skip


def test_built_result_is_valid_and_round_trips(result_doc, tmp_path):
    validate_result(result_doc)
    assert result_doc["frames"][0]["reference_frame"] == 1  # offset for the T-pose frame
    assert result_doc["frames"][-1]["reference_frame"] == 41
    assert [s["name"] for s in result_doc["segments"]] == ["lift", "hold"]
    assert result_doc["frames"][3]["joints_2d"][0] == [160.0, 100.0]  # hip at y = 1 m
    assert result_doc["timing_s"]["total"] == pytest.approx(0.01)
    assert result_doc["summary"]["status"] == "ok"
    path = write_result(result_doc, tmp_path / "out" / "result.json")
    assert read_result_doc(path) == json.loads(json.dumps(result_doc))
    assert not list(path.parent.glob("*.tmp"))


@pytest.mark.parametrize(
    ("mutate", "match"),
    [
        (lambda d: d.pop("frames"), "'frames' is a required property"),
        (lambda d: d["frames"][2]["joints_3d"].pop(), r"frames/2/joints_3d"),
        (lambda d: d["frames"][0].update(selected=5), r"frames/0/selected: 5 is not an index"),
        (lambda d: d["frames"][0].update(image_best=2), r"frames/0/image_best: 2 is not an"),
        (lambda d: d["frames"][1].update(posture_error_deg=-1.0), r"frames/1/posture_error_deg"),
        (lambda d: d["segments"][0].update(bone_mean_errors_deg=[1.0] * 15), r"segments/0/bone"),
        (lambda d: d["segments"][1].update(performer_end=0), r"segments/1: a segment ends"),
        (lambda d: d.update(version=2), "version"),
        (lambda d: d["joints"].reverse(), "joints"),
        (lambda d: d["timing_s"].update(stage=-3), "timing_s/stage"),
    ],
)
def test_invalid_results_fail(result_doc, mutate, match):
    bad = copy.deepcopy(result_doc)
    mutate(bad)
    with pytest.raises(InvalidInput, match=match):
        validate_result(bad)


def test_a_poor_fit_result_with_its_repetitions_is_written(result_doc, tmp_path):
    """Every status the engine gives must pass the schema: ``coach analyze`` could not
    write a ``poor_fit`` result."""
    doc = copy.deepcopy(result_doc)
    doc["summary"].update(
        status="poor_fit",
        repetitions=[{"start": 4, "end": 18, "start_s": 0.8, "end_s": 3.6}],
    )
    write_result(doc, tmp_path / "result.json")
    doc["summary"]["repetitions"][0].pop("end_s")
    with pytest.raises(InvalidInput, match="end_s"):
        validate_result(doc)


def test_read_result_errors(tmp_path):
    with pytest.raises(InvalidInput, match="does not exist"):
        read_result_doc(tmp_path / "nope.json")
    (tmp_path / "bad.json").write_text("[")
    with pytest.raises(InvalidInput, match="not valid JSON"):
        read_result_doc(tmp_path / "bad.json")


def test_candidate_count_must_match(result_doc, rng):
    ref = _reference()
    C0 = np.arange(0, 41, 4)
    cands = [ref[c][None] for c in C0]
    sel = select_and_refine(cands, ref, Segments((0,), 40), C0)
    with pytest.raises(InvalidInput, match="candidates"):
        build_result(
            reference_name="x", reference_frames=41, reference_fps=120.0,
            video={"frames": 11, "fps": 30.0, "width": 320, "height": 240},
            camera=Camera(scale=1.0), selection=sel, candidates=cands[:-1], timing_s={},
        )  # fmt: skip


def test_report_is_self_contained_and_says_what_one_camera_measures(result_doc):
    from engine.report import ONE_CAMERA_NOTE, build_report_html

    page = build_report_html(result_doc)
    assert page.startswith("<!doctype html>") and page.count("<img") >= 2
    assert "src=\"http" not in page and "href=" not in page  # nothing loaded from elsewhere
    assert ONE_CAMERA_NOTE in page
    assert "lift" in page and "hold" in page  # the domain file's segment names


def test_report_plot_shades_the_frames_the_video_does_not_confirm(result_doc):
    import copy

    from engine.report import _error_plot_png

    flagged = copy.deepcopy(result_doc)
    for f in flagged["frames"]:
        f["flags"] = [x for x in f["flags"] if x != "image_misfit"]
    plain = _error_plot_png(flagged)
    flagged["frames"][1]["flags"].append("image_misfit")
    assert _error_plot_png(flagged) != plain


def test_misfit_frames_carry_the_candidate_the_video_fits_best(result_doc):
    from engine.stages.assessment import add_image_best

    doc = copy.deepcopy(result_doc)
    for f in doc["frames"]:
        f["flags"] = [x for x in f["flags"] if x != "image_misfit"]
    doc["frames"][2]["flags"].append("image_misfit")
    cands = [np.array(f["candidates"]) for f in doc["frames"]]
    d_s = [np.array([0.3, 0.1]) for _ in cands]  # the second candidate fits the video better
    cam = Camera(scale=100.0, cx=160.0, cy=200.0)
    add_image_best(doc, cands, d_s, cam)
    validate_result(doc)
    assert [("image_best" in f) for f in doc["frames"]] == [t == 2 for t in range(11)]
    assert doc["frames"][2]["image_best"] == 1
    np.testing.assert_allclose(doc["frames"][2]["image_best_joints_2d"],
                               cam.project(cands[2][1]), atol=0.01)  # fmt: skip


def test_skeleton_drawing_adds_what_the_video_suggests_dashed(result_doc):
    from engine.report import MISFIT_RGB, draw_skeleton

    f = result_doc["frames"][3]
    grey = np.full((240, 320, 3), 128, np.uint8)
    j2, errs = np.asarray(f["joints_2d"]), np.asarray(f["bone_errors_deg"])
    plain = draw_skeleton(grey, j2, errs)

    def amber(img: np.ndarray) -> int:
        return int((np.abs(img.astype(int) - MISFIT_RGB).max(-1) <= 6).sum())

    assert amber(plain) == 0
    drawn = draw_skeleton(grey, j2, errs, video_suggests=j2 + [30.0, 0.0])
    assert amber(drawn) > 30
    np.testing.assert_array_equal(grey, 128)  # the frame itself is left alone


def test_a_reference_with_the_experts_variation_adds_z_scores(rng):
    ref = _reference()
    C0 = np.arange(0, 41, 4)
    cands = [np.stack([ref[c], ref[c] + rng.normal(0, 0.02, (17, 3))]) for c in C0]
    sel = select_and_refine(cands, ref, Segments((0, 20), 40, ("a", "b")), C0, fps_ratio=4.0)
    sd = np.full((42, 16), 10.0)
    sd[21:, 12] = 0.0  # the expert never varies the right forearm in the second segment
    domain = parse_domain({"variation": {"bone_sd_deg": sd.tolist(), "sd_floor_deg": 0.5,
                                         "z_limit": 3}})  # fmt: skip
    doc = build_result(
        reference_name="arm", reference_frames=42, reference_fps=120.0,
        video={"frames": 11, "fps": 30.0, "width": 320, "height": 240},
        camera=Camera(scale=100.0, cx=160.0, cy=200.0), selection=sel, candidates=cands,
        timing_s={}, domain=domain, reference_frame_offset=1,
    )  # fmt: skip
    validate_result(doc)
    errors = np.array([f["bone_errors_deg"] for f in doc["frames"]])
    z = np.array([f["bone_z"] for f in doc["frames"]])
    ref_frames = np.array([f["reference_frame"] for f in doc["frames"]])
    spread = np.maximum(sd[ref_frames], 0.5)
    assert np.allclose(z, errors / spread, atol=0.01)
    outside = [f["outside_expert_range"] for f in doc["frames"]]
    assert outside == list((errors / spread).max(1) > 3)
    share = doc["summary"]["outside_expert_range_share"]
    assert share == pytest.approx(np.mean(outside), abs=1e-4)
    assert any("outside the expert's own range" in m for m in doc["summary"]["messages"])
    seg = doc["segments"]
    assert all(len(s["bone_mean_z"]) == 16 for s in seg)
    assert seg[0]["within_expert_range"] == (max(seg[0]["bone_mean_z"]) <= 3)
    assert doc["domain"]["variation"]["frames"] == 42
