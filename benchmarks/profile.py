"""Where an analysis spends its time: seconds per stage, and the top functions of stage 3
(posture candidates) and of stage 4 (selection), profiled with cProfile.

    python benchmarks/profile.py [--cases P2 P4] [--top 15] [--settings '{"preset": "fast"}']

One process, one case after another (nothing else should run meanwhile). The stage times are
the engine's own (``timing_s``: load, perception, foreground, calibration, alignment,
candidates, selection); stage 3 and 4 run under the profiler, which adds about 10-30 % to
them. Functions are sorted by their own time (``tottime``), with their cumulative time and
call count, so a hot loop shows where it is, not in its callers.
"""

from __future__ import annotations

import sys
from pathlib import Path

# Run as a script, this file's folder comes first on sys.path, and this module's name would
# shadow the standard library's ``profile``, which cProfile imports.
sys.path[:] = [p for p in sys.path if Path(p or ".").resolve() != Path(__file__).resolve().parent]

import argparse  # noqa: E402
import cProfile  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import pstats  # noqa: E402
import time  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
CASES = REPO.parent / "shared" / "bench" / "cases"

from engine.pipeline import candidates, prepare, select  # noqa: E402
from engine.settings import Settings  # noqa: E402


def case_dir(name: str) -> Path:
    """``P2`` -> ``../shared/bench/cases/P2_...``."""
    found = sorted(CASES.glob(f"{name}_*")) or sorted(CASES.glob(name))
    if not found:
        raise SystemExit(f"no case {name} in {CASES}")
    return found[0]


def top_functions(profile: cProfile.Profile, n: int) -> str:
    """The ``n`` functions with the most own time, as pstats prints them."""
    out = io.StringIO()
    stats = pstats.Stats(profile, stream=out)
    stats.strip_dirs().sort_stats("tottime").print_stats(n)
    lines = out.getvalue().splitlines()
    start = next(i for i, line in enumerate(lines) if line.lstrip().startswith("ncalls"))
    return "\n".join(lines[start : start + n + 1])


def run(case: Path, settings: Settings, n: int, dump: Path | None = None) -> None:
    t0 = time.perf_counter()
    prepared = prepare(case / "reference.bvh", case / "video.mp4", settings)
    t_prepare = time.perf_counter() - t0
    stage3 = cProfile.Profile()
    t0 = time.perf_counter()
    stage3.enable()
    chunks = [
        candidates(prepared, r, settings)
        for r in prepared.chunks(max(1, -(-prepared.n_frames // settings.chunk_frames)))
    ]
    stage3.disable()
    t_stage3 = time.perf_counter() - t0
    stage4 = cProfile.Profile()
    t0 = time.perf_counter()
    stage4.enable()
    doc = select(prepared, chunks, settings)
    stage4.disable()
    t_stage4 = time.perf_counter() - t0
    if dump is not None:  # for pstats' callers/callees, or snakeviz
        dump.mkdir(parents=True, exist_ok=True)
        stage3.dump_stats(dump / f"{case.name}-stage3.prof")
        stage4.dump_stats(dump / f"{case.name}-stage4.prof")
    frames = prepared.n_frames
    total = t_prepare + t_stage3 + t_stage4
    print(f"\n## {case.name}: {frames} frames, {total:.1f} s ({total / frames:.2f} s/frame)")
    print("seconds per stage (the engine's timing_s; stages 3-4 under the profiler):")
    for stage, secs in doc["timing_s"].items():
        if stage != "total":
            print(f"  {stage:>12} {secs:7.2f}  ({secs / frames:.3f} s/frame)")
    print(f"  {'prepare':>12} {t_prepare:7.2f}  wall, stages 0-2")
    print(f"\nstage 3 (candidates), {t_stage3:.1f} s wall, top {n} by own time:")
    print(top_functions(stage3, n))
    print(f"\nstage 4 (selection), {t_stage4:.1f} s wall, top {n} by own time:")
    print(top_functions(stage4, n))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="+", default=["P2", "P4"])
    ap.add_argument("--top", type=int, default=15)
    ap.add_argument("--settings", default="{}", help="settings overrides as JSON")
    ap.add_argument("--dump", type=Path, help="also save each profile here (.prof files)")
    args = ap.parse_args()
    settings = Settings.from_dict(json.loads(args.settings))
    for name in args.cases:
        run(case_dir(name), settings, args.top, args.dump)


if __name__ == "__main__":
    main()
