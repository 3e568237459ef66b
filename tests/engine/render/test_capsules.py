"""The analytic capsule rasteriser against brute force, pyrender, and itself (incremental)."""

from __future__ import annotations

import numpy as np
import pytest

from engine import measures
from engine.body.kinematics import forward_kinematics, rotation_about_axis
from engine.body.shapes import BodyShape, capsule_endpoints
from engine.body.skeleton import JOINT_INDEX, N_PARTS, PART_INDEX
from engine.errors import InvalidInput
from engine.render import _raster
from engine.render.camera import Camera
from engine.render.capsules import (
    PART_CAPSULES,
    PartScorer,
    Target,
    d_A_batch,
    d_S_batch,
    project_capsules,
    render,
    silhouettes,
)

SHAPE = BodyShape.default()
CAM = Camera(scale=110.0, cx=160.0, cy=110.0, width=320, height=240)


def _posture(rng: np.random.Generator, spread: float = 0.6, shape: BodyShape = SHAPE) -> np.ndarray:
    """A random posture: each part turned up to ``spread`` rad about a random axis."""
    axes = rng.normal(size=(N_PARTS, 3))
    angles = rng.uniform(-spread, spread, size=N_PARTS)
    R = rotation_about_axis(axes, angles)
    return forward_kinematics(shape.offsets, rng.normal(scale=0.05, size=3), R)


def _rest(shape: BodyShape = SHAPE) -> np.ndarray:
    return forward_kinematics(shape.offsets, np.zeros(3), np.broadcast_to(np.eye(3), (12, 3, 3)))


def _brute_silhouette(ends: np.ndarray, rad: np.ndarray, H: int, W: int) -> tuple:
    """Point-to-segment distance of every pixel to every capsule: (inside, |d - r| margin)."""
    v, u = np.mgrid[0:H, 0:W]
    p = np.stack([u, v], -1).astype(float)[:, :, None, :]  # (H, W, 1, 2)
    a, b = ends[:, 0], ends[:, 1]  # (C, 2)
    ab = b - a
    l2 = np.maximum((ab**2).sum(-1), 1e-300)
    t = np.clip(((p - a) * ab).sum(-1) / l2, 0, 1)
    d = np.linalg.norm(p - (a + t[..., None] * ab), axis=-1)  # (H, W, C)
    margin = np.abs(d - rad).min(-1)
    return (d <= rad).any(-1), margin


def test_single_capsule_matches_brute_force(rng: np.random.Generator) -> None:
    H, W = 60, 80
    for _ in range(200):
        ends = rng.uniform([-10, -10], [W + 10, H + 10], size=(1, 2, 2))
        if rng.random() < 0.15:  # degenerate, horizontal and vertical axes
            k = rng.integers(3)
            if k == 0:
                ends[0, 1] = ends[0, 0]
            else:
                ends[0, 1, k - 1] = ends[0, 0, k - 1]
        rad = rng.uniform(0.3, 15.0, size=1)
        out = np.zeros((1, H, W), dtype=bool)
        _raster.fill_silhouettes(ends[None], rad, out)
        want, margin = _brute_silhouette(ends, rad, H, W)
        bad = (out[0] != want) & (margin > 1e-9)
        assert not bad.any(), (ends, rad, np.argwhere(bad)[:5])


def test_body_silhouette_matches_brute_force_union(rng: np.random.Generator) -> None:
    j = _posture(rng)
    pc = project_capsules(j, SHAPE, CAM)
    want, margin = _brute_silhouette(pc.ends_px, pc.radius_px, CAM.height, CAM.width)
    got = render(j, SHAPE, CAM).silhouette
    assert not ((got != want) & (margin > 1e-9)).any()
    assert got.sum() > 3000


def test_project_capsules_shapes_and_radius() -> None:
    j = np.stack([_rest(), _rest()])
    pc = project_capsules(j, SHAPE, CAM)
    C = len(SHAPE.radii)
    assert pc.ends_px.shape == (2, C, 2, 2)
    assert pc.depth.shape == (2, C, 2)
    np.testing.assert_allclose(pc.radius_px, SHAPE.radii * CAM.scale)
    np.testing.assert_allclose(pc.ends_px[0], CAM.project(capsule_endpoints(j[0])))


