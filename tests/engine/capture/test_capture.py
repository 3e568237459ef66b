"""Reference-free capture: a motion seen by a pose model comes back as the same 3D motion's
bone directions, survives a BVH round trip, is mended where the model swaps left and right,
keeps its knees bending the right way, and refuses a video with nobody in it."""

from __future__ import annotations

import subprocess
import sys

import cv2
import numpy as np
import pytest

from engine.body.kinematics import bone_directions
from engine.body.skeleton import JOINT_INDEX as J
from engine.capture import CaptureSettings, capture, capture_video
from engine.capture.export import capture_csv, write_capture_bvh
from engine.capture.lifting import FACING, S
from engine.capture.pose2d import POINT_MIRROR, P
from engine.errors import InvalidInput, RegistrationFailed
from engine.io.bvh import load_reference
from engine.stages.perception import Perception
from tests.conftest import CMU, REPO

#: BlazePose landmark -> our joint it sits on, for the fake detections.
_LANDMARK_JOINT = {
    11: "l_shoulder",
    12: "r_shoulder",
    13: "l_elbow",
    14: "r_elbow",
    15: "l_wrist",
    16: "r_wrist",
    23: "l_hip",
    24: "r_hip",
    25: "l_knee",
    26: "r_knee",
    27: "l_ankle",
    28: "r_ankle",
}
SCALE, CX, CY = 300.0, 320.0, 400.0  # px per m; image of the world origin


def squat() -> np.ndarray:
    """The CMU squat (64_17) every 4th frame, T-pose dropped: (T, 17, 3), facing +z."""
    path = CMU / "64_17.bvh"
    if not path.exists():
        pytest.skip("../shared/data/cmu is not beside the clone")
    ref = load_reference(path)
    return ref.motion.joints[ref.motion.first_motion_frame :: 4][:150]


def seen_by_model(joints: np.ndarray, *, hints: bool = True) -> Perception:
    """What an exact pose model reports for ``joints`` seen from the front (camera on +z,
    orthographic): landmarks at the joints, the ears at the middle of the head, the depth
    relative to the hips in pixels (larger = farther), facing the camera."""
    T = joints.shape[0]
    cam = joints * np.array([1.0, -1.0, -1.0])  # camera frame: x right, y down, z away
    lm = np.zeros((T, 33, 4))
    lm[..., 3] = 0.99
    hips = 0.5 * (cam[:, J["l_hip"]] + cam[:, J["r_hip"]])
    for i, name in _LANDMARK_JOINT.items():
        lm[:, i, :3] = cam[:, J[name]]
    head = 0.5 * (cam[:, J["neck"]] + cam[:, J["head_top"]])
    lm[:, 7, :3], lm[:, 8, :3], lm[:, 0, :3] = head, head, head
    lm[..., 2] -= hips[:, None, 2]
    lm[..., :3] *= SCALE
    lm[..., 0] += CX
    lm[..., 1] += CY
    if not hints:
        lm[..., 2] = np.nan
    kp = np.full((T, 17, 2), np.nan)
    return Perception(
        mask=np.zeros((T, 1, 1), np.uint8),
        keypoints=kp,
        confidence=np.zeros((T, 17)),
        facing=np.ones(T, np.int8),
        detected=np.ones(T, bool),
        model="exact",
        landmarks=lm,
    )


def limb_error_deg(ours: np.ndarray, truth: np.ndarray) -> float:
    """Mean direction error of the eight limb bones (deg), after the one turn about y that
    lays our first frame's hip line on the truth's (the capture faces +z at frame 0; the
    squat's first frame only nearly does)."""
    limbs = [1, 2, 4, 5, 9, 10, 12, 13]
    a, b = (x[0, J["l_hip"]] - x[0, J["r_hip"]] for x in (ours, truth))
    turn = np.arctan2(a[2], a[0]) - np.arctan2(b[2], b[0])
    c, s = np.cos(turn), np.sin(turn)
    R = np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])
    cos = np.sum((bone_directions(ours) @ R.T)[:, limbs] * bone_directions(truth)[:, limbs], -1)
    return float(np.degrees(np.arccos(np.clip(cos, -1, 1))).mean())


