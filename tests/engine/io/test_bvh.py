import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from engine.body.kinematics import forward_kinematics, rot_y
from engine.body.shapes import BodyShape
from engine.body.skeleton import JOINT_INDEX, JOINTS
from engine.errors import InvalidInput
from engine.io import (
    load_reference,
    read_bvh,
    resample,
    resample_reference,
    sample_at,
    sample_reference,
    write_bvh,
)
from engine.io._bvh_names import normalise_name
from engine.io.bvh import bvh_forward_kinematics
from engine.types import Motion
from tests.conftest import BENCH_CASES

TRUTH = BENCH_CASES / "P1_warp_64_29" / "truth.json"


@pytest.fixture(scope="module")
def cmu_ref():
    from tests.conftest import CMU

    path = CMU / "64_29.bvh"
    if not path.exists():
        pytest.skip("../shared/data/cmu is not beside the clone")
    return load_reference(path)


def random_postures(rng, shape, n):
    q = Rotation.random(n * 12, random_state=rng).as_matrix().reshape(n, 12, 3, 3)
    root = rng.normal(size=(n, 3))
    return forward_kinematics(shape.offsets, root, q)


# ----------------------------------------------------------------- CMU import


def test_cmu_maps_design_table(cmu_ref):
    assert cmu_ref.profile == "cmu"
    assert cmu_ref.source_joint_names[JOINT_INDEX["neck"]] == "Neck1"
    assert cmu_ref.source_joint_names[JOINT_INDEX["head_top"]] == "Head/End"
    assert cmu_ref.source_joint_names[JOINT_INDEX["l_shoulder"]] == "LeftArm"
    assert cmu_ref.units_to_m == pytest.approx(0.056444)
    assert cmu_ref.motion.joints.shape == (580, 17, 3)
    assert cmu_ref.motion.fps == pytest.approx(120.0, rel=1e-4)


def test_cmu_tpose_detected(cmu_ref):
    assert cmu_ref.motion.first_motion_frame == 1
    assert cmu_ref.has_tpose


def hand_fk(path, frame, node):
    """Independent per-frame matrix chain: parse the file naively, multiply 4x4 matrices."""
    lines = [ln.strip() for ln in open(path).read().splitlines()]
    names, parents, offsets, chans, stack = [], [], [], [], []
    for ln in lines:
        if ln == "MOTION":
            break
        tok = ln.split()
        if tok[0] in ("ROOT", "JOINT"):
            names.append(tok[1])
            parents.append(stack[-1] if stack else -1)
            chans.append([])
        elif tok[0] == "End":
            names.append(names[stack[-1]] + "/End")
            parents.append(stack[-1])
            chans.append([])
        elif tok[0] == "{":
            stack.append(len(names) - 1)
        elif tok[0] == "}":
            stack.pop()
        elif tok[0] == "OFFSET":
            offsets.append([float(v) for v in tok[1:]])
        elif tok[0] == "CHANNELS":
            chans[-1] = tok[2:]
    data = lines[lines.index("MOTION") + 3 + frame].split()
    vals = iter(float(v) for v in data)
    M = [None] * len(names)
    for i, p in enumerate(parents):
        L = np.eye(4)
        L[:3, 3] = offsets[i]
        for c in chans[i]:
            v = next(vals)
            if c.endswith("position"):
                L[:3, 3] += v * np.eye(3)[ord(c[0]) - ord("X")]
            else:
                E = np.eye(4)
                E[:3, :3] = Rotation.from_euler(c[0].lower(), v, degrees=True).as_matrix()
                L = L @ E
        M[i] = L if p < 0 else M[p] @ L
    return {n: M[i][:3, 3] for i, n in enumerate(names)}


