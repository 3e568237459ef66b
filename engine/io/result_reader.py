"""The result JSON of an analysis read back as typed, frozen objects (DESIGN.md "Result of an
analysis"); the writer is :mod:`engine.io.result`, the extra keys of
:mod:`engine.stages.assessment` included.

Every reader of a result goes through :meth:`Result.from_dict` (or :func:`read_result` for a
file) instead of reading the dict by key: a malformed document fails once, here, with
:class:`~engine.errors.InvalidInput` naming the JSON path of the problem, and arrays come as
numpy arrays of a known shape. Keys that older results lack, or that only some frames carry,
read as None (a value) or an empty tuple (a list). The document itself stays available as
``Result.doc`` for code that passes the JSON on unchanged (HTTP responses).

This is not the JSON schema check (:func:`engine.io.result.validate_result`, which needs
jsonschema): it checks what the typed fields need (presence, types, shapes, indices) and
accepts a result without frames, so that readers keep their own answer for one.

Axis letters as in :mod:`engine.types`: T' video frames, K candidates, 17 joints, 16 bones.
"""

from __future__ import annotations

import json
import numbers
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

import numpy as np

from engine.body.skeleton import BONE_NAMES, JOINTS
from engine.errors import InvalidInput
from engine.render.camera import Camera

N_JOINTS = len(JOINTS)
N_BONES = len(BONE_NAMES)


# Dataclasses holding arrays compare by identity (eq=False): ``==`` on arrays is elementwise.
@dataclass(frozen=True, eq=False)
class ResultReference:
    """The reference motion analysed against (the BVH file as given)."""

    name: str
    frames: int
    """Frame count, a conversion T-pose included."""
    fps: float


@dataclass(frozen=True, eq=False)
class ResultVideo:
    """The whole performer video (not only an analysed frame range)."""

    frames: int
    fps: float
    width: int
    """Pixels, the video file's own (``joints_2d`` are in these)."""
    height: int
    first_frame: int = 0
    """The first analysed frame (``frames[0].t``): a range the user chose, or the first of
    several repetitions (``summary.repetitions``)."""


@dataclass(frozen=True, eq=False)
class ResultFrame:
    """One video frame t' (DESIGN.md ``frames[i]``)."""

    t: int
    """Video frame number t' (counted from the video's first frame, not the range's)."""
    reference_frame: int
    """C(t'), a frame of the BVH file as given."""
    joints_3d: np.ndarray
    """The selected posture B'_t', world frame, metres. Shape (17, 3)."""
    joints_2d: np.ndarray
    """Its projection, video pixels (u, v). Shape (17, 2)."""
    candidates: np.ndarray
    """Every candidate kept for this frame. Shape (K, 17, 3); K may be 0."""
    selected: int
    """Index of ``joints_3d`` in ``candidates``."""
    posture_error_deg: float
    """eps_t' = d_B(B_C(t'), B'_t')."""
    bone_errors_deg: np.ndarray
    """Angle per bone, order of ``BONE_NAMES``. Shape (16,)."""
    flags: tuple[str, ...]
    """E.g. ``"occluded:l_elbow"``, ``"low_confidence"``, ``"image_misfit"``."""
    score_deg: float | None = None
    """The domain's weighted error (with a domain file only)."""
    bone_error_range_deg: np.ndarray | None = None
    """[lo, hi] per bone over the candidates the video cannot tell apart. Shape (16, 2)."""
    bone_z: np.ndarray | None = None
    """Each bone's error over the expert's spread there (references built from several
    takes only). Shape (16,)."""
    outside_expert_range: bool | None = None
    expert_spread_deg: float | None = None
    expert_joints_2d: np.ndarray | None = None
    """The expert's posture at C(t') where the performer stands, video pixels. Shape (17, 2)."""
    """Mean spread of the expert's bones at C(t') (floored), degrees."""
    image_best: int | None = None
    """In ``image_misfit`` frames: index of the candidate that fits the video best."""
    image_best_joints_2d: np.ndarray | None = None
    """Its projection, video pixels. Shape (17, 2)."""