def test_an_exactly_seen_squat_comes_back_in_3d():
    truth = squat()
    cap = capture(seen_by_model(truth), 30.0, (640, 800), CaptureSettings(height_m=1.75))
    assert cap.joints.shape == truth.shape
    # the limbs' directions, from foreshortening and the chosen depth signs (2.7 deg when
    # written; what is left is the spine's and the hips' conventions, which differ from CMU's)
    assert limb_error_deg(cap.joints, truth) < 5.0
    # DESIGN.md's world frame: y up, feet near the floor, facing +z at frame 0
    assert cap.joints[:, J["head_top"], 1].mean() > cap.joints[:, J["l_ankle"], 1].mean() + 1.0
    assert abs(cap.joints[:, [J["l_ankle"], J["r_ankle"]], 1].min() - 0.08) < 1e-6
    f = np.cross(cap.joints[0, J["l_hip"]] - cap.joints[0, J["r_hip"]], [0, 1, 0])
    assert f[2] > 0.99 * np.linalg.norm(f)


def knees_bend_forwards(j: np.ndarray) -> bool:
    """Every knee bent over 30 deg bends the anatomical way: cross(thigh, shin) points to the
    body's left (so it does in every frame of the CMU files here)."""
    lat = j[:, J["l_hip"]] - j[:, J["r_hip"]]
    ok = True
    for side in "lr":
        thigh = j[:, J[f"{side}_knee"]] - j[:, J[f"{side}_hip"]]
        shin = j[:, J[f"{side}_ankle"]] - j[:, J[f"{side}_knee"]]
        cos = (
            np.sum(thigh * shin, -1)
            / np.linalg.norm(thigh, axis=-1)
            / np.linalg.norm(shin, axis=-1)
        )
        bent = np.degrees(np.arccos(np.clip(cos, -1, 1))) > 30
        assert bent.sum() > 20  # the squat bends them
        ok &= bool(np.all(np.sum(np.cross(thigh, shin) * lat, -1)[bent] > 0))
    return ok


def test_depth_hints_matter_but_continuity_and_limits_carry_without_them():
    truth = squat()
    with_hints = capture(seen_by_model(truth), 30.0, (640, 800))
    without = capture(seen_by_model(truth, hints=False), 30.0, (640, 800))
    assert limb_error_deg(with_hints.joints, truth) < limb_error_deg(without.joints, truth)
    assert knees_bend_forwards(without.joints)


def test_a_wrong_depth_hint_never_breaks_a_knee():
    truth = squat()
    seen = seen_by_model(truth)
    lm = seen.landmarks.copy()
    # the model claims both thighs point the wrong way in depth in every frame (the shins as
    # they are): bent knees would then fold backwards
    for hip, knee, ankle in ((23, 25, 27), (24, 26, 28)):
        moved = 2 * lm[:, hip, 2] - lm[:, knee, 2] - lm[:, knee, 2]
        lm[:, knee, 2] += moved
        lm[:, ankle, 2] += moved
    wrong = Perception(
        seen.mask, seen.keypoints, seen.confidence, seen.facing, seen.detected, seen.model, lm
    )
    assert knees_bend_forwards(capture(wrong, 30.0, (640, 800)).joints)
    weak = capture(wrong, 30.0, (640, 800), CaptureSettings(limit_weight=0.0))
    assert not knees_bend_forwards(weak.joints)  # without the limits the hint would win


def test_left_right_swaps_of_the_model_are_read_back():
    truth = squat()
    seen = seen_by_model(truth)
    lm = seen.landmarks.copy()
    pairs = [(11, 12), (13, 14), (15, 16), (23, 24), (25, 26), (27, 28), (7, 8)]
    for a, b in pairs:  # the model swaps left and right in frames 40-45 and 90
        for t in (*range(40, 46), 90):
            lm[t, [a, b]] = lm[t, [b, a]]
    swapped = Perception(
        seen.mask, seen.keypoints, seen.confidence, seen.facing, seen.detected, seen.model, lm
    )
    clean = capture(seen, 30.0, (640, 800))
    cap = capture(swapped, 30.0, (640, 800))
    assert set(np.flatnonzero(cap.pose.swapped)) == {*range(40, 46), 90}
    np.testing.assert_allclose(cap.pose.uv, clean.pose.uv, atol=1e-6)
    np.testing.assert_allclose(cap.joints, clean.joints, atol=1e-6)


def test_a_bvh_round_trip_gives_the_same_joints(tmp_path):
    cap = capture(seen_by_model(squat()), 30.0, (640, 800))
    for names in ("cmu", "coach"):
        path = write_capture_bvh(cap, tmp_path / f"{names}.bvh", names=names)
        back = load_reference(path, normalise_heading=False)
        assert back.profile == names
        assert back.motion.fps == pytest.approx(30.0)
        np.testing.assert_allclose(back.motion.joints, cap.joints, atol=1e-6)
    rows = capture_csv(cap).splitlines()
    assert len(rows) == 1 + cap.joints.shape[0]
    assert rows[0].startswith("t,time_s,hip_x_m,hip_y_m,hip_z_m")


