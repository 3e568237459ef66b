"""One self-contained HTML page of an analysis (thesis 5.5.3 figures, 6.10 visualisation).

The page holds a contact strip (video frames with the selected skeleton drawn over them, bones
coloured green to red by their error), a plot of eps_t' over time with the performer's segments
as bands (fig. 5.26), and per segment its tempo, mean error and worst bones. Every image is
inline (base64 PNG); the page loads nothing else. Building only: writing is in
:func:`engine.io.result.write_text`.
"""

from __future__ import annotations

import base64
import html
import io
from collections.abc import Mapping, Sequence
from typing import Any

import cv2
import numpy as np

from engine.body.skeleton import BONE_CHILD, BONE_LABELS, BONE_PARENT
from engine.io.result_reader import Result, as_result

#: Error (deg) at which a bone is fully red in the overlays and the 3D view.
ERROR_RED_DEG = 45.0

#: What one video can measure, shown beside every result (reports, the analysis page). On the
#: public benchmark cases the reported errors are about ten times smaller than the true ones
#: while ranking with them at 0.4-0.6 (README, "What one camera can and cannot tell").
ONE_CAMERA_NOTE = (
    "Measured from one camera: bends across the picture show clearly, turns towards or away "
    "from the camera hardly at all, so errors that lie in depth are under-reported. Trust "
    "which frames and bones stand out more than the degrees."
)


def tempo_words(ratio: float | None) -> str:
    """A segment's tempo (performer's duration / expert's) in the one wording every page,
    report and export uses: "12 % slower than the expert", "the expert's tempo"."""
    if ratio is None or not np.isfinite(ratio) or ratio <= 0:
        return "tempo unknown"
    pct = round(abs(ratio - 1.0) * 100)
    if pct == 0:
        return "the expert's tempo"
    return f"{pct} % {'slower' if ratio > 1 else 'faster'} than the expert"


def error_colors(errors_deg: np.ndarray, red_at_deg: float = ERROR_RED_DEG) -> np.ndarray:
    """Green (0 deg) -> yellow -> red (``red_at_deg`` and above), RGB in [0, 1].

    Parameters
    ----------
    errors_deg : ndarray, shape (...)

    Returns
    -------
    rgb : ndarray, shape (..., 3)
    """
    x = np.clip(np.asarray(errors_deg, float) / red_at_deg, 0.0, 1.0)
    r = np.clip(2 * x, 0, 1)
    g = np.clip(2 * (1 - x), 0, 1)
    return np.stack([r, g, np.zeros_like(x)], -1) * 0.9 + 0.05


def _png_b64(rgb: np.ndarray) -> str:
    ok, buf = cv2.imencode(".png", cv2.cvtColor(rgb, cv2.COLOR_RGB2BGR))
    if not ok:  # pragma: no cover - cv2 encodes any uint8 image
        raise RuntimeError("PNG encoding failed")
    return base64.b64encode(buf.tobytes()).decode("ascii")


#: Colour of what the video suggests where it disagrees (image_misfit frames), RGB.
MISFIT_RGB = (250, 176, 5)


def draw_skeleton(
    rgb: np.ndarray,
    joints_2d: np.ndarray,
    bone_errors_deg: np.ndarray,
    video_suggests: np.ndarray | None = None,
) -> np.ndarray:
    """A copy of a video frame with the skeleton drawn over it.

    Parameters
    ----------
    rgb : ndarray of uint8, shape (H, W, 3)
    joints_2d : ndarray, shape (17, 2)
        (u, v) pixels.
    bone_errors_deg : ndarray, shape (16,)
    video_suggests : ndarray, shape (17, 2), optional
        The candidate that fits the video best (a frame's ``image_best_joints_2d``), drawn
        dashed in amber over the skeleton.

    Returns
    -------
    ndarray of uint8, shape (H, W, 3)
    """
    out = np.ascontiguousarray(rgb.copy())
    colors = (error_colors(bone_errors_deg) * 255).astype(int)
    thick = max(1, round(out.shape[0] / 120))
    pts = np.round(np.asarray(joints_2d, float)).astype(int)
    for b in range(len(BONE_LABELS)):
        p, c = pts[BONE_PARENT[b]], pts[BONE_CHILD[b]]
        cv2.line(
            out,
            (int(p[0]), int(p[1])),
            (int(c[0]), int(c[1])),
            tuple(map(int, colors[b])),
            thick,
            cv2.LINE_AA,
        )
    for p in pts:
        cv2.circle(out, (int(p[0]), int(p[1])), thick, (255, 255, 255), -1, cv2.LINE_AA)
    if video_suggests is not None:
        g = np.asarray(video_suggests, float)
        for b in range(len(BONE_LABELS)):
            _dashed_line(out, g[BONE_PARENT[b]], g[BONE_CHILD[b]], MISFIT_RGB, thick, 4 * thick)
    return out


