"""Where the errors come from: the engine with the truth's timing or camera put in its place.

For each case, stages 0-2 run once (``engine.pipeline.prepare``); stages 3-4 then run on

- ``pipeline``: stage 2's C(t') and stage 1's camera (the figures ``coach analyze`` gives),
- ``true_C``: the truth's C(t') (rounded), our camera,
- ``true_camera``: our C(t'), the truth's camera (its scaled orthographic fields),

and the scorer's figures are printed per variant. A figure that improves a lot with an
oracle says which stage limits it. Each variant costs one stage-3 run (~0.5 s per frame).

    python benchmarks/oracles.py [CASE ...] [--variants pipeline true_C true_camera]
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

import numpy as np
from half_rate import SCORE_KEYS as KEYS  # benchmarks/ is on sys.path when run as a script
from half_rate import load_scorer

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
SHARED = REPO.parent / "shared"
VARIANTS = ("pipeline", "true_C", "true_camera")


def with_oracle(prepared, truth: dict, variant: str):
    """``prepared`` with the truth's C(t') or camera in place of the engine's."""
    from engine.render.camera import Camera

    if variant == "true_C":
        c = np.array([f["reference_frame"] for f in truth["frames"]], float)
        top = len(prepared.reference_joints) - 1
        return dataclasses.replace(prepared, C=np.clip(np.round(c), 0, top).astype(int))
    if variant == "true_camera":
        cam = Camera.from_dict(truth["camera"])
        k = prepared.camera.height / cam.height  # the truth's pixels -> working resolution
        cam = dataclasses.replace(
            cam, scale=cam.scale * k, cx=(cam.cx + 0.5) * k - 0.5, cy=(cam.cy + 0.5) * k - 0.5,
            width=prepared.camera.width, height=prepared.camera.height,
        )  # fmt: skip
        return dataclasses.replace(prepared, camera=cam)
    if variant != "pipeline":
        raise SystemExit(f"unknown variant {variant!r}; choose from {VARIANTS}")
    return prepared


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*", type=Path)
    ap.add_argument("--variants", nargs="+", default=list(VARIANTS), choices=VARIANTS)
    args = ap.parse_args(argv)
    from engine.pipeline import candidates, prepare, select

    cases = args.cases or sorted((SHARED / "bench" / "cases").iterdir())
    scorer = load_scorer(next((SHARED / "bench" / "cases").iterdir()))
    print(f"{'case':24s}{'variant':>12s}" + "".join(f"{k:>10s}" for k, _ in KEYS))
    for case in cases:
        truth = json.loads((case / "truth.json").read_text())
        prepared = prepare(case / "reference.bvh", case / "video.mp4")
        for variant in args.variants:
            p = with_oracle(prepared, truth, variant)
            s = scorer.score(truth, select(p, [candidates(p)]))
            row = "".join(f"{s.get(k, float('nan')):10.3f}" for _, k in KEYS)
            print(f"{case.name[:24]:24s}{variant:>12s}{row}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
