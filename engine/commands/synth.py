"""`coach synth REF.bvh OUT_DIR`: a synthetic performer video with exact ground truth."""

from __future__ import annotations

import argparse
import time

import numpy as np


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "synth",
        help="make a synthetic performer case (reference.bvh, video.mp4, truth.json)",
        description=(
            "Synthesise a performer of a reference BVH: per-segment timing changes, wrong "
            "segments with articulated parts, rendered with the mesh body (thesis 2.1, table 2.1)."
        ),
    )
    p.add_argument("reference", help="reference BVH file")
    p.add_argument("out_dir", help="case folder to write")
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument("--fps", type=float, default=30.0, help="video frame rate (default 30)")
    p.add_argument(
        "--warp-strength",
        type=float,
        default=0.25,
        help="sd of each segment's log speed (default 0.25)",
    )
    p.add_argument(
        "--error-deg",
        type=float,
        default=20.0,
        help="articulation amplitude of wrong segments, degrees (default 20)",
    )
    p.add_argument("--n-wrong", type=int, default=2, help="number of wrong segments (default 2)")
    p.add_argument(
        "--parts-per-wrong",
        type=int,
        default=3,
        help="parts articulated per wrong segment (default 3)",
    )
    p.add_argument(
        "--error-parts",
        nargs="+",
        default=None,
        metavar="PART",
        help="parts (or their root joints) that may be articulated",
    )
    p.add_argument("--yaw-deg", type=float, default=0.0, help="global yaw of the performer")
    p.add_argument("--width", type=int, default=320, help="image width (default 320)")
    p.add_argument("--height", type=int, default=240, help="image height (default 240)")
    p.add_argument(
        "--azimuth-deg",
        type=float,
        default=0.0,
        help="camera azimuth, 0 = front, 90 = the body's left side",
    )
    p.add_argument(
        "--noise-sigma",
        type=float,
        default=2.0,
        help="Gaussian sensor noise, grey levels (default 2)",
    )
    p.add_argument("--max-frames", type=int, default=None, help="keep only the first N frames")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from engine.io.bvh import load_reference
    from engine.io.case import write_case
    from engine.synth import SynthSettings, synthesize

    settings = SynthSettings(
        fps=args.fps,
        width=args.width,
        height=args.height,
        warp_strength=args.warp_strength,
        error_deg=args.error_deg,
        n_wrong=args.n_wrong,
        parts_per_wrong=args.parts_per_wrong,
        error_parts=tuple(args.error_parts) if args.error_parts else None,
        yaw_deg=args.yaw_deg,
        azimuth_deg=args.azimuth_deg,
        noise_sigma=args.noise_sigma,
        max_frames=args.max_frames,
    )
    t0 = time.perf_counter()
    reference = load_reference(args.reference)
    case = synthesize(reference, settings=settings, rng=np.random.default_rng(args.seed))
    written = write_case(case, args.out_dir, args.reference)
    print(summary(case.truth, written, time.perf_counter() - t0))
    return 0


def summary(truth: dict, written: dict, seconds: float) -> str:
    """A few lines saying what a case holds."""
    v = truth["video"]
    lines = [
        f"wrote {written['dir']}: {v['frames']} frames {v['width']}x{v['height']} at "
        f"{v['fps']:g} fps ({written['codec']}), reference {truth['reference']['name']} "
        f"({truth['reference']['frames']} frames at {truth['reference_fps']:.0f} fps), "
        f"{seconds:.1f} s",
    ]
    for k, s in enumerate(truth["segments"]):
        what = (
            f"WRONG {s['amplitude_deg']:g} deg: {', '.join(s['articulated_parts'])}"
            if s["wrong"]
            else "right"
        )
        lines.append(
            f"  segment {k}: reference {s['reference_start']}-{s['reference_end']} -> video "
            f"{s['performer_start']:.1f}-{s['performer_end']:.1f} (speed {s['speed']:.2f}), {what}"
        )
    return "\n".join(lines)
