"""`coach silhouettes VIDEO --out DIR`: stage 0 (thesis 4.1) on a video, with a contact sheet."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("silhouettes", help="extract the performer's body regions (stage 0)")
    p.add_argument("video", type=Path)
    p.add_argument("--out", type=Path, required=True, help="output folder")
    p.add_argument("--no-grabcut", action="store_true", help="skip the GrabCut refinement")
    p.set_defaults(func=run)


def contact_sheet(frames: np.ndarray, sil: np.ndarray, edges: np.ndarray, skin: np.ndarray,
                  n: int = 12) -> np.ndarray:
    """A grid of ``n`` frames with silhouette (green tint), skin (red) and edges (yellow)."""
    idx = np.linspace(0, len(frames) - 1, n).round().astype(int)
    tiles = []
    for i in idx:
        img = frames[i].astype(np.float32)
        img[sil[i]] = 0.5 * img[sil[i]] + 0.5 * np.array([0, 255, 0])
        img[skin[i]] = 0.5 * img[skin[i]] + 0.5 * np.array([255, 0, 0])
        img[edges[i]] = (255, 255, 0)
        tiles.append(img.astype(np.uint8))
    rows = [np.concatenate(tiles[r : r + 4], 1) for r in range(0, n, 4)]
    return np.concatenate(rows, 0)


def run(args: argparse.Namespace) -> int:
    import cv2

    from engine.io.video import read_video
    from engine.stages.foreground import ForegroundSettings, extract_foreground

    video = read_video(args.video)
    fg = extract_foreground(video.frames, ForegroundSettings(grabcut=not args.no_grabcut))
    args.out.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(args.out / "foreground.npz", silhouettes=fg.silhouettes,
                        edges=fg.edges, skin=fg.skin, background=fg.background)  # fmt: skip
    sheet = contact_sheet(video.frames, fg.silhouettes, fg.edges, fg.skin)
    cv2.imwrite(str(args.out / "contact_sheet.png"), sheet[..., ::-1])
    cv2.imwrite(str(args.out / "background.png"), fg.background[..., ::-1])
    (args.out / "flags.json").write_text(json.dumps(
        {"flags": [list(f) for f in fg.flags], "timing_s": fg.timing_s}, indent=1))  # fmt: skip
    print(f"{video.n_frames} frames -> {args.out} (timing {fg.timing_s})")
    return 0
