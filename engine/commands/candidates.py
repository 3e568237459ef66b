"""`coach candidates REF.bvh VIDEO --frames 10:40 --truth CASE/truth.json --out cand.json`.

Runs stage 0 (foreground) on the video, takes C(t') and the camera from ``--truth`` (so stage 3
can be judged alone), then stage 3 (thesis 4.6) on the chosen frames. Writes the DESIGN.md
result format for those frames (joints_3d = lowest-cost candidate; the capsule radii are
first fitted to the frame-0 silhouette, see ``engine.stages.calibration.fit_body_shape``)
and optionally a plot of all candidates per frame from the front and the side (thesis fig. 4.11).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np

from engine.errors import InvalidInput


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("candidates", help="stage 3: posture candidates of video frames")
    p.add_argument("reference", type=Path)
    p.add_argument("video", type=Path)
    p.add_argument("--frames", default="0:10", help="START:STOP video frames (stop exclusive)")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--plot", type=Path)
    p.add_argument("--truth", type=Path, help="truth.json: take C(t') and the camera from it")
    p.add_argument("--seed", type=int, default=0)
    p.set_defaults(func=run)


def _frames(spec: str, n: int) -> range:
    try:
        a, b = (int(x) if x else None for x in spec.split(":"))
    except ValueError as exc:
        raise InvalidInput(f"--frames must look like 10:40, got {spec!r}") from exc
    r = range(n)[slice(a, b)]
    if not r:
        raise InvalidInput(f"--frames {spec} selects no frame of a {n}-frame video")
    return r


def run(args: argparse.Namespace) -> int:
    from engine.io.bvh import load_reference, sample_reference
    from engine.io.video import read_video
    from engine.measures import bone_angles
    from engine.render.camera import Camera
    from engine.stages.calibration import fit_body_shape
    from engine.stages.candidates import CandidateSettings, estimate_candidates
    from engine.stages.foreground import extract_foreground

    t0 = time.perf_counter()
    if args.truth is None:
        raise InvalidInput("--truth is required for now (stages 1-2 are not wired in yet)")
    truth = json.loads(Path(args.truth).read_text())
    ref = load_reference(args.reference)
    video = read_video(args.video)
    frames = _frames(args.frames, video.frames.shape[0])
    fg = extract_foreground(video.frames)
    t_fg = time.perf_counter() - t0
    camera = Camera.from_dict(truth["camera"])
    settings = CandidateSettings()
    # the performer's girth from the calibration frame, where the posture is the reference's
    c0 = float(truth["frames"][0]["reference_frame"])
    shape, _ = fit_body_shape(
        sample_reference(ref, np.array([c0]))[0], ref.shape, camera, fg.silhouettes[0]
    )
    rng = np.random.default_rng(args.seed)
    out_frames, prev, all_cands = [], None, []
    t1 = time.perf_counter()
    for t in frames:
        c = float(truth["frames"][t]["reference_frame"])
        init = sample_reference(ref, np.array([c]))[0]
        fc = estimate_candidates(
            fg.silhouettes[t], fg.edges[t], camera, shape, init,
            settings=settings, rng=rng, prev=prev,
        )  # fmt: skip
        prev = fc
        k = int(np.argmin(fc.cost))
        best = fc.candidates[k]
        ang = np.degrees(bone_angles(init, best))
        all_cands.append(fc.candidates)
        out_frames.append({
            "t": t,
            "reference_frame": int(round(c)),
            "joints_3d": best.tolist(),
            "joints_2d": camera.project(best).tolist(),
            "candidates": fc.candidates.tolist(),
            "selected": k,
            "posture_error_deg": float(ang.mean()),
            "bone_errors_deg": ang.tolist(),
            "flags": list(fc.flags),
            "d_s": fc.d_s.tolist(),
        })  # fmt: skip
    t_c = time.perf_counter() - t1
    from engine.body.skeleton import JOINTS

    result = {
        "version": 1,
        "reference": {"name": ref.motion.name, "frames": ref.motion.frames, "fps": ref.motion.fps},
        "video": {"frames": int(video.frames.shape[0]), "fps": float(video.fps),
                  "width": int(video.frames.shape[2]), "height": int(video.frames.shape[1])},
        "joints": list(JOINTS),
        "camera": camera.to_dict(),
        "frames": out_frames,
        "segments": [],
        "timing_s": {"foreground": t_fg, "candidates": t_c, "total": time.perf_counter() - t0},
    }  # fmt: skip
    args.out.write_text(json.dumps(result))
    print(f"{len(out_frames)} frames, {t_c / len(out_frames):.2f} s/frame -> {args.out}")
    if args.plot:
        _plot(all_cands, list(frames), camera, args.plot)
    return 0


def _plot(cands: list[np.ndarray], frames: list[int], camera, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from engine.body.skeleton import BONE_CHILD, BONE_PARENT

    n = min(len(frames), 8)
    pick = np.linspace(0, len(frames) - 1, n).astype(int)
    fig, ax = plt.subplots(2, n, figsize=(2 * n, 4), squeeze=False)
    side = camera.with_(azimuth=camera.azimuth + np.pi / 2)
    for col, i in enumerate(pick):
        for row, cam in enumerate((camera, side)):
            a = ax[row, col]
            for k, c in enumerate(cands[i]):
                uv = cam.project(c)
                for p, q in zip(BONE_PARENT, BONE_CHILD, strict=True):
                    a.plot(uv[[p, q], 0], uv[[p, q], 1], color=plt.cm.tab20(k % 20), lw=1)
            a.invert_yaxis()
            a.set_aspect("equal")
            a.set_xticks([])
            a.set_yticks([])
            a.set_title(f"t'={frames[i]} {'front' if row == 0 else 'side'}", fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
