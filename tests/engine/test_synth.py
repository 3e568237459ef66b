"""Synthetic performers: exact truth, monotone warp, right and wrong segments, playable video."""

from __future__ import annotations

import json
import subprocess
import sys

import cv2
import numpy as np
import pytest

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.render.camera import Camera
from engine.synth import SynthSettings, synthesize
from engine.types import Motion, Segments
from tests.conftest import SHARED
from tests.synthetic import StubReference, swing_joints

SCORE = SHARED / "bench" / "score.py"
AMP = 25.0


@pytest.fixture(scope="module")
def reference() -> StubReference:
    """A 90-frame, 60 fps swing of arms and legs built with forward kinematics."""
    shape = BodyShape.default(1.75)
    T = 90
    joints = swing_joints(shape, T, sway_m=0.2, travel_m=0.3)
    return StubReference(Motion(joints=joints, fps=60.0, name="swing"), shape)


SEGMENTS = Segments(starts=(0, 30, 60), end=89)


@pytest.fixture(scope="module")
def case(reference):
    settings = SynthSettings(
        fps=20.0,
        width=160,
        height=120,
        warp_strength=0.3,
        error_deg=AMP,
        n_wrong=1,
        parts_per_wrong=1,
        noise_sigma=3.0,
    )
    return synthesize(
        reference, settings=settings, rng=np.random.default_rng(11), segments=SEGMENTS
    )


def test_truth_errors_zero_in_right_segments_and_amplitude_in_wrong(case):
    err = np.array([f["bone_errors_deg"] for f in case.truth["frames"]])
    seg = np.array([f["reference_segment"] for f in case.truth["frames"]])
    wrong = [s["wrong"] for s in case.truth["segments"]]
    assert sum(wrong) == 1
    for k, is_wrong in enumerate(wrong):
        e = err[seg == k]
        assert len(e) > 0
        if is_wrong:
            # one part turned AMP deg about an axis normal to its bone, ramped in and out
            assert e.max() == pytest.approx(AMP, abs=0.05)
            assert e[0].max() < 0.5 * AMP and e[-1].max() < 0.5 * AMP
        else:
            assert e.max() < 1e-3


def test_warp_is_monotone_and_pinned(case, reference):
    warp = np.asarray(case.truth["warp"])
    assert warp[0] == 0.0 and warp[-1] == reference.motion.frames - 1
    assert np.all(np.diff(warp) > 0)
    assert len(warp) == len(case.truth["frames"]) == case.frames.shape[0]
    assert [f["reference_frame"] for f in case.truth["frames"]] == case.truth["warp"]
    # the boundaries' video times follow the warp
    for s in case.truth["segments"]:
        t = s["performer_start"]
        if t > 0:
            assert np.interp(t, np.arange(len(warp)), warp) == pytest.approx(
                s["reference_start"], abs=0.5
            )


def test_joints_2d_are_the_exact_projection(case):
    cam = Camera.from_dict(case.truth["camera"])
    j3 = np.array([f["joints_3d"] for f in case.truth["frames"]])
    j2 = np.array([f["joints_2d"] for f in case.truth["frames"]])
    np.testing.assert_allclose(cam.project(j3), j2, atol=1e-3)
    # the body fills about 80 % of the image height and stays inside it
    assert 0 <= j2[..., 0].min() and j2[..., 0].max() < 160
    assert 0 <= j2[..., 1].min() and j2[..., 1].max() < 120
    # and the rendered silhouette covers the projected hip in every frame
    u, v = np.rint(j2[:, 0]).astype(int).T
    assert np.all(case.masks[np.arange(len(u)), v, u])


def test_synthesis_is_reproducible(reference):
    settings = SynthSettings(fps=15.0, width=64, height=48, max_frames=4)
    a = synthesize(reference, settings=settings, rng=np.random.default_rng(3), segments=SEGMENTS)
    b = synthesize(reference, settings=settings, rng=np.random.default_rng(3), segments=SEGMENTS)
    c = synthesize(reference, settings=settings, rng=np.random.default_rng(4), segments=SEGMENTS)
    assert len(a.warp) == 4
    assert np.array_equal(a.frames, b.frames) and a.truth == b.truth
    assert not np.array_equal(a.frames, c.frames)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"fps": 0.0}, "fps"),
        ({"fps": -5.0}, "fps"),
        ({"noise_sigma": -1.0}, "noise_sigma"),
        ({"error_parts": ("l_nose",)}, "l_nose"),
        ({"width": 161}, "width"),
    ],
)
def test_bad_settings_raise(kwargs, match):
    with pytest.raises(InvalidInput, match=match):
        SynthSettings(**kwargs)


def test_fps_above_the_reference_is_refused(reference):
    with pytest.raises(InvalidInput, match="fps"):
        synthesize(reference, settings=SynthSettings(fps=90.0), rng=np.random.default_rng(0))


def test_coach_synth_writes_a_scorable_playable_case(cmu_bvh, tmp_path):
    from engine.cli import main

    out = tmp_path / "case"
    rc = main(
        [
            "synth",
            str(cmu_bvh),
            str(out),
            "--seed",
            "2",
            "--fps",
            "12.5",
            "--width",
            "160",
            "--height",
            "120",
            "--max-frames",
            "14",
            "--azimuth-deg",
            "30",
            "--noise-sigma",
            "2",
        ]
    )
    assert rc == 0
    truth = json.loads((out / "truth.json").read_text())
    assert (out / "reference.bvh").read_bytes() == cmu_bvh.read_bytes()
    assert len(truth["frames"]) == len(truth["warp"]) == 14
    assert truth["warp"][0] == 1.0  # the CMU T-pose frame 0 is skipped, like the public cases
    assert truth["camera"]["type"] == "orthographic" and truth["camera"]["width"] == 160

    cap = cv2.VideoCapture(str(out / "video.mp4"))
    n = 0
    while True:
        ok, frame = cap.read()
        if not ok:
            break
        assert frame.shape == (120, 160, 3)
        n += 1
    cap.release()
    assert n == 14

    res = subprocess.run(
        [sys.executable, str(SCORE), str(out), "--truth-self"],
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    m = json.loads(res.stdout.strip().splitlines()[-1])
    assert m["frames_scored"] == 14
    for key in (
        "temporal_err_ref_frames",
        "joint_2d_err_px_E2P",
        "selected_posture_err_deg",
        "bone_error_estimation_err_deg",
    ):
        assert m[key] == pytest.approx(0.0, abs=1e-5), key
