"""Totally occluded parts take the reference's pose (thesis 6.5)."""

from __future__ import annotations

import numpy as np

from engine.body.kinematics import forward_kinematics, part_rotations
from engine.body.skeleton import BONE_CHILD, JOINTS, N_PARTS, PART_BONES
from engine.stages.candidates.scorer import _Scorer
from engine.stages.candidates.settings import CandidateSettings


def _occluded_parts(scorer: _Scorer, joints: np.ndarray, thr: float) -> list[int]:
    """Parts of ``joints`` (17, 3) with less than ``thr`` of their area visible."""
    vis = scorer.visible_fraction(joints)
    return [p for p in range(N_PARTS) if vis[p] < thr]


def _reset_occluded(
    scorer: _Scorer,
    est: np.ndarray,
    ref: np.ndarray,
    offsets: np.ndarray,
    s: CandidateSettings,
    flags: list[str],
) -> np.ndarray:
    """Totally occluded parts of ``est`` (17, 3) take the reference's pose (thesis 6.5).

    Each is flagged ``occluded:<joint>``. The reset is kept only where the image allows it
    (d_S rises by at most ``s.occluded_tolerance``): a forearm hidden behind the chest in the
    estimate may be there because the reference's pose would stick out of the region, and
    then the image, not the reference, has the last word. The default tolerance is infinite
    (the thesis: always reset), because on a clothed body d_S is no judge of a hidden part.
    """
    occl = _occluded_parts(scorer, est, s.occluded_visible_fraction)
    if not occl:
        return est
    R_ref = part_rotations(ref, offsets)
    d_est = float(scorer.full(est[None])[0])
    for p in occl:
        flags.extend(f"occluded:{JOINTS[BONE_CHILD[b]]}" for b in PART_BONES[p])
        R = part_rotations(est, offsets)
        R[p] = R_ref[p]
        q = forward_kinematics(offsets, est[0], R)
        d = float(scorer.full(q[None])[0])
        if d <= d_est + s.occluded_tolerance:
            est, d_est = q, d
    return est