@dataclass(frozen=True, eq=False)
class ResultSegment:
    """One segment of the reference and the performer's frames matched to it."""

    reference_start: int
    reference_end: int
    performer_start: int
    """First video frame t' of the segment."""
    performer_end: int
    """Last video frame t' of the segment (inclusive)."""
    mean_error_deg: float
    bone_mean_errors_deg: np.ndarray
    """Mean error per bone over the segment's frames. Shape (16,)."""
    name: str | None = None
    status: str | None = None
    """``"ok"``, ``"missing"`` or ``"extra_motion"``."""
    tempo: float | None = None
    worst_frame: int | None = None
    """Video frame t' of the largest posture error."""
    worst_bones: tuple[str, ...] = ()
    initial_performer_start: int | None = None
    boundary_found: bool | None = None
    path_cost: float | None = None
    score_deg: float | None = None
    bone_uncertainty_deg: np.ndarray | None = None
    """Mean width of ``bone_error_range_deg`` per bone over the segment. Shape (16,); None
    for results that predate it and for a segment without frames."""
    bone_mean_z: np.ndarray | None = None
    """``bone_mean_errors_deg`` over the expert's mean spread in the segment. Shape (16,)."""
    within_expert_range: bool | None = None
    outside_bones: tuple[str, ...] = ()


@dataclass(frozen=True, eq=False)
class Fit:
    """How well the reported postures explain the video (``summary.fit``)."""

    region_mismatch_median: float
    region_mismatch_per_frame: np.ndarray
    """1 - Dice of the posture's body with stage 0's region, per frame. Shape (T',)."""
    poor_frames: int
    keypoint_worst_per_frame: np.ndarray | None = None
    """Worst confident keypoint's distance over body height per frame, NaN for a frame
    without one. Shape (T',); None without a pose model."""
    keypoint_off_frames: int | None = None


@dataclass(frozen=True)
class Repetition:
    """One performance of the reference in a video that holds several
    (``summary.repetitions``): file frames start..end-1."""

    start: int
    end: int
    start_s: float
    end_s: float
    analysed: bool


@dataclass(frozen=True, eq=False)
class ResultSummary:
    """The whole analysis in a few words; every field empty when a result has no summary."""

    status: str | None = None
    """``"ok"``, ``"very_different"``, ``"segments_mismatch"`` or ``"poor_fit"``."""
    mean_error_deg: float | None = None
    score_deg: float | None = None
    messages: tuple[str, ...] = ()
    fit: Fit | None = None
    outside_expert_range_share: float | None = None
    repetitions: tuple[Repetition, ...] = ()
    """Every repetition found, when the video holds more than one; empty otherwise."""


