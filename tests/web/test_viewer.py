"""The viser view of an analysis: scene contents, recording, and a real Chromium load."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

viser = pytest.importorskip("viser")

from engine.io.result import build_result  # noqa: E402
from engine.render.camera import Camera  # noqa: E402
from engine.stages.selection import select_and_refine  # noqa: E402
from engine.types import Segments  # noqa: E402
from web.viewer.scene import build_scene, free_port, record_scene, wait_until_listening  # noqa: E402

ARTIFACTS = Path(__file__).resolve().parents[2] / "artifacts"
BASE = np.array([
    [0, 1, 0], [0.1, 1, 0], [0.1, 0.55, 0], [0.1, 0.1, 0], [-0.1, 1, 0], [-0.1, 0.55, 0],
    [-0.1, 0.1, 0], [0, 1.2, 0], [0, 1.4, 0], [0.18, 1.45, 0], [0.45, 1.45, 0], [0.7, 1.45, 0],
    [-0.18, 1.45, 0], [-0.45, 1.45, 0], [-0.7, 1.45, 0], [0, 1.55, 0], [0, 1.75, 0],
], float)  # fmt: skip


@pytest.fixture
def analysis() -> tuple[np.ndarray, dict]:
    """A reference raising the right arm; the performer raises it 30 deg too far forward in
    segment 2, with a depth-flipped decoy candidate per frame."""
    n = 41
    ang = np.linspace(0, np.pi / 2, n)
    ref = np.repeat(BASE[None], n, 0)
    arm = np.stack([-np.cos(ang), np.sin(ang), 0 * ang], -1)
    ref[:, 13], ref[:, 14] = BASE[12] + 0.27 * arm, BASE[12] + 0.52 * arm
    C0 = np.arange(0, 41, 4)
    perf = ref[C0].copy()
    fwd = np.where(C0 >= 20, np.radians(30), 0.0)
    a = np.stack([-np.cos(ang[C0]) * np.cos(fwd), np.sin(ang[C0]), np.sin(fwd)], -1)
    perf[:, 13], perf[:, 14] = BASE[12] + 0.27 * a, BASE[12] + 0.52 * a
    decoy = perf.copy()
    decoy[:, 13:15, 2] *= -1
    cands = [np.stack([perf[i], decoy[i]]) for i in range(len(C0))]
    sel = select_and_refine(cands, ref, Segments((0, 20), 40, ("lift", "hold")), C0, fps_ratio=4.0)
    doc = build_result(
        reference_name="arm", reference_frames=n, reference_fps=120.0,
        video={"frames": len(C0), "fps": 30.0, "width": 320, "height": 240},
        camera=Camera(scale=100.0, cx=160.0, cy=200.0), selection=sel, candidates=cands,
        timing_s={},
    )  # fmt: skip
    return ref, doc


@pytest.fixture
def server():
    s = viser.ViserServer(host="127.0.0.1", port=free_port(), verbose=False)
    yield s
    s.stop()


def test_scene_colours_bones_by_error_and_follows_the_slider(server, analysis):
    ref, doc = analysis
    scene = build_scene(server, ref, doc)
    try:
        green = scene.handles["performer"].colors.copy()
        assert green[..., 1].min() > green[..., 0].max()  # every bone green at frame 0
        scene.handles["slider"].value = 8  # segment 2: the right arm is wrong
        scene.set_frame(8)
        colors = scene.handles["performer"].colors
        assert colors[12, 0, 0] > colors[0, 0, 0]  # r_shoulder->r_elbow redder than a leg bone
        ref_pts = scene.handles["reference"].points
        np.testing.assert_allclose(ref_pts[0, 0], doc["frames"][8]["joints_3d"][0], atol=1e-4)
        assert scene.handles["candidates"].points.shape == (16, 2, 3)
        assert np.ptp(scene.handles["image_best"].points, axis=-2).max() == 0  # video agrees
        scene.handles["show_candidates"].value = False
        assert not scene.handles["candidates"].visible
        assert any(k.startswith("segment_") for k in scene.handles)
    finally:
        scene.close()


def test_recording_is_written(server, analysis, tmp_path):
    ref, doc = analysis
    scene = build_scene(server, ref, doc, gui=False)
    data = record_scene(scene)
    assert len(data) > 1000
    (tmp_path / "a.viser").write_bytes(data)


@pytest.mark.browser
def test_viewer_loads_in_chromium(server, analysis, browser):
    ref, doc = analysis
    scene = build_scene(server, ref, doc)
    scene.set_frame(8)  # segment 2: the arm is red
    port = server.get_port()
    wait_until_listening(port)
    ARTIFACTS.mkdir(exist_ok=True)
    shot = ARTIFACTS / "viewer.png"
    try:
        page = browser.new_page(viewport={"width": 1000, "height": 700})
        page.goto(f"http://127.0.0.1:{port}/", timeout=20_000)
        page.wait_for_selector("canvas", timeout=20_000)
        page.wait_for_timeout(1500)
        assert page.locator("canvas").count() >= 1
        assert page.get_by_text("other possible postures").count() >= 1
        page.screenshot(path=str(shot))
        page.close()
    finally:
        scene.close()
    assert shot.stat().st_size > 5000


def test_scene_shows_what_the_video_suggests_in_misfit_frames(server, analysis):
    ref, doc = analysis
    doc["frames"][8]["flags"].append("image_misfit")
    doc["frames"][8]["image_best"] = 1
    scene = build_scene(server, ref, doc, gui=False)
    try:
        scene.set_frame(8)
        pts = scene.handles["image_best"].points
        decoy = np.asarray(doc["frames"][8]["candidates"][1])
        np.testing.assert_allclose(pts[12], decoy[[12, 13]], atol=1e-5)  # r_shoulder->r_elbow
        scene.set_frame(7)
        assert np.ptp(scene.handles["image_best"].points, axis=-2).max() == 0
    finally:
        scene.close()


def test_against_a_reference_from_takes_the_colours_switch_to_the_experts_range(server, analysis):
    """The arm is 30 deg off in segment 2: red in degrees, but green where the expert's own
    takes vary by 20 deg there (z = 1.5 < 3)."""
    ref, doc = analysis
    for f in doc["frames"]:
        f["bone_z"] = [e / 20.0 for e in f["bone_errors_deg"]]
    doc["domain"] = {"variation": {"z_limit": 3.0}}
    scene = build_scene(server, ref, doc)
    try:
        scene.set_frame(8)
        by_deg = scene.handles["performer"].colors.copy()
        scene.handles["colour_by"].value = "expert's range"
        scene.set_frame(8)
        by_z = scene.handles["performer"].colors
        assert scene.z_limit == 3.0
        assert by_z[12, 0, 1] > by_deg[12, 0, 1]  # r_shoulder->r_elbow: greener by z
        assert by_z[12, 0, 0] <= by_deg[12, 0, 0]
    finally:
        scene.close()


def test_a_result_without_the_experts_range_has_no_colour_switch(server, analysis):
    ref, doc = analysis
    scene = build_scene(server, ref, doc)
    try:
        assert "colour_by" not in scene.handles
    finally:
        scene.close()


def test_the_expert_can_stand_beside_the_performer(server, analysis):
    ref, doc = analysis
    scene = build_scene(server, ref, doc)
    try:
        scene.set_frame(8)
        over = scene.handles["reference"].points.copy()
        scene.handles["side_by_side"].value = True
        scene.set_frame(8)
        beside = scene.handles["reference"].points
        np.testing.assert_allclose(beside - over, np.broadcast_to([0.9, 0.0, 0.0], over.shape),
                                   atol=1e-5)  # fmt: skip
        # the performer stays where they are
        scene.handles["side_by_side"].value = False
        scene.set_frame(8)
        np.testing.assert_allclose(scene.handles["reference"].points, over, atol=1e-6)
    finally:
        scene.close()
