"""Stage 0's learned perception: the model ships in its package, the keypoint term is robust
and left/right-invariant, and the learned mask keeps out what the pose model says is not the
person."""

from __future__ import annotations

import json
import socket
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from engine.body.skeleton import JOINTS
from engine.errors import InvalidInput
from engine.measures import d_K
from engine.stages.perception import (
    KEYPOINT_JOINTS,
    MIRROR,
    Perception,
    facing_from_depths,
    keypoint_offsets,
    landmarks_to_joints,
    readings,
    resolve_swaps,
)
from tests.conftest import BENCH_CASES

P1 = BENCH_CASES / "P1_warp_64_29"


def test_mirror_swaps_left_and_right_only():
    for i, n in enumerate(JOINTS):
        m = JOINTS[MIRROR[i]]
        if n.startswith("l_"):
            assert m == "r_" + n[2:]
        elif n.startswith("r_"):
            assert m == "l_" + n[2:]
        else:
            assert m == n
    assert (MIRROR[MIRROR] == np.arange(len(JOINTS))).all()


def test_landmarks_map_to_our_joints():
    lm = np.arange(33 * 2, dtype=float).reshape(33, 2)
    vis = np.linspace(0.5, 1.0, 33)
    kp, conf = landmarks_to_joints(lm, vis)
    assert np.allclose(kp[JOINTS.index("l_knee")], lm[25])
    assert np.allclose(kp[JOINTS.index("r_wrist")], lm[16])
    assert np.allclose(kp[JOINTS.index("hip")], 0.5 * (lm[23] + lm[24]))
    assert np.isnan(kp[JOINTS.index("head_top")]).all() and conf[JOINTS.index("head_top")] == 0
    assert conf[JOINTS.index("neck")] == 0  # shoulders' mid-point: no weight
    assert set(np.flatnonzero(conf > 0)) == set(KEYPOINT_JOINTS)


def test_facing_from_the_face_depth():
    assert facing_from_depths(nose_z=-30.0, ears_z=0.0, torso_px=60.0) == 1
    assert facing_from_depths(nose_z=30.0, ears_z=0.0, torso_px=60.0) == -1
    assert facing_from_depths(nose_z=2.0, ears_z=0.0, torso_px=60.0) == 0


def _posture_2d(rng) -> np.ndarray:
    return rng.uniform(50, 150, (17, 2))


def test_d_K_is_zero_on_the_keypoints_and_saturates(rng):
    p = _posture_2d(rng)
    conf = np.ones(17)
    assert d_K(p[None], p, conf, tau_px=10.0)[0] == 0.0
    far = p + 1000.0
    assert d_K(far[None], p, conf, tau_px=10.0)[0] == pytest.approx(1.0)
    near = p + np.array([3.0, 4.0])  # 5 px off everywhere
    assert d_K(near[None], p, conf, tau_px=10.0)[0] == pytest.approx(0.5)


def test_d_K_ignores_missing_and_unconfident_joints(rng):
    p = _posture_2d(rng)
    kp = p.copy()
    kp[3] = np.nan
    kp[5] += 500.0  # a wild keypoint with no confidence
    conf = np.ones(17)
    conf[5] = 0.0
    assert d_K(p[None], kp, conf, tau_px=10.0)[0] == 0.0
    assert d_K(p[None], np.full((17, 2), np.nan), conf, tau_px=10.0)[0] == 0.0


def test_d_K_over_both_readings_is_invariant_to_a_swapped_detection(rng):
    postures = rng.uniform(50, 150, (20, 17, 2))
    kp = _posture_2d(rng)
    conf = rng.uniform(0.2, 1.0, 17)
    straight = d_K(postures, *readings(kp, conf), tau_px=15.0)
    swapped = d_K(postures, *readings(kp[MIRROR], conf[MIRROR]), tau_px=15.0)
    np.testing.assert_array_equal(straight, swapped)
    # a posture that matches the mirrored labels costs nothing over both readings, not over one
    assert d_K(kp[MIRROR][None], *readings(kp, conf), tau_px=15.0)[0] == 0.0
    assert d_K(kp[MIRROR][None], kp, conf, tau_px=15.0)[0] > 0.0


