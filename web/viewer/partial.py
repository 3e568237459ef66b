"""The 3D view of an analysis that is still running: what the finished stages already know.

Stage 2 (prepare's output) gives the aligned reference B_C(t') turned by T_t' about the
hip; each stage-3 chunk gives candidate postures for its frames, of which the one with the
lowest d_S (the image evidence stage 4 starts from) is drawn in grey. Stage 4 (the result)
replaces the whole thing with the coloured scene of :func:`web.viewer.scene.build_scene`;
:class:`web.live.LiveViewers` does that swap on the same server, so an open iframe keeps its
connection.

The worker writes every file under a temporary name and renames it into place, so a file that
exists is complete; one that cannot be read yet (or any more) is simply tried again later.
"""

from __future__ import annotations

import json
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import viser

from app.web_surface import AnalysisFolder, load_candidate_chunk, load_prepared
from web.viewer.scene import (
    CAMERA_FOV_DEG,
    CANDIDATE_RGB,
    LABEL_LIFT,
    REFERENCE_RGB,
    _segments_of,
    frame_points,
)

#: Playback rate of the partial scene's loop over the video frames (frames per second).
PARTIAL_FPS = 6.0


@dataclass
class FolderState:
    """What the analysis folder holds so far.

    Attributes
    ----------
    aligned : ndarray, shape (T', 17, 3) or None
        B_C(t') turned by T_t' about the hip (stage 2), once ``prepare.npz`` exists.
    best : ndarray, shape (T', 17, 3) or None
        Lowest-d_S candidate per frame; NaN for frames whose chunk is not finished.
    reference_joints : ndarray, shape (T, 17, 3) or None
        The BVH as given (for the finished scene).
    fps : float
        Video frame rate.
    result : dict or None
        result.json, once it exists.
    """

    aligned: np.ndarray | None = None
    best: np.ndarray | None = None
    reference_joints: np.ndarray | None = None
    fps: float = 30.0
    result: dict[str, Any] | None = None
    chunks_seen: set[str] = field(default_factory=set)

    @property
    def frames_done(self) -> int:
        return 0 if self.best is None else int(np.isfinite(self.best[:, 0, 0]).sum())

    @property
    def n_frames(self) -> int:
        return 0 if self.aligned is None else len(self.aligned)

    @property
    def phase(self) -> str:
        """``waiting`` (nothing yet), ``reference`` (stage 2 done), ``candidates`` (some
        stage-3 frames), ``done`` (result.json)."""
        if self.result is not None:
            return "done"
        if self.aligned is None:
            return "waiting"
        return "candidates" if self.frames_done else "reference"

    def public(self) -> dict[str, Any]:
        return {"phase": self.phase, "frames_done": self.frames_done, "frames": self.n_frames}


def refresh(state: FolderState, work_dir: str | Path) -> bool:
    """Read what is new in the analysis folder into ``state``; True if anything changed."""
    folder = AnalysisFolder(work_dir)
    changed = False
    if state.aligned is None and folder.prepared.is_file():
        try:
            p = load_prepared(folder.prepared)
        except Exception:  # unreadable now: try again on the next poll
            return False
        state.aligned = p.initial_postures(range(p.n_frames))[:, 0]
        state.best = np.full_like(state.aligned, np.nan)
        state.reference_joints = np.asarray(p.reference_joints, float)
        state.fps = float(p.video.fps or 30.0)
        changed = True
    if state.aligned is not None:
        for path in folder.finished_chunks():
            if path.name in state.chunks_seen:
                continue
            try:
                chunk = load_candidate_chunk(path)
            except Exception:
                continue
            state.chunks_seen.add(path.name)
            for t, cands, d_s in zip(chunk.frames, chunk.candidates, chunk.d_s, strict=True):
                if len(cands) and 0 <= int(t) < len(state.best):
                    state.best[int(t)] = cands[int(np.argmin(d_s))] if len(d_s) else cands[0]
            changed = True
    if state.result is None and folder.result.is_file():
        try:
            state.result = json.loads(folder.result.read_text())
            changed = True
        except (OSError, ValueError):
            pass
    return changed


@dataclass
class PartialScene:
    """Handles of the partial scene on a viser server; ``show(state)`` redraws it."""

    server: viser.ViserServer
    state: FolderState | None = None
    handles: dict[str, Any] = field(default_factory=dict)
    current: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None

    def build(self, state: FolderState) -> None:
        """Add the nodes, frame the aligned reference, and start looping over the frames."""
        server = self.server
        self.state = state
        server.scene.set_up_direction("+y")
        look_at, position, floor = frame_points(state.aligned)
        server.initial_camera.fov = np.radians(CAMERA_FOV_DEG)
        server.initial_camera.look_at = tuple(look_at)
        server.initial_camera.position = tuple(position)
        h = self.handles
        h["ground"] = server.scene.add_grid(
            "/ground", width=3, height=3, plane="xz", position=(look_at[0], floor, look_at[2])
        )
        zero = np.zeros((16, 2, 3), np.float32)
        h["best"] = server.scene.add_line_segments(
            "/partial/best", zero, CANDIDATE_RGB, thickness=7, thickness_units="screen"
        )
        h["reference"] = server.scene.add_line_segments(
            "/partial/reference", zero, REFERENCE_RGB, thickness=6, thickness_units="screen"
        )
        h["label"] = server.scene.add_label("/partial/label", "", position=tuple(look_at))
        h["note"] = server.gui.add_markdown(
            "**Analysing.** Blue: the expert aligned to your video (stage 2). Grey: your best "
            "candidate posture so far (stage 3). Colours follow when the analysis is done."
        )
        self.show(0)
        self._thread = threading.Thread(target=self._loop, name="viewer-partial", daemon=True)
        self._thread.start()

    def update(self, state: FolderState) -> None:
        self.state = state
        self.show(self.current)

    def show(self, i: int) -> None:
        """Draw video frame ``i``: aligned reference, and the best candidate if it is ready."""
        with self._lock:
            st = self.state
            if st is None or st.aligned is None:
                return
            i = int(i) % len(st.aligned)
            self.current = i
            ref = st.aligned[i]
            best = st.best[i] if st.best is not None else None
            h = self.handles
            with self.server.atomic():
                if best is not None and np.isfinite(best).all():
                    h["best"].points = _segments_of(best - best[0] + ref[0]).astype(np.float32)
                    h["best"].visible = True
                else:
                    h["best"].visible = False
                h["reference"].points = _segments_of(ref).astype(np.float32)
                if st.phase == "reference":
                    text = f"Analysing. Frame {i}: the expert at the matched moment"
                else:
                    text = (
                        f"Analysing. Frame {i}: postures found for {st.frames_done} of "
                        f"{st.n_frames} frames"
                    )
                h["label"].text = text
                h["label"].position = tuple(float(x) for x in ref[16] + LABEL_LIFT)

    def _loop(self) -> None:
        while not self._stop.wait(1.0 / PARTIAL_FPS):
            self.show(self.current + 1)

    def close(self) -> None:
        """Stop the loop (the nodes stay; :meth:`remove` takes them away)."""
        self._stop.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2)

    def remove(self) -> None:
        """Stop and take every node and GUI element of the partial scene away."""
        self.close()
        for handle in self.handles.values():
            try:
                handle.remove()
            except Exception:  # already gone
                pass
        self.handles.clear()
