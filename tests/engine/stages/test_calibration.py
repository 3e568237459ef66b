"""Stage 1 (thesis 4.2): the camera of public case P1 is recovered from its first frame."""

from __future__ import annotations

import json

import numpy as np
import pytest

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.render import capsules
from engine.render.camera import Camera
from engine.stages.calibration import CalibrationSettings, calibrate, principal_axes
from engine.stages.foreground import contour
from tests.conftest import BENCH_CASES, CMU

P1 = BENCH_CASES / "P1_warp_64_29"


def test_recovers_a_rendered_camera_and_azimuth():
    shape = BodyShape.default(1.75)
    from engine.body.kinematics import forward_kinematics

    j = forward_kinematics(
        shape.offsets, np.array([0, 1.0, 0]), np.broadcast_to(np.eye(3), (12, 3, 3))
    )
    true = Camera(scale=100.0, theta_z=np.radians(3), cx=150, cy=200, azimuth=np.radians(90))
    r = capsules.render(j, shape, true)
    cam, rep = calibrate(j, shape, r.silhouette, r.edges)
    assert cam.scale == pytest.approx(100.0, rel=0.02)
    assert abs(np.degrees(cam.theta_z) - 3) < 2
    assert abs(abs(np.degrees(cam.azimuth)) - 90) < 1e-6  # +-90: mirror-symmetric T-pose


@pytest.mark.skipif(not P1.exists(), reason="public cases not beside the clone")
def test_public_case_p1_camera():
    """Scale within 3 %, angle within 2 deg, position within 5 px of the true camera.

    The frame-0 body region comes from GrabCut, whose colour models start from a random
    k-means (seeded, so this test is deterministic). Across GrabCut seeds 0-6 the
    ``above_ankles`` camera's scale error ranged over -2.6 ... +1.9 % and cy over -2.7 ...
    +6.4 px (seed 0, the engine's: -2.1 %, cy -2.0 px; without ``above_ankles`` -3.1 %, cy
    -4.5 px). Since stage 0 trusts the difference where the background was seen (and
    searches the angle too): -0.7 %, cy +1.3 px; without ``above_ankles`` -3.1 %, cy -3.7 px
    (the shoes still print into the background). The whole video is read: the background
    model needs the performer to move, and in the first 40 frames the head hardly does (it
    prints into the background and the frame-0 region loses it: -3.4 % with 40 frames).
    """
    from engine.io.bvh import load_reference
    from engine.io.video import read_video
    from engine.stages.foreground import extract_foreground

    ref = load_reference(P1 / "reference.bvh")
    truth = Camera.from_dict(json.loads((P1 / "truth.json").read_text())["camera"])
    v = read_video(P1 / "video.mp4")
    fg = extract_foreground(v.frames)
    j = ref.motion.joints[ref.motion.first_motion_frame]
    cam, _ = calibrate(j, ref.shape, fg.silhouettes[0], fg.edges[0],
                       CalibrationSettings(above_ankles=True))  # fmt: skip
    assert cam.scale == pytest.approx(truth.scale, rel=0.03)
    assert abs(np.degrees(cam.theta_z - truth.theta_z)) < 2
    assert abs(cam.cx - truth.cx) < 5 and abs(cam.cy - truth.cy) < 5
    assert abs(np.degrees(cam.azimuth)) < 1e-6


def test_principal_axes_of_a_bar():
    m = np.zeros((50, 50), bool)
    m[5:45, 20:24] = True
    pa = principal_axes(m)
    assert pa.length == pytest.approx(40, abs=1)
    assert abs(pa.direction[0]) < 1e-6