def _pyrender_mask(joints: np.ndarray, shape: BodyShape, cam: Camera) -> np.ndarray:
    """Render the same capsules as trimesh meshes with an orthographic pyrender camera."""
    import pyrender
    import trimesh

    meshes = []
    for (a, b), r in zip(capsule_endpoints(joints), shape.radii, strict=True):
        d = b - a
        L = float(np.linalg.norm(d))
        T = np.eye(4)
        if L > 1e-9:
            T[:3, :3] = trimesh.geometry.align_vectors([0, 0, 1], d / L)[:3, :3]
        T[:3, 3] = 0.5 * (a + b)  # trimesh 4+ builds the capsule centred on the origin
        meshes.append(trimesh.creation.capsule(height=L, radius=float(r), transform=T))
    scene = pyrender.Scene(bg_color=[0, 0, 0, 0])
    scene.add(pyrender.Mesh.from_trimesh(trimesh.util.concatenate(meshes), smooth=False))
    R = cam.R_cam_world
    c, s = np.cos(cam.theta_z), np.sin(cam.theta_z)
    right, down = c * R[0] - s * R[1], s * R[0] + c * R[1]
    # world point seen at the image centre ((W - 1) / 2, (H - 1) / 2): pixel centres at integers
    centre = np.array([(cam.width - 1) / 2 - cam.cx, (cam.height - 1) / 2 - cam.cy])
    P = np.linalg.pinv(cam.A) @ centre - 20.0 * cam.view_dir
    pose = np.eye(4)
    pose[:3, :3] = np.stack([right, -down, -cam.view_dir], axis=1)
    pose[:3, 3] = P
    ocam = pyrender.OrthographicCamera(
        xmag=cam.width / 2 / cam.scale, ymag=cam.height / 2 / cam.scale, znear=0.1, zfar=50.0
    )
    scene.add(ocam, pose=pose)
    try:
        rend = pyrender.OffscreenRenderer(cam.width, cam.height)
    except Exception as exc:  # EGL/OSMesa not available: the only acceptable reason to skip
        pytest.skip(f"pyrender cannot start an offscreen context: {exc}")
    try:
        depth = rend.render(scene, flags=pyrender.RenderFlags.DEPTH_ONLY)
    finally:
        rend.delete()
    return depth > 0


def test_body_silhouette_agrees_with_pyrender(rng: np.random.Generator) -> None:
    for cam in (CAM, CAM.with_(azimuth=np.radians(70), theta_z=np.radians(10))):
        j = _posture(rng)
        want = _pyrender_mask(j, SHAPE, cam)
        got = render(j, SHAPE, cam).silhouette
        iou = (got & want).sum() / (got | want).sum()
        assert iou >= 0.95, iou


def _arm_in_front(z: float) -> np.ndarray:
    """Left upper arm pointing at the camera (z > 0) or away, forearm across the chest."""
    j = _rest().copy()
    sh = j[JOINT_INDEX["l_shoulder"]]
    j[JOINT_INDEX["l_elbow"]] = sh + [0.0, -0.05, z]
    j[JOINT_INDEX["l_wrist"]] = j[JOINT_INDEX["l_elbow"]] + [-0.26, 0.0, 0.0]
    return j