@pytest.mark.parametrize("frame", [0, 1, 200, 579])
def test_fk_matches_hand_written_chain(cmu_ref, cmu_bvh, frame):
    pos = hand_fk(cmu_bvh, frame, None)
    ours = cmu_ref.motion.joints[frame]
    for j, src in enumerate(cmu_ref.source_joint_names):
        want = cmu_ref.R_world_bvh @ pos[src] * 0.056444
        np.testing.assert_allclose(ours[j], want, atol=1e-9)


def test_matches_public_truth_frames(cmu_ref):
    if not TRUTH.exists():
        pytest.skip("public bench case missing")
    truth = json.loads(TRUTH.read_text())
    exact = [f for f in truth["frames"] if max(f["bone_errors_deg"]) == 0.0]
    assert len(exact) > 10
    for fr in exact[:: max(1, len(exact) // 8)]:
        want = np.array(fr["joints_3d"])
        got = sample_reference(cmu_ref, np.array([fr["reference_frame"]]))[0]
        np.testing.assert_allclose(got, want, atol=2e-6)
    # video frame 0 is pinned to an integer reference frame: plain FK must agree
    f0 = truth["frames"][0]
    k = int(f0["reference_frame"])
    assert k == f0["reference_frame"]
    np.testing.assert_allclose(cmu_ref.motion.joints[k], np.array(f0["joints_3d"]), atol=2e-6)


def test_heading_faces_plus_z(cmu_ref, tmp_path):
    # turn the CMU file by 70 deg about y: after import it must face +z again
    J = sample_at(cmu_ref.motion, cmu_ref.shape, np.arange(0, 40, 3))
    turned = J @ rot_y(math.radians(70)).T
    ref = load_reference(write_bvh(tmp_path / "t.bvh", turned, 40.0))
    j0 = ref.motion.joints[0]
    f = np.cross(j0[JOINT_INDEX["l_hip"]] - j0[JOINT_INDEX["r_hip"]], [0, 1, 0])
    assert f[2] > 0 and abs(f[0]) < 1e-9
    assert ref.heading_rad == pytest.approx(-math.radians(70), abs=1e-7)
    np.testing.assert_allclose(ref.motion.joints, J, atol=1e-6)
    raw = load_reference(tmp_path / "t.bvh", normalise_heading=False)
    np.testing.assert_allclose(raw.motion.joints, turned, atol=1e-6)


# ----------------------------------------------------------------- export / round trip


def test_write_round_trip_exact(rng, tmp_path):
    shape = BodyShape.default(1.7)
    J = random_postures(rng, shape, 25)
    # face +z at frame 0 so that heading normalisation is the identity
    J0 = J[0]
    from engine.io.bvh import heading_rotation

    J = J @ heading_rotation(J0).T
    ref = load_reference(write_bvh(tmp_path / "x.bvh", J, 30.0, shape))
    assert ref.profile == "coach"
    assert ref.units_to_m == 1.0
    assert ref.motion.fps == pytest.approx(30.0)
    np.testing.assert_allclose(ref.motion.joints, J, atol=1e-6)
    np.testing.assert_allclose(ref.shape.lengths, shape.lengths, atol=1e-6)


def test_write_round_trip_cmu(cmu_ref, tmp_path):
    J = sample_at(cmu_ref.motion, cmu_ref.shape, np.arange(0, 580, 7))
    ref = load_reference(write_bvh(tmp_path / "c.bvh", J, 120 / 7))
    np.testing.assert_allclose(ref.motion.joints, J, atol=1e-6)
    assert ref.motion.first_motion_frame == 1


def test_write_keeps_bones_a_rigid_hip_and_chest_cannot_hold(cmu_ref, tmp_path):
    """A CMU spine bends at the pelvis, which the rigid hip part cannot reproduce: each such
    bone gets a zero-length joint of its own, so every bone direction comes back exactly."""
    from engine.measures import bone_angles

    J = cmu_ref.motion.joints  # the file's own bones, not resampled onto a rigid body
    path = write_bvh(tmp_path / "n.bvh", J, 120.0, cmu_ref.shape)
    back = load_reference(path)
    assert np.degrees(bone_angles(back.motion.joints, J)).max() < 1e-3
    assert "JOINT hip_to_lower_chest" in path.read_text()
    assert back.profile == "coach" and back.motion.first_motion_frame == 1


def test_write_of_rigid_postures_has_only_the_17_joints(rng, tmp_path):
    shape = BodyShape.default(1.7)
    text = write_bvh(tmp_path / "r.bvh", random_postures(rng, shape, 5), 30.0, shape).read_text()
    assert text.count("JOINT ") + text.count("ROOT ") == 17


def test_write_validates(tmp_path):
    with pytest.raises(InvalidInput, match=r"shape \(T, 17, 3\)"):
        write_bvh(tmp_path / "a.bvh", np.zeros((3, 16, 3)), 30.0)
    with pytest.raises(InvalidInput, match="NaN"):
        write_bvh(tmp_path / "a.bvh", np.full((3, 17, 3), np.nan), 30.0)
    with pytest.raises(InvalidInput, match="fps"):
        write_bvh(tmp_path / "a.bvh", np.zeros((3, 17, 3)), 0.0)


# ----------------------------------------------------------------- resampling


def test_resample_keeps_endpoints_and_fps(cmu_ref):
    m = Motion(cmu_ref.motion.joints[:121], 120.0, first_motion_frame=1)
    shape = cmu_ref.shape
    r = resample(m, 30.0, shape)
    assert r.fps == 30.0
    assert r.frames == 31
    assert r.first_motion_frame == 1
    fk = sample_at(m, shape, np.array([0.0, 120.0]))
    np.testing.assert_allclose(r.joints[[0, -1]], fk, atol=1e-9)
    # hip follows the source exactly at the kept frames
    np.testing.assert_allclose(r.joints[::3, 0], m.joints[::12, 0], atol=1e-9)


def test_resample_reference_local_slerp(cmu_ref):
    r = resample_reference(cmu_ref, 30.0)
    assert r.fps == 30.0 and r.first_motion_frame == 1
    k = np.arange(r.frames)
    f = k * cmu_ref.motion.fps / 30.0
    np.testing.assert_allclose(r.joints[0], cmu_ref.motion.joints[0], atol=1e-12)
    np.testing.assert_allclose(r.joints, sample_reference(cmu_ref, f), atol=1e-12)


def test_sample_at_integer_frames_reproduce_fk_postures(rng):
    shape = BodyShape.default()
    J = random_postures(rng, shape, 6)
    m = Motion(J, 10.0)
    np.testing.assert_allclose(sample_at(m, shape, np.arange(6.0)), J, atol=1e-9)
    mid = sample_at(m, shape, np.array([2.5]))[0]
    np.testing.assert_allclose(mid[0], (J[2, 0] + J[3, 0]) / 2, atol=1e-12)


def test_sampling_validates(cmu_ref):
    with pytest.raises(InvalidInput, match=r"frames must lie in \[0, 579\]"):
        sample_at(cmu_ref.motion, cmu_ref.shape, np.array([0.0, 580.0]))
    with pytest.raises(InvalidInput, match="1-D array of finite"):
        sample_at(cmu_ref.motion, cmu_ref.shape, np.array([[1.0]]))
    with pytest.raises(InvalidInput, match="fps must be a positive"):
        resample(cmu_ref.motion, -1.0, cmu_ref.shape)


# ----------------------------------------------------------------- name tables

MIXAMO = [
    "Hips", "Spine", "Spine1", "Spine2", "Neck", "Head", "HeadTop_End", "LeftShoulder",
    "LeftArm", "LeftForeArm", "LeftHand", "RightShoulder", "RightArm", "RightForeArm",
    "RightHand", "LeftUpLeg", "LeftLeg", "LeftFoot", "RightUpLeg", "RightLeg", "RightFoot",
]  # fmt: skip
BIPED = [
    "Bip01", "Bip01 Pelvis", "Bip01 Spine", "Bip01 Spine1", "Bip01 Spine2", "Bip01 Neck",
    "Bip01 Head", "Bip01 HeadNub", "Bip01 L Clavicle", "Bip01 L UpperArm", "Bip01 L Forearm",
    "Bip01 L Hand", "Bip01 R Clavicle", "Bip01 R UpperArm", "Bip01 R Forearm", "Bip01 R Hand",
    "Bip01 L Thigh", "Bip01 L Calf", "Bip01 L Foot", "Bip01 R Thigh", "Bip01 R Calf",
    "Bip01 R Foot",
]  # fmt: skip


def chain_bvh(names, prefix="", scale=1.0):
    """A flat-ish BVH where every named joint hangs off the root (enough to test mapping)."""
    lines = ["HIERARCHY", f"ROOT {prefix}{names[0]}", "{", "OFFSET 0 0 0",
             "CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation"]  # fmt: skip
    for k, n in enumerate(names[1:]):
        lines += [f"JOINT {prefix}{n}", "{", f"OFFSET {0.1 * scale * (k % 5)} {0.1 * scale * k} 0",
                  "CHANNELS 3 Zrotation Yrotation Xrotation", "}"]  # fmt: skip
    lines += ["}", "MOTION", "Frames: 1", "Frame Time: 0.01"]
    lines.append(" ".join(["0"] * (6 + 3 * (len(names) - 1))))
    return "\n".join(lines) + "\n"


@pytest.mark.parametrize(
    ("names", "prefix", "profile", "want"),
    [
        (
            MIXAMO,
            "mixamorig:",
            "mixamo",
            {"upper_chest": "mixamorig:Spine2", "head_top": "mixamorig:HeadTop_End"},
        ),
        (BIPED, "", "biped", {"hip": "Bip01 Pelvis", "l_knee": "Bip01 L Calf"}),
        (list(JOINTS), "", "coach", {"neck": "neck"}),
    ],
)
def test_other_skeletons_map(tmp_path, names, prefix, profile, want):
    p = tmp_path / "s.bvh"
    p.write_text(chain_bvh(names, prefix))
    ref = load_reference(p, units_to_m=1.0)
    assert ref.profile == profile
    for ours, src in want.items():
        assert ref.source_joint_names[JOINT_INDEX[ours]] == src


def test_normalise_name():
    assert normalise_name("mixamorig:LeftUpLeg") == "lupleg"
    assert normalise_name("Bip001 R Forearm") == "rforearm"
    assert normalise_name("Right_Hand") == "rhand"


def test_unmappable_names_missing_joints(tmp_path):
    p = tmp_path / "u.bvh"
    p.write_text(chain_bvh([n for n in MIXAMO if n not in ("LeftLeg", "Neck")]))
    with pytest.raises(InvalidInput, match=r"missing l_knee, neck \(closest name table: mixamo"):
        load_reference(p, units_to_m=1.0)
    # a user mapping fills the gap
    ref = load_reference(
        p,
        units_to_m=1.0,
        mapping={"l_knee": "LeftFoot", "neck": "Head", "l_ankle": "LeftUpLeg", "l_hip": "Hips"},
    )
    assert ref.profile == "user"


def test_user_mapping_validates(tmp_path):
    p = tmp_path / "u.bvh"
    p.write_text(chain_bvh(MIXAMO))
    with pytest.raises(InvalidInput, match="unknown joints"):
        load_reference(p, units_to_m=1.0, mapping={"elbow": "LeftArm"})
    with pytest.raises(InvalidInput, match="not in the file"):
        load_reference(p, units_to_m=1.0, mapping={"l_elbow": "Nope"})
    with pytest.raises(InvalidInput, match="units_to_m must be a positive"):
        load_reference(p, units_to_m=-2.0)
    p.write_text(chain_bvh(MIXAMO, scale=3.0))
    with pytest.raises(InvalidInput, match="cannot guess the units"):
        load_reference(p)


# ----------------------------------------------------------------- malformed files

GOOD = chain_bvh(list(JOINTS))


def _lines():
    return GOOD.splitlines()


def _without_motion():
    return "\n".join(_lines()[: _lines().index("MOTION")]) + "\n"


def _bad_count():
    ls = _lines()
    ls[-1] = ls[-1] + " 0"
    return "\n".join(ls)


def _nan():
    ls = _lines()
    ls[-1] = "nan " + ls[-1][2:]
    return "\n".join(ls)


def _word():
    ls = _lines()
    ls[-1] = "abc " + ls[-1][2:]
    return "\n".join(ls)


def _channels():
    return GOOD.replace("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation", 1)


def _frames(n):
    return GOOD.replace("Frames: 1", f"Frames: {n}")


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("hello world\n", "not a BVH file"),
        ("", "not a BVH file"),
        (_without_motion(), "no MOTION section"),
        (GOOD[: GOOD.index("JOINT l_knee")], "no MOTION section"),
        (_frames(3), "truncated file: the header announces 3 frames, only 1"),
        (_frames(0), "has 0 frames"),
        (_frames("x"), "Frames must be an integer"),
        (_bad_count(), r"line \d+: frame 0 has \d+ values, the hierarchy has \d+ channels"),
        (_nan(), r"line \d+: frame 0 contains NaN"),
        (_word(), r"line \d+: frame 0: 'abc' is not a number"),
        (_channels(), r"line 9: CHANNELS says 4 channels but lists 3"),
        (GOOD.replace("OFFSET 0.1 0.1 0", "OFFSET 0.1 zz 0", 1), "OFFSET values must be numbers"),
        (GOOD.replace("Frame Time: 0.01", "Frame Time: 0"), "Frame Time must be positive"),
        (GOOD.replace("Xrotation", "Wrotation", 1), "unknown channel 'Wrotation'"),
    ],
)
def test_malformed_files_clear_errors(tmp_path, text, match):
    p = tmp_path / "bad.bvh"
    p.write_text(text)
    with pytest.raises(InvalidInput, match=match):
        load_reference(p)


