"""The result JSON of an analysis (DESIGN.md "Result of an analysis"): build, validate, write.

Degrees and pixels appear here, at the edge; the engine computes in radians and metres.
The schema lives beside this module in ``result_schema.json``.
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Mapping, Sequence
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from engine.body.kinematics import facing_turn, rot_y
from engine.body.skeleton import BONE_NAMES, JOINTS
from engine.errors import InvalidInput
from engine.render.camera import Camera
from engine.types import SegmentReport, Selection

SCHEMA_PATH = Path(__file__).with_name("result_schema.json")


def _r(a: np.ndarray | float, digits: int) -> Any:
    """Rounded nested lists (JSON size: mm and 1/1000 deg are plenty)."""
    return np.round(np.asarray(a, dtype=float), digits).tolist()


def build_result(
    *,
    reference_name: str,
    reference_frames: int,
    reference_fps: float,
    video: Mapping[str, float | int],
    camera: Camera,
    selection: Selection,
    candidates: Sequence[np.ndarray],
    timing_s: Mapping[str, float],
    domain: Any | None = None,
    reference_frame_offset: int = 0,
    video_frame_offset: int = 0,
) -> dict[str, Any]:
    """The result document of DESIGN.md from stage 4's output.

    Parameters
    ----------
    reference_name, reference_frames, reference_fps
        Of the BVH file as given (frame count includes a conversion T-pose).
    video : mapping
        ``frames``, ``fps``, ``width``, ``height`` of the whole video (the analysed frames
        start at ``video_frame_offset``, the result's ``video.first_frame``).
    camera : Camera
        Stage 1's camera, for ``joints_2d`` (thesis 4.2).
    selection : Selection
        Stage 4 (thesis 4.7).
    candidates : list of ndarray, shape (K_t', 17, 3)
        Stage 3's candidate sets, indices matching ``selection.selected``.
    timing_s : mapping
        Seconds per stage; ``total`` is added when absent.
    domain : engine.reference.domain.Domain, optional
        Adds ``score_deg`` (thesis 6.8) and segment names; raw errors are unchanged.
    reference_frame_offset : int
        Added to every reference frame (C was computed on a trimmed reference, e.g. without
        the conversion T-pose).
    video_frame_offset : int
        Added to every video frame (analysis of a frame range ``A:B``).

    Returns
    -------
    dict
        JSON-ready, valid against ``result_schema.json``.
    """
    n = selection.C.shape[0]
    if len(candidates) != n:
        raise InvalidInput(
            f"candidates: expected {n} frames like the selection, got {len(candidates)}"
        )
    # thesis 6.8: the domain's score weighs the raw bone errors; they stay as they are
    score = np.degrees(domain.score(selection.bone_errors)) if domain is not None else None
    frames = _frame_docs(
        selection, candidates, camera.project(selection.joints), score,
        reference_frame_offset, video_frame_offset,
    )  # fmt: skip
    names = list(domain.segment_names) if domain is not None and domain.segment_names else []
    segments = [
        _segment_doc(j, s, names, domain, reference_frame_offset, video_frame_offset)
        for j, s in enumerate(selection.segments)
    ]
    summary = _summary(selection, score)
    if domain is not None and getattr(domain, "bone_sd", None) is not None:
        add_variation(frames, segments, summary, selection, domain, reference_frame_offset)
    timing = {k: float(v) for k, v in timing_s.items()}
    timing.setdefault("total", float(sum(timing.values())))
    return {
        "version": 1,
        **_inputs_doc(reference_name, reference_frames, reference_fps, video, video_frame_offset),
        "joints": list(JOINTS),
        "bones": list(BONE_NAMES),
        "camera": _camera_doc(camera),
        "frames": frames,
        "segments": segments,
        "summary": summary,
        "domain": domain.to_dict() if domain is not None else None,
        "timing_s": timing,
    }


def _inputs_doc(
    reference_name: str,
    reference_frames: int,
    reference_fps: float,
    video: Mapping[str, float | int],
    video_frame_offset: int,
) -> dict[str, Any]:
    """The ``reference`` and ``video`` entries: what was analysed (see :func:`build_result`)."""
    return {
        "reference": {
            "name": reference_name, "frames": int(reference_frames), "fps": float(reference_fps)
        },
        "video": {
            "frames": int(video["frames"]), "fps": float(video["fps"]),
            "width": int(video["width"]), "height": int(video["height"]),
            "first_frame": int(video_frame_offset),
        },
    }  # fmt: skip


def _camera_doc(camera: Camera) -> dict[str, Any]:
    """The ``camera`` entry: stage 1's camera, with its roll in degrees for people."""
    cam = camera.to_dict()
    cam.setdefault("theta_z_deg", float(np.degrees(camera.theta_z)))
    return cam


def _frame_docs(
    selection: Selection,
    candidates: Sequence[np.ndarray],
    joints_2d: np.ndarray,
    score: np.ndarray | None,
    reference_frame_offset: int,
    video_frame_offset: int,
) -> list[dict[str, Any]]:
    """The ``frames`` entries: one per video frame of ``selection``, with the selected
    joints projected (``joints_2d``, shape (T', 17, 2), pixels) and the domain's ``score``
    (T',) in degrees when there is one."""
    deg_bones = np.degrees(selection.bone_errors)
    deg_eps = np.degrees(selection.posture_error)
    frames = []
    for i in range(selection.C.shape[0]):
        f: dict[str, Any] = {
            "t": int(i + video_frame_offset),
            "reference_frame": int(selection.C[i] + reference_frame_offset),
            "joints_3d": _r(selection.joints[i], 4),
            "joints_2d": _r(joints_2d[i], 2),
            "candidates": _r(candidates[i], 4),
            "selected": int(selection.selected[i]),
            "posture_error_deg": float(np.round(deg_eps[i], 3)),
            "bone_errors_deg": _r(deg_bones[i], 3),
            "flags": list(selection.flags[i]),
        }
        if score is not None:
            f["score_deg"] = float(np.round(score[i], 3))
        frames.append(f)
    return frames


def _segment_doc(
    j: int,
    s: SegmentReport,
    names: list[str],
    domain: Any | None,
    reference_frame_offset: int,
    video_frame_offset: int,
) -> dict[str, Any]:
    """The ``segments`` entry of segment ``j``: frames offset to the files' numbering, errors
    in degrees, the domain's name for it when it has one (``names``)."""
    bone_deg = np.degrees(s.bone_mean_errors)
    seg: dict[str, Any] = {
        "reference_start": s.reference_start + reference_frame_offset,
        "reference_end": s.reference_end + reference_frame_offset,
        "performer_start": s.performer_start + video_frame_offset,
        "performer_end": s.performer_end + video_frame_offset,
        "mean_error_deg": float(np.round(np.degrees(s.mean_error), 3)),
        "bone_mean_errors_deg": _r(bone_deg, 3),
        "name": names[j] if j < len(names) else (s.name or f"segment {j + 1}"),
        "status": s.status,
        "tempo": float(np.round(s.tempo, 4)),
        "worst_frame": s.worst_frame + video_frame_offset,
        "worst_bones": [BONE_NAMES[b] for b in np.argsort(-bone_deg)[:3]],
        "initial_performer_start": s.initial_performer_start + video_frame_offset,
        "boundary_found": s.boundary_found,
        "path_cost": float(np.round(s.cost, 6)),
    }
    if domain is not None:
        seg["score_deg"] = float(np.round(np.degrees(domain.score(s.bone_mean_errors)), 3))
    return seg


def add_expert_2d(
    doc: dict[str, Any], expert: np.ndarray, selected: np.ndarray, camera: Camera
) -> None:
    """``frames[i].expert_joints_2d``: the expert's posture at C(t') drawn where the performer
    stands in the video (a SimulCam-style ghost). It is turned about the vertical onto the
    selected posture (least squares over its bones) and moved to its hip, then projected with
    the video's camera, so what differs is the posture, not where the body faces.

    Parameters
    ----------
    expert : ndarray, shape (T', 17, 3)
        The reference at each frame's ``reference_frame``.
    selected : ndarray, shape (T', 17, 3)
        The selected postures (``joints_3d``).
    camera : Camera
        At the video's own size.
    """
    expert, selected = np.asarray(expert, float), np.asarray(selected, float)
    turn = facing_turn(expert[:, None], selected[:, None])  # (T',) one turn per frame
    hip = expert[:, :1]
    placed = np.einsum("tij,tkj->tki", rot_y(turn), expert - hip) + selected[:, :1]
    for f, uv in zip(doc["frames"], camera.project(placed), strict=True):
        f["expert_joints_2d"] = _r(uv, 2)


def add_variation(
    frames: list[dict[str, Any]],
    segments: list[dict[str, Any]],
    summary: dict[str, Any],
    selection: Selection,
    domain: Any,
    reference_frame_offset: int,
) -> None:
    """Errors against the expert's own variation (seed 002 eq. 22, a reference built from
    several takes). Per frame: ``bone_z``, ``outside_expert_range`` and the mean spread of the
    expert's bones there (``expert_spread_deg``, the error plot's band). Per segment:
    ``bone_mean_z``, ``within_expert_range`` and ``outside_bones``. In the summary: the share
    of frames outside."""
    ref = np.asarray(selection.C, int) + reference_frame_offset
    z = domain.z_scores(selection.bone_errors, ref)  # (T', 16)
    outside = z.max(axis=1) > domain.z_limit
    spread = np.maximum(domain.bone_sd, domain.sd_floor)  # (T, 16)
    at = np.degrees(spread[np.clip(ref, 0, len(spread) - 1)].mean(axis=1))  # (T',)
    for f, zi, out, sp in zip(frames, z, outside, at, strict=True):
        f["bone_z"] = _r(zi, 2)
        f["outside_expert_range"] = bool(out)
        f["expert_spread_deg"] = float(np.round(sp, 3))
    for seg, s in zip(segments, selection.segments, strict=True):
        span = spread[s.reference_start + reference_frame_offset : s.reference_end
                      + reference_frame_offset + 1]  # fmt: skip
        zs = s.bone_mean_errors / span.mean(axis=0)
        seg["bone_mean_z"] = _r(zs, 2)
        seg["within_expert_range"] = bool(zs.max() <= domain.z_limit)
        seg["outside_bones"] = [BONE_NAMES[b] for b in np.argsort(-zs) if zs[b] > domain.z_limit]
    share = float(outside.mean())
    summary["outside_expert_range_share"] = round(share, 4)
    summary["messages"].append(
        f"{share:.0%} of the analysed frames are outside the expert's own range "
        f"(a bone over {domain.z_limit:g} times the spread of the expert's takes there)."
    )


def _summary(selection: Selection, score: np.ndarray | None) -> dict[str, Any]:
    """The ``summary``: one status (a very different performer first, thesis 6.7, then
    missing or extra segments, 6.6), the mean error and the messages."""
    messages = list(selection.messages)
    status = "ok"
    if any("very different" in m for m in messages):
        status = "very_different"
    elif any(s.status != "ok" for s in selection.segments):
        status = "segments_mismatch"
    summary: dict[str, Any] = {
        "status": status,
        "mean_error_deg": float(np.round(np.degrees(selection.posture_error).mean(), 3)),
        "messages": messages,
    }
    if score is not None:
        summary["score_deg"] = float(np.round(score.mean(), 3))
    return summary


@lru_cache(maxsize=1)
def load_schema() -> dict[str, Any]:
    """The result JSON schema (draft 2020-12)."""
    return json.loads(SCHEMA_PATH.read_text(encoding="utf-8"))


def validate_result(doc: Any) -> None:
    """Check a result document against the schema and its cross-field rules.

    Raises
    ------
    InvalidInput
        Naming the JSON path of the first problem.
    """
    import jsonschema  # only needed when results are checked

    validator = jsonschema.Draft202012Validator(load_schema())
    err = next(iter(sorted(validator.iter_errors(doc), key=lambda e: list(e.absolute_path))), None)
    if err is not None:
        where = "/".join(str(p) for p in err.absolute_path) or "(root)"
        raise InvalidInput(f"result {where}: {err.message}")
    if doc["joints"] != list(JOINTS):
        raise InvalidInput(f"result joints: expected {list(JOINTS)}")
    for i, f in enumerate(doc["frames"]):
        for key in ("selected", "image_best"):
            if f.get(key, 0) >= len(f["candidates"]):
                raise InvalidInput(
                    f"result frames/{i}/{key}: {f[key]} is not an index into "
                    f"{len(f['candidates'])} candidates"
                )
    for i, s in enumerate(doc["segments"]):
        if s["performer_end"] < s["performer_start"] or s["reference_end"] < s["reference_start"]:
            raise InvalidInput(f"result segments/{i}: a segment ends before it starts")


def write_result(doc: Mapping[str, Any], path: str | os.PathLike) -> Path:
    """Validate and write a result atomically (temporary name, then rename)."""
    validate_result(doc)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=out.name + ".", suffix=".tmp", dir=out.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(doc, fh, separators=(",", ":"))
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return out


def read_result_doc(path: str | os.PathLike) -> dict[str, Any]:
    """Read a result file as its JSON document, validated against the schema (the typed
    reader is :func:`engine.io.result_reader.read_result`).

    Raises
    ------
    InvalidInput
        Missing file, not JSON, or not a valid result.
    """
    p = Path(path)
    try:
        doc = json.loads(p.read_text(encoding="utf-8"))
    except FileNotFoundError as exc:
        raise InvalidInput(f"result file {p} does not exist") from exc
    except json.JSONDecodeError as exc:
        raise InvalidInput(f"result file {p}: not valid JSON ({exc})") from exc
    validate_result(doc)
    return doc


def write_text(text: str, path: str | os.PathLike) -> Path:
    """Write a text artefact (the HTML report) atomically."""
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, out)
    return out


__all__ = [
    "SCHEMA_PATH",
    "build_result",
    "load_schema",
    "read_result_doc",
    "validate_result",
    "write_result",
    "write_text",
]
