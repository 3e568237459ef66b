"""Key frames chosen by the reference's motion, and the cheaper estimate between them
(beyond the thesis; issue 25).

The full search of :func:`~engine.stages.candidates.estimate.estimate_candidates` (in-plane
fit, BP, refinement) runs on key frames only. A frame between two key frames starts from their
best postures, each carried onto the frame's own reference posture (:func:`carry_deviation`),
and is refined by the pattern search (6.4) from the better start; BP, about half of a frame's
time, is skipped there. Key frames lie closer where the reference moves fast (a golf
downswing) and further apart in slow passages, at most ``key_gap`` frames apart.

The key frames are chosen from the whole analysis (:func:`choose_key_frames`), and a chunk
that starts or ends between two key frames also estimates the key frames just outside it
(:func:`key_span`), so a frame's candidates still do not depend on the chunk that computes it.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from engine.body.kinematics import (
    bone_directions,
    bone_vectors,
    joints_from_bones,
    rotation_between,
)
from engine.stages.candidates.settings import CandidateSettings


def reference_motion_deg(initial: np.ndarray) -> np.ndarray:
    """How far the starting posture moves into each frame, shape (T,), degrees.

    The mean over the 16 bones of the angle between a bone's direction in frame t-1 and in
    frame t of ``initial`` (T, 17, 3), the reference B_C(t') turned by T_t'; 0 for frame 0.
    """
    d = bone_directions(np.asarray(initial, float))
    cos = np.clip(np.sum(d[1:] * d[:-1], axis=-1), -1.0, 1.0)
    return np.concatenate([[0.0], np.degrees(np.arccos(cos)).mean(axis=1)])


def choose_key_frames(initial: np.ndarray, gap: int, motion_deg: float) -> np.ndarray:
    """Which frames get stage 3's full search, shape (T,) of bool.

    The first and the last frame are key frames; after a key frame, the next one is the first
    frame at which the starting postures ``initial`` (T, 17, 3) have moved by more than
    ``motion_deg`` (summed :func:`reference_motion_deg`), or ``gap`` frames later. ``gap`` 1
    makes every frame a key frame (the thesis).
    """
    motion = reference_motion_deg(initial)
    keys = np.zeros(len(motion), bool)
    if len(keys) == 0:
        return keys
    keys[0] = keys[-1] = True
    last, moved = 0, 0.0
    for t in range(1, len(motion)):
        moved += motion[t]
        if t - last >= gap or moved > motion_deg:
            keys[t] = True
            last, moved = t, 0.0
    return keys


def key_span(frames: range, keys: np.ndarray) -> range:
    """``frames`` widened to the nearest key frame before its first frame and after its last
    (both ends of a frame between key frames are needed to estimate it)."""
    idx = np.flatnonzero(keys)
    before = idx[idx <= frames.start]
    after = idx[idx >= frames.stop - 1]
    start = int(before[-1]) if len(before) else frames.start
    stop = int(after[0]) + 1 if len(after) else frames.stop
    return range(start, stop)


def carry_deviation(posture: np.ndarray, reference: np.ndarray, target: np.ndarray) -> np.ndarray:
    """A key frame's ``posture`` (17, 3) moved onto another frame's reference posture.

    Each bone of ``target`` (17, 3) is turned by the smallest rotation that takes the key
    frame's ``reference`` (17, 3) bone onto the posture's, keeping ``target``'s bone lengths,
    and the root keeps its offset from the reference's: the performer's deviation from the
    expert at the key frame, carried to a frame whose expert posture has moved on.
    """
    turn = rotation_between(bone_vectors(reference), bone_vectors(posture))  # (16, 3, 3)
    vec = np.einsum("bij,bj->bi", turn, bone_vectors(target))
    root = target[0] + (posture[0] - reference[0])
    return joints_from_bones(root, vec)


def between_settings(s: CandidateSettings) -> CandidateSettings:
    """The refinement of a frame between key frames starts at ``between_step0_deg``: its
    start is already a neighbour's solution, so the coarse first steps that let BP's
    estimate leave a wrong basin are not needed."""
    return dataclasses.replace(s, refine_step0_deg=s.between_step0_deg)
