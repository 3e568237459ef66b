"""The performer's timing (thesis 2.1.3 items 3-4): the reference's segments and a smooth,
strictly monotone time warp with a speed per segment.
"""

from __future__ import annotations

import numpy as np
from scipy.interpolate import PchipInterpolator

from engine.errors import InvalidInput
from engine.types import Motion, Segments


def _default_segments(motion: Motion, n: int) -> Segments:
    first, last = motion.first_motion_frame, motion.frames - 1
    n = max(1, min(n, (last - first) // 2))
    starts = np.round(np.linspace(first, last, n + 1)[:-1]).astype(int)
    return Segments(starts=tuple(int(s) for s in starts), end=int(last))


def reference_segments(motion: Motion, n_segments: int = 4) -> Segments:
    """Segments of a reference: :func:`engine.reference.boundaries.reference_boundaries`
    when that module is available, else ``n_segments`` equal ones from the first motion frame.
    """
    try:
        from engine.reference.boundaries import reference_boundaries
    except ImportError:
        return _default_segments(motion, n_segments)
    return reference_boundaries(motion)


def time_warp(
    segments: Segments,
    reference_fps: float,
    fps: float,
    strength: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A smooth, strictly monotone time warp with a random speed per segment (thesis 2.1.3).

    Parameters
    ----------
    segments : Segments
        Reference segments; the warp runs from ``starts[0]`` to ``end``.
    reference_fps, fps : float
        Frame rates of the reference and the video.
    strength : float
        Standard deviation of each segment's log speed.
    rng : numpy.random.Generator

    Returns
    -------
    warp : ndarray, shape (T',)
        C(t') for t' = 0..L', with C(0) = starts[0] and C(L') = end exactly.
    knots_video : ndarray, shape (n_segments + 1,)
        Video time (fractional frames) of each reference boundary and of the end.
    speeds : ndarray, shape (n_segments,)
        Performer speed relative to the reference in each segment.
    """
    knots_ref = np.array([*segments.starts, segments.end], dtype=float)
    if np.any(np.diff(knots_ref) <= 0):
        raise InvalidInput(f"segments must be strictly increasing, got {knots_ref.tolist()}")
    speeds = np.exp(np.clip(strength * rng.standard_normal(len(segments.starts)), -1.0, 1.0))
    durations = np.diff(knots_ref) / reference_fps * fps / speeds
    knots_video = np.concatenate([[0.0], np.cumsum(durations)])
    L = max(1, int(round(knots_video[-1])))
    knots_video *= L / knots_video[-1]
    # PCHIP keeps the warp monotone and C1: speeds blend across boundaries instead of jumping
    warp = PchipInterpolator(knots_video, knots_ref)(np.arange(L + 1, dtype=float))
    warp[0], warp[-1] = knots_ref[0], knots_ref[-1]
    return np.clip(warp, knots_ref[0], knots_ref[-1]), knots_video, speeds
