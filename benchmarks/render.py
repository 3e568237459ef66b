"""Speed of the analytic capsule rasteriser against pyrender (issue 2, item 5a).

Prints, measured in this one run on one core: full-body silhouette comparisons per second
(render + d_A against a target, no image written) at 160x120 and 320x240, full-body d_S
(d_A + d_E) per second, incremental single-part likelihoods (d_A + d_E) per second, and
pyrender frames per second for the same capsule body (trimesh capsules, OffscreenRenderer,
OrthographicCamera). Timings on a shared machine are noisy: the best of a few repeats is shown.

Single-part rates are given per part (sampling 2000 poses of that part against the 11 others
cached) and for all 12 parts together (harmonic mean: the rate of a sweep that scores the same
number of samples for every part).

Run: NUMBA_NUM_THREADS=1 taskset -c 0 .venv/bin/python benchmarks/render.py [repeats]
"""

from __future__ import annotations

import os
import sys
import time

os.environ["PYOPENGL_PLATFORM"] = "egl"  # before pyrender (and PyOpenGL) are imported

import numpy as np  # noqa: E402

from engine.body.kinematics import forward_kinematics, rotation_about_axis  # noqa: E402
from engine.body.shapes import BodyShape, capsule_endpoints  # noqa: E402
from engine.body.skeleton import N_PARTS, PART_INDEX, PARTS  # noqa: E402
from engine.render.camera import Camera  # noqa: E402
from engine.render.capsules import (  # noqa: E402
    PartScorer,
    Target,
    d_A_batch,
    d_S_batch,
    render,
)


def _posture(shape: BodyShape, R: np.ndarray) -> np.ndarray:
    return forward_kinematics(shape.offsets, np.zeros(3), R)


def _base_rotations() -> np.ndarray:
    """The default posture with a few parts turned (arms down and bent, one knee bent)."""
    R = np.broadcast_to(np.eye(3), (N_PARTS, 3, 3)).copy()
    z = np.array([0.0, 0.0, 1.0])
    x = np.array([1.0, 0.0, 0.0])
    R[PART_INDEX["l_upper_arm"]] = rotation_about_axis(z, -1.2)
    R[PART_INDEX["l_lower_arm"]] = rotation_about_axis(z, -0.6) @ rotation_about_axis(x, -0.4)
    R[PART_INDEX["r_upper_arm"]] = rotation_about_axis(z, 1.0)
    R[PART_INDEX["r_lower_arm"]] = rotation_about_axis(z, 1.9)
    R[PART_INDEX["l_upper_leg"]] = rotation_about_axis(x, -0.4)
    R[PART_INDEX["l_lower_leg"]] = rotation_about_axis(x, 0.2)
    return R


def _samples(shape: BodyShape, n: int, rng: np.random.Generator) -> np.ndarray:
    """Postures jittered around the base one (every part turned up to 0.3 rad)."""
    base = _base_rotations()
    axes = rng.normal(size=(n, N_PARTS, 3))
    ang = rng.uniform(-0.3, 0.3, size=(n, N_PARTS))
    R = rotation_about_axis(axes, ang) @ base
    return forward_kinematics(shape.offsets, np.zeros((n, 3)), R)


def _camera(shape: BodyShape, width: int, height: int) -> Camera:
    """Body about 200 px tall at 320x240 (half at 160x120), centred."""
    scale = 0.83 * height / shape.height
    return Camera(scale=scale, cx=width / 2, cy=height * 0.45, width=width, height=height)


def _best_rate(fn, n_items: int, repeats: int = 3) -> float:  # noqa: ANN001
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return n_items / best


def bench_full(
    shape: BodyShape, width: int, height: int, rng: np.random.Generator, repeats: int
) -> tuple:
    cam = _camera(shape, width, height)
    target = Target.from_render(render(_posture(shape, _base_rotations()), shape, cam))
    J = _samples(shape, 4000, rng)
    d_A_batch(J[:2], target, shape, cam)  # compile / load the numba cache
    d_S_batch(J[:2], target, shape, cam)
    sil = _best_rate(lambda: d_A_batch(J, target, shape, cam), len(J), repeats)
    full = _best_rate(lambda: d_S_batch(J[:1000], target, shape, cam), 1000, repeats)
    return sil, full