def test_an_answer_settles_its_question():
    # one second of the squat with no depth hint: the upper arm stays in depth throughout,
    # so no frame of the clip tells its sign
    truth = squat()[60:90]
    cap = capture(seen_by_model(truth, hints=False), 30.0, (640, 800))
    q = next(q for q in cap.questions if q.segment == "l_upper_arm")
    assert (q.start, q.end) == (0, 30) and q.margin < 3.0
    answered = capture(seen_by_model(truth, hints=False), 30.0, (640, 800), answers={q.id: -q.sign})
    assert q.id not in {x.id for x in answered.questions}
    assert np.all(answered.lifted.signs[q.start : q.end, S[q.segment]] == -q.sign)
    assert "the left upper arm (elbow) towards or away from the camera" in q.text(30.0)
    # with the depth hints the model gives, the same clip asks nothing about that arm
    hinted = capture(seen_by_model(truth), 30.0, (640, 800))
    assert "l_upper_arm" not in {x.segment for x in hinted.questions}


def test_the_facing_question_flips_the_whole_body_when_answered_against_the_labels():
    truth = squat()
    seen = seen_by_model(truth)
    lm = seen.landmarks.copy()
    lm[:, :33] = lm[:, _mirror_landmarks()]  # the model reads the body from behind...
    facing = np.where(np.arange(len(truth)) % 2 == 0, 1, -1).astype(np.int8)  # ...and dithers
    mirrored = Perception(
        seen.mask, seen.keypoints, seen.confidence, facing, seen.detected, seen.model, lm
    )
    cap = capture(mirrored, 30.0, (640, 800))
    q = next(q for q in cap.questions if q.segment == FACING)
    assert q.sign == 1  # as labelled, the body shows its back
    fixed = capture(mirrored, 30.0, (640, 800), answers={q.id: -1})
    np.testing.assert_allclose(
        fixed.pose.uv[:, P["l_hip"]],
        capture(seen, 30.0, (640, 800)).pose.uv[:, P["l_hip"]],
        atol=1e-6,
    )
    assert limb_error_deg(fixed.joints, truth) < limb_error_deg(cap.joints, truth)


def _mirror_landmarks() -> np.ndarray:
    idx = np.arange(33)
    for a, b in [(11, 12), (13, 14), (15, 16), (23, 24), (25, 26), (27, 28), (7, 8)]:
        idx[a], idx[b] = b, a
    return idx


def test_a_perception_without_landmarks_or_person_is_refused():
    seen = seen_by_model(squat()[:20])
    bare = Perception(
        seen.mask, seen.keypoints, seen.confidence, seen.facing, seen.detected, seen.model
    )
    with pytest.raises(InvalidInput, match="no landmarks"):
        capture(bare, 30.0, (640, 800))
    nobody = Perception(
        seen.mask,
        seen.keypoints,
        seen.confidence,
        seen.facing,
        np.zeros(20, bool),
        seen.model,
        np.full((20, 33, 4), np.nan),
    )
    with pytest.raises(RegistrationFailed, match="could not find a person"):
        capture(nobody, 30.0, (640, 800))


def test_a_video_with_nobody_in_it_is_refused_clearly(tmp_path):
    path = tmp_path / "wall.mp4"
    out = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"mp4v"), 30, (160, 120))
    for i in range(20):
        out.write(np.full((120, 160, 3), 90 + i, np.uint8))
    out.release()
    with pytest.raises(RegistrationFailed, match="could not find a person"):
        capture_video(path)


def test_the_capture_command_says_what_is_wrong(tmp_path):
    def coach(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, "-m", "app.cli", *args],
            cwd=REPO,
            capture_output=True,
            text=True,
            timeout=120,
        )

    r = coach("capture", str(tmp_path / "missing.mp4"), "--out", str(tmp_path / "m.bvh"))
    assert r.returncode == 2 and "coach: error:" in r.stderr
    r = coach(
        "capture",
        str(tmp_path / "x.mp4"),
        "--out",
        str(tmp_path / "m.bvh"),
        "--answer",
        "l_shin@3-9=sideways",
    )
    assert r.returncode == 2 and "--answer must look like" in r.stderr
    assert not (tmp_path / "m.bvh").exists()


def test_mirror_table_of_the_capture_points_is_an_involution():
    assert np.array_equal(POINT_MIRROR[POINT_MIRROR], np.arange(len(POINT_MIRROR)))
    assert POINT_MIRROR[P["l_knee"]] == P["r_knee"] and POINT_MIRROR[P["hip"]] == P["hip"]
