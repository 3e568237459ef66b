"""Per-analysis viser servers for the embedded 3D view, started on demand on free local ports.

Each analysis gets its own :class:`viser.ViserServer` on a loopback port (so many viewers can
look at different analyses at once); the page frames it through the app's own origin
(:mod:`web.viewer.proxy`), and every browser tab gets its own view of the scene, moved through
:meth:`LiveViewers.set_frame` as that tab's video plays. Servers idle for ``idle_s`` seconds,
or beyond ``max_servers``, are stopped (least recently used first).

While an analysis runs, :meth:`LiveViewers.ensure_running` starts its server with the partial
scene of :mod:`web.viewer.partial` as soon as stage 2's output exists; a watcher thread polls
the analysis folder every ``poll_s`` seconds, draws stage-3 candidates as their chunk files
appear, and swaps in the finished, coloured scene on the same server once result.json exists
(or when :meth:`LiveViewers.ensure` is asked for the finished analysis first).
"""

from __future__ import annotations

import asyncio
import atexit
import logging
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

log = logging.getLogger("web.live")


class ViewerUnavailable(Exception):
    """The 3D view cannot be served (viser or the scene builder is missing, or it failed)."""


class NothingToShowYet(Exception):
    """A running analysis has no stage-2 output yet: nothing to draw."""


@dataclass
class _Live:
    server: Any
    scene: Any
    port: int
    last_used: float
    #: While the analysis runs: what its folder holds (web.viewer.partial.FolderState).
    state: Any = None
    lock: threading.RLock = field(default_factory=threading.RLock)
    stop: threading.Event = field(default_factory=threading.Event)
    #: Viser client ids handed out so far (viser numbers connections 0, 1, ... in order).
    connections: int = 0
    #: Browser tab token -> its viser client id.
    tabs: dict[str, int] = field(default_factory=dict)
    #: Frames asked for by tabs whose websocket is not relayed yet.
    tab_frames: dict[str, int] = field(default_factory=dict)
    #: Held while a relay opens its upstream connection (see web.viewer.proxy).
    connecting: asyncio.Lock = field(default_factory=asyncio.Lock)

    @property
    def partial(self) -> bool:
        return self.state is not None


