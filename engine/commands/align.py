"""`coach align REF.bvh VIDEO --out align.json [--plot matrix.png]`: stages 0-2 (thesis 4.1-4.5).

Writes the DESIGN.md result fields stage 2 knows: ``camera``, ``frames`` (``t``,
``reference_frame`` = C(t'), ``rotation`` = T_t'), ``video``, ``reference`` and ``timing_s``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "align", help="temporal alignment of a video to a BVH reference (stages 0-2)"
    )
    p.add_argument("reference", type=Path, help="reference motion, BVH")
    p.add_argument("video", type=Path, help="performer's video")
    p.add_argument("--out", type=Path, required=True, help="result JSON")
    p.add_argument(
        "--plot", type=Path, help="PNG of the cost matrix with the path (thesis fig. 5.1)"
    )
    p.add_argument("--k", type=float, default=10.0, help="window factor k (w = kL/L')")
    p.add_argument("--band", type=float, default=0.25, help="band half-width beta/L")
    p.add_argument("--float-ends", type=int, default=0, help="let C(0), C(L') float (frames)")
    p.add_argument("--max-frames", type=int, help="read at most this many video frames")
    p.set_defaults(func=run)


def plot_matrix(cost: np.ndarray, C: np.ndarray, path: Path) -> None:
    """Cost matrix (dark = similar) with the path in yellow, t' up (thesis fig. 5.1)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    m = np.where(np.isfinite(cost), cost, np.nan)
    fig, ax = plt.subplots(figsize=(8, 3.5), dpi=120)
    ax.imshow(m, origin="lower", aspect="auto", cmap="gray", interpolation="nearest")
    ax.plot(C, np.arange(len(C)), ".", color="yellow", ms=2)
    ax.set_xlabel("reference frame t")
    ax.set_ylabel("video frame t'")
    ax.set_title("d(t', t) and the approximate correspondence C")
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)


def run(args: argparse.Namespace) -> int:
    from engine.io.bvh import load_reference
    from engine.io.video import read_video
    from engine.pipeline import run_stages_0_2
    from engine.settings import Settings
    from engine.stages.alignment import AlignmentSettings

    t_all = time.perf_counter()
    t0 = time.perf_counter()
    ref = load_reference(args.reference)
    t_ref = time.perf_counter() - t0
    t0 = time.perf_counter()
    video = read_video(args.video) if args.max_frames is None else \
        read_video(args.video, max_frames=args.max_frames)  # fmt: skip
    t_video = time.perf_counter() - t0
    settings = AlignmentSettings(
        k=args.k, band_fraction=args.band, float_start=args.float_ends, float_end=args.float_ends
    )
    st = run_stages_0_2(ref, video, Settings(alignment=settings))
    fg, camera, res, timing = st.foreground, st.camera, st.alignment, st.timing_s
    timing = {"read_reference": t_ref, "read_video": t_video, **timing}
    timing["total"] = time.perf_counter() - t_all
    out = {
        "version": 1,
        "reference": {"name": ref.motion.name, "frames": ref.motion.frames,
                      "fps": float(ref.motion.fps)},
        "video": video.to_dict(),
        "camera": camera.to_dict(),
        "frames": [
            {"t": int(t), "reference_frame": int(c), "rotation": r.round(6).tolist(),
             "flags": list(fl)}
            for t, (c, r, fl) in enumerate(zip(res.C, res.rotations, fg.flags, strict=True))
        ],
        "alignment": {"E_C": res.E_C, "one_to_one_relaxed": bool(res.relaxed)},
        "body_width_factors": st.width_factors,
        "timing_s": {k: round(float(v), 4) for k, v in timing.items()},
    }  # fmt: skip
    args.out.parent.mkdir(parents=True, exist_ok=True)
    tmp = args.out.with_suffix(args.out.suffix + ".tmp")
    tmp.write_text(json.dumps(out, indent=1))
    tmp.replace(args.out)
    if args.plot:
        plot_matrix(res.cost, res.C, args.plot)
    print(f"aligned {video.n_frames} frames to {ref.motion.frames} reference frames "
          f"in {timing['total']:.1f} s -> {args.out}")  # fmt: skip
    return 0
