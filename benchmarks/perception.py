"""Stage 0's learned perception on the public cases: masks and keypoints against the truth.

Per case, at the engine's working resolution (240 rows):

- **mask**: the body region of the learned mask alone (MediaPipe > 0.5), of the thesis' method
  (``ForegroundSettings(fuse_learned=False)``) and of the fused one, against the truth body.
  The generator's mesh wears clothes and shoes, our capsules do not, so (as the stage-0 test
  does) ``prec`` is the share of the region within the capsule body (truth postures, the
  reference's shape, the truth camera) dilated by 4 px, ``rec`` the share of the capsule body
  the region covers, and ``iou`` the IoU with the capsule body dilated by 2 px;
- **keypoints**: the median distance of the 12 limb keypoints to the truth's joints (px and %
  of the body's height in the image), as labelled and after choosing per frame the better of
  the labels and their mirror; the share of frames where the mirror fits better (``swap``)
  and where no person was found (``miss``);
- **ms/frame** of the pose model.

    python benchmarks/perception.py [CASE ...]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import cv2
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
SHARED = REPO.parent / "shared"

from engine.body.skeleton import JOINTS  # noqa: E402
from engine.io.bvh import load_reference  # noqa: E402
from engine.io.video import read_video  # noqa: E402
from engine.render import capsules  # noqa: E402
from engine.render.camera import Camera  # noqa: E402
from engine.stages.foreground import ForegroundSettings, extract_foreground  # noqa: E402
from engine.stages.perception import MIRROR, perceive  # noqa: E402

LIMBS = [JOINTS.index(n) for n in (
    "l_hip", "l_knee", "l_ankle", "r_hip", "r_knee", "r_ankle", "l_shoulder", "l_elbow",
    "l_wrist", "r_shoulder", "r_elbow", "r_wrist")]  # fmt: skip


def truth_bodies(
    case: Path, n: int, height: int, width: int
) -> tuple[np.ndarray, np.ndarray, float]:
    """Capsule bodies of the truth postures at the working size, (T', H, W) bool; the truth's
    2D joints scaled to it, (T', 17, 2); and the factor from the video's pixels."""
    truth = json.loads((case / "truth.json").read_text())
    cam = Camera.from_dict(truth["camera"])
    # the truth's azimuth_deg turns the other way than ours: take the view from its rotation
    # (our camera x axis at azimuth a is (cos a, 0, -sin a))
    R = np.array(truth["camera"]["R_cam_world"])
    k = height / cam.height
    cam = Camera(scale=cam.scale * k, theta_z=cam.theta_z, cx=(cam.cx + 0.5) * k - 0.5,
                 cy=(cam.cy + 0.5) * k - 0.5, azimuth=float(np.arctan2(-R[0, 2], R[0, 0])),
                 width=width, height=height)  # fmt: skip
    shape = load_reference(case / "reference.bvh").shape
    j3 = np.array([f["joints_3d"] for f in truth["frames"][:n]])
    j2 = (np.array([f["joints_2d"] for f in truth["frames"][:n]]) + 0.5) * k - 0.5
    return capsules.silhouettes(j3, shape, cam), j2, k


def mask_scores(region: np.ndarray, body: np.ndarray) -> tuple[float, float, float]:
    """Mean precision, recall and IoU of regions (T', H, W) against capsule bodies."""
    k4 = np.ones((9, 9), np.uint8)
    k2 = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5))
    p, r, iou = [], [], []
    for s, m in zip(region, body, strict=True):
        big = cv2.dilate(m.astype(np.uint8), k4) > 0
        mid = cv2.dilate(m.astype(np.uint8), k2) > 0
        p.append((s & big).sum() / max(s.sum(), 1))
        r.append((s & m).sum() / max(m.sum(), 1))
        iou.append((s & mid).sum() / max((s | mid).sum(), 1))
    return float(np.mean(p)), float(np.mean(r)), float(np.mean(iou))


def keypoint_scores(perc, j2: np.ndarray) -> dict[str, float]:
    det = perc.detected
    kp, t = perc.keypoints[det][:, LIMBS], j2[det][:, LIMBS]
    kpm = perc.keypoints[det][:, MIRROR][:, LIMBS]
    e = np.linalg.norm(kp - t, axis=-1)
    em = np.linalg.norm(kpm - t, axis=-1)
    swap = em.mean(1) < e.mean(1)
    best = np.where(swap[:, None], em, e)
    height = np.ptp(j2[..., 1], axis=1).max()
    return {
        "px": float(np.median(e)), "px_resolved": float(np.median(best)),
        "pct_resolved": float(100 * np.median(best) / height),
        "swap": float(swap.mean()), "miss": float(1 - det.mean()),
    }  # fmt: skip


def run(case: Path) -> None:
    v = read_video(case / "video.mp4")
    f = v.frames
    t0 = time.perf_counter()
    perc = perceive(f)
    ms = 1000 * (time.perf_counter() - t0) / len(f)
    body, j2, _ = truth_bodies(case, len(f), f.shape[1], f.shape[2])
    thesis = extract_foreground(f, ForegroundSettings(fuse_learned=False)).silhouettes
    fused = extract_foreground(f, learned=perc.mask).silhouettes
    learned = perc.person()
    det = perc.detected
    print(f"{case.name}  ({len(f)} frames, {f.shape[2]}x{f.shape[1]}, {ms:.0f} ms/frame)")
    for name, region in (("learned", learned), ("thesis", thesis), ("fused", fused)):
        p, r, iou = mask_scores(region, body)
        pd, rd, iod = mask_scores(region[det], body[det]) if det.any() else (np.nan,) * 3
        print(f"  mask {name:8s} prec {p:.3f} rec {r:.3f} iou {iou:.3f}   "
              f"(detected frames: prec {pd:.3f} rec {rd:.3f} iou {iod:.3f})")  # fmt: skip
    k = keypoint_scores(perc, j2)
    print(f"  keypoints  {k['px']:.1f} px as labelled, {k['px_resolved']:.1f} px "
          f"({k['pct_resolved']:.1f} % of height) after left/right; swap {100 * k['swap']:.0f} %"
          f", miss {100 * k['miss']:.0f} %")  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("cases", nargs="*", help="case folder names (default: every public case)")
    args = ap.parse_args()
    root = SHARED / "bench" / "cases"
    names = args.cases or sorted(p.name for p in root.iterdir() if (p / "truth.json").exists())
    for name in names:
        run(root / name)


if __name__ == "__main__":
    main()