class LiveViewers:
    """The running viser servers, one per analysis id."""

    def __init__(
        self,
        *,
        host: str = "127.0.0.1",
        max_servers: int = 8,
        idle_s: float = 900.0,
        poll_s: float = 0.5,
    ):
        self.host = host
        self.poll_s = poll_s
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
                if live.partial:  # the analysis finished before the watcher saw it
                    with live.lock:
                        if live.partial:
                            self._finish(live, *load())
                return live.port
            self._evict_locked()
            live = self._start(load)
            self._live[analysis_id] = live
            log.info("live.started analysis=%s port=%d", analysis_id, live.port)
            return live.port

    def ensure_running(self, analysis_id: str, work_dir: str | Path) -> tuple[int, dict[str, Any]]:
        """The port of a running analysis' viewer and what it shows (``FolderState.public``).

        Starts the server with the partial scene once stage 2's output exists; raises
        :class:`NothingToShowYet` before that.
        """
        with self._lock:
            live = self._live.get(analysis_id)
            if live is not None:
                live.last_used = time.monotonic()
                return live.port, self._public(live)
            try:
                from web.viewer.partial import FolderState, refresh
            except ImportError as exc:
                raise ViewerUnavailable(f"the 3D viewer is not installed ({exc})") from exc
            state = FolderState()
            refresh(state, work_dir)
            if state.aligned is None:
                raise NothingToShowYet("stage 2 has not finished yet")
            self._evict_locked()
            live = self._start_partial(state)
            self._live[analysis_id] = live
            threading.Thread(
                target=self._watch, args=(analysis_id, live, Path(work_dir)),
                name=f"viewer-watch-{analysis_id[:8]}", daemon=True,
            ).start()  # fmt: skip
            log.info("live.started_partial analysis=%s port=%d", analysis_id, live.port)
            return live.port, self._public(live)

    def state(self, analysis_id: str) -> dict[str, Any] | None:
        """What the analysis' viewer shows now, or None if it has none."""
        live = self._live.get(analysis_id)
        return None if live is None else self._public(live)

    @staticmethod
    def _public(live: _Live) -> dict[str, Any]:
        if live.partial:
            return live.state.public()
        n = len(live.scene.frames)
        return {"phase": "done", "frames_done": n, "frames": n}

    def port_of(self, analysis_id: str) -> int | None:
        """The port of the analysis' running viewer, or None."""
        live = self._live.get(analysis_id)
        if live is None:
            return None
        live.last_used = time.monotonic()
        return live.port

    def connect_lock(self, analysis_id: str) -> asyncio.Lock:
        """The lock a relay holds while it connects to the analysis' viewer."""
        live = self._live.get(analysis_id)
        return asyncio.Lock() if live is None else live.connecting

    def next_client_id(self, analysis_id: str) -> int:
        """The viser client id the next connection to the analysis' viewer gets (viser's
        websocket server numbers connections 0, 1, 2, ... as they arrive; the relays connect
        one at a time, under :meth:`connect_lock`)."""
        live = self._live[analysis_id]
        with live.lock:
            live.connections += 1
            return live.connections - 1

    def bind_tab(self, analysis_id: str, tab: str, client_id: int) -> None:
        """Tab ``tab`` is viser client ``client_id``: its frames go to that client's view."""
        live = self._live.get(analysis_id)
        if live is None:
            return
        with live.lock:
            live.tabs[tab] = client_id
            while len(live.tabs) > MAX_TABS:  # reloads leave dead tabs behind: oldest go
                live.tabs.pop(next(iter(live.tabs)))
            frame = live.tab_frames.pop(tab, None)
        if frame is not None:
            self.set_frame(analysis_id, frame, tab)

    def set_frame(self, analysis_id: str, frame: int, tab: str) -> bool:
        """Show ``frame`` in tab ``tab``'s own 3D view of the finished analysis."""
        live = self._live.get(analysis_id)
        if live is None or live.partial:
            return False
        live.last_used = time.monotonic()
        n = len(live.scene.frames)
        i = min(max(int(frame), 0), n - 1)
        with live.lock:
            client_id = live.tabs.get(tab)
            if client_id is None:  # its websocket is not relayed yet: shown when it is
                live.tab_frames[tab] = i
                while len(live.tab_frames) > MAX_TABS:
                    live.tab_frames.pop(next(iter(live.tab_frames)))
                return True
        live.scene.set_frame(i, client_id)  # moves that tab's slider too
        return True

    def _start(self, load: Callable[[], tuple[Any, dict[str, Any]]]) -> _Live:
        try:
            from web.viewer.scene import build_scene, wait_until_listening
        except ImportError as exc:
            raise ViewerUnavailable(f"the 3D viewer is not installed ({exc})") from exc
        reference_joints, result = load()
        server, port = self._new_server()
        try:
            scene = build_scene(server, reference_joints, result, per_client=True)
            server.gui.main_panel.minimize()
            wait_until_listening(port)
        except Exception as exc:
            server.stop()
            raise ViewerUnavailable(f"the 3D view could not be built ({exc})") from exc
        return _Live(server, scene, port, time.monotonic())

    def _new_server(self) -> tuple[Any, int]:
        import viser

        from web.viewer.scene import free_port

        port = free_port()
        server = viser.ViserServer(host=self.host, port=port, verbose=False)
        # Embedded beside the video, the panel starts minimised to its title bar (the caller
        # minimises it once its GUI is added) so the scene has the whole frame; no logo or
        # share link. viser 1.1 deprecates control_layout for main_panel placement.
        server.gui.configure_theme(control_width="small", show_logo=False, show_share_button=False)
        return server, port

    def _start_partial(self, state: Any) -> _Live:
        from web.viewer.partial import PartialScene
        from web.viewer.scene import wait_until_listening

        server, port = self._new_server()
        try:
            scene = PartialScene(server)
            scene.build(state)
            server.gui.main_panel.minimize()
            wait_until_listening(port)
        except Exception as exc:
            server.stop()
            raise ViewerUnavailable(f"the 3D view could not be built ({exc})") from exc
        return _Live(server, scene, port, time.monotonic(), state=state)

    def _finish(self, live: _Live, reference_joints: Any, result: dict[str, Any]) -> None:
        """Replace the partial scene by the finished one, on the same server (lock held)."""
        from web.viewer.scene import build_scene

        live.stop.set()
        live.scene.remove()
        live.scene = build_scene(live.server, reference_joints, result, per_client=True)
        live.state = None

    def _watch(self, analysis_id: str, live: _Live, work_dir: Path) -> None:
        """Poll the analysis folder until the finished scene is up or the viewer stops."""
        from web.viewer.partial import refresh

        while not live.stop.wait(self.poll_s):
            with live.lock:
                if not live.partial:
                    return
                try:
                    changed = refresh(live.state, work_dir)
                    if live.state.result is not None:
                        self._finish(live, live.state.reference_joints, live.state.result)
                        log.info("live.finished analysis=%s", analysis_id)
                        return
                    if changed:
                        live.scene.update(live.state)
                except Exception as exc:  # keep the view; the next poll may do better
                    log.warning("live.refresh_failed analysis=%s error=%s", analysis_id, exc)

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
        live.stop.set()
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


#: Tabs remembered per viewer.
MAX_TABS = 256

_viewers: LiveViewers | None = None


def get_viewers() -> LiveViewers:
    """The process-wide viewers (stopped at interpreter exit)."""
    global _viewers
    if _viewers is None:
        import os

        _viewers = LiveViewers(host=os.environ.get("COACH_VIEWER_HOST", "127.0.0.1"))
        atexit.register(_viewers.stop_all)
    return _viewers