def test_offsets_are_measured_after_left_right_and_removed_from_both_readings(rng):
    pred = rng.uniform(50, 150, (5, 17, 2))
    off = rng.normal(0, 3, (17, 2))
    kp = pred + off
    kp[2] = kp[2][MIRROR]  # one frame's labels swapped
    conf = np.ones((5, 17))
    np.testing.assert_allclose(keypoint_offsets(kp, conf, pred), off)
    both, c = readings(kp[0], conf[0], off)
    np.testing.assert_allclose(both[0], pred[0])  # labels as given, offsets removed
    both, c = readings(kp[2], conf[2], off)
    np.testing.assert_allclose(both[1], pred[2])  # the swapped frame: its mirrored reading
    assert c.shape == (2, 17)


def test_resolve_swaps_finds_the_mirrored_frames(rng):
    pred = rng.uniform(50, 150, (6, 17, 2))
    kp = pred + rng.normal(0, 1, pred.shape)
    kp[[1, 4]] = kp[[1, 4]][:, MIRROR]
    conf = np.ones((6, 17))
    assert list(resolve_swaps(kp, pred, conf)) == [False, True, False, False, True, False]


def test_perception_arrays_round_trip():
    n, h, w = 3, 8, 10
    p = Perception(
        mask=np.full((n, h, w), 200, np.uint8), keypoints=np.zeros((n, 17, 2)),
        confidence=np.ones((n, 17)), facing=np.array([1, 0, -1], np.int8),
        detected=np.array([True, False, True]), model="m-1",
    )  # fmt: skip
    q = Perception.from_arrays(p.to_arrays())
    assert q is not None and q.model == "m-1"
    np.testing.assert_array_equal(q.facing, p.facing)
    assert Perception.from_arrays({}) is None
    assert p.person().all()


def test_the_pose_model_ships_in_its_package_and_loads_without_network():
    """The TFLite models are inside the pinned wheel; a run with every socket refused works."""
    import mediapipe

    root = Path(mediapipe.__file__).parent / "modules"
    for rel in ("pose_detection/pose_detection.tflite", "pose_landmark/pose_landmark_full.tflite"):
        assert (root / rel).stat().st_size > 100_000, rel
    code = (
        "import socket\n"
        "def refuse(*a, **k):\n"
        "    raise OSError('network disabled in this test')\n"
        "socket.socket.connect = refuse\n"
        "socket.create_connection = refuse\n"
        "import numpy as np\n"
        "from engine.stages.perception import perceive\n"
        "p = perceive(np.full((2, 96, 64, 3), 128, np.uint8))\n"
        "print(p.model, int(p.detected.sum()))\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    model, found = out.stdout.split()
    assert model.startswith("mediapipe-pose-full-0.10.")
    assert found == "0"  # a grey image shows nobody
    assert socket.socket.connect is not None


def test_bad_frames_are_refused():
    from engine.stages.perception import perceive

    with pytest.raises(InvalidInput, match="frames must be uint8"):
        perceive(np.zeros((2, 8, 8), np.uint8))


@pytest.mark.skipif(not P1.exists(), reason="public cases not beside the clone")
def test_keypoints_on_a_public_case_are_near_the_truth_after_left_right():
    from engine.io.video import read_video
    from engine.stages.perception import perceive

    v = read_video(P1 / "video.mp4", max_frames=20)
    p = perceive(v.frames)
    truth = json.loads((P1 / "truth.json").read_text())
    j2 = np.array([f["joints_2d"] for f in truth["frames"][:20]])
    assert p.detected.all()
    limbs = [i for i in KEYPOINT_JOINTS if JOINTS[i] != "hip"]
    swap = resolve_swaps(p.keypoints, j2, p.confidence)
    kp = np.where(swap[:, None, None], p.keypoints[:, MIRROR], p.keypoints)
    err = np.linalg.norm(kp[:, limbs] - j2[:, limbs], axis=-1)
    # measured 4.1 px median over the whole case (benchmarks/perception.py), body ~175 px
    assert np.median(err) < 8.0
    assert (p.mask[:, 100:200, 140:180] > 127).mean() > 0.5  # the torso is in the mask
