"""Reference-free capture (issue 23) on the public cases, against their truth, ignoring the
reference.

Per case (``coach capture``'s defaults, the video at its own size):

- **2D**: median distance of the 12 limb points (hips, knees, ankles, shoulders, elbows,
  wrists) to the truth's joints in % of the body's image height: the model's keypoints as it
  labels them (``kp``), the same after choosing per frame the better of the labels and their
  mirror with the truth's help (``kp_lr``), and the capture's own 2D pose after its label
  continuity, gap filling and smoothing (``pose``);
- **3D bone direction** error (deg, mean over the 16 bones and every frame) against the
  truth's ``joints_3d`` after one heading rotation for the whole video, with the automatic
  depth signs (``auto``) and with the truth's signs imposed (``truth_signs``); ``limbs`` is
  ``auto`` over the eight limb bones only;
- **answered**: the same after the questions are answered as a user who sees the truth would
  (the front/back question from the truth's 2D joints, each depth question by the truth's
  majority sign over its span); ``ans_limbs`` over the limb bones;
- **PA-MPJPE** (mm): joint error after a similarity (Procrustes) alignment per frame, automatic;
- **questions** left for the user; **swaps**: frames whose left/right labels were read against
  the model's; **s/frame** of the whole capture (decode, pose model, lift).

    python benchmarks/capture.py [--cases P1 P5 ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
SHARED = REPO.parent / "shared"

from engine.body.kinematics import bone_directions  # noqa: E402
from engine.body.skeleton import JOINTS  # noqa: E402
from engine.capture import CaptureSettings, capture  # noqa: E402
from engine.capture.lifting import FACING, SEGMENTS, S  # noqa: E402
from engine.capture.pose2d import POINT_MIRROR, P, faces_camera  # noqa: E402
from engine.io.video import read_video  # noqa: E402
from engine.stages.perception import perceive  # noqa: E402

LIMB_POINTS = [
    "l_hip",
    "l_knee",
    "l_ankle",
    "r_hip",
    "r_knee",
    "r_ankle",
    "l_shoulder",
    "l_elbow",
    "l_wrist",
    "r_shoulder",
    "r_elbow",
    "r_wrist",
]
LIMB_BONES = [1, 2, 4, 5, 9, 10, 12, 13]


def truth_points(truth: dict, key: str) -> np.ndarray:
    """The truth's joints (T', 17, d) as capture points (T', 15, d): hip and shoulder
    mid-points, the head top for the head."""
    j = np.array([f[key] for f in truth["frames"]], float)
    ix = {n: JOINTS.index(n) for n in JOINTS}
    out = np.empty((j.shape[0], len(P), j.shape[2]))
    for name, i in P.items():
        if name == "neck":
            out[:, i] = 0.5 * (j[:, ix["l_shoulder"]] + j[:, ix["r_shoulder"]])
        elif name == "head":
            out[:, i] = j[:, ix["head_top"]]
        else:
            out[:, i] = j[:, ix[name]]
    return out


def err_2d(uv: np.ndarray, truth: np.ndarray, height_px: float, mirror: bool) -> float:
    """Median limb-point distance (% of height), optionally the better of labels and mirror
    per frame."""
    idx = [P[n] for n in LIMB_POINTS]
    d = np.linalg.norm(uv[:, idx] - truth[:, idx], axis=-1)
    if mirror:
        dm = np.linalg.norm(uv[:, POINT_MIRROR][:, idx] - truth[:, idx], axis=-1)
        pick = np.nanmean(dm, 1) < np.nanmean(d, 1)
        d = np.where(pick[:, None], dm, d)
    return float(100 * np.nanmedian(d) / height_px)


def heading_aligned_error(ours: np.ndarray, truth: np.ndarray, bones: list[int] | None) -> float:
    """Mean bone-direction error (deg) after the one rotation about y that best lays our
    directions on the truth's over the whole video."""
    a, b = bone_directions(ours), bone_directions(truth)
    # best yaw: maximise sum a_rot . b over the xz components (closed form)
    s = np.sum(a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2])
    c = np.sum(a[..., 0] * b[..., 0] + a[..., 2] * b[..., 2])
    th = np.arctan2(s, c)
    R = np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
    ang = np.degrees(np.arccos(np.clip(np.sum((a @ R.T) * b, -1), -1, 1)))
    return float(ang[:, bones].mean() if bones else ang.mean())


