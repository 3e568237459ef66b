"""`coach candidates REF.bvh VIDEO --frames 10:40 --out cand.json [--plot cand.png]`: stage 3 alone.

Runs stages 0-2 on the whole video (:func:`engine.pipeline.prepare`: foreground, camera,
C(t')), then stage 3 (thesis 4.6) on the chosen frames, and writes the DESIGN.md result format
for those frames (joints_3d = the lowest-cost candidate, errors against the reference at C(t'))
so ``../shared/bench/score.py`` reads it; ``--plot`` draws all candidates per frame from the
front and the side (thesis fig. 4.11). With ``--truth CASE/truth.json`` (a bench case), C(t')
and the camera come from the truth instead, so stage 3 is judged alone.
"""

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from engine.errors import InvalidInput

if TYPE_CHECKING:
    from engine.body.shapes import BodyShape
    from engine.io.bvh import Reference
    from engine.render.camera import Camera
    from engine.settings import Settings


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("candidates", help="stage 3: posture candidates of video frames")
    p.add_argument("reference", type=Path)
    p.add_argument("video", type=Path)
    p.add_argument("--frames", default="0:10", help="START:STOP video frames (stop exclusive)")
    p.add_argument("--out", type=Path, required=True)
    p.add_argument("--plot", type=Path)
    p.add_argument("--truth", type=Path, help="truth.json: take C(t') and the camera from it")
    p.add_argument("--fast", action="store_true", help="the 'fast' settings preset")
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


@dataclass
class _Inputs:
    """What stage 3 needs for the chosen frames, from stages 0-2 or from a bench truth."""

    reference: Reference
    n_video: int
    fps: float
    silhouettes: np.ndarray  # (N, H, W) bool, the chosen frames
    edges: np.ndarray  # (N, H, W) bool
    camera: Camera  # working resolution
    camera_file: Camera  # the same camera in the video file's pixels
    shape: BodyShape
    C: np.ndarray  # (N,) reference frame per chosen video frame
    initial: np.ndarray  # (N, M, 17, 3) initial postures, the reference's first
    timing: dict


def _from_truth(
    args: argparse.Namespace, frames_spec: str, settings: Settings
) -> tuple[_Inputs, range]:
    from engine.io.bvh import load_reference, sample_reference
    from engine.io.video import read_video
    from engine.render.camera import Camera
    from engine.stages.calibration import fit_body_shape
    from engine.stages.foreground import extract_foreground

    t0 = time.perf_counter()
    truth = json.loads(Path(args.truth).read_text())
    ref = load_reference(args.reference)
    camera = Camera.from_dict(truth["camera"])
    video = read_video(args.video, height=camera.height)
    frames = _frames(frames_spec, video.frames.shape[0])
    fg = extract_foreground(video.frames, settings.foreground)
    # the performer's girth from the calibration frame, where the posture is the reference's
    c0 = float(truth["frames"][0]["reference_frame"])
    shape, _ = fit_body_shape(
        sample_reference(ref, np.array([c0]))[0], ref.shape, camera, fg.silhouettes[0]
    )
    idx = np.asarray(frames)
    C = np.array([float(truth["frames"][t]["reference_frame"]) for t in idx])
    inputs = _Inputs(
        ref, int(video.frames.shape[0]), float(video.fps), fg.silhouettes[idx], fg.edges[idx],
        camera, camera, shape, C, sample_reference(ref, C)[:, None],
        {"foreground": time.perf_counter() - t0},
    )  # fmt: skip
    return inputs, frames


def _from_stages(
    args: argparse.Namespace, frames_spec: str, settings: Settings
) -> tuple[_Inputs, range]:
    from engine.io.bvh import load_reference
    from engine.pipeline import prepare
    from engine.reference.domain import find_domain

    p = prepare(args.reference, args.video, settings, domain=find_domain(args.reference))
    frames = _frames(frames_spec, p.n_frames)
    idx = np.asarray(frames)
    v = p.video
    inputs = _Inputs(
        load_reference(args.reference), p.n_frames, v.fps, p.silhouettes[idx], p.edges[idx],
        p.camera, p.camera.resized(v.original_width, v.original_height), p.shape,
        p.C[idx].astype(float), p.initial_postures(frames),
        dict(p.timing_s),
    )  # fmt: skip
    return inputs, frames


def run(args: argparse.Namespace) -> int:
    from engine.body.skeleton import JOINTS
    from engine.io.bvh import sample_reference
    from engine.measures import bone_angles
    from engine.settings import Settings
    from engine.stages.candidates import estimate_candidates_chunk, frame_rngs

    for name in ("reference", "video"):
        if not Path(getattr(args, name)).exists():
            raise InvalidInput(f"{name}: {getattr(args, name)} does not exist")
    t0 = time.perf_counter()
    settings = Settings.from_dict({"preset": "fast" if args.fast else "default"})
    source = _from_truth if args.truth is not None else _from_stages
    x, frames = source(args, args.frames, settings)
    t1 = time.perf_counter()
    fcs = estimate_candidates_chunk(
        x.silhouettes, x.edges, x.camera, x.shape, x.initial, settings=settings.candidates,
        rng=frame_rngs(args.seed, frames),
    )  # fmt: skip
    t_c = time.perf_counter() - t1
    out_frames = []
    ref_at_C = sample_reference(x.reference, x.C)
    for t, c, init, fc in zip(frames, x.C, ref_at_C, fcs, strict=True):
        k = int(np.argmin(fc.cost))
        best = fc.candidates[k]
        ang = np.degrees(bone_angles(init, best))
        out_frames.append({
            "t": t,
            "reference_frame": int(round(float(c))),
            "joints_3d": best.tolist(),
            "joints_2d": x.camera_file.project(best).tolist(),
            "candidates": fc.candidates.tolist(),
            "selected": k,
            "posture_error_deg": float(ang.mean()),
            "bone_errors_deg": ang.tolist(),
            "flags": list(fc.flags),
            "d_s": fc.d_s.tolist(),
        })  # fmt: skip
    motion = x.reference.motion
    result = {
        "version": 1,
        "reference": {"name": motion.name, "frames": motion.frames, "fps": motion.fps},
        "video": {"frames": x.n_video, "fps": x.fps, "width": x.camera_file.width,
                  "height": x.camera_file.height},
        "joints": list(JOINTS),
        "camera": x.camera_file.to_dict(),
        "frames": out_frames,
        "segments": [],
        "timing_s": {**x.timing, "candidates": t_c, "total": time.perf_counter() - t0},
    }  # fmt: skip
    args.out.write_text(json.dumps(result))
    print(f"{len(out_frames)} frames, {t_c / len(out_frames):.2f} s/frame -> {args.out}")
    if args.plot:
        _plot([f.candidates for f in fcs], list(frames), x.camera, args.plot)
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
