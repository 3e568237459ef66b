"""What the API and the pages say about a result: per-segment tempo, worst bones, names.

The engine's result document (DESIGN.md) holds per-frame and per-segment numbers; this turns
them into what a coach reads: each segment's tempo against the reference, its worst bones
with how sure they are, and the segment's name from the reference's domain.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from app import models
from app.api.errors import ApiError
from app.models import Analysis, Reference
from app.schemas import SegmentPublic
from worker.engine_surface import (
    BEND_LABELS,
    BONE_CHILD,
    BONE_LABELS,
    BONE_NAMES,
    BONE_PARENT,
    JOINT_ANGLES,
    POSTURE_ANGLES,
    InvalidInput,
    Result,
    ResultFrame,
    ResultSegment,
    as_result,
    bone_label,
    joint_angles_deg,
    posture_angles_deg,
    tempo_words,
)


def misfit_bones(frames: Sequence[ResultFrame], height: float) -> list[str]:
    """Up to two bones whose picture differs most between the reported posture and the one
    that fits the video best, over ``image_misfit`` frames carrying ``image_best_joints_2d``.

    Bone vectors are compared in pixels, so a shift of the whole body does not count; a bone
    must differ by what a viewer notices (``height`` / 80, at least 3 px).
    """
    pairs = [(f.joints_2d, f.image_best_joints_2d) for f in frames
             if f.image_best_joints_2d is not None]  # fmt: skip
    if not pairs:
        return []
    p, g = (np.stack(x) for x in zip(*pairs, strict=True))  # (k, 17, 2) each
    diff = (g[:, BONE_CHILD] - g[:, BONE_PARENT]) - (p[:, BONE_CHILD] - p[:, BONE_PARENT])
    d = np.linalg.norm(diff, axis=-1).mean(0)  # (16,)
    px = max(3.0, height / 80)
    return [BONE_NAMES[b] for b in np.argsort(-d)[:2] if d[b] >= px]


def _tempo(seg: ResultSegment, ref_fps: float, vid_fps: float) -> float | None:
    """The performer's duration of a segment over the reference's (1 = as the expert)."""
    ref_len = seg.reference_end - seg.reference_start
    perf_len = seg.performer_end - seg.performer_start
    if ref_len > 0 and ref_fps > 0 and vid_fps > 0:
        return (perf_len / vid_fps) / (ref_len / ref_fps)
    return None


def _by_bone(values: np.ndarray | None) -> dict[str, float]:
    return {} if values is None else dict(zip(BONE_NAMES, map(float, values), strict=False))


def summarise_segments(result: Result | Mapping[str, Any]) -> list[SegmentPublic]:
    """One summary per reference segment of a result.

    Raises
    ------
    InvalidInput
        A malformed result document.
    """
    r = as_result(result)
    misfit = [f for f in r.frames if "image_misfit" in f.flags]
    out = []
    for i, seg in enumerate(r.segments):
        inside = [f for f in misfit if seg.performer_start <= f.t <= seg.performer_end]
        named = _by_bone(seg.bone_mean_errors_deg)
        worst = max(named, key=named.__getitem__) if named else None
        out.append(
            SegmentPublic(
                index=i,
                reference_start=seg.reference_start,
                reference_end=seg.reference_end,
                performer_start=seg.performer_start,
                performer_end=seg.performer_end,
                tempo_ratio=_tempo(seg, r.reference.fps, r.video.fps),
                mean_error_deg=seg.mean_error_deg,
                worst_bone=worst,
                worst_bone_error_deg=named[worst] if worst else None,
                bone_mean_errors_deg=named,
                misfit_frames=len(inside),
                misfit_bones=misfit_bones(inside, float(r.video.height)),
                bone_uncertainty_deg=_by_bone(seg.bone_uncertainty_deg),
                within_expert_range=seg.within_expert_range,
                outside_bones=list(seg.outside_bones),
                bone_mean_z=_by_bone(seg.bone_mean_z),
            )
        )
    return out


def segments_or_error(result: Result) -> list[SegmentPublic]:
    """:func:`summarise_segments`, or a 500 ``bad_result`` naming what is malformed."""
    try:
        return summarise_segments(result)
    except InvalidInput as exc:
        raise ApiError(500, "bad_result", f"the result is malformed ({exc})") from None


def segment_names(ref: Reference, n: int) -> list[str]:
    """The coach's names of a reference's ``n`` segments ("segment i" where unnamed)."""
    return models.segment_names(ref.domain_config, n)


def page_summary(analysis: Analysis, result: Result) -> dict[str, Any]:
    """Segments with names, tempo, score and worst bones, plus what the page header shows,
    in a coach's words: bones by their labels (``bone_labels``, in the result's bone order),
    tempo as one sentence. The API's ``/segments`` keeps the data contract's bone keys."""
    segments = segments_or_error(result)
    names = segment_names(analysis.reference, len(segments))
    coach_named = bool((analysis.reference.domain_config or {}).get("segment_names"))
    out = []
    for s, raw, name in zip(segments, result.segments, names, strict=True):
        d = s.model_dump()
        d["name"] = name if coach_named else (raw.name or name)
        d["tempo_text"] = tempo_words(s.tempo_ratio)
        # (bone, mean error, width of its range over the candidates the video cannot tell
        # apart, or None for results that predate it)
        worst = sorted(s.bone_mean_errors_deg.items(), key=lambda kv: -kv[1])[:3]
        d["worst_bones"] = [(bone_label(b), e, s.bone_uncertainty_deg.get(b)) for b, e in worst]
        d["worst_bone"] = bone_label(s.worst_bone) if s.worst_bone else None
        d["misfit_bones"] = [bone_label(b) for b in s.misfit_bones]
        d["outside_bones"] = [bone_label(b) for b in s.outside_bones]
        d["score"] = s.mean_error_deg if raw.score_deg is None else raw.score_deg
        out.append(d)
    return {
        "analysis_id": analysis.id,
        "reference": analysis.reference.name,
        "performer": analysis.performer.display_name,
        "bone_labels": list(BONE_LABELS),
        "segments": out,
        "key_positions": key_positions(
            out, (analysis.reference.domain_config or {}).get("key_position_names") or ()
        ),
    }


def key_positions(
    segments: Sequence[Mapping[str, Any]], names: Sequence[str] = ()
) -> list[dict[str, Any]]:
    """The moments between the reference's segments (each start, then the last one's end),
    each with the performer's video frame and the expert's frame. Named by the coach's
    ``names`` ("address", "top", "impact") when there is one per moment, else by the
    segments: "start of backswing" (with segments named address, backswing, downswing: the
    top of the backswing), "end of downswing"."""
    out = [
        {"name": f"start of {s['name']}", "frame": s["performer_start"],
         "reference_frame": s["reference_start"]}
        for s in segments
    ]  # fmt: skip
    if segments:
        last = segments[-1]
        out.append({"name": f"end of {last['name']}", "frame": last["performer_end"],
                    "reference_frame": last["reference_end"]})  # fmt: skip
    if len(names) == len(out):
        for k, name in zip(out, names, strict=True):
            k["name"] = name
    return out


def bend_angles(result: Result, reference_joints: np.ndarray) -> dict[str, Any]:
    """Every joint's bend (the angle between a bone and the one before it, 0 when straight)
    in every video frame, the performer's and the expert's at the matched moment C(t').

    Bends do not depend on where each body stands or faces, so the performer's 3D posture
    and the reference's are compared as they are. ``reference_joints`` is (T, 17, 3).

    Returns
    -------
    dict
        ``bends``: per bend its ``label`` ("left knee") and ``joint`` (where it is, a joint
        index of the data contract); ``performer`` and ``expert``: (frames, bends) degrees.
        ``posture``: the labels of :data:`POSTURE_ANGLES` (spine tilt from the vertical,
        shoulder and hip turn since the first frame), and ``performer_posture`` and
        ``expert_posture``: (frames, 4) degrees, each body against its own first frame (the
        expert's at the moment matched to the performer's first frame).
    """
    ref = np.asarray(reference_joints, float)
    frames = np.clip([f.reference_frame for f in result.frames], 0, len(ref) - 1)
    none = np.zeros((0, len(JOINT_ANGLES)))
    perf = joint_angles_deg(result.joints_3d) if result.frames else none
    expert = joint_angles_deg(ref[frames]) if result.frames else none
    stand = np.zeros((0, len(POSTURE_ANGLES)))
    perf_stand = posture_angles_deg(result.joints_3d) if result.frames else stand
    expert_stand = posture_angles_deg(ref[frames]) if result.frames else stand
    return {
        "bends": [{"label": BEND_LABELS[b], "joint": int(BONE_PARENT[b])}
                  for _, _, b in JOINT_ANGLES],
        "performer": np.round(perf, 1).tolist(),
        "expert": np.round(expert, 1).tolist(),
        "posture": [{"label": label} for label in POSTURE_ANGLES],
        "performer_posture": np.round(perf_stand, 1).tolist(),
        "expert_posture": np.round(expert_stand, 1).tolist(),
    }  # fmt: skip
