"""Files the pages serve: a browser-playable video, skeleton thumbnails, CSV and BVH exports.

Everything here is a plain function of paths and result documents (no request objects), so
the routes stay thin and the functions are testable on their own.
"""

from __future__ import annotations

import csv
import io
import os
import threading
from fractions import Fraction
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from engine.body.skeleton import BONE_CHILD, BONE_NAMES, BONE_PARENT, JOINTS

#: Longest side of the browser rendition; phones do not need more and encoding stays quick.
MAX_RENDITION_HEIGHT = 720
_locks: dict[str, threading.Lock] = {}
_locks_guard = threading.Lock()


def _lock_for(key: str) -> threading.Lock:
    with _locks_guard:
        return _locks.setdefault(key, threading.Lock())


# ---- browser-playable video
def playable_video(video_path: str | Path, work_dir: str | Path) -> Path:
    """An H.264/yuv420p MP4 of the upload at ``<work_dir>/web/video.mp4``, made on first use.

    Uploads may be HEVC or MPEG-4 Part 2, which Chromium cannot play; frames are re-encoded
    one by one (no whole-video array in memory), rotation metadata applied, one output frame
    per decoded frame so that frame t' of the result is at t' / fps in the browser.
    """
    out = Path(work_dir) / "web" / "video.mp4"
    if out.is_file():
        return out
    with _lock_for(str(out)):
        if out.is_file():
            return out
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".video.{os.getpid()}.{threading.get_ident()}.mp4")
        try:
            _transcode(Path(video_path), tmp)
            os.replace(tmp, out)
        finally:
            tmp.unlink(missing_ok=True)
    return out