def bench_part(shape: BodyShape, rng: np.random.Generator, repeats: int) -> dict[str, float]:
    """Single-part d_S rates per part, and over all 12 parts (total samples / total time)."""
    cam = _camera(shape, 320, 240)
    base = _posture(shape, _base_rotations())
    target = Target.from_render(render(base, shape, cam))
    scorer = PartScorer(target, shape, cam, base)
    J = _samples(shape, 2000, rng)
    rates = {}
    for p in range(N_PARTS):
        scorer.score(p, J[:2])  # builds the fixed-part cache once, as BP does per part
        rates[PARTS[p]] = _best_rate(lambda p=p: scorer.score(p, J), len(J), repeats)
    # the harmonic mean: what a BP sweep that samples every part equally often gets
    rates["all 12 parts"] = N_PARTS / sum(1.0 / rates[name] for name in PARTS)

    def bp_sweep() -> None:
        # as stage 3 does per iteration: a new context (every cache dropped), then 40
        # samples (settings.candidates.n_samples) of each part, cache build included
        scorer.set_pose(base)
        for p in range(N_PARTS):
            scorer.score(p, J[:40])

    rates["BP sweep, 40/part"] = _best_rate(bp_sweep, 40 * N_PARTS, 3 * repeats)
    return rates


def bench_pyrender(shape: BodyShape, frames: int = 30) -> float | str:
    try:
        import pyrender
        import trimesh
    except ImportError as exc:
        return f"not installed ({exc})"
    cam = _camera(shape, 320, 240)
    joints = _posture(shape, _base_rotations())
    meshes = []
    for (a, b), r in zip(capsule_endpoints(joints), shape.radii, strict=True):
        d = b - a
        L = float(np.linalg.norm(d))
        T = np.eye(4)
        T[:3, :3] = trimesh.geometry.align_vectors([0, 0, 1], d / L)[:3, :3]
        T[:3, 3] = 0.5 * (a + b)  # trimesh builds the capsule centred on the origin
        meshes.append(trimesh.creation.capsule(height=L, radius=float(r), transform=T))
    scene = pyrender.Scene(bg_color=[0, 0, 0, 0])
    node = scene.add(pyrender.Mesh.from_trimesh(trimesh.util.concatenate(meshes)))
    R = cam.R_cam_world
    pose = np.eye(4)
    pose[:3, :3] = np.stack([R[0], -R[1], -R[2]], axis=1)
    centre = np.array([(cam.width - 1) / 2 - cam.cx, (cam.height - 1) / 2 - cam.cy])
    pose[:3, 3] = np.linalg.pinv(cam.A) @ centre - 20.0 * cam.view_dir
    ocam = pyrender.OrthographicCamera(
        xmag=cam.width / 2 / cam.scale, ymag=cam.height / 2 / cam.scale, znear=0.1, zfar=50.0
    )
    scene.add(ocam, pose=pose)
    try:
        renderer = pyrender.OffscreenRenderer(cam.width, cam.height)
    except Exception as exc:  # noqa: BLE001 - report, do not fail the other figures
        return f"cannot start ({exc})"
    try:
        renderer.render(scene)
        t = time.perf_counter()
        for i in range(frames):
            # move the body each frame, as a renderer inside a search loop would
            pose_i = np.eye(4)
            pose_i[0, 3] = 0.001 * i
            scene.set_pose(node, pose_i)
            renderer.render(scene)
        return frames / (time.perf_counter() - t)
    finally:
        renderer.delete()


def main() -> None:
    repeats = int(sys.argv[1]) if len(sys.argv) > 1 else 5
    rng = np.random.default_rng(0)
    shape = BodyShape.default()
    print(f"capsule rasteriser, one core, best of {repeats} (shared machine: figures are noisy)")
    for w, h in ((160, 120), (320, 240)):
        sil, full = bench_full(shape, w, h, rng, repeats)
        print(f"  {w}x{h}: full-body silhouette + d_A   {sil:10,.0f} /s")
        print(f"  {w}x{h}: full-body d_S (d_A + d_E)    {full:10,.0f} /s")
    for name, rate in bench_part(shape, rng, repeats).items():
        print(f"  320x240: single-part d_S, {name:<17s} {rate:10,.0f} /s (incremental)")
    fps = bench_pyrender(shape)
    if isinstance(fps, str):
        print(f"pyrender: {fps}")
    else:
        print(f"pyrender 320x240 capsule mesh: {fps:8.1f} frames/s ({1000 / fps:.1f} ms/frame)")


if __name__ == "__main__":
    main()
