"""The posture errors eps_t' over time (smoothed within segments, 2.1.3 item 6), the flags
per frame and the reports per segment (6.6), and the overall messages (6.7).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.ndimage import gaussian_filter1d, median_filter

from engine.stages.selection.boundaries import _Segmentation
from engine.types import SegmentReport


def owned_frames(spans: Sequence[tuple[int, int]]) -> list[tuple[int, int]]:
    """The frames ``(first, last)`` each performer segment ``(start, end)`` owns.

    Consecutive segments share their boundary frame, and the later one owns it (its DP sets
    that frame's C and candidate), so every segment but the last ends one frame early unless
    it has a single frame.
    """
    last = len(spans) - 1
    return [(ps, pe - 1 if i < last and pe > ps else pe) for i, (ps, pe) in enumerate(spans)]


def smooth_errors(
    bone_err: np.ndarray,
    owned: Sequence[tuple[int, int]],
    sigma_frames: float,
    median_frames: int = 1,
) -> np.ndarray:
    """Each bone's error (T', 16) over time: a running median of ``median_frames``, then a
    Gaussian of std ``sigma_frames``.

    Within each segment's own frames ``owned`` (:func:`owned_frames`) only: thesis 2.1.3
    item 6 and 2.1.6 D, the motion is smooth within a segment so its posture errors change
    slowly there, and they may change at its boundaries. The median drops a frame whose
    selected candidate jumped alone (the Gaussian alone would spread that spike over its
    neighbours). Near a segment's ends the Gaussian is cut there and renormalised, so an end
    frame's error is neither pulled towards zero nor counted more than once.
    """
    if sigma_frames <= 0 and median_frames <= 1:
        return bone_err
    out = bone_err.copy()
    for first, last in owned:
        if last <= first:
            continue
        x = bone_err[first : last + 1]
        if median_frames > 1:
            x = median_filter(x, size=(median_frames, 1), mode="nearest")
        if sigma_frames > 0:
            num = gaussian_filter1d(x, sigma_frames, axis=0, mode="constant")
            den = gaussian_filter1d(np.ones(len(x)), sigma_frames, mode="constant")
            x = num / den[:, None]
        out[first : last + 1] = x
    return out


def _frame_flags(
    seg: _Segmentation,
    eps: np.ndarray,
    large: float,
    candidate_flags: Sequence[Sequence[str]] | None,
) -> list[list[str]]:
    """Flags per video frame: stage 3's, then large errors (eps (T',) above ``large``
    radians), segment boundaries and the frames of missing or extra segments (6.6)."""
    flags: list[list[str]] = [
        list(candidate_flags[t]) if candidate_flags else [] for t in range(eps.shape[0])
    ]
    for t in np.flatnonzero(eps > large):
        flags[t].append("large_error")
    for i, (ps, pe) in enumerate(seg.spans):
        if i > 0:
            flags[ps].append("segment_boundary" if seg.found[i] else "segment_boundary_estimated")
        if seg.status[i] != "ok":
            for frame in range(ps, pe + 1):
                flags[frame].append(f"{seg.status[i]}_segment")
    return flags


def _segment_reports(
    seg: _Segmentation,
    eps: np.ndarray,
    bone_err: np.ndarray,
    costs: list[float],
) -> list[SegmentReport]:
    """One report per segment, its statistics over the frames it owns (:func:`owned_frames`)
    of the posture errors eps (T',) and bone errors (T', 16)."""
    owned = owned_frames(seg.spans)
    reports = []
    for i, ((ps, pe), (rs, re)) in enumerate(zip(seg.spans, seg.bounds, strict=True)):
        sl = slice(owned[i][0], owned[i][1] + 1)
        reports.append(
            SegmentReport(
                reference_start=int(rs), reference_end=int(re),
                performer_start=int(ps), performer_end=int(pe),
                initial_performer_start=int(seg.initial[i]), name=seg.names[i],
                status=seg.status[i], boundary_found=bool(seg.found[i]),
                tempo=float(seg.tempo[i]), mean_error=float(eps[sl].mean()),
                bone_mean_errors=bone_err[sl].mean(0), worst_frame=ps + int(np.argmax(eps[sl])),
                cost=float(costs[i]),
            )
        )  # fmt: skip
    return reports


def _messages(eps: np.ndarray, large: float, reports: list[SegmentReport]) -> list[str]:
    """Overall messages: a performer very different everywhere (6.7) gets one message
    instead of per-bone noise; missing and extra segments are named (6.6)."""
    messages = []
    if float(eps.mean()) > large:
        messages.append(
            f"Your motion is very different from the reference (mean posture error "
            f"{np.degrees(eps.mean()):.0f} deg): detailed per-bone errors are not meaningful; "
            "check that you performed the same motion, filmed from the expected side."
        )
    for i, r in enumerate(reports):
        if r.status == "missing":
            messages.append(f"Segment {r.name or i + 1} seems to be missing.")
        elif r.status == "extra_motion":
            messages.append(f"Segment {r.name or i + 1} seems to contain extra motion.")
    return messages