def _transcode(src: Path, dst: Path) -> None:
    import av

    faststart = {"movflags": "+faststart"}  # playable while it downloads
    with av.open(str(src)) as inp, av.open(str(dst), "w", format="mp4", options=faststart) as out:
        ins = inp.streams.video[0]
        rate = ins.average_rate or ins.guessed_rate or Fraction(30)
        rate = Fraction(rate).limit_denominator(1001)
        try:
            st = out.add_stream("libx264", rate=rate, options={"crf": "23", "preset": "veryfast"})
        except Exception:  # no libx264 in this PyAV: still a file, though not H.264
            st = out.add_stream("mpeg4", rate=rate)
        st.pix_fmt = "yuv420p"
        size = None
        for i, frame in enumerate(inp.decode(ins)):
            rgb = frame.to_ndarray(format="rgb24")
            rot = int(getattr(frame, "rotation", 0) or 0) % 360
            if rot:
                rgb = np.ascontiguousarray(np.rot90(rgb, k=rot // 90))
            if size is None:
                h, w = rgb.shape[:2]
                scale = min(1.0, MAX_RENDITION_HEIGHT / h)
                size = (max(2, int(w * scale) // 2 * 2), max(2, int(h * scale) // 2 * 2))
                st.width, st.height = size
            vf = av.VideoFrame.from_ndarray(rgb, format="rgb24").reformat(
                width=size[0], height=size[1], format="yuv420p"
            )
            vf.pts = i
            vf.time_base = 1 / rate
            for pkt in st.encode(vf):
                out.mux(pkt)
        for pkt in st.encode():
            out.mux(pkt)


# ---- skeleton pictures
@lru_cache(maxsize=16)
def _reference_joints(path: str, mtime: float) -> np.ndarray:
    from engine.io.bvh import load_reference

    return np.asarray(load_reference(path).motion.joints, float)


def reference_joints(path: str | Path) -> np.ndarray:
    """Reference joints (T, 17, 3), world frame, frames as in the BVH file (cached)."""
    p = str(path)
    return _reference_joints(p, os.path.getmtime(p))


def skeleton_svg(postures: np.ndarray, *, height: int = 120, label: str = "") -> str:
    """Front view (x right, y up) of postures (N, 17, 3) side by side, as a small SVG."""
    postures = np.asarray(postures, float).reshape(-1, len(JOINTS), 3)
    xy = postures[..., :2].copy()
    xy[..., 0] = -xy[..., 0]  # facing +z: the body's left on the picture's right
    lo, hi = xy.reshape(-1, 2).min(0), xy.reshape(-1, 2).max(0)
    span_y = max(hi[1] - lo[1], 1e-6)
    scale = (height - 12) / span_y
    cell = max((hi[0] - lo[0]) * scale, height * 0.45) + 12
    lines = []
    for n, p in enumerate(xy):
        cx = n * cell + cell / 2 - (p[:, 0].min() + p[:, 0].max()) / 2 * scale
        u = cx + p[:, 0] * scale
        v = height - 6 - (p[:, 1] - lo[1]) * scale
        for b in range(len(BONE_NAMES)):
            i, j = int(BONE_PARENT[b]), int(BONE_CHILD[b])
            lines.append(f'<line x1="{u[i]:.1f}" y1="{v[i]:.1f}" x2="{u[j]:.1f}" y2="{v[j]:.1f}"/>')
        hx, hy = u[JOINTS.index("head_top")], v[JOINTS.index("head_top")]
        lines.append(f'<circle cx="{hx:.1f}" cy="{hy + 5:.1f}" r="5"/>')
    width = int(cell * len(xy))
    title = f"<title>{_esc(label)}</title>" if label else ""
    return (
        f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height}" '
        f'width="{width}" height="{height}" role="img">{title}'
        f'<rect width="100%" height="100%" fill="#f4f6fa"/>'
        f'<g stroke="#3b5bdb" stroke-width="3" stroke-linecap="round" fill="#3b5bdb">'
        + "".join(lines)
        + "</g></svg>"
    )


def _esc(s: str) -> str:
    return s.replace("&", "&amp;").replace("<", "&lt;").replace(">", "&gt;").replace('"', "&quot;")


def reference_thumbnail(path: str | Path, first_frame: int = 0) -> str:
    j = reference_joints(path)
    return skeleton_svg(j[min(max(first_frame, 0), len(j) - 1)][None])


def reference_strip(path: str | Path, boundaries: list[int], first_frame: int = 0) -> str:
    """Postures at the segment boundaries (or 6 evenly spaced frames) as one strip."""
    j = reference_joints(path)
    frames = sorted({int(f) for f in boundaries if 0 <= int(f) < len(j)})
    if len(frames) < 2:
        frames = np.linspace(first_frame, len(j) - 1, 6).round().astype(int).tolist()
    return skeleton_svg(j[frames], height=140)


# ---- exports
def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


#: Joint angle columns: (name, parent bone, bone); the angle between consecutive bones.
JOINT_ANGLES = tuple(
    (f"angle_{JOINTS[int(BONE_PARENT[b])]}_deg:{BONE_NAMES[pb]}|{BONE_NAMES[b]}", pb, b)
    for b in range(len(BONE_NAMES))
    for pb in range(len(BONE_NAMES))
    if int(BONE_CHILD[pb]) == int(BONE_PARENT[b])
)


def joint_angles_deg(joints: np.ndarray) -> np.ndarray:
    """Angles (deg) between consecutive bones of postures (T, 17, 3) -> (T, len(JOINT_ANGLES))."""
    j = np.asarray(joints, float)
    d = _unit(j[:, BONE_CHILD] - j[:, BONE_PARENT])
    pb = [a[1] for a in JOINT_ANGLES]
    b = [a[2] for a in JOINT_ANGLES]
    cos = np.clip((d[:, pb] * d[:, b]).sum(-1), -1.0, 1.0)
    return np.degrees(np.arccos(cos))


def result_csv(result: dict[str, Any]) -> str:
    """One row per video frame: timing, errors per bone, the performer's joint angles."""
    frames = result.get("frames") or []
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(
        ["t", "time_s", "reference_frame", "selected", "posture_error_deg"]
        + [f"error_deg:{b}" for b in BONE_NAMES]
        + [a[0] for a in JOINT_ANGLES]
    )
    fps = float((result.get("video") or {}).get("fps") or 0) or 1.0
    joints = np.array([f["joints_3d"] for f in frames], float).reshape(-1, len(JOINTS), 3)
    angles = joint_angles_deg(joints) if len(frames) else np.zeros((0, len(JOINT_ANGLES)))
    for f, a in zip(frames, angles, strict=True):
        w.writerow(
            [f["t"], f"{f['t'] / fps:.4f}", f["reference_frame"], f.get("selected", 0),
             f"{float(f['posture_error_deg']):.3f}"]
            + [f"{float(e):.3f}" for e in f["bone_errors_deg"]]
            + [f"{float(x):.3f}" for x in a]
        )  # fmt: skip
    return buf.getvalue()


def result_bvh(result: dict[str, Any], dest: Path) -> Path:
    """The performer's selected motion (joints_3d with root motion) as BVH at ``dest``."""
    from engine.io.bvh import write_bvh

    frames = result.get("frames") or []
    joints = np.array([f["joints_3d"] for f in frames], float).reshape(-1, len(JOINTS), 3)
    fps = float((result.get("video") or {}).get("fps") or 30.0)
    return write_bvh(dest, joints, fps)


def error_plot_svg(result: dict[str, Any], *, width: int = 720, height: int = 180) -> str:
    """eps_t' over the video frames with segment boundaries, as an inline SVG (printable)."""
    frames = result.get("frames") or []
    if not frames:
        return ""
    err = np.array([f["posture_error_deg"] for f in frames], float)
    top = max(float(np.nanmax(err)) if np.isfinite(err).any() else 1.0, 10.0) * 1.1
    n = max(len(frames) - 1, 1)
    pad = 30

    def x(i: float) -> float:
        return pad + (width - pad - 6) * i / n

    def y(v: float) -> float:
        return 6 + (height - 26) * (1 - v / top)

    pts = " ".join(f"{x(i):.1f},{y(v):.1f}" for i, v in enumerate(np.nan_to_num(err)))
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height}" '
             f'class="plot" role="img" aria-label="posture error per frame">']  # fmt: skip
    for s in result.get("segments") or []:
        parts.append(
            f'<line x1="{x(s["performer_start"]):.1f}" x2="{x(s["performer_start"]):.1f}" '
            f'y1="6" y2="{height - 20}" stroke="#999" stroke-dasharray="3 3"/>'
        )
    for v in np.linspace(0, top, 4)[:-1]:
        parts.append(f'<text x="2" y="{y(v) + 4:.1f}" font-size="10">{v:.0f}&#176;</text>')
    parts.append(f'<polyline points="{pts}" fill="none" stroke="#c92a2a" stroke-width="2"/>')
    parts.append(f'<text x="{pad}" y="{height - 4}" font-size="10">frame 0</text>')
    parts.append(f'<text x="{width - 60}" y="{height - 4}" font-size="10">frame {n}</text>')
    parts.append("</svg>")
    return "".join(parts)
