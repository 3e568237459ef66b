"""`coach capture VIDEO --out motion.bvh [--height 1.80]`: 3D motion from one video, no
reference needed (seed 001; :mod:`engine.capture`).

Prints the questions the capture could not settle on its own, each with an id; run again
with ``--answer ID=towards`` (or ``=away``; ``yes``/``no`` for the facing question) to
settle them.
"""

from __future__ import annotations

import argparse
import sys

from engine.errors import InvalidInput

_WORDS = {"towards": -1, "yes": -1, "away": 1, "no": 1}


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "capture",
        help="capture 3D motion from one video (no reference) and export it as BVH",
        description=(
            "Capture the performer's 3D motion from VIDEO alone: 2D pose from the learned "
            "pose model, each bone's depth from its foreshortening, depth signs chosen from "
            "continuity, joint limits and the model's depth hint (seed 001). Writes a BVH "
            "with root motion, one frame per video frame; the questions it could not settle "
            "are printed (answer them with --answer)."
        ),
    )
    p.add_argument("video", help="video file of one performer, whole body in view")
    p.add_argument("--out", required=True, help="BVH file to write")
    p.add_argument("--height", type=float, default=1.75, help="performer's height, m (1.75)")
    p.add_argument(
        "--skeleton",
        choices=("cmu", "coach"),
        default="cmu",
        help="joint names: CMU's (default, read by most tools) or this project's",
    )
    p.add_argument("--csv", help="also write joint positions and angles per frame here")
    p.add_argument("--json", help="also write a summary (questions, timings) here")
    p.add_argument(
        "--answer",
        action="append",
        default=[],
        metavar="ID=towards|away",
        help="settle a printed question (repeatable)",
    )
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.set_defaults(func=run)


def parse_answers(specs: list[str]) -> dict[str, int]:
    """``["l_forearm@40-62=towards", "facing@0-90=yes"]`` -> {id: -1 or +1}.

    Raises
    ------
    InvalidInput
        A malformed answer (names ``--answer``).
    """
    out = {}
    for spec in specs:
        qid, sep, word = spec.rpartition("=")
        if not sep or "@" not in qid or word.lower() not in _WORDS:
            raise InvalidInput(
                f"--answer must look like ID=towards or ID=away (yes/no for facing), got {spec!r}"
            )
        out[qid] = _WORDS[word.lower()]
    return out


def run(args: argparse.Namespace) -> int:
    from engine.capture import CaptureSettings, capture_video
    from engine.capture.export import write_capture_files

    answers = parse_answers(args.answer)
    s = CaptureSettings(height_m=args.height) if _height_ok(args.height) else None
    progress = None if args.quiet else _progress
    cap = capture_video(args.video, s, answers=answers, on_progress=progress)
    paths = write_capture_files(
        cap, args.out, names=args.skeleton, csv_path=args.csv, json_path=args.json
    )
    if not args.quiet:
        print(file=sys.stderr)
    n = cap.joints.shape[0]
    print(f"captured {n} frames at {cap.fps:.1f} fps -> {', '.join(map(str, paths))}")
    for q in cap.questions:
        print(f"  question {q.id}: {q.text(cap.fps)}")
    if cap.questions:
        print("  answer with --answer ID=towards|away (yes|no for facing) and run again")
    return 0


def _height_ok(height: float) -> bool:
    if not 0.5 <= height <= 2.5:
        raise InvalidInput(f"--height must be between 0.5 and 2.5 m, got {height}")
    return True


def _progress(stage: str, share: float) -> None:
    if round(100 * share) % 5 == 0:  # every 5 %, not every frame
        print(f"\r{stage}: {100 * share:3.0f} %", end="", file=sys.stderr, flush=True)