def test_labels_show_the_nearer_part() -> None:
    for z, expect in ((0.28, "l_lower_arm"), (-0.28, "upper_chest")):
        j = _arm_in_front(z)
        mid = CAM.project(0.5 * (j[JOINT_INDEX["l_elbow"]] + j[JOINT_INDEX["l_wrist"]]))
        col, row = np.round(mid).astype(int)
        r = render(j, SHAPE, CAM)
        part = r.labels[row, col]
        assert part == PART_INDEX[expect] or (z < 0 and part in (1, 2)), part
    # the forearm in front of the torso draws internal edges inside the silhouette
    r = render(_arm_in_front(0.28), SHAPE, CAM)
    fore = r.labels == PART_INDEX["l_lower_arm"]
    inner = r.edges & fore
    inside_torso = np.zeros_like(fore)
    inside_torso[:, 140:180] = True
    assert (inner & inside_torso).sum() >= 10
    # and with the arm behind, the forearm is hidden where it crosses the torso
    rb = render(_arm_in_front(-0.28), SHAPE, CAM)
    assert ((rb.labels == PART_INDEX["l_lower_arm"]) & inside_torso).sum() < fore.sum() / 3


def test_render_box_is_a_crop(rng: np.random.Generator) -> None:
    j = _posture(rng)
    full = render(j, SHAPE, CAM)
    box = (50, 150, 100, 220)
    part = render(j, SHAPE, CAM, box=box)
    crop = np.s_[50:150, 100:220]
    np.testing.assert_array_equal(part.silhouette, full.silhouette[crop])
    np.testing.assert_array_equal(part.labels, full.labels[crop])
    np.testing.assert_array_equal(part.edges, full.edges[crop])


def _target(rng: np.random.Generator) -> tuple[np.ndarray, Target]:
    j = _posture(rng)
    r = render(j, SHAPE, CAM)
    return j, Target.from_render(r)


def test_batch_equals_single_and_reference(rng: np.random.Generator) -> None:
    _, tgt = _target(rng)
    J = np.stack([_posture(rng) for _ in range(6)])
    J[0, :, 0] += 3.0  # one posture entirely off-screen
    # one across the image's left edge and one across its bottom: outlines at the border
    J[1, :, 0] -= CAM.project(J[1])[:, 0].mean() / CAM.scale
    J[2, :, 1] -= (CAM.height - CAM.project(J[2])[:, 1].mean()) / CAM.scale
    sils = silhouettes(J, SHAPE, CAM)
    dA = d_A_batch(J, tgt, SHAPE, CAM)
    dS = d_S_batch(J, tgt, SHAPE, CAM, lambda_A=0.7, lambda_E=1.3)
    dS_no_edges = d_S_batch(J, tgt, SHAPE, CAM, lambda_A=0.7, lambda_E=0.0)  # from row spans
    for n in range(len(J)):
        r = render(J[n], SHAPE, CAM)
        np.testing.assert_array_equal(sils[n], r.silhouette)
        assert dA[n] == pytest.approx(measures.d_A(r.silhouette, tgt.silhouette), abs=1e-12)
        ref = measures.d_S(
            r.silhouette, r.edges, tgt.silhouette, tgt.edges, lambda_A=0.7, lambda_E=1.3
        )
        assert dS[n] == pytest.approx(ref, abs=1e-9)
        ref = measures.d_S(
            r.silhouette, r.edges, tgt.silhouette, tgt.edges, lambda_A=0.7, lambda_E=0.0
        )
        assert dS_no_edges[n] == pytest.approx(ref, abs=1e-12)
    assert dA[0] == 1.0
    for n in (1, 2):  # really cut by the border
        uv = CAM.project(J[n])
        assert uv[:, 0].min() < 0 < uv[:, 0].max() or uv[:, 1].max() > CAM.height > uv[:, 1].min()


def test_identity_scores_zero(rng: np.random.Generator) -> None:
    j, tgt = _target(rng)
    assert d_S_batch(j[None], tgt, SHAPE, CAM)[0] == pytest.approx(0.0, abs=1e-12)


def test_subpixel_area_is_the_capsules_analytic_area(rng: np.random.Generator) -> None:
    H, W = 60, 80
    full = np.ones((H, W), bool)
    prefix = np.zeros((H, W + 1), np.int32)
    np.cumsum(full, axis=1, out=prefix[:, 1:])
    for _ in range(20):
        a = rng.uniform([20, 20], [60, 40])
        b = a + rng.uniform(-15, 15, size=2)
        r = rng.uniform(2.0, 8.0)
        out = np.empty((1, 2))
        _raster.sil_counts_smooth(np.stack([a, b])[None, None], np.array([r]), prefix, 16, out)
        exact = 2 * r * np.linalg.norm(b - a) + np.pi * r * r
        assert out[0, 0] == pytest.approx(exact, rel=5e-3)
        assert out[0, 1] == pytest.approx(out[0, 0], rel=1e-9)  # all inside the target


