"""Wall time of ``coach analyze`` on public cases, and the scorer's figures of each result.

    python benchmarks/analyze_speed.py [--cases P2 P4 P5] [--code /path/to/checkout] \
        [--out /tmp/speed] [--preset fast]

One case at a time, each in a fresh process (nothing else should run meanwhile), after a
warm-up run on three frames of P1 that fills numba's on-disk cache, so no case pays for
compilation. ``--code`` runs another checkout of this repository (``git worktree add``) with
this one's virtualenv: the way to time "before" and "after" in one session on one machine.
Prints seconds, seconds per video frame, and the scorer's coach-facing figures.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CASES = REPO.parent / "shared" / "bench" / "cases"
SCORE = REPO.parent / "shared" / "bench" / "score.py"
KEYS = (
    "temporal_err_video_frames", "boundary_err_max_frames", "best_candidate_err_deg_E3B",
    "joint_2d_err_pct_height", "posture_error_rank_corr", "bone_rank_corr",
    "error_magnitude_ratio", "segment_error_rank_corr",
)  # fmt: skip
SHORT = ("temporal", "bnd.max", "best", "E2P%", "rank", "bone.rk", "mag", "seg.rk")


def case_dir(name: str) -> Path:
    found = sorted(CASES.glob(f"{name}_*")) or sorted(CASES.glob(name))
    if not found:
        raise SystemExit(f"no case {name} in {CASES}")
    return found[0]


def analyze(code: Path, case: Path, out: Path, extra: list[str]) -> float:
    """Run ``coach analyze`` from checkout ``code``; returns its wall seconds."""
    env = dict(os.environ, PYOPENGL_PLATFORM="egl", PYTHONPATH=str(code))
    cmd = [sys.executable, "-c", "from app.cli import main; main()", "analyze",
           str(case / "reference.bvh"), str(case / "video.mp4"), "--out", str(out),
           "--quiet", *extra]  # fmt: skip
    t0 = time.perf_counter()
    subprocess.run(cmd, env=env, cwd=code, check=True, stderr=subprocess.DEVNULL)
    return time.perf_counter() - t0


def score(case: Path, result: Path) -> dict:
    run = subprocess.run(
        [sys.executable, str(SCORE), str(case), str(result), "--json"],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    try:
        return json.loads(run.stdout)
    except ValueError:
        return {}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=["P2", "P4", "P5"])
    ap.add_argument("--code", type=Path, default=REPO, help="checkout to run (default: this)")
    ap.add_argument("--out", type=Path, default=Path("/tmp/coach-speed"))
    ap.add_argument("--preset", default="", help="coach analyze --preset (default: none)")
    ap.add_argument("--workers", type=int, help="coach analyze --workers (default: its own)")
    args = ap.parse_args()
    extra = ["--preset", args.preset] if args.preset else []
    if args.workers:
        extra += ["--workers", str(args.workers)]
    args.out.mkdir(parents=True, exist_ok=True)
    analyze(args.code, case_dir("P1"), args.out / "warmup.json", [*extra, "--frames", "0:3"])
    print(f"code: {args.code.resolve()}")
    print(f"{'case':<26} {'s':>7} {'s/frame':>8} " + " ".join(f"{k:>8}" for k in SHORT))
    for name in args.cases:
        case = case_dir(name)
        result = args.out / f"{case.name}.json"
        seconds = analyze(args.code, case, result, extra)
        frames = len(json.loads(result.read_text())["frames"])
        figures = score(case, result)
        cells = " ".join(f"{figures.get(k, float('nan')):8.3f}" for k in KEYS)
        print(f"{case.name[:26]:<26} {seconds:7.1f} {seconds / frames:8.3f} {cells}", flush=True)


if __name__ == "__main__":
    main()
