"""Thesis experiment 5.2: accuracy of stage-3 posture candidates, synthetic and on bench cases.

Synthetic (default): reference postures of CMU 64_29 at regular intervals are rendered as target
regions with the capsule rasteriser (320x240, body ~200 px tall); the initial posture is the
truth with every part turned about its parent joint by a random angle in [-20, 20] deg (5.2.2).
Prints E_2P, E_2M (px, eq. 5.1-5.2, of the lowest-d_S candidate), E_3B (deg, eq. 5.3, of the
best candidate) and of the selected (lowest-d_S) one, and seconds per frame.

Case (``--case DIR``): a bench case's video through stage 0 (foreground), its true C(t') and
camera; the initial posture is the reference at the true C(t'). Prints the E_3B of the initial
posture, of the selected candidate and of the best candidate, and E_2P of the selected one.

    .venv/bin/python benchmarks/candidates.py [--frames 50] [--thesis] [--seed 0] [--set k=v ...]
    .venv/bin/python benchmarks/candidates.py --case /work/shared/bench/cases/P1_warp_64_29 \
        --range 40:46 [--no-fit-radii]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from engine.body.kinematics import rotation_about_axis
from engine.body.skeleton import N_PARTS, PART_ROOT_JOINT
from engine.io.bvh import load_reference, sample_reference
from engine.measures import d_B
from engine.render.camera import Camera
from engine.render.capsules import render
from engine.stages.candidates import (
    _SUBTREE_JOINTS,
    CandidateSettings,
    estimate_candidates,
    fit_radii,
)

CMU = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "cmu" / "64_29.bvh"


def perturb(joints: np.ndarray, max_deg: float, rng: np.random.Generator) -> np.ndarray:
    """Turn every part (with its subtree) about its root joint by U[-max, max] deg."""
    out = joints.copy()
    for p in range(N_PARTS):
        J = out[PART_ROOT_JOINT[p]]
        R = rotation_about_axis(rng.normal(size=3), np.radians(rng.uniform(-max_deg, max_deg)))
        sub = _SUBTREE_JOINTS[p]
        out[sub] = J + (out[sub] - J) @ R.T
    return out


def camera_for(joints: np.ndarray, height_px: float = 200.0) -> Camera:
    h = joints[:, 1].max() - joints[:, 1].min()
    scale = height_px / max(h, 1.2)
    cam = Camera(scale=scale, width=320, height=240)
    c = cam.project(joints).mean(0)
    return cam.with_(cx=160.0 - c[0], cy=120.0 - c[1])


def _summary(rows: dict[str, list[float]]) -> None:
    for name, v in rows.items():
        v = np.asarray(v)
        print(f"{name:16s} mean {v.mean():7.2f}  sd {v.std():6.2f}  max {v.max():7.2f}")


def synthetic(args: argparse.Namespace, settings: CandidateSettings) -> None:
    ref = load_reference(CMU)
    rng = np.random.default_rng(args.seed)
    # own stream for the perturbations, so every setting is judged on the same initial postures
    rng_init = np.random.default_rng([args.seed, 1])
    T = ref.motion.frames
    frames = np.linspace(ref.motion.first_motion_frame, T - 1, args.frames).astype(int)
    rows: dict[str, list[float]] = {
        k: [] for k in ("E_2P px", "E_2M px", "E_3B deg", "selected deg", "init deg", "s/frame")
    }
    for f in frames:
        truth = ref.motion.joints[f]
        cam = camera_for(truth)
        r = render(truth, ref.shape, cam)
        init = perturb(truth, 20.0, rng_init)
        t0 = time.perf_counter()
        fc = estimate_candidates(
            r.silhouette, r.edges, cam, ref.shape, init, settings=settings, rng=rng
        )
        rows["s/frame"].append(time.perf_counter() - t0)
        err = np.linalg.norm(cam.project(fc.best) - cam.project(truth), axis=-1)
        rows["E_2P px"].append(err.mean())
        rows["E_2M px"].append(err.max())
        rows["E_3B deg"].append(np.degrees(d_B(fc.candidates, truth).min()))
        rows["selected deg"].append(np.degrees(d_B(fc.best, truth)))
        rows["init deg"].append(np.degrees(d_B(init, truth)))
    _summary(rows)
    print(f"frames {len(frames)}")


def _foreground(case: Path, cache: Path | None) -> dict[str, np.ndarray]:
    if cache is not None and cache.exists():
        return dict(np.load(cache))
    from engine.io.video import read_video
    from engine.stages.foreground import extract_foreground

    fg = extract_foreground(read_video(case / "video.mp4").frames)
    out = {"sil": fg.silhouettes, "edges": fg.edges}
    if cache is not None:
        np.savez_compressed(cache, **out)
    return out


def on_case(args: argparse.Namespace, settings: CandidateSettings) -> None:
    case = Path(args.case)
    truth = json.loads((case / "truth.json").read_text())
    ref = load_reference(case / "reference.bvh")
    cam = Camera.from_dict(truth["camera"])
    fg = _foreground(case, Path(args.cache) if args.cache else None)
    shape = ref.shape
    if not args.no_fit_radii:
        t0 = time.perf_counter()
        joints0 = sample_reference(ref, np.array([truth["frames"][0]["reference_frame"]]))[0]
        shape = fit_radii(fg["sil"][0], joints0, ref.shape, cam)
        k = np.round(shape.radii / ref.shape.radii, 2)
        print(f"fit_radii {time.perf_counter() - t0:.2f} s: factors {k}")
    a, b = (int(x) for x in args.range.split(":"))
    rng = np.random.default_rng(args.seed)
    rows: dict[str, list[float]] = {
        k: []
        for k in ("init deg", "selected deg", "best deg", "E_2P sel px", "E_2P init px", "s/frame")
    }
    prev = None
    for t in range(a, b):
        fr = truth["frames"][t]
        init = sample_reference(ref, np.array([fr["reference_frame"]]))[0]
        true3 = np.asarray(fr["joints_3d"])
        t0 = time.perf_counter()
        fc = estimate_candidates(
            fg["sil"][t], fg["edges"][t], cam, shape, init, settings=settings, rng=rng, prev=prev
        )
        rows["s/frame"].append(time.perf_counter() - t0)
        prev = fc
        rows["init deg"].append(np.degrees(d_B(init, true3)))
        rows["selected deg"].append(np.degrees(d_B(fc.best, true3)))
        rows["best deg"].append(np.degrees(d_B(fc.candidates, true3).min()))
        rows["E_2P sel px"].append(
            np.linalg.norm(cam.project(fc.best) - fr["joints_2d"], axis=-1).mean()
        )
        rows["E_2P init px"].append(
            np.linalg.norm(cam.project(init) - fr["joints_2d"], axis=-1).mean()
        )
        if args.verbose:
            print(
                t,
                {k: round(float(v[-1]), 2) for k, v in rows.items()},
                len(fc.candidates),
                fc.flags,
            )
    _summary(rows)
    print(f"{case.name} frames {a}:{b}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--thesis", action="store_true", help="thesis settings (slow)")
    ap.add_argument("--set", nargs="*", default=[], help="settings overrides key=value")
    ap.add_argument("--case", help="bench case folder (video.mp4, reference.bvh, truth.json)")
    ap.add_argument("--range", default="40:46", help="video frames START:STOP of --case")
    ap.add_argument("--cache", help=".npz cache of the case's stage-0 foreground")
    ap.add_argument("--no-fit-radii", action="store_true")
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args(argv)
    settings = CandidateSettings.thesis() if args.thesis else CandidateSettings()
    for kv in args.set:
        k, v = kv.split("=")
        settings = replace(settings, **{k: type(getattr(settings, k))(v)})
    if args.case:
        on_case(args, settings)
    else:
        synthetic(args, settings)
    print(f"settings {settings}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
