"""Stage 3 on key frames only (issue 25): what it saves and what it costs, on the public cases.

Each case is prepared once (stages 0-2, the default settings); then stages 3-4 run once per
variant, stage 3 on ``--workers`` processes, and the scorer's figures are printed with stage
3's wall time. The variants are the full search (``key_gap`` 1), the same with another random
seed (the yardstick: a change smaller than a new seed's is noise), and key frames with the
gaps and motion thresholds given.

    python benchmarks/key_frames.py [--cases P1 P2 ...] [--gaps 3] [--motion 4 2] [--workers 2]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from cases import COACH_KEYS  # benchmarks/ is on sys.path when run as a script
from half_rate import SCORE_KEYS, load_scorer

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
CASES = REPO.parent / "shared" / "bench" / "cases"
KEYS = (*SCORE_KEYS, *COACH_KEYS)


def variants(gaps: list[int], motions: list[float]) -> dict[str, dict]:
    """Settings overrides by name: the full search, another seed, and each key-frame pair."""
    out: dict[str, dict] = {"full": {}, "seed 1": {"seed": 1}}
    for g in gaps:
        for m in motions:
            out[f"gap {g}, {m:g} deg"] = {"candidates": {"key_gap": g, "key_motion_deg": m}}
    return out


def run_case(case: Path, runs: dict[str, dict], workers: int) -> list[tuple[str, float, dict]]:
    """(variant, stage-3 seconds, scores) for each variant of ``runs`` on ``case``."""
    from engine.pipeline import all_candidates, prepare, select
    from engine.settings import Settings

    prepared = prepare(case / "reference.bvh", case / "video.mp4", Settings())
    truth = json.loads((case / "truth.json").read_text())
    scorer = load_scorer(case)
    rows = []
    for name, override in runs.items():
        s = Settings.from_dict(override)
        t0 = time.perf_counter()
        chunks = all_candidates(prepared, s, workers=workers)
        seconds = time.perf_counter() - t0
        scores = scorer.score(truth, select(prepared, chunks, s))
        rows.append((name, seconds / prepared.n_frames, scores))
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=["P1", "P2", "P3", "P4", "P5", "P6"])
    ap.add_argument("--gaps", nargs="+", type=int, default=[3])
    ap.add_argument("--motion", nargs="+", type=float, default=[4.0, 2.0])
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args()
    runs = variants(args.gaps, args.motion)
    print(f"{'case':5s}{'variant':16s}{'s3 s/fr':>9s}" + "".join(f"{k:>9s}" for k, _ in KEYS))
    for name in args.cases:
        case = next(iter(sorted(CASES.glob(f"{name}_*"))), None)
        if case is None:
            raise SystemExit(f"no case {name} in {CASES}")
        for variant, per_frame, s in run_case(case, runs, args.workers):
            figures = "".join(f"{s.get(k, float('nan')):9.3f}" for _, k in KEYS)
            print(f"{name:5s}{variant:16s}{per_frame:9.3f}" + figures, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
