"""Per-analysis viser servers for the embedded 3D view, started on demand on free local ports.

Each analysis gets its own :class:`viser.ViserServer` (so many viewers can look at different
analyses at once); the page embeds it in an iframe and moves its frame through
:meth:`LiveViewers.set_frame` as the video plays. Servers idle for ``idle_s`` seconds, or
beyond ``max_servers``, are stopped (least recently used first).
"""

from __future__ import annotations

import atexit
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

log = logging.getLogger("web.live")


class ViewerUnavailable(Exception):
    """The 3D view cannot be served (viser or the scene builder is missing, or it failed)."""


@dataclass
class _Live:
    server: Any
    scene: Any
    port: int
    last_used: float


class LiveViewers:
    """The running viser servers, one per analysis id."""

    def __init__(self, *, host: str = "127.0.0.1", max_servers: int = 8, idle_s: float = 900.0):
        self.host = host
        self.max_servers = max_servers
        self.idle_s = idle_s
        self._live: dict[str, _Live] = {}
        self._lock = threading.Lock()

    def ensure(self, analysis_id: str, load: Callable[[], tuple[Any, dict[str, Any]]]) -> int:
        """The port of the analysis' viewer, starting it when needed.

        ``load()`` returns ``(reference_joints (T, 17, 3), result dict)``; it is called only
        when a server has to be started.
        """
        with self._lock:
            live = self._live.get(analysis_id)
            if live is not None:
                live.last_used = time.monotonic()
                return live.port
            self._evict_locked()
            live = self._start(load)
            self._live[analysis_id] = live
            log.info("live.started analysis=%s port=%d", analysis_id, live.port)
            return live.port

    def set_frame(self, analysis_id: str, frame: int) -> bool:
        live = self._live.get(analysis_id)
        if live is None:
            return False
        live.last_used = time.monotonic()
        n = len(live.scene.frames)
        live.scene.set_frame(min(max(int(frame), 0), n - 1))  # moves its slider too
        return True

    def _start(self, load: Callable[[], tuple[Any, dict[str, Any]]]) -> _Live:
        try:
            import viser

            from web.viewer.scene import build_scene, free_port, wait_until_listening
        except ImportError as exc:
            raise ViewerUnavailable(f"the 3D viewer is not installed ({exc})") from exc
        reference_joints, result = load()
        port = free_port()
        server = viser.ViserServer(host=self.host, port=port, verbose=False)
        try:
            # Embedded beside the video, the panel starts minimised to its title bar so the
            # scene has the whole frame (the page shows the legend and drives the frame); no
            # logo or share link. viser 1.1 deprecates control_layout for main_panel placement.
            server.gui.configure_theme(
                control_width="small", show_logo=False, show_share_button=False
            )
            scene = build_scene(server, reference_joints, result)
            server.gui.main_panel.minimize()
            wait_until_listening(port)
        except Exception as exc:
            server.stop()
            raise ViewerUnavailable(f"the 3D view could not be built ({exc})") from exc
        return _Live(server, scene, port, time.monotonic())

    def _evict_locked(self) -> None:
        now = time.monotonic()
        stale = [k for k, v in self._live.items() if now - v.last_used > self.idle_s]
        by_age = sorted(self._live, key=lambda k: self._live[k].last_used)
        while len(self._live) - len(stale) >= self.max_servers and by_age:
            k = by_age.pop(0)
            if k not in stale:
                stale.append(k)
        for k in stale:
            self._stop(self._live.pop(k))

    @staticmethod
    def _stop(live: _Live) -> None:
        try:
            live.scene.close()
        finally:
            live.server.stop()

    def stop_all(self) -> None:
        with self._lock:
            while self._live:
                _, live = self._live.popitem()
                try:
                    self._stop(live)
                except Exception as exc:
                    log.warning("live.stop_failed error=%s", exc)

    def __len__(self) -> int:
        return len(self._live)


_viewers: LiveViewers | None = None


def get_viewers() -> LiveViewers:
    """The process-wide viewers (stopped at interpreter exit)."""
    global _viewers
    if _viewers is None:
        import os

        _viewers = LiveViewers(host=os.environ.get("COACH_VIEWER_HOST", "127.0.0.1"))
        atexit.register(_viewers.stop_all)
    return _viewers