@dataclass(frozen=True, eq=False)
class Result:
    """A result document (DESIGN.md), typed. Build with :meth:`from_dict` or :func:`read_result`.

    The per-frame arrays are also available stacked over the frames (``joints_3d``,
    ``bone_errors_deg``, ...), computed on first use.
    """

    doc: dict[str, Any] = field(repr=False)
    """The document read (the same object when it is a dict, not a copy): pass it on
    unchanged."""
    version: int
    reference: ResultReference
    video: ResultVideo
    joints: tuple[str, ...]
    """The 17 joint names, order of ``engine.body.skeleton.JOINTS``."""
    camera: Camera
    """Stage 1's camera in the video file's pixels."""
    frames: tuple[ResultFrame, ...]
    segments: tuple[ResultSegment, ...]
    summary: ResultSummary
    timing_s: Mapping[str, float]
    """Seconds per stage, ``total`` included."""
    bones: tuple[str, ...] | None = None
    domain: Mapping[str, Any] | None = None
    """The reference's domain file as used (thesis 6.8), as in the document."""
    analysis_id: str | None = None
    """Added by the worker."""

    @classmethod
    def from_dict(cls, doc: Any) -> Result:
        """Read a result document.

        Parameters
        ----------
        doc : mapping
            As :func:`engine.io.result.build_result` returns it or ``json.load`` reads it.

        Returns
        -------
        Result

        Raises
        ------
        InvalidInput
            A missing key, or a value of the wrong type or shape, naming its JSON path
            (``result frames/3/joints_3d: expected shape (17, 3), got (16, 3)``).
        """
        d = _mapping(doc, "(root)")
        version = _int(_req(d, "version", ""), "version")
        if version != 1:
            raise InvalidInput(f"result version: expected 1, got {version}")
        joints = _strings(_req(d, "joints", ""), "joints")
        if joints != JOINTS:
            raise InvalidInput(f"result joints: expected {list(JOINTS)}, got {list(joints)}")
        frames = _list(_req(d, "frames", ""), "frames")
        segments = _list(_req(d, "segments", ""), "segments")
        timing = _mapping(_req(d, "timing_s", ""), "timing_s")
        return cls(
            doc=d if isinstance(d, dict) else dict(d),
            version=version,
            reference=_reference(_req(d, "reference", ""), "reference"),
            video=_video(_req(d, "video", ""), "video"),
            joints=joints,
            camera=_camera(_req(d, "camera", ""), "camera"),
            frames=tuple(_frame(f, f"frames/{i}") for i, f in enumerate(frames)),
            segments=tuple(_segment(s, f"segments/{i}") for i, s in enumerate(segments)),
            summary=_summary(d.get("summary"), "summary"),
            timing_s={str(k): _num(v, f"timing_s/{k}") for k, v in timing.items()},
            bones=_opt(d, "bones", "", _strings),
            domain=_opt(d, "domain", "", _mapping),
            analysis_id=_opt(d, "analysis_id", "", _str),
        )

    # ---- the frames' values stacked over T'
    @cached_property
    def t(self) -> np.ndarray:
        """Video frame numbers t'. Shape (T',), int."""
        return _frozen(np.array([f.t for f in self.frames], dtype=int))

    @cached_property
    def reference_frame(self) -> np.ndarray:
        """C(t'). Shape (T',), int."""
        return _frozen(np.array([f.reference_frame for f in self.frames], dtype=int))

    @cached_property
    def joints_3d(self) -> np.ndarray:
        """Selected postures, world frame, metres. Shape (T', 17, 3)."""
        return _stack([f.joints_3d for f in self.frames], (N_JOINTS, 3))

    @cached_property
    def joints_2d(self) -> np.ndarray:
        """Their projections, video pixels. Shape (T', 17, 2)."""
        return _stack([f.joints_2d for f in self.frames], (N_JOINTS, 2))

    @cached_property
    def posture_error_deg(self) -> np.ndarray:
        """eps_t'. Shape (T',)."""
        return _frozen(np.array([f.posture_error_deg for f in self.frames], dtype=float))

    @cached_property
    def bone_errors_deg(self) -> np.ndarray:
        """Error per bone. Shape (T', 16)."""
        return _stack([f.bone_errors_deg for f in self.frames], (N_BONES,))

    @cached_property
    def score_deg(self) -> np.ndarray | None:
        """The domain score per frame, shape (T',); None unless every frame has one."""
        scores = [f.score_deg for f in self.frames]
        if not scores or any(s is None for s in scores):
            return None
        return _frozen(np.array(scores, dtype=float))

    @cached_property
    def frame_index(self) -> Mapping[int, int]:
        """Video frame t' -> its index into ``frames``."""
        return {f.t: i for i, f in enumerate(self.frames)}


def as_result(result: Result | Mapping[str, Any]) -> Result:
    """``result`` itself if typed, else :meth:`Result.from_dict` of it (readers that still
    take documents from callers)."""
    return result if isinstance(result, Result) else Result.from_dict(result)


