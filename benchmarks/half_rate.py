"""Thesis table 5.1 robustness check: the same case at half the frame rate.

Derives a half-rate case from a public case (every other video frame; the truth's frames,
warp and fps subsampled and renumbered), analyses both with ``engine.pipeline.analyze`` and
prints the scorer's temporal and boundary figures side by side. Boundary errors are in video
frames of each case's own rate (thesis: within 2 frames at 25 and 12.5 fps).

    python benchmarks/half_rate.py ../shared/bench/cases/P1_warp_64_29 [--out /tmp/half]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import shutil
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


# the scorer's figures the engine benchmarks print, as (column, score.py key)
SCORE_KEYS = (
    ("temporal", "temporal_err_video_frames"),
    ("boundary", "boundary_err_mean_frames"),
    ("selected", "selected_posture_err_deg"),
    ("best", "best_candidate_err_deg_E3B"),
    ("E2P", "joint_2d_err_px_E2P"),
    ("est.err", "bone_error_estimation_err_deg"),
    ("rank", "posture_error_rank_corr"),
)


def load_scorer(case: Path):
    path = case.parents[1] / "score.py"
    spec = importlib.util.spec_from_file_location("bench_score", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def half_rate_case(case: Path, out: Path) -> Path:
    """Write ``out`` = ``case`` at half the frame rate (even frames kept)."""
    from engine.io.encode import write_video
    from engine.io.video import read_video

    out.mkdir(parents=True, exist_ok=True)
    shutil.copyfile(case / "reference.bvh", out / "reference.bvh")
    video = read_video(case / "video.mp4", height=0)
    write_video(out / "video.mp4", video.frames[::2], video.fps / 2)
    truth = json.loads((case / "truth.json").read_text())
    frames = [dict(f, t=f["t"] // 2) for f in truth["frames"] if f["t"] % 2 == 0]
    truth.update(frames=frames, fps=truth["fps"] / 2, warp=truth["warp"][::2])
    (out / "truth.json").write_text(json.dumps(truth))
    return out


def analyse(case: Path, settings: dict) -> dict:
    from engine.pipeline import analyze
    from engine.settings import Settings

    t0 = time.perf_counter()
    result = analyze(case / "reference.bvh", case / "video.mp4", Settings.from_dict(settings))
    result["timing_s"]["wall"] = time.perf_counter() - t0
    return result


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("case", type=Path)
    ap.add_argument("--out", type=Path, default=Path("/tmp/half_rate"))
    ap.add_argument("--preset", default="default")
    a = ap.parse_args()
    scorer = load_scorer(a.case)
    half = half_rate_case(a.case, a.out / (a.case.name + "_half"))
    keys = ("temporal_err_video_frames", "boundary_err_mean_frames", "boundary_err_max_frames",
            "selected_posture_err_deg", "best_candidate_err_deg_E3B", "seconds_per_video_frame")
    rows = {}
    for name, case in (("full rate", a.case), ("half rate", half)):
        result = analyse(case, {"preset": a.preset})
        truth = json.loads((case / "truth.json").read_text())
        rows[name] = (truth["fps"], scorer.score(truth, result))
    print(f"{'':10s} {'fps':>6s} " + " ".join(f"{k:>28s}" for k in keys))
    for name, (fps, s) in rows.items():
        print(f"{name:10s} {fps:6.1f} " + " ".join(f"{s.get(k, float('nan')):28.3f}" for k in keys))


if __name__ == "__main__":
    main()
