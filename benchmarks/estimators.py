"""Stage-3 estimators compared through the whole pipeline on bench cases.

Stages 0-2 run once per case (cached in ``--cache`` as the service's stage file), then stage 3
with each estimator (``bp``, ``in_plane``, ``hybrid``, or those given) and the default stage 4;
prints the scorer's figures (``../shared/bench/score.py``) per case and estimator: temporal
and boundary error, selected and best-candidate E_3B, E_2P, bone-error estimation error, rank
correlation of eps_t' and stage 3's seconds per frame.

    .venv/bin/python benchmarks/estimators.py ../shared/bench/cases/P1_warp_64_29 \
        [more cases] [--estimators bp hybrid] [--set in_plane_prior=0.3] [--cache /tmp/est]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from half_rate import SCORE_KEYS, load_scorer  # benchmarks/ is on sys.path when run as a script

from engine.pipeline import Prepared, candidates, prepare, select
from engine.settings import Settings


def prepared_for(case: Path, cache: Path) -> Prepared:
    path = cache / f"{case.name}_prepared.npz"
    if path.exists():
        return Prepared.load(path)
    p = prepare(case / "reference.bvh", case / "video.mp4")
    p.save(path)
    return p


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="+", type=Path, help="bench case folders")
    ap.add_argument("--estimators", nargs="+", default=["bp", "in_plane", "hybrid"])
    ap.add_argument("--set", nargs="*", default=[], help="candidate settings key=value")
    ap.add_argument("--cache", type=Path, default=Path("/tmp/coach-estimators"))
    args = ap.parse_args(argv)
    args.cache.mkdir(parents=True, exist_ok=True)
    scorer = load_scorer(args.cases[0])
    extra = {k: json.loads(v) for k, v in (kv.split("=", 1) for kv in args.set)}
    keys = SCORE_KEYS
    head = "".join(f"{k:>10s}" for k, _ in keys)
    print(f"{'case':24s} {'estimator':10s}{head}  s3 s/frame")
    for case in args.cases:
        truth = json.loads((case / "truth.json").read_text())
        p = prepared_for(case, args.cache)
        for est in args.estimators:
            settings = Settings.from_dict({"candidates": {**extra, "estimator": est}})
            t0 = time.perf_counter()
            chunks = [candidates(p, r, settings) for r in p.chunks(16)]
            s3 = (time.perf_counter() - t0) / p.n_frames
            s = scorer.score(truth, select(p, chunks, settings))
            row = "".join(f"{s.get(k, float('nan')):10.3f}" for _, k in keys)
            print(f"{case.name[:24]:24s} {est:10s}{row}  {s3:.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