def read_result(path: str | os.PathLike) -> Result:
    """Read a result file (``result.json``).

    Raises
    ------
    InvalidInput
        Missing file, not JSON, or not a result (see :meth:`Result.from_dict`).
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise InvalidInput(f"result file {p} does not exist") from exc
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InvalidInput(f"result file {p}: not valid JSON ({exc})") from exc
    return Result.from_dict(doc)


# ---- the parts
def _reference(v: Any, where: str) -> ResultReference:
    m = _mapping(v, where)
    return ResultReference(
        name=_str(_req(m, "name", where), f"{where}/name"),
        frames=_int(_req(m, "frames", where), f"{where}/frames"),
        fps=_num(_req(m, "fps", where), f"{where}/fps"),
    )


def _video(v: Any, where: str) -> ResultVideo:
    m = _mapping(v, where)
    return ResultVideo(
        frames=_int(_req(m, "frames", where), f"{where}/frames"),
        fps=_num(_req(m, "fps", where), f"{where}/fps"),
        width=_int(_req(m, "width", where), f"{where}/width"),
        height=_int(_req(m, "height", where), f"{where}/height"),
        first_frame=_int(m.get("first_frame", 0), f"{where}/first_frame"),
    )


def _camera(v: Any, where: str) -> Camera:
    m = _mapping(v, where)
    for key in ("scale", "theta_z_deg", "cx", "cy"):
        _num(_req(m, key, where), f"{where}/{key}")
    for key in ("azimuth_deg", "perspective_distance_m"):
        _opt(m, key, where, _num)
    for key in ("width", "height"):
        _opt(m, key, where, _int)
    return Camera.from_dict(dict(m))


def _frame(v: Any, where: str) -> ResultFrame:
    m = _mapping(v, where)

    def req(key: str) -> Any:
        return _req(m, key, where)

    candidates = _array(req("candidates"), (None, N_JOINTS, 3), f"{where}/candidates")
    selected = _index(req("selected"), len(candidates), f"{where}/selected")
    image_best = _opt(m, "image_best", where, _int)
    if image_best is not None:
        image_best = _index(image_best, len(candidates), f"{where}/image_best")
    return ResultFrame(
        t=_int(req("t"), f"{where}/t"),
        reference_frame=_int(req("reference_frame"), f"{where}/reference_frame"),
        joints_3d=_array(req("joints_3d"), (N_JOINTS, 3), f"{where}/joints_3d"),
        joints_2d=_array(req("joints_2d"), (N_JOINTS, 2), f"{where}/joints_2d"),
        candidates=candidates,
        selected=selected,
        posture_error_deg=_num(req("posture_error_deg"), f"{where}/posture_error_deg"),
        bone_errors_deg=_array(req("bone_errors_deg"), (N_BONES,), f"{where}/bone_errors_deg"),
        flags=_strings(req("flags"), f"{where}/flags"),
        score_deg=_opt(m, "score_deg", where, _num),
        bone_error_range_deg=_opt_array(m, "bone_error_range_deg", (N_BONES, 2), where),
        image_best=image_best,
        image_best_joints_2d=_opt_array(m, "image_best_joints_2d", (N_JOINTS, 2), where),
        bone_z=_opt_array(m, "bone_z", (N_BONES,), where),
        outside_expert_range=_opt(m, "outside_expert_range", where, _bool),
        expert_spread_deg=_opt(m, "expert_spread_deg", where, _num),
        expert_joints_2d=_opt_array(m, "expert_joints_2d", (N_JOINTS, 2), where),
    )


def _segment(v: Any, where: str) -> ResultSegment:
    m = _mapping(v, where)

    def frame(key: str) -> int:
        return _int(_req(m, key, where), f"{where}/{key}")

    uncertainty = m.get("bone_uncertainty_deg")
    return ResultSegment(
        reference_start=frame("reference_start"),
        reference_end=frame("reference_end"),
        performer_start=frame("performer_start"),
        performer_end=frame("performer_end"),
        mean_error_deg=_num(_req(m, "mean_error_deg", where), f"{where}/mean_error_deg"),
        bone_mean_errors_deg=_array(
            _req(m, "bone_mean_errors_deg", where), (N_BONES,), f"{where}/bone_mean_errors_deg"
        ),
        name=_opt(m, "name", where, _str),
        status=_opt(m, "status", where, _str),
        tempo=_opt(m, "tempo", where, _num),
        worst_frame=_opt(m, "worst_frame", where, _int),
        worst_bones=_opt(m, "worst_bones", where, _strings) or (),
        initial_performer_start=_opt(m, "initial_performer_start", where, _int),
        boundary_found=_opt(m, "boundary_found", where, _bool),
        path_cost=_opt(m, "path_cost", where, _num),
        score_deg=_opt(m, "score_deg", where, _num),
        # a segment that owns no frame has [] (engine.stages.assessment.add_uncertainty)
        bone_uncertainty_deg=(
            _opt_array(m, "bone_uncertainty_deg", (N_BONES,), where) if uncertainty else None
        ),
        bone_mean_z=_opt_array(m, "bone_mean_z", (N_BONES,), where),
        within_expert_range=_opt(m, "within_expert_range", where, _bool),
        outside_bones=_opt(m, "outside_bones", where, _strings) or (),
    )


def _summary(v: Any, where: str) -> ResultSummary:
    if v is None:
        return ResultSummary()
    m = _mapping(v, where)
    return ResultSummary(
        status=_opt(m, "status", where, _str),
        mean_error_deg=_opt(m, "mean_error_deg", where, _num),
        score_deg=_opt(m, "score_deg", where, _num),
        messages=_opt(m, "messages", where, _strings) or (),
        fit=_opt(m, "fit", where, _fit),
        outside_expert_range_share=_opt(m, "outside_expert_range_share", where, _num),
        repetitions=tuple(
            _repetition(r, f"{where}/repetitions/{i}")
            for i, r in enumerate(_opt(m, "repetitions", where, _list) or ())
        ),
    )


def _repetition(v: Any, where: str) -> Repetition:
    m = _mapping(v, where)
    start, end = (_int(_req(m, k, where), f"{where}/{k}") for k in ("start", "end"))
    if not 0 <= start < end:
        raise InvalidInput(f"{where}: start..end must be a range of frames, got {start}..{end}")
    return Repetition(
        start=start, end=end,
        start_s=_num(_req(m, "start_s", where), f"{where}/start_s"),
        end_s=_num(_req(m, "end_s", where), f"{where}/end_s"),
        analysed=_bool(_req(m, "analysed", where), f"{where}/analysed"),
    )  # fmt: skip


def _fit(v: Any, where: str) -> Fit:
    m = _mapping(v, where)
    worst = _opt(m, "keypoint_worst_per_frame", where, _list)
    if worst is not None:  # JSON has no NaN: a frame without a confident keypoint says null
        worst = [np.nan if x is None else x for x in worst]
        worst = _array(worst, (None,), f"{where}/keypoint_worst_per_frame")
    return Fit(
        region_mismatch_median=_num(
            _req(m, "region_mismatch_median", where), f"{where}/region_mismatch_median"
        ),
        region_mismatch_per_frame=_array(
            _req(m, "region_mismatch_per_frame", where),
            (None,),
            f"{where}/region_mismatch_per_frame",
        ),  # fmt: skip
        poor_frames=_int(_req(m, "poor_frames", where), f"{where}/poor_frames"),
        keypoint_worst_per_frame=worst,
        keypoint_off_frames=_opt(m, "keypoint_off_frames", where, _int),
    )


# ---- checked conversions; ``where`` is the JSON path named in the error
def _req(m: Mapping[str, Any], key: str, where: str) -> Any:
    if key not in m:
        raise InvalidInput(f"result {where or '(root)'}: missing key {key!r}")
    return m[key]


def _opt(m: Mapping[str, Any], key: str, where: str, read: Any) -> Any:
    """``read(value, path)`` of an optional key; None when absent or null."""
    v = m.get(key)
    return None if v is None else read(v, f"{where}/{key}" if where else key)


def _got(v: Any) -> str:
    text = repr(v)
    return f"{type(v).__name__} {text if len(text) <= 40 else text[:37] + '...'}"


def _mapping(v: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(v, Mapping):
        raise InvalidInput(f"result {where}: expected an object, got {_got(v)}")
    return v


def _list(v: Any, where: str) -> Sequence[Any]:
    if not isinstance(v, list | tuple):
        raise InvalidInput(f"result {where}: expected a list, got {_got(v)}")
    return v


def _str(v: Any, where: str) -> str:
    if not isinstance(v, str):
        raise InvalidInput(f"result {where}: expected a string, got {_got(v)}")
    return v


def _strings(v: Any, where: str) -> tuple[str, ...]:
    return tuple(_str(x, f"{where}/{i}") for i, x in enumerate(_list(v, where)))


def _bool(v: Any, where: str) -> bool:
    if not isinstance(v, bool | np.bool_):
        raise InvalidInput(f"result {where}: expected true or false, got {_got(v)}")
    return bool(v)


def _int(v: Any, where: str) -> int:
    if not isinstance(v, numbers.Integral) or isinstance(v, bool | np.bool_):
        raise InvalidInput(f"result {where}: expected an integer, got {_got(v)}")
    return int(v)


def _num(v: Any, where: str) -> float:
    if not isinstance(v, numbers.Real) or isinstance(v, bool | np.bool_):
        raise InvalidInput(f"result {where}: expected a number, got {_got(v)}")
    return float(v)


def _index(k: int, n: int, where: str) -> int:
    k = _int(k, where)
    if n and not 0 <= k < n:  # without candidates there is nothing to index
        raise InvalidInput(f"result {where}: {k} is not an index into {n} candidates")
    return k


def _array(v: Any, shape: tuple[int | None, ...], where: str) -> np.ndarray:
    """Numbers of ``shape`` (None: any length) as a read-only float array."""
    dims = ["K" if s is None else str(s) for s in shape]
    want = f"({dims[0]},)" if len(dims) == 1 else f"({', '.join(dims)})"  # as numpy says shapes
    if not isinstance(v, list | tuple | np.ndarray):
        raise InvalidInput(f"result {where}: expected a list of shape {want}, got {_got(v)}")
    try:
        # no dtype: null, strings and ragged lists show as a non-numeric dtype or an error
        a = np.array(v)
    except ValueError:
        raise InvalidInput(f"result {where}: expected numbers of shape {want}") from None
    if a.shape == (0,) and shape[0] is None:  # e.g. no candidates
        a = a.reshape((0, *(n or 0 for n in shape[1:])))
    if a.dtype.kind not in "iuf":
        raise InvalidInput(f"result {where}: expected numbers of shape {want}")
    fits = a.ndim == len(shape) and all(s in (None, n) for s, n in zip(shape, a.shape, strict=True))
    if not fits:
        raise InvalidInput(f"result {where}: expected shape {want}, got {a.shape}")
    return _frozen(a.astype(float, copy=False))


def _opt_array(
    m: Mapping[str, Any], key: str, shape: tuple[int | None, ...], where: str
) -> np.ndarray | None:
    return _opt(m, key, where, lambda v, at: _array(v, shape, at))


def _stack(arrays: list[np.ndarray], shape: tuple[int, ...]) -> np.ndarray:
    return _frozen(np.stack(arrays) if arrays else np.zeros((0, *shape)))


def _frozen(a: np.ndarray) -> np.ndarray:
    """Read-only: the result is shared by its readers."""
    a.setflags(write=False)
    return a


__all__ = [
    "Fit",
    "Result",
    "ResultFrame",
    "ResultReference",
    "ResultSegment",
    "ResultSummary",
    "ResultVideo",
    "as_result",
    "read_result",
]
