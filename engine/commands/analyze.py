"""`coach analyze REF.bvh VIDEO --out result.json [--report report.html]`: the whole registration.

Runs :func:`engine.pipeline.analyze` (thesis 4.1-4.7) in this process and writes the result
JSON of DESIGN.md, plus an optional self-contained HTML report.
"""

from __future__ import annotations

import argparse
import os
from pathlib import Path

from engine.errors import InvalidInput


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "analyze",
        help="register a performer video against a reference BVH and report posture errors",
        description=(
            "Register VIDEO against REF.bvh (thesis chapter 4): temporal correspondence, "
            "posture candidates, selection, per-frame/bone/segment errors. A domain file "
            "REF.domain.json beside the BVH (thesis 6.8) names segments and weights bones."
        ),
    )
    p.add_argument("reference", help="reference BVH file")
    p.add_argument("video", help="performer video file")
    p.add_argument("--out", required=True, help="result JSON to write")
    p.add_argument("--report", help="also write a self-contained HTML report here")
    p.add_argument("--frames", help="analyse only video frames A:B (Python slice, B exclusive)")
    p.add_argument("--fast", action="store_true", help="fewer samples and candidates (previews)")
    p.add_argument(
        "--preset", choices=("default", "fast", "thesis"),
        help="settings preset: 'thesis' runs the thesis' evidence alone, without the learned "
        "pose model (--fast is --preset fast)",
    )  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--workers", type=int, default=len(os.sched_getaffinity(0)),
        help="cores to use: processes for the posture candidates, the longest stage, and "
        "threads for stages 0-2 (default: every core); the result is the same with any number",
    )  # fmt: skip
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run)


def parse_frames(spec: str | None, n: int) -> tuple[int, int]:
    """``"A:B"`` -> (A, B) clipped to [0, n]; None -> (0, n).

    Raises
    ------
    InvalidInput
        Malformed or empty range (names ``--frames``).
    """
    if not spec:
        return 0, n
    parts = spec.split(":")
    try:
        if len(parts) != 2:
            raise ValueError
        a = int(parts[0]) if parts[0] else 0
        b = int(parts[1]) if parts[1] else n
    except ValueError as exc:
        raise InvalidInput(f"--frames: expected A:B (e.g. 10:200), got {spec!r}") from exc
    a, b = max(0, a if a >= 0 else n + a), min(n, b if b >= 0 else n + b)
    if b - a < 2:
        raise InvalidInput(
            f"--frames: {spec!r} leaves {max(b - a, 0)} frames of {n}; need at least 2"
        )
    return a, b


def _progress(quiet: bool):
    def report(stage: str, fraction: float) -> None:
        if not quiet:
            print(f"\r{stage:>12s} {100 * fraction:5.1f} %", end="", flush=True)

    return report


def read_video_count(path: str) -> int:
    """Frame count of a video, refusing unreadable files before any work starts."""
    from engine.io.video import probe_video

    return int(probe_video(path).frames)


def run(args: argparse.Namespace) -> int:
    from engine.io.result import write_result, write_text
    from engine.io.result_reader import Result
    from engine.report import build_report_html

    for name in ("reference", "video"):
        if not Path(getattr(args, name)).exists():
            raise InvalidInput(f"{name}: {getattr(args, name)} does not exist")
    from engine.io.video import read_video
    from engine.pipeline import analyze
    from engine.reference.domain import find_domain
    from engine.settings import Settings

    if args.workers < 1:
        raise InvalidInput(f"--workers must be >= 1, got {args.workers}")
    n = read_video_count(args.video)
    frames = parse_frames(args.frames, n) if args.frames else None
    preset = args.preset or ("fast" if args.fast else "default")
    settings = Settings.from_dict({
        "preset": preset, "seed": args.seed,
        "foreground": {"threads": args.workers}, "alignment": {"threads": args.workers},
    })  # fmt: skip
    doc = analyze(
        args.reference, args.video, settings, domain=find_domain(args.reference),
        frames=frames, workers=args.workers, on_progress=_progress(args.quiet),
    )  # fmt: skip
    write_result(doc, args.out)
    result = Result.from_dict(doc)
    if not args.quiet:
        summary = result.summary
        print(f"\nwrote {args.out}: {summary.status}, mean posture error "
              f"{summary.mean_error_deg:.1f} deg")  # fmt: skip
        for m in summary.messages:
            print(f"  {m}")
    if args.report:
        # the analysed frames: those asked for, or the first of several repetitions
        a = result.video.first_frame
        b = a + len(result.frames)
        video = read_video(args.video, height=result.video.height, max_frames=b)
        write_text(build_report_html(result, video.frames[a:b]), args.report)
        if not args.quiet:
            print(f"wrote {args.report}")
    return 0
