"""Performer segment boundaries (thesis 4.7.1) and the segments' status (6.6).

Around stage 2's boundary, smooth candidate sequences are searched for the frame where the
boundary joints change direction (2.1.6 C) closest to the reference's boundary posture; a
segment far too short is "missing", far too long "extra_motion".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from engine.body.skeleton import JOINT_INDEX
from engine.stages.selection.evidence import _angles, _Evidence
from engine.stages.selection.settings import SelectionSettings
from engine.types import Segments

ProgressFn = Callable[[str, float], None]


def _smooth_sequences(dirs: np.ndarray, valid: np.ndarray, threshold: float) -> np.ndarray:
    """Smooth candidate sequences over a window (thesis 4.7.1 step 3).

    Viterbi over the window with transition cost d_B between consecutive candidates; one
    sequence per candidate at the window's last frame, kept when every step stays below
    ``threshold``.

    Parameters
    ----------
    dirs : ndarray, shape (n, K, 16, 3)
        Bone directions of the window's candidates.
    valid : ndarray of bool, shape (n, K)
    threshold : float
        Radians.

    Returns
    -------
    sequences : ndarray of int, shape (M, n)
        Candidate index per window frame, M >= 1 (the smoothest is kept even above threshold).
    """
    n, k = valid.shape
    cost = np.where(valid[0], 0.0, np.inf)
    worst = np.zeros(k)
    back = np.zeros((n, k), dtype=int)
    for i in range(1, n):
        step = _angles(dirs[i - 1][:, None], dirs[i][None]).mean(-1)  # (K_prev, K)
        total = cost[:, None] + step
        back[i] = np.argmin(total, axis=0)
        cost = np.where(valid[i], total[back[i], np.arange(k)], np.inf)
        worst = np.maximum(worst[back[i]], step[back[i], np.arange(k)])
    paths = np.empty((k, n), dtype=int)
    paths[:, -1] = np.arange(k)
    for i in range(n - 1, 0, -1):
        paths[:, i - 1] = back[i, paths[:, i]]
    keep = np.isfinite(cost) & (worst <= threshold)
    if not keep.any():
        keep = cost == cost.min()
    return np.unique(paths[keep], axis=0)


def _boundary_frames(rel: np.ndarray, cos_tau: float, pause_speed: float) -> np.ndarray:
    """Frames of a sequence that satisfy the boundary condition (thesis 2.1.6 C).

    v_tau . v_tau+1 < tau for any boundary joint, with directions taken from the last moving
    velocity before and the first moving velocity after, so a pause (2.1.3 item 4) counts as a
    boundary at its first still frame.

    Parameters
    ----------
    rel : ndarray, shape (n, J_b, 3)
        Boundary joints relative to the hip along one smooth sequence.

    Returns
    -------
    frames : ndarray of int
        Window-relative indices tau in [1, n-2].
    """
    n = rel.shape[0]
    if n < 3:
        return np.zeros(0, dtype=int)
    v = np.diff(rel, axis=0)  # v[i] = motion from i to i+1, (n-1, J_b, 3)
    speed = np.linalg.norm(v, axis=-1)
    moving = speed > pause_speed
    unit = v / np.maximum(speed, 1e-12)[..., None]
    # last moving velocity arriving at tau (index <= tau-1), first leaving it (index >= tau)
    idx = np.arange(n - 1)[:, None].repeat(rel.shape[1], 1)
    last_in = np.maximum.accumulate(np.where(moving, idx, -1), axis=0)
    first_out = np.minimum.accumulate(np.where(moving, idx, n)[::-1], axis=0)[::-1]
    taus = np.arange(1, n - 1)
    li, fo = last_in[taus - 1], first_out[taus]
    ok = (li >= 0) & (fo < n - 1)
    j = np.arange(rel.shape[1])
    cos = np.sum(unit[np.clip(li, 0, n - 2), j] * unit[np.clip(fo, 0, n - 2), j], -1)
    hit = (ok & (cos < cos_tau)).any(-1)
    # a still run is one boundary: keep only the first frame of a run of hits that is still
    still_at = ~moving[taus].any(-1) & ~moving[taus - 1].any(-1)
    first_of_run = hit & ~(still_at & np.r_[False, hit[:-1]])
    return taus[first_of_run]


def _find_boundary(
    lo: int,
    hi: int,
    t_ref: int,
    ev: _Evidence,
    s: SelectionSettings,
    joint_ids: np.ndarray,
    initial: int,
) -> tuple[int, bool]:
    """Performer boundary for reference boundary ``t_ref`` in [lo, hi].

    Thesis 4.7.1 steps 3-5, eq. 4.23; returns (frame, whether the velocity condition held).
    """
    seqs = _smooth_sequences(
        ev.cand_dirs[lo : hi + 1], ev.valid[lo : hi + 1], np.radians(s.smooth_threshold_deg)
    )
    frames = np.arange(lo, hi + 1)
    best: tuple[float, int] | None = None
    fallback: tuple[float, int] | None = None
    for seq in seqs:
        joints = ev.cand_joints[frames, seq]
        rel = joints[:, joint_ids] - joints[:, :1]
        err = _angles(ev.ref_dirs[t_ref][None], ev.cand_dirs[frames, seq]).mean(-1)  # d_B
        # image evidence and the pull towards stage 2's boundary (see SelectionSettings)
        err = err + ev.image[frames, seq]
        err = err + np.radians(s.anchor_deg_per_frame) * np.abs(frames - initial)
        for tau in _boundary_frames(rel, np.cos(np.radians(s.direction_change_deg)), s.pause_speed):
            if best is None or err[tau] < best[0]:
                best = (float(err[tau]), int(lo + tau))
        i = int(np.argmin(err))
        if fallback is None or err[i] < fallback[0]:
            fallback = (float(err[i]), int(lo + i))
    if best is not None:
        return best[1], True
    assert fallback is not None  # seqs is never empty
    return fallback[1], False


def _initial_boundary(C0: np.ndarray, t_ref: int) -> int:
    """First video frame whose C reaches ``t_ref`` (4.7.1 step 1)."""
    hit = np.flatnonzero(C0 >= t_ref)
    return int(hit[0]) if hit.size else len(C0) - 1


@dataclass(frozen=True)
class _Segmentation:
    """The performer's segments (4.7.1) and their 6.6 status, one entry per reference segment.

    Attributes
    ----------
    bounds : list of (int, int)
        (start, end) reference frames of each segment, inclusive.
    starts : list of int
        First video frame of each segment (monotone; ``starts[0] == 0``).
    spans : list of (int, int)
        (start, end) video frames of each segment, inclusive; consecutive ones share a frame.
    initial : list of int
        Stage 2's start of each segment (:func:`_initial_boundary`), then the last frame.
    found : list of bool
        Whether each start satisfied the velocity condition (the first always does).
    tempo : ndarray, shape (n_segments,)
        Performer duration / reference duration.
    status : list of str
        "ok", "missing" or "extra_motion".
    names : tuple of str
        The reference segments' names ("" when unnamed).
    """

    bounds: list[tuple[int, int]]
    starts: list[int]
    spans: list[tuple[int, int]]
    initial: list[int]
    found: list[bool]
    tempo: np.ndarray
    status: list[str]
    names: tuple[str, ...]


def _segment_names(segments: Segments) -> tuple[str, ...]:
    """One name per segment: the given ones, padded (or cut) with ""."""
    n = len(segments.starts)
    names = tuple(segments.names) or ("",) * n
    if len(names) != n:
        names = tuple(names[i] if i < len(names) else "" for i in range(n))
    return names


def _performer_starts(
    ev: _Evidence,
    bounds: list[tuple[int, int]],
    s: SelectionSettings,
    on_progress: ProgressFn | None,
) -> tuple[list[int], list[int], list[bool]]:
    """Performer boundaries (thesis 4.7.1), one per interior reference boundary.

    Each is searched within ``s.boundary_window`` of stage 2's and never before the previous
    one, so the segments stay in temporal order (2.1.6 B). Returns (initial, starts, found):
    stage 2's starts plus the last frame, the chosen starts, and whether the velocity
    condition held at each.
    """
    n_v = ev.n_frames
    joint_ids = np.array([JOINT_INDEX[j] for j in s.boundary_joints])
    initial = [0] + [_initial_boundary(ev.C0, t) for t, _ in bounds[1:]] + [n_v - 1]
    starts = [0]
    found = [True]
    for j, (t_ref, _) in enumerate(bounds[1:], start=1):
        lo = max(starts[-1], initial[j] - s.boundary_window)
        hi = min(n_v - 1, initial[j] + s.boundary_window)
        lo = min(lo, hi)
        tau, ok = _find_boundary(lo, hi, t_ref, ev, s, joint_ids, initial[j])
        starts.append(max(tau, starts[-1]))
        found.append(ok)
        if on_progress:
            on_progress("selection", 0.2 * j / max(len(bounds) - 1, 1))
    return initial, starts, found


def _segment_status(
    spans: list[tuple[int, int]],
    bounds: list[tuple[int, int]],
    fps_ratio: float,
    s: SelectionSettings,
) -> tuple[np.ndarray, list[str]]:
    """Tempo (n_segments,) of each performed segment and its status (thesis 6.6).

    A segment far slower than the median tempo, or too short, is "missing"; one far faster
    is "extra_motion": reported rather than forced to match.
    """
    tempo = np.array(
        [
            (pe - ps) * fps_ratio / max(re - rs, 1)
            for (ps, pe), (rs, re) in zip(spans, bounds, strict=True)
        ]
    )
    median = float(np.median(tempo[tempo > 0])) if (tempo > 0).any() else 1.0
    status = []
    for i, (ps, pe) in enumerate(spans):
        if pe - ps < s.min_segment_frames or tempo[i] < s.missing_tempo * median:
            status.append("missing")
        elif tempo[i] > s.extra_tempo * median:
            status.append("extra_motion")
        else:
            status.append("ok")
    return tempo, status


def _segment_performer(
    ev: _Evidence,
    reference_segments: Segments,
    fps_ratio: float,
    s: SelectionSettings,
    on_progress: ProgressFn | None,
) -> _Segmentation:
    """Thesis 4.7.1 (performer boundaries) and 6.6 (missing or extra segments)."""
    bounds = reference_segments.bounds()
    initial, starts, found = _performer_starts(ev, bounds, s, on_progress)
    spans = list(zip(starts, starts[1:] + [ev.n_frames - 1], strict=True))
    tempo, status = _segment_status(spans, bounds, fps_ratio, s)
    names = _segment_names(reference_segments)
    return _Segmentation(bounds, starts, spans, initial, found, tempo, status, names)
