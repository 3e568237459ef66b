"""A motion at fractional frames and at other frame rates: on the 17-joint body (slerp of part
rotations) or, for a loaded reference, by slerp of the file's own local rotations (the
benchmark truth's convention).
"""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from engine.body.kinematics import forward_kinematics, part_rotations
from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.io.bvh.kinematics import bvh_forward_kinematics, local_transforms
from engine.io.bvh.load import Reference
from engine.types import Motion


def _check_frames(motion: Motion, frames: np.ndarray) -> np.ndarray:
    f = np.asarray(frames, dtype=float)
    if f.ndim != 1 or not np.all(np.isfinite(f)):
        raise InvalidInput(f"frames must be a 1-D array of finite numbers, got shape {f.shape}")
    if f.size and (f.min() < 0 or f.max() > motion.frames - 1):
        raise InvalidInput(
            f"frames must lie in [0, {motion.frames - 1}], got [{f.min():g}, {f.max():g}]"
        )
    return f


def sample_at(motion: Motion, shape: BodyShape, frames: np.ndarray) -> np.ndarray:
    """Postures of a motion at fractional frames (slerp of part rotations, linear root).

    The body is rebuilt with forward kinematics on ``shape`` (thesis 2.1.1: H fixed, B_t
    from p_t and theta_t), so bone lengths are constant; multi-bone parts (abdomen, upper
    chest) become rigid.

    Parameters
    ----------
    motion : Motion
    shape : BodyShape
    frames : ndarray, shape (N,)
        Fractional frame numbers in [0, T - 1].

    Returns
    -------
    joints : ndarray, shape (N, 17, 3)

    Raises
    ------
    InvalidInput
        When ``frames`` is not 1-D, not finite or out of range.
    """
    f = _check_frames(motion, frames)
    return _interpolate(motion.joints, shape, f)


def _interpolate(joints: np.ndarray, shape: BodyShape, f: np.ndarray) -> np.ndarray:
    T = joints.shape[0]
    R = part_rotations(joints, shape.offsets)
    if T == 1:
        Ri = np.broadcast_to(R[0], (f.size,) + R.shape[1:])
        root = np.broadcast_to(joints[0, 0], (f.size, 3))
        return forward_kinematics(shape.offsets, root, Ri)
    times = np.arange(T, dtype=float)
    Ri = np.empty((f.size,) + R.shape[1:])
    for p in range(R.shape[1]):
        Ri[:, p] = Slerp(times, Rotation.from_matrix(R[:, p]))(f).as_matrix()
    root = np.stack([np.interp(f, times, joints[:, 0, k]) for k in range(3)], axis=-1)
    return forward_kinematics(shape.offsets, root, Ri)


def _resample_frames(motion: Motion, fps: float) -> tuple[np.ndarray, int]:
    """Old fractional frames (N,) of the new frames at ``fps``, and the new first motion frame.

    Raises InvalidInput when ``fps`` is not a positive finite number.
    """
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise InvalidInput(f"fps must be a positive number, got {fps!r}")
    n = int(math.floor(motion.duration_s * fps + 1e-6)) + 1
    f = np.minimum(np.arange(n) * motion.fps / fps, motion.frames - 1)
    first = int(math.ceil(motion.first_motion_frame * fps / motion.fps - 1e-9))
    return f, first


def resample(motion: Motion, fps: float, shape: BodyShape) -> Motion:
    """The motion at another frame rate (slerp of part rotations, linear root).

    New frame k is at time k / fps, for every such time within the motion, so the first
    frame is kept and the last one too when the duration is a whole number of new frames.

    Parameters
    ----------
    motion : Motion
    fps : float
        New frame rate, frames per second.
    shape : BodyShape
        Body whose bone lengths the resampled postures get.

    Returns
    -------
    Motion
        ``first_motion_frame`` is the first new frame at or after the old one.

    Raises
    ------
    InvalidInput
        When ``fps`` is not a positive finite number.
    """
    f, first = _resample_frames(motion, fps)
    joints = _interpolate(motion.joints, shape, f)
    return Motion(joints=joints, fps=float(fps), name=motion.name, first_motion_frame=first)


def sample_reference(reference: Reference, frames: np.ndarray) -> np.ndarray:
    """The reference at fractional frames by slerp of the file's *local* rotations.

    This is the convention of the benchmark truth files (the source skeleton's own joints
    interpolated, then mapped), unlike :func:`sample_at`, which interpolates on the
    17-joint body.

    Parameters
    ----------
    reference : Reference
    frames : ndarray, shape (N,)
        Fractional frame numbers in [0, T - 1].

    Returns
    -------
    joints : ndarray, shape (N, 17, 3)
        World frame of the reference (metres, heading-normalised).
    """
    f = _check_frames(reference.motion, frames)
    bvh = reference.bvh
    R, t = local_transforms(bvh)
    times = np.arange(bvh.frames, dtype=float)
    N = R.shape[1]
    if bvh.frames == 1:
        Ri, ti = np.broadcast_to(R[:1], (f.size, N, 3, 3)), np.broadcast_to(t[:1], (f.size, N, 3))
    else:
        Ri = np.empty((f.size, N, 3, 3))
        for n in range(N):
            Ri[:, n] = Slerp(times, Rotation.from_matrix(R[:, n]))(f).as_matrix()
        lo = np.clip(np.floor(f).astype(int), 0, bvh.frames - 2)
        w = (f - lo)[:, None, None]
        ti = (1 - w) * t[lo] + w * t[lo + 1]
    idx = np.array([reference.bvh.names.index(n) for n in reference.source_joint_names])
    pos = bvh_forward_kinematics(bvh, Ri, ti)[:, idx] * reference.units_to_m
    return pos @ reference.R_world_bvh.T


def resample_reference(reference: Reference, fps: float) -> Motion:
    """The reference at another frame rate, by slerp of the file's local rotations.

    Like :func:`resample` (same frame times, same ``first_motion_frame`` rule) but with
    the benchmark truth's interpolation (:func:`sample_reference`), so bone directions keep
    the source skeleton's non-rigid spine and shoulders exactly.

    Parameters
    ----------
    reference : Reference
    fps : float
        New frame rate.

    Returns
    -------
    Motion

    Raises
    ------
    InvalidInput
        When ``fps`` is not a positive finite number.
    """
    m = reference.motion
    f, first = _resample_frames(m, fps)
    joints = sample_reference(reference, f)
    return Motion(joints=joints, fps=float(fps), name=m.name, first_motion_frame=first)
