"""How much smoothing the per-bone errors over time helps (``SelectionSettings.error_*``).

Reads results written by ``benchmarks/cases.py --save`` with the smoothing off, smooths their
per-bone errors as stage 4 would (:func:`engine.stages.selection.smooth_errors`, within each
performer segment: a running median, then a Gaussian) for several settings, and prints the
scorer's rank correlation of eps_t' with the truth and its bone-error estimation error per
case and their mean. Smoothing changes nothing else in the result, so the rest of the
analysis need not be re-run.

    python benchmarks/cases.py --extra --save /tmp/raw \
        --set '{"selection": {"error_smoothing_s": 0, "error_median_frames": 1}}'
    python benchmarks/smoothing.py /tmp/raw [--cache /tmp/coach-cases] [--settings 1:0 3:0.05]

A setting ``M:S`` is a median of M frames, then a Gaussian of std S seconds.
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


def smoothed(result: dict, median_frames: int, sigma_s: float) -> dict:
    """``result`` with its per-bone errors and eps_t' smoothed as stage 4 would."""
    from engine.stages.selection import owned_frames, smooth_errors

    out = copy.deepcopy(result)
    err = np.array([f["bone_errors_deg"] for f in result["frames"]], dtype=float)
    spans = [(s["performer_start"], s["performer_end"]) for s in result["segments"]]
    fps = float(result["video"]["fps"])
    err = smooth_errors(err, owned_frames(spans), sigma_s * fps, median_frames)
    for f, e in zip(out["frames"], err, strict=True):
        f["bone_errors_deg"] = e.tolist()
        f["posture_error_deg"] = float(e.mean())
    return out


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("results", type=Path, help="folder of <case>.json from cases.py --save")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/coach-cases"))
    ap.add_argument(
        "--settings", nargs="+", default=["1:0", "1:0.05", "3:0", "3:0.05", "5:0.05", "3:0.1"],
        help="median frames:Gaussian std seconds",
    )
    args = ap.parse_args(argv)
    scorer = load_scorer(next(PUBLIC.iterdir()))
    files = sorted(args.results.glob("*.json"))
    if not files:
        ap.error(f"no result .json in {args.results}")
    combos = [(int(m), float(g)) for m, g in (c.split(":") for c in args.settings)]
    print(f"{'case':24s}" + "".join(f"{f'{m} / {g:g} s':>16s}" for m, g in combos))
    rows = []
    for path in files:
        case = PUBLIC / path.stem if (PUBLIC / path.stem).exists() else args.cache / path.stem
        truth = json.loads((case / "truth.json").read_text())
        result = json.loads(path.read_text())
        figs = []
        for m, g in combos:
            sc = scorer.score(truth, smoothed(result, m, g))
            figs.append((sc["posture_error_rank_corr"], sc["bone_error_estimation_err_deg"]))
        rows.append(figs)
        print(f"{path.stem[:24]:24s}" + "".join(f"{r:9.3f} /{e:6.2f}" for r, e in figs))
    mean = np.mean(rows, axis=0)
    print(f"{'mean':24s}" + "".join(f"{r:9.3f} /{e:6.2f}" for r, e in mean))
    print("(rank correlation of eps_t' / bone-error estimation error, deg; median frames / std)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
