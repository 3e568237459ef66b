"""Capture step 4: the captured motion as files other tools read.

- BVH, one frame per video frame, root motion included, in our skeleton's names or CMU's
  (:data:`engine.io.bvh.write.CMU_NAMES`); the bone lengths are constant, so the file's
  joints are the capture's exactly (:func:`engine.io.bvh.load_reference` reads it back).
- CSV: per frame the time, each joint's position and every joint angle.
"""

from __future__ import annotations

import csv
import io
import json
import os
from pathlib import Path
from typing import TYPE_CHECKING

from engine.body.limits import JOINT_ANGLES, joint_angles_deg
from engine.body.skeleton import JOINTS
from engine.io.bvh import write_bvh

if TYPE_CHECKING:
    from engine.capture import Capture


def write_capture_bvh(cap: Capture, path: str | os.PathLike, *, names: str = "cmu") -> Path:
    """Write the capture as BVH (``names``: ``"cmu"`` or ``"coach"``)."""
    return write_bvh(path, cap.joints, cap.fps, cap.shape, names=names)


def capture_csv(cap: Capture) -> str:
    """One row per video frame: frame, time, the 17 joints (x, y, z in metres, DESIGN.md's
    world frame) and the angle between each pair of consecutive bones (degrees)."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(
        [
            "t",
            "time_s",
            *(f"{j}_{a}_m" for j in JOINTS for a in "xyz"),
            *(a[0] for a in JOINT_ANGLES),
        ]
    )
    angles = joint_angles_deg(cap.joints)
    for t, (p, a) in enumerate(zip(cap.joints, angles, strict=True)):
        w.writerow(
            [t, f"{t / cap.fps:.4f}", *(f"{x:.5f}" for x in p.ravel()), *(f"{x:.3f}" for x in a)]
        )
    return buf.getvalue()


def write_capture_files(
    cap: Capture,
    bvh: str | os.PathLike,
    *,
    names: str = "cmu",
    csv_path: str | os.PathLike | None = None,
    json_path: str | os.PathLike | None = None,
) -> list[Path]:
    """Write the BVH and, when asked, the CSV and the summary JSON; the paths written."""
    out = [write_capture_bvh(cap, bvh, names=names)]
    if csv_path is not None:
        out.append(Path(csv_path))
        out[-1].write_text(capture_csv(cap))
    if json_path is not None:
        out.append(Path(json_path))
        out[-1].write_text(json.dumps(cap.summary(), indent=1))
    return out
