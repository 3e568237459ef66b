"""Thesis experiment 5.2: accuracy of stage-3 posture candidates, synthetic and on bench cases.

Synthetic (default): reference postures of CMU 64_29 at regular intervals are rendered as target
regions with the capsule rasteriser (320x240, body ~200 px tall); the initial posture is the
truth with every part turned about its parent joint by a random angle in [-20, 20] deg (5.2.2).
Prints E_2P, E_2M (px, eq. 5.1-5.2) and the E_3B (deg, eq. 5.3) of the selected candidate
(``FrameCandidates.best``: lowest d_S + prior, lowest d_S when ``prior_weight`` is 0), the
E_3B of the best candidate, and seconds per frame. ``--exact`` runs
``CandidateSettings.exact_body()`` (the escape, restarts, no prior), ``--thesis`` the
thesis' settings.

Case (``--case DIR``): a bench case's video through stage 0 (foreground), its true C(t') and
camera; the initial posture is the reference at the true C(t'). Prints the E_3B of the initial
posture, of the selected candidate and of the best candidate, and E_2P of the selected one.

End to end (``--case DIR --e2e``): stages 3 and 4 on every frame of the case with its true C
(rounded) and camera, so they are judged apart from stages 0-2: the scorer's posture figures
(selected and best-candidate E_3B, E_2P, bone-error estimation error, rank correlation of
eps_t'), C's error before and after stage 4 and the boundary error. ``--out`` caches stage 3,
``--reuse`` re-runs stage 4 alone with ``--sel key=value`` selection settings.

    .venv/bin/python benchmarks/candidates.py [--frames 50] [--thesis | --exact] [--seed 0] \
        [--set k=v ...]
    .venv/bin/python benchmarks/candidates.py --case /work/shared/bench/cases/P1_warp_64_29 \
        --range 40:46 [--no-fit-radii]
    .venv/bin/python benchmarks/candidates.py --case /work/shared/bench/cases/P1_warp_64_29 \
        --e2e --out /tmp/p1_stage3.npz [--reuse --sel image_weight=2]
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from engine.io.bvh import load_reference, sample_reference
from engine.measures import d_B
from engine.render.camera import Camera
from engine.render.capsules import render
from engine.stages.calibration import fit_body_shape
from engine.stages.candidates import CandidateSettings, estimate_candidates
from engine.stages.candidates import perturb_parts as perturb

CMU = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "cmu" / "64_29.bvh"


def camera_for(joints: np.ndarray, height_px: float = 200.0) -> Camera:
    """A 320x240 front camera with the joints' box ``height_px`` tall, centred in the image.

    Centring the box (not the joints' mean, which sits high because of the arms) keeps the
    feet in the picture, as in the thesis' experiment.
    """
    h = joints[:, 1].max() - joints[:, 1].min()
    scale = height_px / max(h, 1.2)
    cam = Camera(scale=scale, width=320, height=240)
    uv = cam.project(joints)
    c = (uv.min(0) + uv.max(0)) / 2.0
    return cam.with_(cx=160.0 - c[0], cy=120.0 - c[1])


def _setting(settings: object, kv: str) -> dict[str, object]:
    """``key=value`` as a field of ``settings``, the value parsed as the field's type."""
    k, v = kv.split("=", 1)
    kind = type(getattr(settings, k))
    if kind is bool:  # bool("False") is True
        if v not in ("True", "False", "true", "false", "1", "0"):
            raise SystemExit(f"{k} takes True or False, got {v!r}")
        return {k: v in ("True", "true", "1")}
    return {k: kind(v)}


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
    # the mean is pulled up by a few frames stuck in a wrong basin; say how many
    stuck = int((np.asarray(rows["E_2P px"]) > 1.5).sum())
    print(f"frames {len(frames)}, of which {stuck} with E_2P > 1.5 px")


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
        shape, _ = fit_body_shape(joints0, ref.shape, cam, fg["sil"][0])
        k = np.round(shape.radii / ref.shape.radii, 2)
        print(f"fit_body_shape {time.perf_counter() - t0:.2f} s: factors {k}")
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


def _truth_eps(truth: dict) -> tuple[np.ndarray, np.ndarray]:
    tb = np.array([f["bone_errors_deg"] for f in truth["frames"]], float)
    return tb, tb.mean(-1)


def end_to_end(args: argparse.Namespace, settings: CandidateSettings) -> None:
    """Stages 3-4 on a whole case with the true C and camera (isolates them from stages 0-2).

    Stage 3's output is cached in ``--out`` (an .npz) so stage 4 can be re-run alone with
    ``--reuse``. Prints the scorer's posture metrics (selected and best E_3B, E_2P, bone-error
    estimation error, rank correlation of eps_t') and C's error before and after stage 4.
    """
    from engine.io.bvh import load_reference as _load
    from engine.reference.domain import find_domain, reference_segments
    from engine.stages.candidates import estimate_candidates_chunk
    from engine.stages.selection import SelectionSettings, select_and_refine

    case = Path(args.case)
    truth = json.loads((case / "truth.json").read_text())
    ref = _load(case / "reference.bvh")
    cam = Camera.from_dict(truth["camera"])
    fg = _foreground(case, Path(args.cache) if args.cache else None)
    n = len(truth["frames"])
    C_true = np.array([f["reference_frame"] for f in truth["frames"]], float)
    C0 = np.clip(np.round(C_true), 0, ref.motion.frames - 1).astype(int)
    out = Path(args.out) if args.out else None
    if args.reuse and out is not None and out.exists():
        z = np.load(out)
        split = np.cumsum(z["counts"])[:-1]
        cands, d_s = np.split(z["cands"], split), np.split(z["d_s"], split)
        flags = [() for _ in range(n)]
        secs = float(z["seconds"])
    else:
        shape = ref.shape
        if not args.no_fit_radii:
            shape, _ = fit_body_shape(ref.motion.joints[C0[0]], ref.shape, cam, fg["sil"][0])
        t0 = time.perf_counter()
        fcs = estimate_candidates_chunk(
            fg["sil"], fg["edges"], cam, shape, ref.motion.joints[C0], settings=settings,
            rng=np.random.default_rng(args.seed),
        )  # fmt: skip
        secs = (time.perf_counter() - t0) / n
        cands, d_s = [f.candidates for f in fcs], [f.d_s for f in fcs]
        flags = [f.flags for f in fcs]
        if out is not None:
            np.savez_compressed(
                out, cands=np.concatenate(cands), d_s=np.concatenate(d_s),
                counts=np.array([len(c) for c in cands]), seconds=secs,
            )  # fmt: skip
    sel_settings = SelectionSettings()
    for kv in args.sel:
        sel_settings = replace(sel_settings, **_setting(sel_settings, kv))
    segs = reference_segments(ref.motion, find_domain(case / "reference.bvh"))
    sel = select_and_refine(
        cands, ref.motion.joints, segs, C0.astype(float), settings=sel_settings,
        fps_ratio=truth["reference_fps"] / truth["fps"], video_fps=truth["fps"],
        candidate_flags=flags,
        candidate_d_s=None if args.no_image_cost else d_s,
    )  # fmt: skip
    gt = np.array([f["joints_3d"] for f in truth["frames"]], float)
    tb, teps = _truth_eps(truth)
    init_err = np.degrees(d_B(ref.motion.joints[C0], gt))
    sel_err = np.degrees(d_B(sel.joints, gt))
    best_err = np.array([np.degrees(d_B(c, g).min()) for c, g in zip(cands, gt, strict=True)])
    e2p = np.linalg.norm(
        cam.project(sel.joints) - np.array([f["joints_2d"] for f in truth["frames"]]), axis=-1
    ).mean()
    from scipy.stats import spearmanr

    est_b = np.degrees(sel.bone_errors)
    ratio = truth["reference_fps"] / truth["fps"]
    print(
        f"{case.name}  s/frame {secs:.2f}  candidates/frame {np.mean([len(c) for c in cands]):.1f}"
    )
    print(f"  initial (ref at true C) E3B {init_err.mean():6.2f} deg")
    print(f"  selected E3B            {sel_err.mean():6.2f} deg   E2P {e2p:5.2f} px")
    print(f"  best-candidate E3B      {best_err.mean():6.2f} deg")
    print(
        f"  bone-error est. err     {np.abs(est_b - tb).mean():6.2f} deg  (all-zero estimate "
        f"{np.abs(tb).mean():.2f})"
    )
    print(f"  rank corr eps           {spearmanr(np.degrees(sel.posture_error), teps)[0]:6.3f}")
    print(
        f"  C err video frames: before {np.abs(C0 - C_true).mean() / ratio:.2f}  after "
        f"{np.abs(sel.C - C_true).mean() / ratio:.2f}"
    )
    warp = np.asarray(truth["warp"], float)
    b_err = [
        abs(r.performer_start - np.interp(r.reference_start, warp, np.arange(len(warp))))
        for r in sel.segments[1:]
    ]
    print(
        f"  boundary err video frames {np.mean(b_err):.2f} (initial "
        f"{[r.initial_performer_start for r in sel.segments[1:]]}, found "
        f"{[r.performer_start for r in sel.segments[1:]]})"
    )
    print(f"  selected == candidate 0 (1st estimate) in {np.mean(sel.selected == 0):.2f} of frames")
    if args.dump:
        np.savez_compressed(
            args.dump, est_bones=est_b, true_bones=tb, est_eps=np.degrees(sel.posture_error),
            true_eps=teps, joints=sel.joints, truth=gt, reference=ref.motion.joints[C0],
        )  # fmt: skip


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=50)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--thesis", action="store_true", help="thesis settings (slow)")
    ap.add_argument(
        "--exact", action="store_true",
        help="CandidateSettings.exact_body() (escape, restarts, no prior)",
    )
    ap.add_argument("--set", nargs="*", default=[], help="settings overrides key=value")
    ap.add_argument("--case", help="bench case folder (video.mp4, reference.bvh, truth.json)")
    ap.add_argument("--range", default="40:46", help="video frames START:STOP of --case")
    ap.add_argument("--cache", help=".npz cache of the case's stage-0 foreground")
    ap.add_argument("--no-fit-radii", action="store_true")
    ap.add_argument("-v", "--verbose", action="store_true")
    ap.add_argument("--e2e", action="store_true", help="stages 3-4 on the whole --case, true C")
    ap.add_argument("--out", help="--e2e: .npz cache of stage 3's candidates")
    ap.add_argument("--reuse", action="store_true", help="--e2e: reuse --out, run stage 4 only")
    ap.add_argument("--sel", nargs="*", default=[], help="--e2e: selection settings key=value")
    ap.add_argument("--dump", help="--e2e: .npz of per-frame estimated and true errors")
    ap.add_argument("--no-image-cost", action="store_true", help="--e2e: thesis d_c = d_B only")
    args = ap.parse_args(argv)
    settings = CandidateSettings.thesis() if args.thesis else CandidateSettings()
    if args.exact:
        settings = CandidateSettings.exact_body()
    for kv in args.set:
        settings = replace(settings, **_setting(settings, kv))
    if args.case and args.e2e:
        end_to_end(args, settings)
    elif args.case:
        on_case(args, settings)
    else:
        synthetic(args, settings)
    print(f"settings {settings}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
