"""The whole engine on the real clips of ``../shared/data/real`` (no ground truth: judge by eye).

For each clip, ``engine.pipeline.analyze`` against its reference, then a contact sheet of 8
frames spread over the video with the reported skeleton drawn over it (green; the pose
model's keypoints as white dots) into ``--out`` (keep those images out of the repository),
and one line of what the result says: status, messages, mean error, fit, camera, seconds.

    python benchmarks/real_videos.py --out /tmp/real [--only golf]
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

from engine.body.skeleton import BONE_CHILD, BONE_PARENT  # noqa: E402

#: clip, reference (the data README's pairing)
CLIPS = (
    ("golf_dtl.mov", "63_01.bvh"),
    ("squat_front_5fps.mp4", "64_17.bvh"),
    ("squat_side_barbell.mp4", "64_17.bvh"),
)


def contact_sheet(video: Path, result: dict, out: Path, n: int = 8) -> None:
    """``n`` frames spread over the video, the reported skeleton drawn, in a 4-wide grid."""
    cap = cv2.VideoCapture(str(video))
    frames = []
    while True:
        ok, f = cap.read()
        if not ok:
            break
        frames.append(f)
    cap.release()
    by_t = {f["t"]: f for f in result["frames"]}
    # over the analysed frames: the whole video, or the repetition analysed of several
    ts = sorted(by_t)
    picks = np.linspace(ts[0], min(ts[-1], len(frames) - 1), n).round().astype(int)
    tiles = []
    for t in picks:
        img = frames[t].copy()
        f = by_t.get(int(t))
        if f is not None:
            j = np.asarray(f["joints_2d"])
            w = max(2, img.shape[0] // 200)
            for a, b in zip(BONE_PARENT, BONE_CHILD, strict=True):
                cv2.line(img, tuple(int(v) for v in j[a]), tuple(int(v) for v in j[b]),
                         (0, 220, 0), w, cv2.LINE_AA)  # fmt: skip
            cv2.putText(img, f"t={t} C={f['reference_frame']} {f['posture_error_deg']:.0f}deg",
                        (10, 30), cv2.FONT_HERSHEY_SIMPLEX, 0.8, (0, 255, 255), 2)  # fmt: skip
        scale = 360 / img.shape[0]
        tiles.append(cv2.resize(img, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA))
    width = max(t.shape[1] for t in tiles)
    tiles = [cv2.copyMakeBorder(t, 0, 0, 0, width - t.shape[1], cv2.BORDER_CONSTANT) for t in tiles]
    rows = [np.hstack(tiles[i : i + 4]) for i in range(0, len(tiles), 4)]
    cv2.imwrite(str(out), np.vstack(rows))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, required=True, help="folder for sheets and results")
    ap.add_argument("--only", default="", help="only the clips whose name contains this")
    ap.add_argument("--set", default="{}", help="settings overrides (JSON)")
    args = ap.parse_args()
    from engine.errors import EngineError
    from engine.pipeline import analyze
    from engine.settings import Settings

    args.out.mkdir(parents=True, exist_ok=True)
    for clip, ref in CLIPS:
        if args.only not in clip:
            continue
        video = SHARED / "data" / "real" / clip
        t0 = time.perf_counter()
        try:
            result = analyze(
                SHARED / "data" / "cmu" / ref, video, Settings.from_dict(json.loads(args.set))
            )
        except EngineError as exc:
            print(f"{clip}: refused: {exc}")
            continue
        dt = time.perf_counter() - t0
        stem = Path(clip).stem
        (args.out / f"{stem}.json").write_text(json.dumps(result))
        contact_sheet(video, result, args.out / f"{stem}.png")
        s, cam = result["summary"], result["camera"]
        print(f"{clip}: status {s['status']}, mean error {s['mean_error_deg']:.1f} deg, "
              f"region mismatch {s['fit']['region_mismatch_median']:.2f}, camera azimuth "
              f"{cam['azimuth_deg']:.0f} roll {cam['theta_z_deg']:.0f} deg, "
              f"{dt / len(result['frames']):.2f} s/frame")  # fmt: skip
        for m in s["messages"]:
            print(f"   - {m}")


if __name__ == "__main__":
    main()
