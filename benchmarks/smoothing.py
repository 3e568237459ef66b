"""How much smoothing the per-bone errors over time helps (``SelectionSettings.error_smoothing_s``).

Reads results written by ``benchmarks/cases.py --save`` with the smoothing off, smooths their
per-bone errors as stage 4 would (:func:`engine.stages.selection.smooth_errors`, within each
performer segment) for several kernel widths, and prints the scorer's rank correlation of
eps_t' with the truth and its bone-error estimation error per case and their mean. Smoothing
changes nothing else in the result, so the rest of the analysis need not be re-run.

    python benchmarks/cases.py --set '{"selection": {"error_smoothing_s": 0}}' --save /tmp/raw
    python benchmarks/smoothing.py /tmp/raw [--cache /tmp/coach-cases] [--sigmas 0 0.05 0.1]
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np
from half_rate import load_scorer  # benchmarks/ is on sys.path when run as a script

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
PUBLIC = REPO.parent / "shared" / "bench" / "cases"


def smoothed(result: dict, sigma_s: float) -> dict:
    """``result`` with its per-bone errors and eps_t' smoothed over ``sigma_s`` seconds."""
    from engine.stages.selection import smooth_errors

    out = copy.deepcopy(result)
    err = np.array([f["bone_errors_deg"] for f in result["frames"]], dtype=float)
    spans = [(s["performer_start"], s["performer_end"]) for s in result["segments"]]
    err = smooth_errors(err, spans, sigma_s * float(result["video"]["fps"]))
    for f, e in zip(out["frames"], err, strict=True):
        f["bone_errors_deg"] = e.tolist()
        f["posture_error_deg"] = float(e.mean())
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path, help="folder of <case>.json from cases.py --save")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/coach-cases"))
    ap.add_argument("--sigmas", type=float, nargs="+", default=[0, 0.033, 0.05, 0.1, 0.15])
    args = ap.parse_args(argv)
    scorer = load_scorer(next(PUBLIC.iterdir()))
    files = sorted(args.results.glob("*.json"))
    if not files:
        ap.error(f"no result .json in {args.results}")
    print(f"{'case':24s}" + "".join(f"{f'{s:g} s':>16s}" for s in args.sigmas))
    rows = []
    for path in files:
        case = PUBLIC / path.stem if (PUBLIC / path.stem).exists() else args.cache / path.stem
        truth = json.loads((case / "truth.json").read_text())
        result = json.loads(path.read_text())
        figs = []
        for s in args.sigmas:
            sc = scorer.score(truth, smoothed(result, s))
            figs.append((sc["posture_error_rank_corr"], sc["bone_error_estimation_err_deg"]))
        rows.append(figs)
        print(f"{path.stem[:24]:24s}" + "".join(f"{r:9.3f} /{e:6.2f}" for r, e in figs))
    mean = np.mean(rows, axis=0)
    print(f"{'mean':24s}" + "".join(f"{r:9.3f} /{e:6.2f}" for r, e in mean))
    print("(rank correlation of eps_t' / bone-error estimation error, deg)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
