"""Thesis 5.1 stage-2 experiments on a public case (figs 5.3-5.7), printed as tables.

    python benchmarks/alignment.py [CASE_DIR] [--stride N]

Computes the cost matrix d(t', t) once over the full band (every ``stride``-th reference
frame), then runs the DP of eq. 4.11 for k in {1,2,4,7,10,20} (beta/L = 50 %) and for
beta/L in {5,10,20,40,100} % (k = 10), reporting E_C (eq. 4.10), the mean |C - C_true| in
reference frames, and the DP time.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from engine.errors import InvalidInput  # noqa: E402
from engine.io.bvh import load_reference  # noqa: E402
from engine.io.video import read_video  # noqa: E402
from engine.stages.alignment import (  # noqa: E402
    AlignmentSettings,
    band_mask,
    cost_entries,
    dp_path,
    half_camera,
    make_targets,
    rotate_about_hip,
    rotation_samples,
    step_costs,
    window_size,
)  # fmt: skip
from engine.stages.calibration import calibrate  # noqa: E402
from engine.stages.foreground import extract_foreground  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("case", nargs="?", default="/work/shared/bench/cases/P1_warp_64_29")
    ap.add_argument("--stride", type=int, default=2, help="reference-frame stride of the matrix")
    a = ap.parse_args()
    case = Path(a.case)
    ref = load_reference(case / "reference.bvh")
    frames = json.loads((case / "truth.json").read_text())["frames"]
    truth = np.array([f["reference_frame"] for f in frames])
    video = read_video(case / "video.mp4")
    fg = extract_foreground(video.frames)
    c0 = ref.motion.first_motion_frame
    joints = ref.motion.joints[c0 :: a.stride]
    cam, _ = calibrate(ref.motion.joints[c0], ref.shape, fg.silhouettes[0], fg.edges[0])
    s = AlignmentSettings()
    posed = rotate_about_hip(joints, rotation_samples(s.yaw_deg, s.tilt_deg))
    targets = make_targets(fg.silhouettes, fg.skin if s.skin_edges else None, s.compare_height)
    n_v, n_r = len(targets), len(joints)
    t0 = time.perf_counter()
    cost, _ = cost_entries(posed, targets, ref.shape, half_camera(cam, s.compare_height),
                           np.ones((n_v, n_r), bool), s)  # fmt: skip
    t_cost = time.perf_counter() - t0
    frames = c0 + a.stride * np.arange(n_r)
    print(f"case {case.name}: {n_v} video frames x {n_r} reference frames (stride {a.stride}); "
          f"cost matrix {t_cost:.1f} s = {1e3 * t_cost / cost.size:.3f} ms per d(t', t) "
          "(shared 2-core machine, noisy)")  # fmt: skip

    def run(k: float, band: float, slope: float = 0.0) -> tuple[float, float, float]:
        mask = band_mask(n_v, n_r, band * (n_r - 1))
        w = window_size(k, n_r, n_v)
        # the shipped DP adds a slope prior (alignment.step_costs); 0 is the thesis' eq. 4.11
        steps = step_costs(w, (n_r - 1) / max(n_v - 1, 1), slope) if slope else None
        t = time.perf_counter()
        try:
            C, total = dp_path(
                np.where(mask, cost, np.inf), window=w, min_step=0, step_cost=steps
            )
        except InvalidInput:
            return np.nan, np.nan, time.perf_counter() - t
        dt = time.perf_counter() - t
        e_c = float(cost[np.arange(n_v), C].mean())  # E_C of eq. 4.10, without the prior
        return e_c, float(np.abs(frames[C] - truth).mean()), dt

    slope = AlignmentSettings().slope_weight
    print(
        "\nwindow (fig 5.3-5.4), beta/L = 50 %; thesis DP, then with the shipped slope prior "
        f"({slope})\n   k    E_C    |C-C_true| ref frames   |  E_C    |C-C_true|"
    )
    for k in (1, 2, 4, 7, 10, 20):
        e, err, _ = run(k, 0.5)
        e2, err2, _ = run(k, 0.5, slope)
        print(f"{k:4d} {e:7.4f} {err:9.2f}              | {e2:7.4f} {err2:9.2f}")
    print(
        "\nband (fig 5.5-5.7), k = 10\nbeta/L  E_C    |C-C_true|  DP ms   |  with slope prior: "
        "E_C  |C-C_true|"
    )
    for b in (0.05, 0.10, 0.20, 0.40, 1.00):
        e, err, dt = run(10, b)
        e2, err2, _ = run(10, b, slope)
        print(f"{100 * b:5.0f}% {e:7.4f} {err:9.2f} {1e3 * dt:8.2f}   | {e2:7.4f} {err2:9.2f}")

if __name__ == "__main__":
    main()