def pa_mpjpe_mm(ours: np.ndarray, truth: np.ndarray) -> float:
    """Mean joint error (mm) after a per-frame similarity alignment (Umeyama)."""
    errs = []
    for x, y in zip(ours, truth, strict=True):
        mx, my = x.mean(0), y.mean(0)
        xc, yc = x - mx, y - my
        U, sv, Vt = np.linalg.svd(yc.T @ xc)
        D = np.diag([1, 1, np.sign(np.linalg.det(U @ Vt))])
        R = U @ D @ Vt
        k = np.trace(np.diag(sv) @ D) / np.sum(xc**2)
        errs.append(np.linalg.norm(k * xc @ R.T - yc, axis=-1).mean())
    return float(1000 * np.mean(errs))


def truth_signs(truth: dict, n_frames: int) -> np.ndarray:
    """The truth's depth sign of each capture segment (T', 12) in its camera frame."""
    R = np.array(truth["camera"]["R_cam_world"])
    pts = truth_points(truth, "joints_3d") @ R.T  # camera frame: z away
    a = np.array([P[s[1]] for s in SEGMENTS])
    b = np.array([P[s[2]] for s in SEGMENTS])
    return np.sign(pts[:n_frames, b, 2] - pts[:n_frames, a, 2]).astype(np.int8)


def oracle_answers(cap, truth: dict, signs: np.ndarray) -> dict[str, int]:
    """What a user who knows the truth answers to each question."""
    out = {}
    for q in cap.questions:
        if q.segment == FACING:
            out[q.id] = -1 if faces_camera(truth_points(truth, "joints_2d")) else 1
        else:
            out[q.id] = 1 if signs[q.start : q.end, S[q.segment]].sum() >= 0 else -1
    return out


def run_case(case: Path, s: CaptureSettings) -> dict:
    truth = json.loads((case / "truth.json").read_text())
    ext = json.loads((case / "case.json").read_text())["image_extent_of_body"]
    t0 = time.perf_counter()
    video = read_video(case / "video.mp4", height=0)  # as filmed: the truth's pixels
    perception = perceive(video.frames)
    cap = capture(perception, video.fps, (video.width, video.height), s)
    seconds = time.perf_counter() - t0
    n = cap.joints.shape[0]
    t2d = truth_points(truth, "joints_2d")[:n]
    h = ext["v_max_px"] - ext["v_min_px"]
    j3 = np.array([f["joints_3d"] for f in truth["frames"]], float)[:n]
    size = (video.width, video.height)
    ts = truth_signs(truth, n)
    forced = capture(perception, video.fps, size, s, signs=ts)
    answered = capture(perception, video.fps, size, s, answers=oracle_answers(cap, truth, ts))
    return {
        "case": case.name,
        "frames": n,
        "kp": err_2d(cap.pose.raw, t2d, h, False),
        "kp_lr": err_2d(cap.pose.raw, t2d, h, True),
        "pose": err_2d(cap.pose.uv, t2d, h, False),
        "auto": heading_aligned_error(cap.joints, j3, None),
        "limbs": heading_aligned_error(cap.joints, j3, LIMB_BONES),
        "answered": heading_aligned_error(answered.joints, j3, None),
        "ans_limbs": heading_aligned_error(answered.joints, j3, LIMB_BONES),
        "truth_signs": heading_aligned_error(forced.joints, j3, None),
        "pa_mpjpe": pa_mpjpe_mm(cap.joints, j3),
        "questions": len(cap.questions),
        "swaps": int(cap.pose.swapped.sum()),
        "s_per_frame": seconds / n,
    }


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", nargs="*", default=["P1", "P2", "P3", "P4", "P5", "P6"])
    args = ap.parse_args(argv)
    cases = sorted(
        c
        for c in (SHARED / "bench" / "cases").iterdir()
        if c.is_dir() and c.name.split("_")[0] in args.cases
    )
    cols = [
        "kp",
        "kp_lr",
        "pose",
        "auto",
        "limbs",
        "answered",
        "ans_limbs",
        "truth_signs",
        "pa_mpjpe",
        "questions",
        "swaps",
        "s_per_frame",
    ]
    print(f"{'case':36s} " + " ".join(f"{c:>11s}" for c in cols))
    for case in cases:
        r = run_case(case, CaptureSettings(working_height=0))
        print(
            f"{r['case']:36s} "
            + " ".join(f"{r[c]:11.3f}" if isinstance(r[c], float) else f"{r[c]:11d}" for c in cols),
            flush=True,
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
