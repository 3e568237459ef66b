"""Build the viser scene of one analysis (thesis 6.10: colour-coded errors, animation).

The reference posture B_C(t') (blue-grey) and the performer's selected posture B'_t' (each bone
green -> red by its error) are drawn as line segments with their hips overlaid; the other
candidates are thin translucent-grey lines behind a checkbox. A frame slider, a play button and
one button per segment (jumping to its worst frame) drive the scene. The same scene can be
written as a ``.viser`` recording (viser's scene serializer) for static playback.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import viser

from app.web_surface import (
    BONE_CHILD,
    BONE_PARENT,
    ERROR_RED_DEG,
    MISFIT_RGB,
    Result,
    ResultFrame,
    ResultSegment,
    as_result,
    error_colors,
)

#: What an unsure bone fades to (see :func:`bone_colours`).
UNSURE_GREY = np.array([0.6, 0.6, 0.6])

REFERENCE_RGB = (110, 130, 200)
CANDIDATE_RGB = (190, 190, 190)
#: The candidate that fits the video best, shown where the video disagrees (image_misfit).
IMAGE_BEST_RGB = MISFIT_RGB
#: Vertical field of view of the initial camera; narrower than viser's 75 deg so the
#: figure is not stretched at the edges of a tall, narrow iframe.
CAMERA_FOV_DEG = 50.0
#: Initial viewing direction (from the body to the camera, world frame): in front (+z, the
#: reference faces +z at frame 0), a little to the body's left and above, so depth is visible.
CAMERA_DIRECTION = np.array([0.45, 0.3, 1.0])
LABEL_LIFT = np.array([0.0, 0.25, 0.0])
#: Where the expert stands in the side-by-side layout: a body's width and a half to the side
#: (world x), so that two arms' lengths never overlap.
SIDE_BY_SIDE_M = np.array([0.9, 0.0, 0.0])
#: Fraction of the view's height the body's tallest extent fills.
FILL = 0.8


def _segments_of(joints: np.ndarray) -> np.ndarray:
    """Bone line segments of postures: (..., 17, 3) -> (..., 16, 2, 3)."""
    return np.stack([joints[..., BONE_PARENT, :], joints[..., BONE_CHILD, :]], -2)


def _hidden_at(point: np.ndarray) -> np.ndarray:
    """One zero-length segment at ``point`` (3,): how a line handle shows nothing, (1, 2, 3)."""
    return np.repeat(np.asarray(point, np.float32)[None], 2, 0)[None]


def _rgb_pairs(rgb01: np.ndarray) -> np.ndarray:
    """Per-bone colours (16, 3) in [0, 1] -> (16, 2, 3) uint8 for line segments."""
    c = np.clip(np.asarray(rgb01) * 255, 0, 255).astype(np.uint8)
    return np.repeat(c[:, None], 2, 1)


def bone_colours(
    frame: ResultFrame | Mapping[str, Any], *, z_limit: float | None = None
) -> np.ndarray:
    """Per-bone colours (16, 3) in [0, 1] of a result frame: the error's colour, washed out
    towards grey as the bone's range over the candidates the video cannot tell apart
    (``bone_error_range_deg``) widens, fully at ``ERROR_RED_DEG`` (x 0.7): a bright red bone
    is a sure fault, a pale one a guess about depth.

    With ``z_limit`` (a reference built from takes), the colour says how far the bone is
    outside the expert's own variation instead: red at ``bone_z = z_limit``.

    ``frame`` is a :class:`~engine.io.result_reader.ResultFrame` or a mapping with
    ``bone_errors_deg`` and, optionally, ``bone_error_range_deg`` and ``bone_z``."""
    if isinstance(frame, ResultFrame):
        errors, rng, z = frame.bone_errors_deg, frame.bone_error_range_deg, frame.bone_z
    else:
        errors, rng = frame["bone_errors_deg"], frame.get("bone_error_range_deg")
        z = frame.get("bone_z")
    if z_limit is not None and z is not None:
        errors = np.asarray(z, float) * (ERROR_RED_DEG / z_limit)  # z_limit shows as red
    rgb = error_colors(np.asarray(errors, float))
    if rng is None or not len(rng):
        return rgb
    width = np.ptp(np.asarray(rng, float), axis=1)
    k = 0.7 * np.clip(width / ERROR_RED_DEG, 0.0, 1.0)[:, None]
    return rgb * (1 - k) + UNSURE_GREY * k


@dataclass
class View:
    """What one viewer sees: its scene handles, its GUI, its frame and colouring.

    ``target`` is the :class:`viser.ViserServer` (the shared view: recordings, and what a
    client sees before its own view exists) or one :class:`viser.ClientHandle` (a browser
    tab's own view, whose scene nodes shadow the shared ones of the same name).
    """

    target: Any
    handles: dict[str, Any] = field(default_factory=dict)
    current: int = 0
    #: Colour bones by the expert's range (red at this z) instead of degrees; None: degrees.
    z_limit: float | None = None
    #: Draw the expert beside the performer (SIDE_BY_SIDE_M to the side) instead of over them.
    side_by_side: bool = False


@dataclass
class ViewerScene:
    """A built scene; ``set_frame`` shows one video frame in one view.

    Attributes
    ----------
    frames : tuple of ResultFrame
        ``result.frames``.
    reference_joints : ndarray, shape (T, 17, 3)
        The BVH as given (frame numbers of the result index it directly).
    view : View
        The server-wide view.
    clients : dict of int to View
        With ``per_client``: each connected client's own view, by viser client id.
    """

    server: viser.ViserServer
    reference_joints: np.ndarray
    frames: tuple[ResultFrame, ...]
    fps: float
    segments: tuple[ResultSegment, ...] = ()
    result_doc: Mapping[str, Any] = field(default_factory=dict)
    view: View | None = None
    clients: dict[int, View] = field(default_factory=dict)
    #: Frames asked for clients whose view does not exist yet (shown when it does).
    wanted: dict[int, int] = field(default_factory=dict)
    gui: bool = True
    look_at: np.ndarray = field(default_factory=lambda: np.zeros(3))
    _lock: threading.Lock = field(default_factory=threading.Lock)
    _stop: threading.Event = field(default_factory=threading.Event)
    _thread: threading.Thread | None = None

    @property
    def handles(self) -> dict[str, Any]:
        """The shared view's handles."""
        assert self.view is not None
        return self.view.handles

    @property
    def current(self) -> int:
        assert self.view is not None
        return self.view.current

    @property
    def z_limit(self) -> float | None:
        """The shared view's colouring: None for degrees, else red at this bone z."""
        assert self.view is not None
        return self.view.z_limit

    def postures(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(reference (17, 3), selected (17, 3), other candidates (K-1, 17, 3)) of frame i,
        the reference translated so its hip sits on the performer's."""
        f = self.frames[i]
        sel = f.joints_3d
        ref = self.reference_joints[f.reference_frame]
        ref = ref - ref[0] + sel[0]
        cands = f.candidates if len(f.candidates) else sel[None]
        others = np.delete(cands, f.selected, axis=0) if len(cands) > 1 else cands[:0]
        return ref, sel, others

    def set_frame(self, i: int, client_id: int | None = None) -> None:
        """Show video frame index ``i`` (into ``frames``) in the shared view, or in client
        ``client_id``'s own view (remembered until that view exists)."""
        if client_id is None:
            assert self.view is not None
            self.show(self.view, i)
            return
        with self._lock:
            view = self.clients.get(client_id)
            if view is None:
                self.wanted[client_id] = int(i)
                return
        self.show(view, i)

    def show(self, view: View, i: int) -> None:
        """Show frame ``i`` in ``view``."""
        i = int(np.clip(i, 0, len(self.frames) - 1))
        view.current = i
        ref, sel, others = self.postures(i)
        if view.side_by_side:
            ref = ref + SIDE_BY_SIDE_M
        f = self.frames[i]
        h = view.handles
        with view.target.atomic():
            h["reference"].points = _segments_of(ref).astype(np.float32)
            h["performer"].points = _segments_of(sel).astype(np.float32)
            h["performer"].colors = _rgb_pairs(bone_colours(f, z_limit=view.z_limit))
            if len(others):
                h["candidates"].points = _segments_of(others).reshape(-1, 2, 3).astype(np.float32)
            else:
                h["candidates"].points = _hidden_at(sel[0])
            best = f.image_best
            if best is not None and 0 <= best < len(f.candidates):
                pts = _segments_of(f.candidates[best])
            else:  # the video agrees with the reported posture: nothing to show
                pts = _hidden_at(sel[0])
            h["image_best"].points = pts.astype(np.float32)
            h["label"].text = (
                f"frame {f.t}: {f.posture_error_deg:.1f}° from the expert's frame "
                f"{f.reference_frame}"
            )
            top = sel[16] + LABEL_LIFT  # above the performer's head, or the expert's if higher
            top[1] = max(sel[16, 1], ref[16, 1]) + LABEL_LIFT[1]
            h["label"].position = tuple(float(x) for x in top)
        if "slider" in h and h["slider"].value != i:
            h["slider"].value = i

    def add_client(self, client: Any) -> None:
        """A browser tab connected: its own view (handles shadowing the shared ones, its own
        GUI), at the frame asked for it, or the shared view's."""
        view = View(client)
        _add_handles(view, self.look_at)
        if self.gui:
            _add_gui(self, view)
        with self._lock:
            self.clients[client.client_id] = view
            start = self.wanted.pop(client.client_id, None)
        self.show(view, self.current if start is None else start)

    def drop_client(self, client: Any) -> None:
        with self._lock:
            self.clients.pop(client.client_id, None)
            self.wanted.pop(client.client_id, None)

    def views(self) -> list[View]:
        with self._lock:
            return [v for v in (self.view, *self.clients.values()) if v is not None]

    def close(self) -> None:
        """Stop the play thread."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=2)


def frame_body(scene: ViewerScene) -> tuple[np.ndarray, np.ndarray, float]:
    """Where the initial camera looks from and to, so the whole motion fills the view.

    The box of every selected posture and its hip-aligned reference over all frames gives the
    target (its centre) and the distance (its largest extent fills ``FILL`` of the vertical
    field of view, with room for a sphere of that size in any orbit).

    Returns
    -------
    look_at : ndarray, shape (3,)
    position : ndarray, shape (3,)
    floor : float
        Lowest joint height (y), for the ground grid.
    """
    pts = []
    for i in range(len(scene.frames)):
        ref, sel, _ = scene.postures(i)
        pts += [ref, sel]
    return frame_points(np.concatenate(pts))


def frame_points(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """:func:`frame_body` for any points (..., 3): (look_at, position, floor); NaN ignored."""
    p = np.asarray(points, float).reshape(-1, 3)
    p = p[np.isfinite(p).all(1)]
    if not len(p):
        p = np.zeros((1, 3))
    lo, hi = p.min(0), p.max(0)
    look_at = (lo + hi) / 2
    extent = float(max(np.linalg.norm(hi - lo) * 0.85, hi[1] - lo[1], 0.5))
    distance = extent / 2 / np.tan(np.radians(CAMERA_FOV_DEG) / 2) / FILL
    direction = CAMERA_DIRECTION / np.linalg.norm(CAMERA_DIRECTION)
    return look_at, look_at + distance * direction, float(lo[1])


def _legend_html() -> str:
    stops = ", ".join(
        f"rgb{tuple(int(c * 255) for c in error_colors(d))} {100 * d / ERROR_RED_DEG:.0f}%"
        for d in np.linspace(0, ERROR_RED_DEG, 5)
    )
    return (
        "<div style='font-size:12px'>bone error"
        f"<div style='height:12px;background:linear-gradient(to right,{stops})'></div>"
        f"<div style='display:flex;justify-content:space-between'><span>0&deg;</span>"
        f"<span>{ERROR_RED_DEG / 2:.0f}&deg;</span><span>&ge;{ERROR_RED_DEG:.0f}&deg;</span></div>"
        "<div><span style='color:rgb(110,130,200)'>&#9632;</span> the expert "
        "<span style='color:#aaa'>&#9632;</span> other possible postures</div>"
        f"<div><span style='color:rgb{MISFIT_RGB}'>&#9632;</span> what the video shows where it "
        "disagrees</div><div>paler: the video cannot tell the bone's depth</div></div>"
    )


def build_scene(
    server: viser.ViserServer,
    reference_joints: np.ndarray,
    result: Result | Mapping[str, Any],
    *,
    gui: bool = True,
    per_client: bool = False,
) -> ViewerScene:
    """Add an analysis to a viser server.

    Parameters
    ----------
    server : viser.ViserServer
    reference_joints : ndarray, shape (T, 17, 3)
        Reference joints, world frame, frames counted as in the BVH file.
    result : Result or dict
        A result, or its document (DESIGN.md).
    gui : bool
        Add the GUI (slider, play, candidates toggle, legend, segments).
    per_client : bool
        Give every connecting browser tab its own view: its own frame, slider, colouring
        and candidate toggle (issue 21 item 2), moved by ``set_frame(i, client_id)``. The
        GUI is then per client only; without it, one GUI and one frame for everyone.

    Returns
    -------
    ViewerScene
        Showing the first frame.
    """
    ref = np.asarray(reference_joints, float)
    result = as_result(result)
    if not result.frames:
        raise ValueError("result: no frames to show")
    scene = ViewerScene(server, ref, result.frames, result.video.fps, result.segments,
                        result_doc=result.doc, gui=gui)  # fmt: skip
    server.scene.set_up_direction("+y")
    look_at, position, floor = frame_body(scene)
    scene.look_at = look_at
    server.scene.add_grid(
        "/ground", width=3, height=3, plane="xz", position=(look_at[0], floor, look_at[2])
    )
    # Every new client starts (and "Reset View" returns) close to the body, not at viser's
    # default of 3 m out on every axis around the world origin, where a 1.7 m figure is small.
    server.initial_camera.fov = np.radians(CAMERA_FOV_DEG)
    server.initial_camera.look_at = tuple(look_at)
    server.initial_camera.position = tuple(position)
    scene.view = View(server)
    _add_handles(scene.view, look_at)
    if gui and not per_client:
        _add_gui(scene, scene.view)
    scene.show(scene.view, 0)
    if per_client:
        server.on_client_connect(scene.add_client)  # also replayed for connected clients
        server.on_client_disconnect(scene.drop_client)
    if gui:
        scene._thread = threading.Thread(target=_play, args=(scene,), name="viewer-play",
                                         daemon=True)  # fmt: skip
        scene._thread.start()
    return scene


def _add_handles(view: View, look_at: np.ndarray) -> None:
    """The scene nodes of one view (line segments and the frame's label)."""
    api = view.target.scene
    zero = np.zeros((16, 2, 3), np.float32)
    h = view.handles
    h["candidates"] = api.add_line_segments(
        "/candidates", zero, CANDIDATE_RGB, thickness=3, thickness_units="screen"
    )
    h["image_best"] = api.add_line_segments(
        "/image_best", zero, IMAGE_BEST_RGB, thickness=5, thickness_units="screen"
    )
    h["reference"] = api.add_line_segments(
        "/reference", zero, REFERENCE_RGB, thickness=6, thickness_units="screen"
    )
    h["performer"] = api.add_line_segments(
        "/performer", zero, np.zeros((16, 2, 3), np.uint8), thickness=8, thickness_units="screen"
    )
    h["label"] = api.add_label("/label", "", position=tuple(look_at + (0.0, 1.2, 0.0)))


def _add_gui(scene: ViewerScene, view: View) -> None:
    gui, h, n = view.target.gui, view.handles, len(scene.frames)
    slider = gui.add_slider("frame", min=0, max=max(n - 1, 1), step=1, initial_value=0)
    play = gui.add_checkbox("play", initial_value=False)
    show = gui.add_checkbox("other possible postures", initial_value=True)
    beside = gui.add_checkbox("expert beside you", initial_value=False,
                              hint="off: the expert is drawn over you, hips together")  # fmt: skip
    gui.add_html(_legend_html())
    h.update(slider=slider, play=play, show_candidates=show, side_by_side=beside)

    @beside.on_update
    def _(_event: Any) -> None:
        view.side_by_side = bool(beside.value)
        scene.show(view, view.current)

    @slider.on_update
    def _(_event: Any) -> None:
        if int(slider.value) != view.current:
            scene.show(view, int(slider.value))

    @show.on_update
    def _(_event: Any) -> None:
        h["candidates"].visible = bool(show.value)

    if all(f.bone_z is not None for f in scene.frames):  # a reference built from takes
        limit = float(((scene.result_doc.get("domain") or {}).get("variation") or {})
                      .get("z_limit", 3.0))  # fmt: skip
        by = gui.add_dropdown(
            "colour by", ("degrees", "expert's range"), initial_value="degrees",
            hint=f"expert's range: red where a bone is {limit:g} times the expert's own spread",
        )  # fmt: skip
        h["colour_by"] = by

        @by.on_update
        def _(_event: Any) -> None:
            view.z_limit = limit if by.value == "expert's range" else None
            scene.show(view, view.current)

    t_to_i = {f.t: i for i, f in enumerate(scene.frames)}
    with gui.add_folder("segments"):
        for j, s in enumerate(scene.segments):
            worst = t_to_i.get(s.performer_start if s.worst_frame is None else s.worst_frame, 0)
            label = f"{s.name or j + 1}: {s.mean_error_deg:.1f}°"
            if (s.status or "ok") != "ok":
                label += f" ({s.status})"
            button = gui.add_button(label)
            button.on_click(lambda _e, i=worst: scene.show(view, i))
            h[f"segment_{j}"] = button


def _play(scene: ViewerScene) -> None:
    """Advance every view whose "play" box is ticked, at the video's frame rate."""
    n = len(scene.frames)
    while not scene._stop.wait(1.0 / max(scene.fps, 1.0)):
        for view in scene.views():
            play = view.handles.get("play")
            if play is not None and play.value:
                scene.show(view, (view.current + 1) % n)


def record_scene(scene: ViewerScene, *, stride: int = 1) -> bytes:
    """A ``.viser`` recording of the whole analysis: one keyframe per video frame.

    Parameters
    ----------
    scene : ViewerScene
        Built with :func:`build_scene`.
    stride : int
        Record every ``stride``-th frame.

    Returns
    -------
    bytes
        Write to ``name.viser``; play with viser's static client.
    """
    serializer = scene.server.get_scene_serializer()
    for i in range(0, len(scene.frames), max(1, stride)):
        scene.set_frame(i)
        serializer.insert_sleep(stride / max(scene.fps, 1.0))
    data = serializer.serialize()
    scene.set_frame(0)
    return data


def free_port() -> int:
    """An unused TCP port on localhost."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def wait_until_listening(port: int, timeout_s: float = 10.0) -> None:
    """Block until something accepts connections on ``port``."""
    import socket

    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise TimeoutError(f"nothing listens on port {port} after {timeout_s} s")
