"""Files the API serves: a browser-playable video, skeleton thumbnails, CSV and BVH exports.

Everything here is a plain function of paths and results (no request objects), so the routes
stay thin and the functions are testable on their own. A result is a
:class:`engine.io.result_reader.Result` or its document; a malformed document raises
:class:`engine.errors.InvalidInput`.
"""

from __future__ import annotations

import csv
import io
import os
import threading
from collections.abc import Callable, Mapping
from fractions import Fraction
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from worker.engine_surface import (
    BONE_CHILD,
    BONE_LABELS,
    BONE_NAMES,
    BONE_PARENT,
    JOINT_ANGLES,
    JOINTS,
    MISFIT_RGB,
    Result,
    as_result,
    column_name,
    draw_skeleton,
    joint_angles_deg,
    load_reference,
    write_bvh,
)

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
    return _made_once(
        Path(work_dir) / "web" / "video.mp4", lambda tmp: _transcode(Path(video_path), tmp)
    )


def _made_once(out: Path, write: Callable[[Path], None]) -> Path:
    """``out``, written by ``write(tmp)`` on first use: one writer per file at a time, and
    an atomic rename so that readers never see half a file."""
    if out.is_file():
        return out
    with _lock_for(str(out)):
        if out.is_file():
            return out
        out.parent.mkdir(parents=True, exist_ok=True)
        tmp = out.with_name(f".{out.stem}.{os.getpid()}.{threading.get_ident()}{out.suffix}")
        try:
            write(tmp)
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


#: Width of the list pages' thumbnails (twice their CSS size, for high-density screens).
THUMBNAIL_WIDTH = 160