def _dashed_line(
    img: np.ndarray, a: np.ndarray, b: np.ndarray, color: tuple[int, ...], thick: int, dash: int
) -> None:
    """cv2 has no dashed lines: draw every other piece of ``dash`` pixels from a to b."""
    length = float(np.linalg.norm(b - a))
    n = max(1, int(length // dash))
    for k in range(0, n, 2):
        p = a + (b - a) * k / n
        q = a + (b - a) * min(k + 1, n) / n
        cv2.line(img, (int(round(p[0])), int(round(p[1]))), (int(round(q[0])), int(round(q[1]))),
                 color, thick, cv2.LINE_AA)  # fmt: skip


def _strip_frames(result: Result, n: int) -> list[int]:
    """Indices into result.frames: segment starts, worst frames, then evenly spaced."""
    t_to_i = result.frame_index
    picks: list[int] = []
    for s in result.segments:
        for t in (s.performer_start, s.worst_frame):
            i = t_to_i.get(t) if t is not None else None
            if i is not None and i not in picks:
                picks.append(i)
    even = np.linspace(0, len(result.frames) - 1, n).round().astype(int)
    picks += [int(i) for i in even if int(i) not in picks]
    return sorted(picks[:n])


def _error_plot_png(result: Result | Mapping[str, Any]) -> str:
    import matplotlib

    matplotlib.use("Agg", force=False)
    from matplotlib.figure import Figure

    result = as_result(result)
    t = result.t
    eps = result.posture_error_deg
    fig = Figure(figsize=(8, 2.6), dpi=100)
    ax = fig.add_subplot()
    for j, s in enumerate(result.segments):
        ax.axvspan(s.performer_start, s.performer_end, color=f"C{j % 10}", alpha=0.12, lw=0)
        mid = (s.performer_start + s.performer_end) / 2
        label = str(j + 1) if s.name is None else s.name
        ax.text(mid, 1.0, label, transform=ax.get_xaxis_transform(),
                ha="center", va="bottom", fontsize=8)  # fmt: skip
    misfit = [i for i, f in enumerate(result.frames) if "image_misfit" in f.flags]
    for k, i in enumerate(misfit):  # frames the video does not confirm: errors may be too small
        ax.axvspan(t[i] - 0.5, t[i] + 0.5, color=np.divide(MISFIT_RGB, 255), alpha=0.35, lw=0,
                   label="video disagrees (image_misfit)" if k == 0 else None)  # fmt: skip
    ax.plot(t, eps, color="k", lw=1.2, label="posture error eps_t'")
    if result.score_deg is not None:
        ax.plot(
            t,
            result.score_deg,
            color="C3",
            lw=1,
            ls="--",
            label="domain score",
        )
    ax.set_xlabel("video frame t'")
    ax.set_ylabel("deg")
    ax.set_xlim(t.min(), max(t.max(), t.min() + 1))
    ax.set_ylim(bottom=0)
    ax.legend(loc="upper left", fontsize=8, frameon=False)
    fig.tight_layout()
    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _strip_html(
    result: Result, video_frames: np.ndarray | Sequence[np.ndarray] | None, n: int
) -> str:
    """The contact strip: ``n`` frames with their skeletons coloured by error."""
    w, h = result.video.width, result.video.height
    out = []
    for i in _strip_frames(result, n):
        f = result.frames[i]
        img = (
            np.asarray(video_frames[i], np.uint8)
            if video_frames is not None and i < len(video_frames)
            else np.full((h, w, 3), 60, np.uint8)
        )
        drawn = draw_skeleton(img, f.joints_2d, f.bone_errors_deg, f.image_best_joints_2d)
        cap = f"t'={f.t} &rarr; t={f.reference_frame}, {f.posture_error_deg:.1f}&deg;"
        out.append(
            f'<figure><img alt="frame {f.t}" src="data:image/png;base64,{_png_b64(drawn)}">'
            f"<figcaption>{cap}</figcaption></figure>"
        )
    return "".join(out)


def _segment_rows(result: Result) -> str:
    """One table row per segment: frames, tempo, errors, status and its worst bones."""
    e = html.escape
    rows = []
    for j, s in enumerate(result.segments):
        worst = ", ".join(
            f"{e(BONE_LABELS[b])} ({s.bone_mean_errors_deg[b]:.0f}&deg;)"
            for b in np.argsort(-s.bone_mean_errors_deg)[:3]
        )
        status = s.status or "ok"
        score = "&ndash;" if s.score_deg is None else f"{s.score_deg:.1f}"
        rows.append(
            f"<tr class='{e(status)}'><td>{e(str(j + 1) if s.name is None else s.name)}</td>"
            f"<td>{s.reference_start}&ndash;{s.reference_end}</td>"
            f"<td>{s.performer_start}&ndash;{s.performer_end}</td>"
            f"<td>{e(tempo_words(s.tempo))}</td><td>{s.mean_error_deg:.1f}</td>"
            f"<td>{score}</td><td>{e(status)}</td><td>{worst}</td></tr>"
        )
    return "".join(rows)


def build_report_html(
    result: Result | Mapping[str, Any],
    video_frames: np.ndarray | Sequence[np.ndarray] | None = None,
    *,
    strip_frames: int = 8,
) -> str:
    """The HTML report of one analysis.

    Parameters
    ----------
    result : Result or dict
        A result, or its document (:func:`engine.io.result.build_result`).
    video_frames : ndarray of uint8, shape (T, H, W, 3), or sequence of (H, W, 3), optional
        RGB frames indexed like ``result.frames``; without them the strip shows the
        skeletons on a grey background.
    strip_frames : int
        Frames in the contact strip.

    Returns
    -------
    str
        A complete HTML document with every image inline.

    Raises
    ------
    InvalidInput
        ``result`` is not a result document.
    """
    result = as_result(result)
    frames = result.frames
    w = result.video.width
    strip = _strip_html(result, video_frames, strip_frames)
    rows = _segment_rows(result)
    e = html.escape
    summary = result.summary
    messages = "".join(f"<p class='msg'>{e(m)}</p>" for m in summary.messages)
    timing = ", ".join(f"{e(k)} {v:.2f} s" for k, v in result.timing_s.items())
    legend = "".join(
        f"<span style='background:rgb{tuple(int(c * 255) for c in rgb)}'>{d:.0f}&deg;</span>"
        for d, rgb in zip(
            np.linspace(0, ERROR_RED_DEG, 6),
            error_colors(np.linspace(0, ERROR_RED_DEG, 6)),
            strict=True,
        )
    )
    mean_deg = summary.mean_error_deg
    if mean_deg is None:
        mean_deg = float(np.mean(result.posture_error_deg))
    head = (
        f"{len(frames)} video frames at {result.video.fps:g} fps against "
        f"{result.reference.frames} reference frames at {result.reference.fps:g} fps. "
        f"Mean posture error {mean_deg:.1f}&deg;."
    )
    columns = "".join(
        f"<th>{c}</th>" for c in ("segment", "reference", "performer", "tempo",
                                  "mean error (&deg;)", "score (&deg;)", "status", "worst bones")
    )  # fmt: skip
    title = f"Motion analysis: {e(result.reference.name)}"
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>
body{{font-family:system-ui,sans-serif;margin:1.5em;color:#222}}
.strip{{display:flex;flex-wrap:wrap;gap:6px}} figure{{margin:0}}
figure img{{width:{min(w, 200)}px;display:block}} figcaption{{font-size:11px}}
table{{border-collapse:collapse}} td,th{{border:1px solid #ccc;padding:3px 8px;font-size:13px}}
tr.missing td,tr.extra_motion td{{background:#fde2e2}} .msg{{color:#a00;font-weight:600}}
.legend span{{display:inline-block;padding:0 6px;font-size:11px}} .note{{color:#555}}
</style></head><body>
<h1>{title}</h1>
<p>{head}</p>
<p class="note">{e(ONE_CAMERA_NOTE)}</p>
{messages}
<h2>Frames</h2><div class="legend">bone error: {legend}</div>
<div class="strip">{strip}</div>
<h2>Posture error over time</h2>
<img alt="posture error" src="data:image/png;base64,{_error_plot_png(result)}">
<h2>Segments</h2>
<table><tr>{columns}</tr>{rows}</table>
<p><small>Timing: {timing}</small></p>
</body></html>
"""


__all__ = [
    "ERROR_RED_DEG", "ONE_CAMERA_NOTE", "build_report_html", "draw_skeleton", "error_colors",
]  # fmt: skip
