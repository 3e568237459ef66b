"""The resumable pipeline (prepare -> candidates -> select) on a tiny synthetic case."""

from __future__ import annotations

import dataclasses
import time

import numpy as np
import pytest

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.io.bvh import write_bvh
from engine.io.case import write_case
from engine.io.result import validate_result
from engine.pipeline import (
    CandidateChunk,
    Prepared,
    all_candidates,
    analyze,
    candidates,
    prepare,
    select,
)
from engine.settings import Settings
from engine.stages.selection import SelectionSettings
from engine.synth import SynthSettings, synthesize
from engine.types import Motion, Segments
from tests.synthetic import StubReference, swing_joints

#: Small and fast: stages 0-2 as configured, stage 3 with few samples.
SETTINGS = {
    "preset": "fast",
    "chunk_frames": 8,
    "candidates": {"n_samples": 8, "n_iterations": 2, "refine_sweeps": 1, "n_candidates": 4},
}
S = Settings.from_dict(SETTINGS)


@pytest.fixture(scope="module")
def case_dir(tmp_path_factory):
    """A 60 fps arm-and-leg swing, filmed at 15 fps (160 x 120) with one wrong segment."""
    shape = BodyShape.default(1.75)
    T = 60
    joints = swing_joints(shape, T)
    folder = tmp_path_factory.mktemp("case")
    bvh = write_bvh(folder / "swing.bvh", joints, 60.0, shape)
    synth = synthesize(
        StubReference(Motion(joints=joints, fps=60.0, name="swing"), shape),
        settings=SynthSettings(
            fps=15.0,
            width=160,
            height=120,
            warp_strength=0.2,
            n_wrong=1,
            parts_per_wrong=1,
            noise_sigma=2.0,
        ),  # fmt: skip
        rng=np.random.default_rng(3),
        segments=Segments(starts=(0, 30), end=59),
    )
    written = write_case(synth, folder / "case", bvh)
    return written


@pytest.fixture(scope="module")
def prepared(case_dir) -> Prepared:
    return prepare(case_dir["reference"], case_dir["video"], S)


