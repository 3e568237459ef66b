"""Segment boundaries of a reference motion (thesis 2.1.1 item 4, 5.4.2).

A boundary is where a chosen joint (the right wrist in the thesis) sharply changes its
direction of motion: the angle between its 3D velocity v_t and v_{t+dt},
``arccos(v_t . v_{t+dt} / (|v_t| |v_{t+dt}|))`` (thesis 5.4.2), exceeds a threshold
(60 deg for Tai Chi, 120 deg for golf in the thesis). Three additions make this robust on
real motion capture: the trajectory is smoothed (Gaussian, ``smooth_s``) before
differentiating; directions are ignored where the joint is nearly still (``min_speed``),
where they are only noise; and boundaries closer than ``min_segment_s`` to each other or to
the ends are dropped, keeping the sharper turn.

Defaults: ``step`` = 10 frames at 120 fps (the thesis' dt, scaled with the frame rate),
``threshold_deg`` = 60 (thesis, Tai Chi). On CMU 64_29 (golfer bending down to the ground
and standing up) these give boundaries at the bottom of the reach (frame 274, 102 deg) and at
a later hand reversal (473, 69 deg); a third turn (544, 101 deg) lies within 0.4 s of the end.
120 deg (the thesis' golf value) finds none there: its hand turns are slower than a swing's.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from scipy.ndimage import gaussian_filter1d
from scipy.signal import find_peaks

from engine.body.skeleton import JOINT_INDEX, JOINTS
from engine.errors import InvalidInput
from engine.types import Motion, Segments


def _step_frames(motion: Motion, step: int | None) -> int:
    if step is None:
        return max(2, int(round(motion.fps * 10.0 / 120.0)))
    if not isinstance(step, int | np.integer) or step < 1:
        raise InvalidInput(f"step must be a positive whole number of frames, got {step!r}")
    return int(step)


def direction_change(
    motion: Motion,
    *,
    joint: str = "r_wrist",
    step: int | None = None,
    smooth_s: float = 0.05,
    min_speed: float = 0.1,
) -> tuple[np.ndarray, np.ndarray]:
    """Speed and velocity-direction change of one joint (thesis 5.4.2).

    Only the motion's own frames (from ``motion.first_motion_frame``) are used, so a
    conversion T-pose does not produce a spurious jump.

    Parameters
    ----------
    motion : Motion
        Joints (T, 17, 3), metres.
    joint : str
        Joint name (:data:`~engine.body.skeleton.JOINTS`).
    step : int, optional
        dt in frames; the change at frame t compares v at t - step // 2 and
        t + step - step // 2. Default: 10 frames at 120 fps, scaled with ``motion.fps``.
    smooth_s : float
        Standard deviation of the Gaussian smoothing of the trajectory, seconds (0: none).
    min_speed : float
        Speed (m/s) below which a direction is treated as undefined (change set to 0).

    Returns
    -------
    speed : ndarray, shape (T,)
        m/s; 0 before ``first_motion_frame``.
    change : ndarray, shape (T,)
        Direction change in radians, [0, pi]; 0 where undefined.

    Raises
    ------
    InvalidInput
        Unknown joint, bad step, negative smoothing or speed.
    """
    if joint not in JOINT_INDEX:
        raise InvalidInput(f"joint must be one of {', '.join(JOINTS)}; got {joint!r}")
    if not (np.isfinite(smooth_s) and smooth_s >= 0):
        raise InvalidInput(f"smooth_s must be a non-negative number of seconds, got {smooth_s!r}")
    if not (np.isfinite(min_speed) and min_speed >= 0):
        raise InvalidInput(f"min_speed must be a non-negative speed in m/s, got {min_speed!r}")
    k = _step_frames(motion, step)
    T, f0 = motion.frames, motion.first_motion_frame
    speed, change = np.zeros(T), np.zeros(T)
    p = np.asarray(motion.joints[f0:, JOINT_INDEX[joint]], dtype=float)
    if len(p) < 2:
        return speed, change
    if smooth_s > 0:
        p = gaussian_filter1d(p, smooth_s * motion.fps, axis=0, mode="nearest")
    v = np.gradient(p, axis=0) * motion.fps
    s = np.linalg.norm(v, axis=1)
    speed[f0:] = s
    a, b = k // 2, k - k // 2
    if len(p) > k:
        va, vb = v[: len(p) - k], v[k:]
        cos = np.sum(va * vb, axis=1) / np.maximum(s[: len(p) - k] * s[k:], 1e-12)
        ang = np.arccos(np.clip(cos, -1.0, 1.0))
        ang[(s[: len(p) - k] < min_speed) | (s[k:] < min_speed)] = 0.0
        change[f0 + a : f0 + len(p) - b] = ang
    return speed, change


def reference_boundaries(
    motion: Motion,
    *,
    joint: str = "r_wrist",
    threshold_deg: float = 60.0,
    step: int | None = None,
    smooth_s: float = 0.05,
    min_speed: float = 0.1,
    min_segment_s: float = 0.4,
) -> Segments:
    """Reference segment boundaries from a joint's velocity-direction change (thesis 5.4.2).

    Parameters
    ----------
    motion : Motion
        Joints (T, 17, 3), metres; segments start at ``motion.first_motion_frame``.
    joint : str
        Joint whose direction changes mark boundaries (thesis: right wrist).
    threshold_deg : float
        Smallest direction change at a boundary, degrees (thesis: 60 Tai Chi, 120 golf).
    step, smooth_s, min_speed
        See :func:`direction_change`.
    min_segment_s : float
        Shortest segment, seconds: the sharpest turns are kept first, and a turn closer
        than this to a kept one or to either end of the motion is dropped.

    Returns
    -------
    Segments
        ``starts[0] = motion.first_motion_frame``, then the boundaries in increasing order;
        ``end`` = last frame; unnamed.

    Raises
    ------
    InvalidInput
        Bad parameters (see :func:`direction_change`), threshold outside (0, 180) or
        negative minimum segment length.
    """
    if not (np.isfinite(threshold_deg) and 0 < threshold_deg < 180):
        raise InvalidInput(f"threshold_deg must lie in (0, 180), got {threshold_deg!r}")
    if not (np.isfinite(min_segment_s) and min_segment_s >= 0):
        raise InvalidInput(f"min_segment_s must be a non-negative number, got {min_segment_s!r}")
    _, change = direction_change(
        motion, joint=joint, step=step, smooth_s=smooth_s, min_speed=min_speed
    )
    first, last = motion.first_motion_frame, motion.frames - 1
    min_len = max(1, int(round(min_segment_s * motion.fps)))
    peaks, _ = find_peaks(change, height=np.radians(threshold_deg))
    kept: list[int] = []
    for t in sorted(peaks.tolist(), key=lambda i: -change[i]):
        if t - first < min_len or last - t < min_len:
            continue
        if all(abs(t - u) >= min_len for u in kept):
            kept.append(t)
    starts = (first, *sorted(kept))
    return Segments(starts=starts, end=last, names=("",) * len(starts))


def segments_from_list(
    starts: Sequence[int], motion: Motion, names: Sequence[str] | None = None
) -> Segments:
    """Segments from a coach's own list of segment starts (overrides the detected ones).

    Parameters
    ----------
    starts : sequence of int
        First frame of each segment, strictly increasing, within [0, T - 1]; frame numbers
        count the file's frames (frame 0 = a T-pose when there is one).
    motion : Motion
    names : sequence of str, optional
        One name per segment.

    Returns
    -------
    Segments
        Ending at the motion's last frame.

    Raises
    ------
    InvalidInput
        Empty, non-integer, unsorted or out-of-range starts; wrong number of names.
    """
    s = list(starts)
    if not s:
        raise InvalidInput("starts must list at least one segment start")
    if not all(isinstance(v, int | np.integer) and not isinstance(v, bool) for v in s):
        raise InvalidInput(f"starts must be whole frame numbers, got {s!r}")
    if any(b <= a for a, b in zip(s, s[1:], strict=False)):
        raise InvalidInput(f"starts must be strictly increasing, got {s!r}")
    if s[0] < 0 or s[-1] > motion.frames - 1:
        raise InvalidInput(
            f"starts must lie in [0, {motion.frames - 1}] (the reference's frames), got {s!r}"
        )
    if names is None:
        nm = ("",) * len(s)
    else:
        nm = tuple(str(n) for n in names)
        if len(nm) != len(s):
            raise InvalidInput(
                f"names must give one name per segment: {len(s)} starts, {len(nm)} names"
            )
    return Segments(starts=tuple(int(v) for v in s), end=motion.frames - 1, names=nm)