def test_validation():
    shape = BodyShape.default()
    z = np.zeros((20, 20), bool)
    with pytest.raises(InvalidInput, match="joints must be"):
        calibrate(np.zeros((3, 3)), shape, z, z)
    with pytest.raises(InvalidInput, match="silhouette and edges"):
        calibrate(np.zeros((17, 3)), shape, z, np.zeros((3, 3), bool))
    with pytest.raises(InvalidInput, match="no body region"):
        calibrate(np.zeros((17, 3)), shape, z, z)
    with pytest.raises(InvalidInput, match="at least 3|body region"):
        principal_axes(z)
    from engine.stages.calibration import refine_on_frames

    cam = Camera(scale=10.0, width=20, height=20)
    masks = np.zeros((2, 20, 20), bool)
    with pytest.raises(InvalidInput, match="must agree"):
        refine_on_frames(cam, np.zeros((3, 17, 3)), shape, masks, masks)
    with pytest.raises(InvalidInput, match="must agree"):
        refine_on_frames(cam, np.zeros((2, 16, 3)), shape, masks, masks)


def test_fit_body_shape_recovers_wider_limbs():
    from dataclasses import replace

    from engine.body.kinematics import forward_kinematics
    from engine.stages.calibration import fit_body_shape

    shape = BodyShape.default(1.75)
    eye = np.broadcast_to(np.eye(3), (12, 3, 3))
    j = forward_kinematics(shape.offsets, np.array([0, 1.0, 0]), eye)
    cam = Camera(scale=100.0, theta_z=0.0, cx=160, cy=200, width=320, height=240)
    wide = replace(shape, radii=shape.radii * 1.3)
    sil = capsules.silhouettes(j[None], wide, cam)[0]
    fitted, f = fit_body_shape(j, shape, cam, sil)
    assert f["arms"] == pytest.approx(1.3, abs=0.1) and f["legs"] == pytest.approx(1.3, abs=0.1)
    m = capsules.silhouettes(j[None], fitted, cam)[0]
    assert (m & sil).sum() / (m | sil).sum() > 0.95
    with pytest.raises(InvalidInput, match="bounds"):
        fit_body_shape(j, shape, cam, sil, bounds=(1.2, 2.0))
    with pytest.raises(InvalidInput, match="silhouette must be"):
        fit_body_shape(j, shape, cam, sil[:10])


def test_refinement_corrects_the_in_plane_angle():
    # PCA's angle is biased by whatever the region lacks (a leg) or has in excess; the
    # refinement must correct it, or the position settles off the truth to compensate
    from engine.body.kinematics import forward_kinematics
    from engine.stages.calibration.search import _refine

    shape = BodyShape.default(1.75)
    j = forward_kinematics(
        shape.offsets, np.array([0, 1.0, 0]), np.broadcast_to(np.eye(3), (12, 3, 3))
    )
    true = Camera(scale=100.0, theta_z=0.0, cx=160, cy=200, width=320, height=240)
    r = capsules.render(j, shape, true)
    target = capsules.Target.from_masks(r.silhouette, r.edges)
    start = true.with_(theta_z=np.radians(3.5), cx=163.0, scale=104.0)
    cam, d = _refine(j, shape, target, start, CalibrationSettings())
    assert abs(np.degrees(cam.theta_z)) < 0.5
    assert abs(cam.cx - 160) < 1 and abs(cam.cy - 200) < 1
    assert cam.scale == pytest.approx(100, rel=0.01)


def test_mirror_azimuth_faces_the_other_way():
    from engine.stages.calibration import mirror_azimuth

    scores = {0.0: 0.50, 15.0: 0.45, 165.0: 0.52, -180.0: 0.51, 90.0: 0.40}
    assert mirror_azimuth(scores, 15.0) == -180.0  # 90 is exactly 75 deg away: same side
    assert mirror_azimuth(scores, -180.0) == 15.0
    assert mirror_azimuth({0.0: 0.5}, 0.0) is None


P2 = BENCH_CASES / "P2_take_64_30_vs_64_29"


