"""Stage 4 in one call: boundaries, selection, refined C, posture errors (thesis 4.7)."""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np

from engine.stages.selection.boundaries import _segment_performer
from engine.stages.selection.errors import (
    _frame_flags,
    _messages,
    _segment_reports,
    owned_frames,
    smooth_errors,
)
from engine.stages.selection.evidence import _angles, _check_settings, _evidence, _validate
from engine.stages.selection.paths import _refine_segments
from engine.stages.selection.settings import SelectionSettings
from engine.types import Segments, Selection

ProgressFn = Callable[[str, float], None]


def select_and_refine(
    candidates: Sequence[np.ndarray],
    reference_joints: np.ndarray,
    reference_segments: Segments,
    C_initial: np.ndarray,
    *,
    settings: SelectionSettings | None = None,
    fps_ratio: float = 1.0,
    video_fps: float = 30.0,
    candidate_flags: Sequence[Sequence[str]] | None = None,
    candidate_d_s: Sequence[np.ndarray] | None = None,
    on_progress: ProgressFn | None = None,
) -> Selection:
    """Stage 4: boundaries, candidate selection, refined C and posture errors (thesis 4.7).

    Parameters
    ----------
    candidates : list of ndarray, shape (K_t', 17, 3) each
        Posture candidates per video frame, world frame (stage 3).
    reference_joints : ndarray, shape (T, 17, 3)
        Reference postures B_t.
    reference_segments : Segments
        Reference boundaries T_b (frame numbers of ``reference_joints``).
    C_initial : ndarray, shape (T',)
        Approximate correspondence from stage 2 (may be fractional).
    settings : SelectionSettings, optional
    fps_ratio : float
        Reference fps / video fps, for tempo.
    video_fps : float
        Frames per second of the video, for ``settings.error_smoothing_s``.
    candidate_flags : list of list of str, optional
        Stage-3 flags per video frame, passed through.
    candidate_d_s : list of ndarray, shape (K_t',) each, optional
        d_S of each candidate against its frame's body region (stage 3). When given, the
        candidate cost carries the image evidence (``settings.image_weight``) and candidates
        beyond ``settings.image_margin`` of their frame's best are dropped.
    on_progress : callable(stage, fraction), optional

    Returns
    -------
    Selection

    Raises
    ------
    InvalidInput
        On shapes, segments outside the reference or a non-positive ``fps_ratio``.
    """
    s = settings or SelectionSettings()
    cands, ref, C0 = _validate(
        candidates, reference_joints, reference_segments, C_initial, fps_ratio
    )
    _check_settings(s, video_fps)
    ev = _evidence(cands, ref, C0, candidate_d_s, s)
    seg = _segment_performer(ev, reference_segments, fps_ratio, s, on_progress)  # 4.7.1, 6.6
    C, ell, costs = _refine_segments(ev, seg, fps_ratio, s, on_progress)  # 4.7.2

    # eps_t' = d_B(B_C(t'), B'_t') per bone, smoothed within segments (2.1.3 item 6)
    frames = np.arange(ev.n_frames)
    bone_err = _angles(ev.ref_dirs[C], ev.cand_dirs[frames, ell])
    bone_err = smooth_errors(
        bone_err, owned_frames(seg.spans), s.error_smoothing_s * video_fps, s.error_median_frames
    )
    eps = bone_err.mean(-1)

    large = np.radians(s.large_error_deg)
    flags = _frame_flags(seg, eps, large, candidate_flags)
    reports = _segment_reports(seg, eps, bone_err, costs)
    return Selection(
        performer_segments=Segments(tuple(seg.starts), ev.n_frames - 1, seg.names),
        C=C, selected=ell, joints=ev.cand_joints[frames, ell], posture_error=eps,
        bone_errors=bone_err, flags=tuple(tuple(f) for f in flags), segments=tuple(reports),
        messages=tuple(_messages(eps, large, reports)),
    )  # fmt: skip