def test_subpixel_d_A_is_smooth_in_sub_pixel_shifts(rng: np.random.Generator) -> None:
    j, tgt = _target(rng)
    shifts = np.arange(-10, 11) * 0.1  # pixels
    moved = j[None] + (shifts / CAM.scale)[:, None, None] * np.array([1.0, 0.0, 0.0])
    d = d_A_batch(moved, tgt, SHAPE, CAM, subpixel_rows=4)
    # one valley, falling then rising at every 0.1 px step, at the target's own posture up to
    # the target's pixel quantisation (its pixels are whole, the body's outline is not)
    k = int(np.argmin(d))
    assert abs(shifts[k]) <= 0.2
    assert np.all(np.diff(d[k:]) > 0) and np.all(np.diff(d[: k + 1]) < 0)
    # close to the pixel-centre d_A (the difference is the boundary pixels' partial coverage)
    assert abs(d[10] - d_A_batch(j[None], tgt, SHAPE, CAM)[0]) < 0.05
    off = j + np.array([5.0, 0.0, 0.0])  # off-screen: nothing overlaps
    assert d_A_batch(off[None], tgt, SHAPE, CAM, subpixel_rows=4)[0] == 1.0


def test_subpixel_overlap_moves_where_pixel_centres_do_not() -> None:
    # a forearm-sized capsule moved sideways by 0.1 px steps against its own pixel mask
    H, W = 40, 60
    ends = np.array([[[30.0, 8.0], [30.0, 30.0]]])
    rad = np.array([3.3])
    mask = np.zeros((1, H, W), bool)
    _raster.fill_silhouettes(ends[None], rad, mask)
    prefix = np.zeros((H, W + 1), np.int32)
    np.cumsum(mask[0], axis=1, out=prefix[:, 1:])
    moved = ends[None] + np.arange(7)[:, None, None, None] * np.array([0.1, 0.0])
    centres = np.empty((7, 2), np.int64)
    smooth = np.empty((7, 2))
    _raster.sil_counts(moved, rad, prefix, centres)
    _raster.sil_counts_smooth(moved, rad, prefix, 4, smooth)
    assert np.any(np.diff(centres[:, 1]) == 0)  # pixel centres: flat steps
    assert np.all(np.diff(smooth[:, 1]) < 0)  # sub-pixel: every step loses overlap
    np.testing.assert_allclose(smooth[:, 0], smooth[0, 0], rtol=1e-9)  # same area throughout


@pytest.mark.parametrize("part", range(N_PARTS))
def test_incremental_equals_full(rng: np.random.Generator, part: int) -> None:
    _, tgt = _target(rng)
    base = _posture(rng)
    scorer = PartScorer(tgt, SHAPE, CAM, base)
    samples = np.stack([_posture(rng, spread=1.2) for _ in range(8)])
    samples[1] = base  # unmoved
    samples[2, :, 0] += 5.0  # moving part off-screen
    got = scorer.score(part, samples)
    for s in range(len(samples)):
        scorer.update_part(part, samples[s])
        assert got[s] == pytest.approx(scorer.current_score(), abs=1e-9)
        scorer.set_pose(base)


def test_incremental_equals_d_S_batch_for_a_leaf(rng: np.random.Generator) -> None:
    """Moving only the wrist moves only the forearm: the whole posture is a skeleton again."""
    _, tgt = _target(rng)
    base = _posture(rng)
    scorer = PartScorer(tgt, SHAPE, CAM, base)
    samples = np.repeat(base[None], 20, 0)
    w = JOINT_INDEX["l_wrist"]
    samples[:, w] += rng.normal(scale=0.15, size=(20, 3))
    got = scorer.score(PART_INDEX["l_lower_arm"], samples)
    np.testing.assert_allclose(got, d_S_batch(samples, tgt, SHAPE, CAM), atol=1e-9)