def _same(a, b) -> None:
    for f in ("reference_joints", "silhouettes", "edges", "C", "rotations"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    np.testing.assert_allclose(a.shape.radii, b.shape.radii)
    np.testing.assert_allclose(a.shape.offsets, b.shape.offsets)
    assert a.camera.to_dict() == b.camera.to_dict()
    assert a.segments == b.segments and a.flags == b.flags and a.video == b.video
    for f in ("keypoints", "keypoint_confidence"):
        np.testing.assert_array_equal(getattr(a, f), getattr(b, f), err_msg=f)
    assert a.perception_model == b.perception_model
    assert a.framing == b.framing


def test_prepared_round_trip(prepared, tmp_path) -> None:
    prepared.save(tmp_path / "prepared.npz")
    _same(prepared, Prepared.load(tmp_path / "prepared.npz"))
    assert prepared.framing == ()  # the synthetic performer is whole and large in the picture


def test_what_the_first_frame_shows_reaches_the_result(prepared, tmp_path) -> None:
    cut = dataclasses.replace(prepared, framing=("Your feet are out of the picture: step back.",))
    cut.save(tmp_path / "prepared.npz")
    back = Prepared.load(tmp_path / "prepared.npz")
    _same(cut, back)
    doc = select(back, [candidates(back, range(back.n_frames), S)], S)
    assert doc["summary"]["messages"][-1] == (
        "At the start of the video, your feet are out of the picture: step back."
    )


def test_initial_postures_are_the_turned_and_the_plain_reference(prepared) -> None:
    init = prepared.initial_postures(range(prepared.n_frames))
    assert init.shape == (prepared.n_frames, 2, 17, 3)
    ref = prepared.reference_joints[prepared.C]
    np.testing.assert_allclose(init[:, 1], ref)
    np.testing.assert_allclose(init[:, 0, 0], ref[:, 0])  # turned about the hip
    turned = init[:, 0] - ref[:, :1]
    np.testing.assert_allclose(turned, (ref - ref[:, :1]) @ prepared.rotations.transpose(0, 2, 1))


def test_candidate_chunk_round_trip_and_select(prepared, tmp_path) -> None:
    chunks = [candidates(prepared, r, S) for r in prepared.chunks(2)]
    for i, c in enumerate(chunks):
        assert len(c.candidates) == len(c.d_s) == len(c.frames)
        assert all(len(k) == len(d) for k, d in zip(c.candidates, c.d_s, strict=True))
        c.save(tmp_path / f"c{i}.npz")
        back = CandidateChunk.load(tmp_path / f"c{i}.npz")
        np.testing.assert_array_equal(back.frames, c.frames)
        for k0, k1, d0, d1 in zip(c.candidates, back.candidates, c.d_s, back.d_s, strict=True):
            np.testing.assert_array_equal(k0, k1)
            np.testing.assert_array_equal(d0, d1)
        assert back.flags == c.flags
    doc = select(prepared, chunks[::-1], S)  # any order
    validate_result(doc)
    with pytest.raises(InvalidInput, match="cover every video frame"):
        select(prepared, chunks[:1], S)


def test_candidates_do_not_depend_on_the_chunking(prepared) -> None:
    # one chunk or three: every frame gets the same candidates (per-frame random streams)
    whole = candidates(prepared, range(2, 8), S)
    parts = [candidates(prepared, r, S) for r in (range(2, 3), range(3, 6), range(6, 8))]
    cut = [k for c in parts for k in c.candidates]
    assert len(cut) == len(whole.candidates) == 6
    for a, b in zip(whole.candidates, cut, strict=True):
        np.testing.assert_array_equal(a, b)
    # the previous frame's candidates as extra starts (6.7) still work, threaded within a chunk
    prev = {**SETTINGS, "candidates": {**SETTINGS["candidates"], "n_prev": 3}}
    assert candidates(prepared, range(2, 8), Settings.from_dict(prev)).frames.tolist() == list(
        range(2, 8)
    )


def test_key_frames_do_not_depend_on_the_chunking_either(prepared) -> None:
    # frames between key frames start from their key frames' solutions: a chunk that cuts
    # between two key frames estimates them too, so each frame's candidates stay the same
    keyed = Settings.from_dict({**SETTINGS, "candidates": {**SETTINGS["candidates"], "key_gap": 3}})
    whole = candidates(prepared, range(prepared.n_frames), keyed)
    parts = [candidates(prepared, r, keyed) for r in (range(0, 4), range(4, 5), range(5, 11))]
    parts.append(candidates(prepared, range(11, prepared.n_frames), keyed))
    cut = [k for c in parts for k in c.candidates]
    assert [int(t) for c in parts for t in c.frames] == list(range(prepared.n_frames))
    for a, b in zip(whole.candidates, cut, strict=True):
        np.testing.assert_array_equal(a, b)
    # and they are not the full search's: the frames between key frames were estimated apart
    full = candidates(prepared, range(prepared.n_frames), S)
    same = [np.array_equal(a, b) for a, b in zip(whole.candidates, full.candidates, strict=True)]
    assert same[0] and same[-1] and not all(same)


def test_stage_3_on_two_processes_gives_the_same_candidates(prepared) -> None:
    one = all_candidates(prepared, S, workers=1)
    progress: list[float] = []
    two = all_candidates(prepared, S, workers=2, on_progress=lambda _, f: progress.append(f))
    assert [c.frames.tolist() for c in two] == [c.frames.tolist() for c in one]
    assert len(one) >= 2  # there was something to share
    for a, b in zip(one, two, strict=True):
        for k0, k1, d0, d1 in zip(a.candidates, b.candidates, a.d_s, b.d_s, strict=True):
            np.testing.assert_array_equal(k0, k1)
            np.testing.assert_array_equal(d0, d1)
        assert a.flags == b.flags
    assert progress == sorted(progress) and progress[-1] == 1.0


def test_analyze_gives_a_valid_result(case_dir) -> None:
    import json

    doc = analyze(case_dir["reference"], case_dir["video"], S)
    validate_result(doc)
    json.dumps(doc, allow_nan=False)  # a browser's JSON.parse refuses NaN
    n = len(doc["frames"])
    assert n == doc["video"]["frames"] >= 10
    ref = [f["reference_frame"] for f in doc["frames"]]
    assert ref == sorted(ref)
    for f in doc["frames"]:
        assert 0 <= f["selected"] < len(f["candidates"])


def test_frames_the_video_does_not_confirm_are_flagged():
    from engine.stages.assessment import flag_image_misfit
    from engine.stages.selection import Selection

    n = 4
    sel = Selection(
        performer_segments=Segments((0,), n - 1), C=np.arange(n), selected=np.array([0, 1, 0, 1]),
        joints=np.zeros((n, 17, 3)), posture_error=np.zeros(n), bone_errors=np.zeros((n, 16)),
        flags=((),) * n, segments=(), messages=(),
    )  # fmt: skip
    d_s = [np.array([0.30, 0.9]), np.array([0.9, 0.35]), np.array([0.6, 0.2]), np.array([0, 0.5])]
    out = flag_image_misfit(sel, d_s, 0.1)
    assert [("image_misfit" in f) for f in out.flags] == [False, False, True, True]
    assert any("2 of 4 frames" in m for m in out.messages)
    assert flag_image_misfit(sel, d_s, 1.0) is sel


def test_candidates_command_runs_stages_0_to_3_and_writes_a_scorable_result(
    case_dir, tmp_path, capsys
) -> None:
    import json

    from engine.cli import main

    out, png = tmp_path / "cand.json", tmp_path / "cand.png"
    args = [case_dir["reference"], case_dir["video"], "--frames", "3:6", "--fast"]
    assert main(["candidates", *args, "--out", str(out), "--plot", str(png)]) == 0
    doc = json.loads(out.read_text())
    assert [f["t"] for f in doc["frames"]] == [3, 4, 5]
    for f in doc["frames"]:
        assert 0 <= f["selected"] < len(f["candidates"])
        assert f["joints_3d"] == f["candidates"][f["selected"]]
        assert len(f["bone_errors_deg"]) == 16 and len(f["joints_2d"]) == 17
    # C from stage 2 follows the truth's correspondence within a few reference frames
    truth = json.loads(open(case_dir["truth"]).read())
    true_c = [truth["frames"][f["t"]]["reference_frame"] for f in doc["frames"]]
    err = [abs(f["reference_frame"] - c) for f, c in zip(doc["frames"], true_c, strict=True)]
    assert max(err) <= 8, err
    assert png.stat().st_size > 5_000
    # with the truth, C(t') is the truth's
    assert main(["candidates", *args, "--out", str(out), "--truth", case_dir["truth"]]) == 0
    doc = json.loads(out.read_text())
    for f in doc["frames"]:
        assert f["reference_frame"] == round(truth["frames"][f["t"]]["reference_frame"])


def test_candidates_command_bad_input_is_one_line_error(case_dir, tmp_path, capsys) -> None:
    from engine.cli import main

    out = str(tmp_path / "c.json")
    assert main(["candidates", case_dir["reference"], "missing.mp4", "--out", out]) == 2
    assert "does not exist" in capsys.readouterr().err
    bad = ["candidates", case_dir["reference"], case_dir["video"], "--out", out, "--fast"]
    assert main([*bad, "--frames", "x:y"]) == 2
    assert "--frames" in capsys.readouterr().err
    assert main([*bad, "--frames", "500:600"]) == 2
    assert "selects no frame" in capsys.readouterr().err


def test_analyze_command_refuses_a_worker_count_below_one(case_dir, tmp_path, capsys) -> None:
    from engine.cli import main

    out = tmp_path / "r.json"
    cmd = ["analyze", case_dir["reference"], case_dir["video"], "--out", str(out), "--quiet"]
    assert main([*cmd, "--workers", "0"]) == 2
    assert "--workers must be >= 1" in capsys.readouterr().err
    assert not out.exists()


def test_analyze_with_one_worker_uses_one_core(case_dir, tmp_path) -> None:
    # --workers bounds the cores: no stage-3 process pool, and no stage 0-2 threads either
    import threading

    from engine.cli import main

    seen: set[str] = set()
    done = threading.Event()

    def watch() -> None:
        while not done.is_set():
            seen.update(t.name for t in threading.enumerate())
            time.sleep(0.005)

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        out = tmp_path / "r.json"
        cmd = ["analyze", case_dir["reference"], case_dir["video"], "--out", str(out), "--quiet",
               "--fast", "--workers", "1"]  # fmt: skip
        assert main(cmd) == 0 and out.exists()
        assert not {n for n in seen if n.startswith(("coach-stage", "coach-background"))}, seen
        # the watcher does see the stages' threads when they run
        from engine.threads import map_in_threads

        assert list(map_in_threads(lambda i: time.sleep(0.05) or i, range(4), 2)) == [0, 1, 2, 3]
        time.sleep(0.02)
        assert any(n.startswith("coach-stage") for n in seen), seen
    finally:
        done.set()
        watcher.join()


def test_a_video_with_nobody_in_it_fails_with_a_plain_message(case_dir, tmp_path) -> None:
    from engine.errors import RegistrationFailed
    from engine.io.encode import write_video

    rng = np.random.default_rng(0)
    wall = rng.integers(60, 200, (120, 160, 3), dtype=np.uint8)
    frames = np.repeat(wall[None], 16, 0)
    frames = np.clip(frames + rng.normal(0, 1.5, frames.shape), 0, 255).astype(np.uint8)
    write_video(tmp_path / "empty.mp4", frames, 15.0)
    with pytest.raises(RegistrationFailed, match="could not find a person"):
        prepare(case_dir["reference"], tmp_path / "empty.mp4", S)


def test_a_region_that_is_not_a_body_ends_poor_fit_not_ok(prepared) -> None:
    """Stage 0's region replaced by a blob of wall: no posture explains it, and the result
    says so instead of reporting errors as the performer's."""
    import dataclasses

    from engine.stages.assessment import assess_fit

    sil = np.zeros_like(prepared.silhouettes)
    sil[:, 10:110, 20:140] = True  # a rectangle of "body" filling the picture
    bad = dataclasses.replace(prepared, silhouettes=sil, edges=np.zeros_like(sil))
    chunks = [candidates(bad, r, S) for r in bad.chunks(1)]
    doc = select(bad, chunks, S)
    assert doc["summary"]["status"] == "poor_fit"
    assert "separate you from the background" in doc["summary"]["messages"][0]
    # the real regions fit: the same check leaves the status alone
    good = select(prepared, [candidates(prepared, r, S) for r in prepared.chunks(1)],
                  S)  # fmt: skip
    assert good["summary"]["status"] != "poor_fit"
    assert good["summary"]["fit"]["region_mismatch_median"] < 0.3
    doc2 = {"summary": {"status": "ok", "messages": []}}
    lax = SelectionSettings(poor_fit_region=1.0, poor_fit_frames=1.0)
    assess_fit(doc2, np.stack([c[0] for c in chunks[0].candidates]), bad, lax)
    assert doc2["summary"]["status"] == "ok"  # the thresholds decide


def test_reported_motion_that_leaves_the_keypoints_ends_poor_fit(prepared) -> None:
    """Where the reported postures leave the detected body in many frames (a video of
    several repetitions against one), the result says so."""
    import dataclasses
    import json

    from engine.stages.assessment import assess_fit

    postures = prepared.reference_joints[prepared.C]
    kp = prepared.camera.project(postures)
    conf = np.ones(kp.shape[:2])
    good = dataclasses.replace(prepared, keypoints=kp, keypoint_confidence=conf,
                               keypoint_offsets=np.zeros((17, 2)))  # fmt: skip
    doc = {"summary": {"status": "ok", "messages": []}}
    assess_fit(doc, postures, good, SelectionSettings())
    assert doc["summary"]["status"] == "ok"
    assert doc["summary"]["fit"]["keypoint_off_frames"] == 0
    moved = kp.copy()
    height = np.ptp(kp[0, :, 1])
    moved[::2, 3] += [0.0, 0.6 * height]  # an ankle far below in half the frames
    bad = dataclasses.replace(good, keypoints=moved)
    doc = {"summary": {"status": "ok", "messages": []}}
    assess_fit(doc, postures, bad, SelectionSettings())
    assert doc["summary"]["status"] == "poor_fit"
    assert "several repetitions" in doc["summary"]["messages"][0]
    # a frame where the pose model saw nobody: null, not NaN (JSON has none)
    blind = conf.copy()
    blind[1] = 0.0
    doc = {"summary": {"status": "ok", "messages": []}}
    assess_fit(doc, postures, dataclasses.replace(good, keypoint_confidence=blind),
               SelectionSettings())  # fmt: skip
    assert doc["summary"]["fit"]["keypoint_worst_per_frame"][1] is None
    json.dumps(doc, allow_nan=False)


def test_the_thesis_preset_runs_without_the_pose_model(case_dir) -> None:
    import json

    p = prepare(case_dir["reference"], case_dir["video"],
                Settings.from_dict({**SETTINGS, "preset": "thesis"}))  # fmt: skip
    assert p.keypoints is None and p.perception_model == ""
    # and still finds the timing as it did before the pose model (the figure of
    # test_candidates_command_runs_stages_0_to_3_and_writes_a_scorable_result)
    truth = json.loads(open(case_dir["truth"]).read())
    true_c = np.array([f["reference_frame"] for f in truth["frames"]])
    assert np.abs(p.C - true_c).max() <= 8
    q = prepare(case_dir["reference"], case_dir["video"], S)
    assert q.keypoints is not None and q.keypoints.shape == (q.n_frames, 17, 2)
    assert q.perception_model.startswith("mediapipe")


def test_an_analysis_against_a_reference_from_takes_reports_the_experts_range(case_dir, tmp_path):
    """Seed 002 end to end: three takes (the swing and two warps of it) -> `write_model` ->
    the analysis reads the domain beside the BVH and adds z-scores against the spread."""
    from engine.commands.reference_build import write_model
    from engine.reference.action_model import Take, build_action_model
    from engine.reference.domain import find_domain
    from engine.reference.synchronisation import interpolate

    shape = BodyShape.default(1.75)
    joints = swing_joints(shape, 60)
    u = np.linspace(0.0, 1.0, 60)
    takes = [Take("swing", joints, 60.0, shape)] + [
        Take(f"w{a}", interpolate(joints, (u + a * np.sin(2 * np.pi * u) / 6.3) * 59) +
             np.random.default_rng(k).normal(0, 0.01, joints.shape), 60.0, shape)
        for k, a in enumerate((0.3, -0.3))
    ]  # fmt: skip
    bvh, _, _ = write_model(build_action_model(takes), tmp_path / "swing3", sport="test")
    domain = find_domain(bvh)
    assert domain is not None and domain.bone_sd is not None
    doc = analyze(bvh, case_dir["video"], S, domain=domain)
    validate_result(doc)
    assert all(len(f["bone_z"]) == 16 and f["expert_spread_deg"] >= 5.0 for f in doc["frames"])
    share = doc["summary"]["outside_expert_range_share"]
    assert share == pytest.approx(np.mean([f["outside_expert_range"] for f in doc["frames"]]))
    assert all(isinstance(s["within_expert_range"], bool) for s in doc["segments"])
    assert doc["domain"]["variation"]["takes"] == ["swing", "w0.3", "w-0.3"]


def test_the_expert_is_drawn_where_the_performer_stands(case_dir) -> None:
    """Where the synthetic performer holds the expert's posture (true error under 2 deg), the
    expert's projected joints land on the performer's true joints within a few pixels."""
    import json

    doc = analyze(case_dir["reference"], case_dir["video"], S)
    truth = {f["t"]: f for f in json.load(open(case_dir["truth"]))["frames"]}
    same = [f for f in doc["frames"] if truth[f["t"]]["posture_error_deg"] < 2.0]
    assert len(same) >= 5
    off = [np.linalg.norm(np.subtract(f["expert_joints_2d"], truth[f["t"]]["joints_2d"]), axis=1)
           for f in same]  # fmt: skip
    height = doc["video"]["height"]
    assert np.median(off) < 0.03 * height  # 3.6 px on 120 rows