def test_missing_file(tmp_path):
    with pytest.raises(InvalidInput, match="cannot read BVH file"):
        read_bvh(tmp_path / "nope.bvh")


@pytest.mark.parametrize("order", ["XYZ", "ZXY", "YZX", "ZYX"])
def test_crlf_and_any_rotation_order(tmp_path, order):
    a = [30.0, -50.0, 70.0]
    chans = " ".join(f"{c}rotation" for c in order)
    text = (
        "HIERARCHY\nROOT a\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition "
        f"{chans}\nJOINT b\n{{\nOFFSET 0 0 0\nCHANNELS 3 {chans}\nEnd Site\n{{\n"
        "OFFSET 0.3 0.5 0.7\n}\n}\n}\nMOTION\nFrames: 2\nFrame Time: 0.5\n"
        f"1 2 3 0 0 0 {a[0]} {a[1]} {a[2]}\n0 0 0 {a[0]} {a[1]} {a[2]} 0 0 0\n"
    ).replace("\n", "\r\n")
    p = tmp_path / "crlf.bvh"
    p.write_bytes(text.encode())
    b = read_bvh(p)
    assert b.names == ("a", "b", "b/End") and b.frames == 2 and b.fps == 2.0
    pos = bvh_forward_kinematics(b)
    R = Rotation.from_euler(order, a, degrees=True).as_matrix()  # intrinsic: R1 @ R2 @ R3
    np.testing.assert_allclose(pos[0, 2], [1, 2, 3] + R @ [0.3, 0.5, 0.7], atol=1e-12)
    np.testing.assert_allclose(pos[1, 2], R @ [0.3, 0.5, 0.7], atol=1e-12)
