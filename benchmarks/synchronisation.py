"""Seed 002's synchronisation measured: known warps of a real take, then the real takes.

    python benchmarks/synchronisation.py [--takes 10] [--band 0.1] [--plot-dir DIR]

1. Synthetic: ``--takes`` takes made from the CMU golf swing 63_01 by known smooth monotonic
   warps (length 0.8-1.25 times, a sine of one or two periods on top, the rate varying by up
   to 30 % or 60 %) with small posture noise (3 mm or 1 cm per joint). Each is synchronised
   back to 63_01: mu = 0 (DTW), eq. 20's rule of thumb, and that followed by the sub-frame
   refinement (the default, ``refine_warp``). Prints the recovered
   warp's mean and max error in frames, its roughness (sum of |second differences|), and
   the time per pair and for building the whole set's model (every pair, seed 002 eq. 19).
2. Real: every ``63_*`` swing, and 64_29 / 64_30. Prints the frame of the key events of each
   take in the median take's time before (linear stretch, eq. 7) and after synchronisation:
   top of the backswing and impact for golf (slowest and fastest hands), the lowest point
   of the head for the bend-down.
"""

from __future__ import annotations

import argparse
import glob
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.io.bvh import load_reference  # noqa: E402
from engine.reference.action_model import Take, TakesSettings, build_action_model  # noqa: E402
from engine.reference.posture_space import ActionSpace, posture_vectors  # noqa: E402
from engine.reference.synchronisation import interpolate, synchronise  # noqa: E402

CMU = Path(__file__).resolve().parents[2] / "shared" / "data" / "cmu"


def synthetic_takes(
    take: Take, n: int, rng: np.random.Generator, *, amplitude: float, noise_m: float
) -> list[tuple[Take, np.ndarray]]:
    """``n`` warped copies of ``take`` with the true positions (P,) of each pattern frame.

    Each is 0.8-1.25 times as long, with a sine of one or two periods on top of the linear
    warp: the local rate varies by up to ``amplitude`` (0.3: from 0.7 to 1.3 times); plus
    Gaussian noise of ``noise_m`` on every joint."""
    P = len(take.joints)
    out = []
    for k in range(n):
        F = int(round(P * rng.uniform(0.8, 1.25)))
        a, periods = rng.uniform(0.1, amplitude), int(rng.integers(1, 3))
        s = np.linspace(0.0, 1.0, F)
        # h(s) = s + a sin(2 pi k s) / (2 pi k): monotonic for a < 1, h(0) = 0, h(1) = 1
        h = s + a * np.sin(2 * np.pi * periods * s) / (2 * np.pi * periods)
        src = h * (P - 1)  # frame of the pattern shown at each new frame
        joints = interpolate(take.joints, src) + rng.normal(0.0, noise_m, (F, 17, 3))
        truth = np.interp(np.arange(P), src, np.arange(F, dtype=float))  # inverse warp
        out.append((Take(f"warp{k}", joints, take.fps, take.shape), truth))
    return out


def run_synthetic(n_takes: int, band: float) -> None:
    base = Take.from_reference(load_reference(CMU / "63_01.bvh"))
    speed = np.linalg.norm(np.diff(base.joints, axis=0), axis=-1).max(-1) * base.fps
    moving = np.concatenate([[False], speed > 0.3])  # frames where some joint moves > 0.3 m/s
    print(
        f"synthetic: {n_takes} warps of 63_01 ({len(base.joints)} frames, "
        f"{moving.mean():.0%} of them moving), band {band:g}; errors in frames, "
        "all frames / moving frames only (a still posture has no timing to recover)"
    )
    print(f"{'rate +-':>7} {'noise':>6} {'mu':>8} {'mean err':>12} {'max err':>12} "
          f"{'roughness':>9} {'ms/pair':>8}")  # fmt: skip
    for amplitude in (0.3, 0.6):
        for noise in (0.003, 0.01):
            takes = synthetic_takes(base, n_takes, np.random.default_rng(0),
                                    amplitude=amplitude, noise_m=noise)  # fmt: skip
            psi0 = posture_vectors(base.joints, base.shape.offsets)
            psis = [posture_vectors(t.joints, t.shape.offsets) for t, _ in takes]
            space = ActionSpace.fit(np.concatenate([psi0, *psis]))
            x0 = space.project(psi0)
            for label, mu, refine in (("0 (DTW)", 0.0, False), ("eq. 20", None, False),
                                      ("+ refine", None, True)):  # fmt: skip
                err, err_m, mx, mx_m, rough, secs = [], [], [], [], [], []
                for (_, truth), psi in zip(takes, psis, strict=True):
                    t0 = time.perf_counter()
                    s = synchronise(x0, space.project(psi), mu=mu, band=band, refine=refine)
                    secs.append(time.perf_counter() - t0)
                    e = np.abs(s.positions - truth)
                    err.append(e.mean())
                    err_m.append(e[moving].mean())
                    mx.append(e.max())
                    mx_m.append(e[moving].max())
                    rough.append(s.roughness)
                print(f"{amplitude:7.1f} {100 * noise:4.1f}cm {label:>8} "
                      f"{np.mean(err):5.2f} / {np.mean(err_m):4.2f} "
                      f"{np.max(mx):5.1f} / {np.max(mx_m):4.1f} {np.mean(rough):9.1f} "
                      f"{1000 * np.mean(secs):8.1f}")  # fmt: skip
            truth_rough = np.mean([np.abs(np.diff(t, 2)).sum() for _, t in takes])
            print(f"{'':7} {'':6} {'truth':>8} {'':12} {'':12} {truth_rough:9.1f}")
    takes = synthetic_takes(base, n_takes - 1, np.random.default_rng(0), amplitude=0.3,
                            noise_m=0.003)  # fmt: skip
    t0 = time.perf_counter()
    model = build_action_model([base] + [t for t, _ in takes], TakesSettings(band=band))
    print(
        f"a set of {n_takes} takes (every pair, median, model): "
        f"{time.perf_counter() - t0:.2f} s; median take {model.names[model.median]}"
    )


