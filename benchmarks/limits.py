"""What the silhouette can tell: the public cases' remaining errors against the image itself.

For each case, stages 0-2 run once (``engine.pipeline.prepare``); then, with the engine's
camera and fitted body and d_S as stage 3 computes it (full resolution, d_A only):

1. **timing**: in the frames where stage 2's C(t') is more than one video frame from the
   truth's, d_S of the reference posture at each; how often the image itself prefers the
   engine's timing (then no search or DP over this likelihood can find the truth's);
2. **visibility**: the performer's true deviation from the reference at the true timing
   (E_3B, deg) against what it moves in the image (mean 2D joint displacement with the hips
   put together, px), per frame and overall;
3. **the likelihood's own minimum**: stage 3's in-plane search on d_S alone (no prior)
   started at the truth's posture; how far it walks (E_3B deg, E_2P px) and whether it ends
   lower than the truth. A likelihood whose minimum is far from the truth makes any
   estimator that trusts it wander.

    python benchmarks/limits.py [CASE ...] [--every N]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
SHARED = REPO.parent / "shared"


def _true_C(prepared, truth: dict) -> tuple[np.ndarray, np.ndarray]:
    """The truth's C(t'), (T',) fractional, and rounded to a reference frame index (T',)."""
    C = np.array([f["reference_frame"] for f in truth["frames"]], float)
    top = len(prepared.reference_joints) - 1
    return C, np.clip(np.round(C), 0, top).astype(int)


def _timing(prepared, truth: dict, ratio: float) -> str:
    from engine.render.capsules import Target, d_S_batch

    C_true, idx = _true_C(prepared, truth)
    off = np.flatnonzero(np.abs(prepared.C - C_true) / ratio > 1.0)
    if len(off) == 0:
        return "timing: stage 2 is within one video frame of the truth everywhere"
    ours, theirs = [], []
    for t in off:
        target = Target.from_masks(prepared.silhouettes[t], prepared.edges[t])
        both = prepared.reference_joints[[prepared.C[t], idx[t]]]
        d = d_S_batch(both, target, prepared.shape, prepared.camera, lambda_E=0.0)
        ours.append(d[0])
        theirs.append(d[1])
    o, th = np.array(ours), np.array(theirs)
    return (
        f"timing: {len(off)} frames more than 1 video frame off; d_S ours {o.mean():.3f}, "
        f"truth's {th.mean():.3f}; the image prefers ours in {np.mean(o < th):.0%} of them"
    )


def _visibility(prepared, truth: dict) -> str:
    from engine.measures import d_B

    ref = prepared.reference_joints[_true_C(prepared, truth)[1]]
    gt = np.array([f["joints_3d"] for f in truth["frames"]], float)
    e3 = np.degrees(d_B(ref, gt))
    p, g = prepared.camera.project(ref), prepared.camera.project(gt)
    moved = np.linalg.norm((p - p[:, :1]) - (g - g[:, :1]), axis=-1).mean(-1)
    dev = e3 > 2.0
    per_deg = (moved[dev] / e3[dev]).mean() if dev.any() else float("nan")
    return (
        f"visibility: true deviation {e3.mean():.2f} deg moves the joints {moved.mean():.2f} px "
        f"(hips together); {per_deg:.2f} px per deg where it exceeds 2 deg; body height "
        f"{np.ptp(g[..., 1], axis=-1).mean():.0f} px"
    )


def _own_minimum(prepared, truth: dict, every: int) -> str:
    from engine.measures import d_B
    from engine.stages.candidates import CandidateSettings, estimate_candidates

    s = CandidateSettings(estimator="in_plane", in_plane_prior=0.0, n_candidates=1)
    rng = np.random.default_rng(0)
    walked, e2p, lower = [], [], []
    for t in range(0, prepared.n_frames, every):
        gt = np.asarray(truth["frames"][t]["joints_3d"], float)
        fc = estimate_candidates(
            prepared.silhouettes[t], prepared.edges[t], prepared.camera, prepared.shape,
            gt, settings=s, rng=rng,
        )  # fmt: skip
        walked.append(np.degrees(d_B(fc.candidates[0], gt)))
        cam = prepared.camera
        e2p.append(np.linalg.norm(cam.project(fc.candidates[0]) - cam.project(gt), -1).mean())
        lower.append(fc.d_s[0] < fc.history[0] - 1e-9)
    return (
        f"own minimum: from the truth, d_S alone walks {np.mean(walked):.2f} deg (median "
        f"{np.median(walked):.2f}; joints {np.mean(e2p):.2f} px, median {np.median(e2p):.2f}) "
        f"to a lower d_S in {np.mean(lower):.0%} of {len(walked)} frames"
    )


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*", type=Path)
    ap.add_argument("--every", type=int, default=4, help="frame stride of part 3")
    args = ap.parse_args(argv)
    from engine.pipeline import prepare

    cases = args.cases or sorted((SHARED / "bench" / "cases").iterdir())
    for case in cases:
        truth = json.loads((case / "truth.json").read_text())
        prepared = prepare(case / "reference.bvh", case / "video.mp4")
        ratio = truth["reference_fps"] / truth["fps"]
        print(case.name)
        print("  " + _timing(prepared, truth, ratio))
        print("  " + _visibility(prepared, truth))
        print("  " + _own_minimum(prepared, truth, args.every), flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