def video_thumbnail(video_path: str | Path, work_dir: str | Path, frame: int = 0) -> Path:
    """A small JPEG of video frame ``frame`` (rotation applied, as the page shows it) at
    ``<work_dir>/web/thumbnail.jpg``, made on first use.

    Raises
    ------
    ValueError
        The video holds no frame ``frame``, or cannot be decoded.
    """
    import av
    import cv2

    def write(tmp: Path) -> None:
        rgb = None
        with av.open(str(video_path)) as inp:
            for t, f in enumerate(inp.decode(inp.streams.video[0])):
                if t == frame:
                    rgb = f.to_ndarray(format="rgb24")
                    rot = int(getattr(f, "rotation", 0) or 0) % 360
                    if rot:
                        rgb = np.ascontiguousarray(np.rot90(rgb, k=rot // 90))
                    break
        if rgb is None:
            raise ValueError(f"the video has no frame {frame}")
        h, w = rgb.shape[:2]
        small = cv2.resize(rgb, (THUMBNAIL_WIDTH, max(1, round(h * THUMBNAIL_WIDTH / w))),
                           interpolation=cv2.INTER_AREA)  # fmt: skip
        ok, buf = cv2.imencode(".jpg", cv2.cvtColor(small, cv2.COLOR_RGB2BGR))
        if not ok:
            raise ValueError("the frame cannot be encoded")
        tmp.write_bytes(buf.tobytes())

    return _made_once(Path(work_dir) / "web" / "thumbnail.jpg", write)


# ---- skeleton pictures
@lru_cache(maxsize=16)
def _reference_joints(path: str, mtime: float) -> np.ndarray:

    return np.asarray(load_reference(path).motion.joints, float)


def reference_joints(path: str | Path) -> np.ndarray:
    """Reference joints (T, 17, 3), world frame, frames as in the BVH file (cached)."""
    p = str(path)
    return _reference_joints(p, os.path.getmtime(p))


def reference_motion_curve(
    path: str | Path, first_frame: int = 0, max_points: int = 1000
) -> dict[str, Any]:
    """How fast the expert's hands move over the reference, for placing its segment
    boundaries on a plot: the wrists' mean speed relative to the hip, m/s, per frame
    (averaged into at most ``max_points`` points; ``step`` frames each). Frames up to the
    motion's ``first_frame`` read 0: a conversion T-pose before it is not motion."""
    joints = reference_joints(path)
    rel = joints[:, [JOINTS.index("l_wrist"), JOINTS.index("r_wrist")]] - joints[:, :1]
    speed = np.r_[0.0, np.linalg.norm(np.diff(rel, axis=0), axis=-1).mean(-1)]  # m per frame
    speed[: first_frame + 1] = 0.0
    step = max(1, -(-len(speed) // max_points))
    pad = (-len(speed)) % step
    binned = np.r_[speed, np.full(pad, speed[-1])].reshape(-1, step).mean(-1)
    return {
        "frames": int(len(speed)),
        "step": int(step),
        "speed_m_per_frame": np.round(binned, 5).tolist(),
    }


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


#: Postures in a reference picker's looping preview, and the longest loop (seconds).
PREVIEW_FRAMES = 36
PREVIEW_MAX_LOOP_S = 4.0


def reference_preview(
    path: str | Path, first_frame: int = 0, *, frames: int = PREVIEW_FRAMES, fps: float = 0.0
) -> dict[str, Any]:
    """A few dozen postures of a reference for a small looping preview, front and side view.

    Coordinates are in [0, 1] with y down, one scale for both views (so proportions hold),
    each view centred on the motion's mean hip; frames sampled evenly from the first motion
    frame (after a T-pose) to the last.

    Returns
    -------
    dict
        ``{"frames": n, "fps": playback rate, "bones": [[parent, child] x 16],
        "front": [[[u, v] x 17] x n], "side": [[[u, v] x 17] x n]}``. Front: seen from the
        front (the body's left on the right); side: seen from the body's left (forward to the
        left).
    """
    j = reference_joints(path)
    first = min(max(int(first_frame), 0), len(j) - 1)
    idx = np.linspace(first, len(j) - 1, max(2, min(frames, len(j) - first))).round().astype(int)
    p = j[idx]
    views = {
        "front": np.stack([-p[..., 0], p[..., 1]], -1),
        "side": np.stack([-p[..., 2], p[..., 1]], -1),
    }
    centre = {k: v[:, 0].mean(0) for k, v in views.items()}
    half_x = max(float(np.abs(v[..., 0] - centre[k][0]).max()) for k, v in views.items())
    lo_y, hi_y = float(p[..., 1].min()), float(p[..., 1].max())
    span = max(2 * half_x, hi_y - lo_y, 1e-6) * 1.1
    out: dict[str, Any] = {}
    for k, v in views.items():
        u = 0.5 + (v[..., 0] - centre[k][0]) / span
        w = 0.5 - (v[..., 1] - (lo_y + hi_y) / 2) / span
        out[k] = np.round(np.stack([u, w], -1), 4).tolist()
    duration = (idx[-1] - idx[0]) / fps if fps > 0 else PREVIEW_MAX_LOOP_S
    loop_s = min(max(duration, 1.0), PREVIEW_MAX_LOOP_S)
    return {
        "frames": len(idx),
        "fps": round(len(idx) / loop_s, 3),
        "bones": [[int(a), int(b)] for a, b in zip(BONE_PARENT, BONE_CHILD, strict=True)],
        **out,
    }


# ---- report stills
#: Stills in the printable report.
REPORT_STILLS = 4


def still_frames(result: Result | Mapping[str, Any], n: int = REPORT_STILLS) -> list[int]:
    """Indices into ``result.frames``: each segment's worst frame, then evenly spaced.

    A segment with frames the video does not confirm (``image_misfit``) shows the worst of
    those instead, where the dashed posture tells what the reported one misses.
    """
    result = as_result(result)
    frames = result.frames
    if not frames:
        return []
    t_to_i = result.frame_index
    picks: list[int] = []
    for seg in result.segments:
        a, b = seg.performer_start, seg.performer_end
        inside = [t_to_i[t] for t in range(a, b + 1) if t in t_to_i]
        misfit = [i for i in inside if "image_misfit" in frames[i].flags]
        worst = seg.worst_frame
        if misfit:
            i = max(misfit, key=lambda k: frames[k].posture_error_deg)
        elif worst is not None and worst in t_to_i:
            i = t_to_i[worst]
        elif inside:
            i = max(inside, key=lambda k: frames[k].posture_error_deg)
        else:
            continue
        if i not in picks:
            picks.append(i)
    for i in np.linspace(0, len(frames) - 1, n).round().astype(int):
        if len(picks) >= n:
            break
        if int(i) not in picks:
            picks.append(int(i))
    return sorted(picks[:n])


def report_stills(
    video_path: str | Path,
    work_dir: str | Path,
    result: Result | Mapping[str, Any],
    *,
    n: int = REPORT_STILLS,
) -> list[dict[str, Any]]:
    """Video frames with the selected skeleton drawn over them (bones coloured by error), as
    JPEG data URIs for the printable report (inline, so printing needs no further requests).

    Returns
    -------
    list of dict
        ``{"t", "time_s", "error_deg", "src"}`` per still, in time order; empty when the video
        cannot be read.
    """
    import base64

    import av
    import cv2

    result = as_result(result)
    frames = result.frames
    picks = still_frames(result, n)
    if not picks:
        return []
    wanted = {frames[i].t: i for i in picks}
    vw, vh = float(result.video.width), float(result.video.height)
    fps = result.video.fps or 30.0
    out: list[dict[str, Any]] = []
    try:
        src = playable_video(video_path, work_dir)  # rotation applied, as the page shows it
        with av.open(str(src)) as inp:
            for t, frame in enumerate(inp.decode(inp.streams.video[0])):
                if t > max(wanted):
                    break
                if t not in wanted:
                    continue
                f = frames[wanted[t]]
                rgb = frame.to_ndarray(format="rgb24")
                h, w = rgb.shape[:2]
                if w > 480:  # print resolution, not the upload's
                    h, w = round(h * 480 / w), 480
                    rgb = cv2.resize(rgb, (w, h), interpolation=cv2.INTER_AREA)
                scale = [w / (vw or w), h / (vh or h)]
                best = f.image_best_joints_2d  # image_misfit frames: what the video shows
                drawn = draw_skeleton(
                    rgb, f.joints_2d * scale, f.bone_errors_deg,
                    None if best is None else best * scale,
                )  # fmt: skip
                ok, buf = cv2.imencode(
                    ".jpg", cv2.cvtColor(drawn, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, 85]
                )
                if ok:
                    out.append({
                        "t": t, "time_s": t / fps, "error_deg": f.posture_error_deg,
                        "src": "data:image/jpeg;base64," + base64.b64encode(buf.tobytes()).decode(),
                    })  # fmt: skip
    except Exception:  # a report without pictures beats no report
        return out
    return out


# ---- exports
def result_csv(result: Result | Mapping[str, Any]) -> str:
    """One row per video frame: timing, errors per bone (``error_deg_left_upper_arm``), each
    bone's range over the candidates the video cannot tell apart (``range_deg_...`` as
    ``lo-hi``; empty for results that predate it), the performer's joint angles
    (``angle_deg_left_knee``): every column named once, in a coach's words."""
    result = as_result(result)
    frames = result.frames
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(
        ["t", "time_s", "reference_frame", "selected", "posture_error_deg"]
        + [f"error_deg_{column_name(b)}" for b in BONE_LABELS]
        + [f"range_deg_{column_name(b)}" for b in BONE_LABELS]
        + [a[0] for a in JOINT_ANGLES]
    )
    fps = result.video.fps or 1.0
    angles = joint_angles_deg(result.joints_3d) if len(frames) else np.zeros((0, len(JOINT_ANGLES)))
    for f, a in zip(frames, angles, strict=True):
        ranges = () if f.bone_error_range_deg is None else f.bone_error_range_deg
        w.writerow(
            [f.t, f"{f.t / fps:.4f}", f.reference_frame, f.selected, f"{f.posture_error_deg:.3f}"]
            + [f"{e:.3f}" for e in f.bone_errors_deg]
            + [f"{lo:.1f}-{hi:.1f}" for lo, hi in ranges]
            + [""] * (len(BONE_NAMES) - len(ranges))
            + [f"{x:.3f}" for x in a]
        )  # fmt: skip
    return buf.getvalue()


def result_bvh(result: Result | Mapping[str, Any], dest: Path) -> Path:
    """The performer's selected motion (joints_3d with root motion) as BVH at ``dest``."""

    result = as_result(result)
    return write_bvh(dest, result.joints_3d, result.video.fps or 30.0)


#: Heights (deg) of the error plots' axes, four whole-degree grid steps each (analysis.js too)
PLOT_TOPS = (4, 8, 12, 20, 40, 60, 80, 120, 180)


def plot_top(most: float) -> int:
    """The axis height for curves that reach ``most`` deg: the smallest of :data:`PLOT_TOPS`
    with 10 % to spare. The axis fits the curves, so small errors still show which frames
    stand out."""
    return next((v for v in PLOT_TOPS if v >= most * 1.1), PLOT_TOPS[-1])


def error_plot_svg(
    result: Result | Mapping[str, Any], *, width: int = 720, height: int = 180
) -> str:
    """eps_t' over the video frames with segment boundaries, as an inline SVG (printable)."""
    result = as_result(result)
    frames = result.frames
    if not frames:
        return ""
    err = result.posture_error_deg
    top = plot_top(float(np.nanmax(err)) if np.isfinite(err).any() else 0.0)
    n = max(len(frames) - 1, 1)
    pad = 30

    def x(i: float) -> float:
        return pad + (width - pad - 6) * i / n

    def y(v: float) -> float:
        return 6 + (height - 26) * (1 - v / top)

    pts = " ".join(f"{x(i):.1f},{y(v):.1f}" for i, v in enumerate(np.nan_to_num(err)))
    parts = [f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 {width} {height}" '
             f'class="plot" role="img" aria-label="posture error per frame">']  # fmt: skip
    # frames the video does not confirm (image_misfit): their errors may be too small
    step = (width - pad - 6) / n
    for i, f in enumerate(frames):
        if "image_misfit" in f.flags:
            parts.append(
                f'<rect class="misfit-mark" x="{x(i) - step / 2:.1f}" y="6" width="{step:.1f}" '
                f'height="{height - 26}" fill="rgb{MISFIT_RGB}" fill-opacity="0.35"/>'
            )
    for s in result.segments:
        parts.append(
            f'<line x1="{x(s.performer_start):.1f}" x2="{x(s.performer_start):.1f}" '
            f'y1="6" y2="{height - 20}" stroke="#999" stroke-dasharray="3 3"/>'
        )
    for v in np.linspace(0, top, 5):
        parts.append(f'<text x="2" y="{y(v) + 4:.1f}" font-size="10">{v:.0f}&#176;</text>')
    parts.append(f'<polyline points="{pts}" fill="none" stroke="#c92a2a" stroke-width="2"/>')
    parts.append(f'<text x="{pad}" y="{height - 4}" font-size="10">frame 0</text>')
    parts.append(f'<text x="{width - 60}" y="{height - 4}" font-size="10">frame {n}</text>')
    parts.append("</svg>")
    return "".join(parts)