def golf_events(joints: np.ndarray, fps: float) -> dict[str, int]:
    """Impact: fastest hands; top of the backswing: slowest hands in the 0.8 s before it."""
    hands = joints[:, [11, 14]].mean(1)
    speed = np.linalg.norm(np.diff(hands, axis=0), axis=1) * fps
    impact = int(np.argmax(speed))
    lo, hi = max(0, impact - int(0.8 * fps)), max(1, impact - int(0.08 * fps))
    return {"top": lo + int(np.argmin(speed[lo:hi])), "impact": impact}


def bend_events(joints: np.ndarray, fps: float) -> dict[str, int]:
    """The bottom of the bend: the head's lowest point."""
    return {"bottom": int(np.argmin(joints[:, 16, 1]))}


def run_real(files: list[str], events, band: float, plot_dir: Path | None) -> None:
    takes = [Take.from_reference(load_reference(f)) for f in files]
    for label, mu in (("mu 0 (DTW)", 0.0), ("mu eq. 20", None)):
        t0 = time.perf_counter()
        model = build_action_model(takes, TakesSettings(mu=mu, band=band))
        dt = time.perf_counter() - t0
        P = len(model.mean_joints)
        print(f"\n{label}: {len(takes)} takes in {dt:.2f} s, median {model.names[model.median]} "
              f"({P} frames), aSpace {model.space.dims} dims")  # fmt: skip
        rows = {}
        for i in np.flatnonzero(model.kept):
            ev = events(takes[i].joints, takes[i].fps)
            F = len(takes[i].joints)
            sync = model.syncs[i]
            rows[model.names[i]] = {
                k: (round(v * (P - 1) / (F - 1)), int(np.argmin(np.abs(sync.positions - v))))
                for k, v in ev.items()
            }
            print(f"  {model.names[i]:>6}: " + "  ".join(
                f"{k} {v} -> linear {a:4d}, synchronised {b:4d}"
                for (k, v), (a, b) in zip(ev.items(), rows[model.names[i]].values(), strict=True)
            ) + f"   roughness {sync.roughness:6.1f}")  # fmt: skip
        for k in next(iter(rows.values())):
            lin = [r[k][0] for r in rows.values()]
            syn = [r[k][1] for r in rows.values()]
            print(f"  {k}: spread over the takes {max(lin) - min(lin)} frames linear, "
                  f"{max(syn) - min(syn)} synchronised")  # fmt: skip
        if plot_dir is not None and mu is None:
            from engine.reference.takes_plot import plot_takes

            plot_dir.mkdir(parents=True, exist_ok=True)
            path = plot_dir / f"sync_{Path(files[0]).stem}.png"
            plot_takes(model, path)
            print(f"  plot {path}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--takes", type=int, default=10)
    ap.add_argument("--band", type=float, default=TakesSettings().band)
    ap.add_argument("--plot-dir", type=Path, default=None)
    args = ap.parse_args()
    run_synthetic(args.takes, args.band)
    run_real(sorted(glob.glob(str(CMU / "63_*.bvh"))), golf_events, args.band, args.plot_dir)
    run_real([str(CMU / "64_29.bvh"), str(CMU / "64_30.bvh")], bend_events, args.band,
             args.plot_dir)  # fmt: skip


if __name__ == "__main__":
    main()
