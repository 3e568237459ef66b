"""`coach demo`: synthesise a short performer of the bundled CMU golf swing and write the case."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from engine.errors import InvalidInput

#: The demo reference, relative to the repository (the shared data sits beside the clone).
DEMO_REFERENCE = Path("..") / "shared" / "data" / "cmu" / "64_29.bvh"


def _repo_root() -> Path:
    return Path(__file__).resolve().parents[2]


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "demo",
        help="make a demo synthetic case from the CMU golf swing 64_29",
        description="Synthesise a short performer of ../shared/data/cmu/64_29.bvh and write "
        "the case folder (reference.bvh, video.mp4, truth.json).",
    )
    p.add_argument("--out", default="demo_case", help="case folder (default ./demo_case)")
    p.add_argument(
        "--reference",
        default=None,
        help=f"reference BVH (default {DEMO_REFERENCE} from the repository)",
    )
    p.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from engine.commands.synth import summary
    from engine.io.bvh import load_reference
    from engine.io.case import write_case
    from engine.synth import SynthSettings, synthesize

    ref_path = Path(args.reference) if args.reference else _repo_root() / DEMO_REFERENCE
    if not ref_path.is_file():
        raise InvalidInput(
            f"demo reference {ref_path} is missing: put the shared data beside the clone "
            f"(../shared/data/cmu/64_29.bvh) or pass --reference FILE.bvh"
        )
    settings = SynthSettings(
        fps=25.0, width=320, height=240, n_wrong=2, error_deg=20.0, noise_sigma=2.0
    )
    t0 = time.perf_counter()
    case = synthesize(
        load_reference(ref_path), settings=settings, rng=np.random.default_rng(args.seed)
    )
    written = write_case(case, args.out, ref_path)
    print(summary(case.truth, written, time.perf_counter() - t0))
    print(
        f"play {written['video']}; score an analysis with "
        f"python ../shared/bench/score.py {written['dir']} RESULT.json"
    )
    return 0