@pytest.mark.parametrize("part", range(N_PARTS))
def test_incremental_d_A_counts_the_pixels_of_a_whole_render(
    rng: np.random.Generator, part: int
) -> None:
    """Without d_E the part scorer merges row spans instead of rendering: its value must be
    a whole render's, bit for bit, with parts overlapping, off-screen, cut by the image's
    edge or unmoved."""
    _, tgt = _target(rng)
    base = _posture(rng)
    samples = np.stack([_posture(rng, spread=1.2) for _ in range(10)])
    samples[1] = base  # unmoved
    samples[2, :, 0] += 5.0  # moving part off-screen
    samples[3, :, 0] += 1.4  # cut by the image's edge
    scorer = PartScorer(tgt, SHAPE, CAM, base, lambda_E=0.0)
    got = scorer.score(part, samples)
    for s in range(len(samples)):
        whole = PartScorer(tgt, SHAPE, CAM, base, lambda_E=0.0)
        whole.update_part(part, samples[s])
        assert got[s] == whole.current_score(), s  # the image path's d_A, exactly
    # and after a part moved, the cached spans of the others are not reused stale
    scorer.update_part((part + 1) % N_PARTS, samples[4])
    again = PartScorer(tgt, SHAPE, CAM, base, lambda_E=0.0)
    again.update_part((part + 1) % N_PARTS, samples[4])
    np.testing.assert_array_equal(scorer.score(part, samples), again.score(part, samples))


def test_update_part_keeps_other_caches(rng: np.random.Generator) -> None:
    _, tgt = _target(rng)
    base = _posture(rng)
    scorer = PartScorer(tgt, SHAPE, CAM, base)
    other = _posture(rng)
    scorer.update_part(4, other)
    moved = base.copy()
    # a configuration with part 4 from ``other``: score of part 0 at its base pose
    got = scorer.score(0, moved[None])[0]
    assert got == pytest.approx(scorer.current_score(), abs=1e-9)
    assert len(PART_CAPSULES) == N_PARTS


@pytest.mark.parametrize(
    ("call", "match"),
    [
        (lambda t: render(np.zeros((16, 3)), SHAPE, CAM), r"joints must have shape \(17, 3\)"),
        (lambda t: render(np.full((17, 3), np.nan), SHAPE, CAM), "NaN"),
        (lambda t: render(_rest(), SHAPE, CAM, box=(0, 500, 0, 10)), "box"),
        (lambda t: silhouettes(_rest(), SHAPE, CAM), r"\(N, 17, 3\)"),
        (lambda t: d_S_batch(np.zeros((2, 17, 2)), t, SHAPE, CAM), r"\(N, 17, 3\)"),
        (lambda t: d_A_batch(_rest()[None], t, SHAPE, CAM.with_(width=100)), "target is"),
        (lambda t: d_A_batch(_rest()[None], t, SHAPE, CAM, subpixel_rows=-1), "sub"),
        (lambda t: project_capsules(np.zeros((17, 2)), SHAPE, CAM), "joints"),
        (lambda t: PartScorer(t, SHAPE, CAM, _rest()).score(12, _rest()[None]), "part"),
        (lambda t: PartScorer(t, SHAPE, CAM, _rest()).score(1, _rest()), "joints_samples"),
        (lambda t: Target.from_masks(np.zeros((4, 4)), np.zeros((4, 5))), "edges"),
        (lambda t: Target.from_masks(np.zeros(4), np.zeros(4)), "silhouette"),
    ],
)
def test_bad_inputs_raise(call, match: str) -> None:  # noqa: ANN001
    tgt = Target.from_render(render(_rest(), SHAPE, CAM))
    with pytest.raises(InvalidInput, match=match):
        call(tgt)
