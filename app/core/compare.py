"""Progress over time: one performer's analyses, and two attempts side by side.

Plain functions of results (no requests, no database), so the endpoints in
:mod:`app.api.routes.performers` stay thin and the numbers are testable on their own. A result is a
:class:`engine.io.result_reader.Result` or its document.

Two attempts of the same reference line up through the reference: each video frame t' has
its reference frame C(t') (``reference_frame``), so both error curves are plotted against the
reference's frames and attempts of different speeds share one timeline.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from functools import lru_cache
from typing import Any

from app.core.summary import summarise_segments
from worker.engine_surface import InvalidInput, Result, as_result, read_result, tempo_words

#: A change smaller than this (degrees, or tempo ratio x 100 %) counts as "about the same".
SAME_ERROR_DEG = 1.0
SAME_TEMPO = 0.05


def mean_error_deg(result: Result | Mapping[str, Any]) -> float | None:
    """Mean posture error eps_t' over the video frames, or None without frames."""
    errs = [f.posture_error_deg for f in as_result(result).frames]
    return sum(errs) / len(errs) if errs else None


@lru_cache(maxsize=256)
def _mean_error_file(path: str, mtime: float) -> float | None:
    try:
        return mean_error_deg(read_result(path))
    except (OSError, InvalidInput):
        return None


def mean_error_of_file(path: str | os.PathLike | None) -> float | None:
    """:func:`mean_error_deg` of a result.json (cached by path and modification time)."""
    if not path:
        return None
    try:
        return _mean_error_file(str(path), os.path.getmtime(path))
    except OSError:
        return None


def _change(a: float | None, b: float | None, same: float) -> str | None:
    """Going from a to b, lower being better: "better", "worse", "same"; None if unknown."""
    if a is None or b is None:
        return None
    if abs(b - a) < same:
        return "same"
    return "better" if b < a else "worse"


def _tempo_change(a: float | None, b: float | None) -> str | None:
    """Closer to the expert's tempo (ratio 1) is better."""
    if a is None or b is None:
        return None
    return _change(abs(a - 1.0), abs(b - 1.0), SAME_TEMPO)


def error_curve(result: Result | Mapping[str, Any]) -> list[list[float]]:
    """``[[reference_frame, posture_error_deg], ...]`` in video order (C is monotone)."""
    return [
        [float(f.reference_frame), round(f.posture_error_deg, 3)] for f in as_result(result).frames
    ]


def compare_results(
    result_a: Result | Mapping[str, Any], result_b: Result | Mapping[str, Any], names: list[str]
) -> dict[str, Any]:
    """Attempt A (earlier) against attempt B (later) of the same reference.

    Parameters
    ----------
    result_a, result_b : Result or dict
        Results, or their documents (DESIGN.md).
    names : list of str
        Segment names, by the reference's segment index.

    Returns
    -------
    dict
        ``mean`` ({a, b, change}), ``segments`` (one per segment index in either result:
        ``name``, ``a`` and ``b`` with ``mean_error_deg``, ``tempo_ratio``, ``tempo_text``,
        ``reference_start``, ``reference_end`` (or None when that attempt lacks the segment),
        ``error_change_deg`` (b - a), ``error_change`` and ``tempo_change`` ("better",
        "worse", "same" or None)),
        ``curves`` ({a, b}: :func:`error_curve`) and ``reference_frames`` ([first, last]
        reference frame either curve covers).
    """
    result_a, result_b = as_result(result_a), as_result(result_b)
    seg_a, seg_b = summarise_segments(result_a.doc), summarise_segments(result_b.doc)
    rows = []
    for i in range(max(len(seg_a), len(seg_b))):
        sides = {}
        for key, segs in (("a", seg_a), ("b", seg_b)):
            s = segs[i] if i < len(segs) else None
            sides[key] = None if s is None else {
                "mean_error_deg": round(s.mean_error_deg, 3),
                "tempo_ratio": None if s.tempo_ratio is None else round(s.tempo_ratio, 4),
                "tempo_text": tempo_words(s.tempo_ratio),
                "reference_start": s.reference_start, "reference_end": s.reference_end,
                "performer_start": s.performer_start, "performer_end": s.performer_end,
            }  # fmt: skip
        ea = sides["a"] and sides["a"]["mean_error_deg"]
        eb = sides["b"] and sides["b"]["mean_error_deg"]
        ta = sides["a"] and sides["a"]["tempo_ratio"]
        tb = sides["b"] and sides["b"]["tempo_ratio"]
        rows.append({
            "index": i, "name": names[i] if i < len(names) else f"segment {i + 1}",
            "a": sides["a"], "b": sides["b"],
            "error_change_deg": None if ea is None or eb is None else round(eb - ea, 3),
            "error_change": _change(ea, eb, SAME_ERROR_DEG),
            "tempo_change": _tempo_change(ta, tb),
        })  # fmt: skip
    ma, mb = mean_error_deg(result_a), mean_error_deg(result_b)
    curves = {"a": error_curve(result_a), "b": error_curve(result_b)}
    frames = [p[0] for c in curves.values() for p in c]
    return {
        "mean": {
            "a": None if ma is None else round(ma, 3),
            "b": None if mb is None else round(mb, 3),
            "change_deg": None if ma is None or mb is None else round(mb - ma, 3),
            "change": _change(ma, mb, SAME_ERROR_DEG),
        },
        "segments": rows,
        "curves": curves,
        "reference_frames": [min(frames), max(frames)] if frames else [0, 0],
    }