@pytest.fixture(scope="module")
def p2_stages():
    from engine.io.bvh import load_reference
    from engine.io.video import read_video
    from engine.pipeline import run_stages_0_2

    if not P2.exists():
        pytest.skip("public cases not beside the clone")
    ref = load_reference(P2 / "reference.bvh")
    return ref, run_stages_0_2(ref, read_video(P2 / "video.mp4"))


def test_the_whole_video_tells_front_from_back(p2_stages):
    """P2's first frame alone fits a back view best (refined d_S); stage 2 over the whole
    video prefers the front (mean cost E_C 0.38 against 0.56), which is the truth."""
    ref, r = p2_stages
    assert abs(np.degrees(r.camera.azimuth)) < 1e-6
    assert len(r.view_costs) == 2 and r.view_costs[0.0] == min(r.view_costs.values())
    j = ref.motion.joints[ref.motion.first_motion_frame]
    alone, _ = calibrate(j, ref.shape, r.foreground.silhouettes[0], r.foreground.edges[0])
    assert abs(np.degrees(alone.azimuth)) > 90


def test_many_frames_polish_p2s_camera(p2_stages):
    """P2's frame-0 region carries part of a prop of the shirt's colour. The camera polished
    on 15 frames over the video is closer to the truth than the frame-0 front-view camera:
    measured scale -6.1 % -> -4.2 %, cy -8.3 -> -6.8 px, in-plane angle 2.5 -> 1.5 deg."""
    ref, r = p2_stages
    truth = Camera.from_dict(json.loads((P2 / "truth.json").read_text())["camera"])
    j = ref.motion.joints[ref.motion.first_motion_frame]
    one, _ = calibrate(j, ref.shape, r.foreground.silhouettes[0], r.foreground.edges[0],
                       CalibrationSettings(azimuths_deg=(0.0,)))  # fmt: skip

    def errors(c: Camera) -> np.ndarray:
        return np.abs([100 * (c.scale / truth.scale - 1), c.cy - truth.cy,
                       np.degrees(c.theta_z - truth.theta_z)])  # fmt: skip

    before, after = errors(one), errors(r.camera)
    assert after[0] <= before[0] - 1.0, (before, after)
    assert after[1] <= before[1] and after[2] <= before[2], (before, after)


@pytest.mark.skipif(not (CMU / "64_29.bvh").exists(), reason="CMU data not beside the clone")
def test_many_frames_outvote_one_faulty_frame():
    """A prop glued to the body's side in one frame drags a camera fitted to that frame
    alone; fitted to eight frames of which that is one, the camera stays near the truth."""
    from engine.io.bvh import load_reference
    from engine.stages.calibration.search import _refine, refine_on_frames

    ref = load_reference(CMU / "64_29.bvh")
    postures = ref.motion.joints[np.linspace(1, ref.motion.frames - 1, 8).astype(int)]
    true = Camera(scale=110.0, cx=160.0, cy=215.0, width=320, height=240)
    renders = [capsules.render(p, ref.shape, true) for p in postures]
    sil = np.array([x.silhouette for x in renders])
    edges = np.array([x.edges for x in renders])
    rows = np.flatnonzero(sil[0].any(1))
    right = np.flatnonzero(sil[0].any(0)).max()
    sil[0, rows[0] + 30 : rows[-1] - 30, right : right + 14] = True  # the prop
    edges[0] = contour(sil[0])
    start = true.with_(scale=104.0, cx=163.0, cy=211.0)
    target = capsules.Target.from_masks(sil[0], edges[0])
    alone, _ = _refine(postures[0], ref.shape, target, start, CalibrationSettings())
    many, _ = refine_on_frames(start, postures, ref.shape, sil, edges)
    assert abs(many.cx - 160) < 1 and abs(many.cy - 215) < 1
    assert many.scale == pytest.approx(110, rel=0.01)
    assert abs(alone.cx - 160) + abs(alone.cy - 215) > 2 * (abs(many.cx - 160) + abs(many.cy - 215))
