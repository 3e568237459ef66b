"""Escape from wrong basins: parts jump, then the refinement runs again (beyond the thesis).

BP and the pattern search (thesis 6.4) are local: a forearm that starts on the wrong side of
the torso, pointing at the camera when it hangs down, or a chest turned the wrong way, stays
there. With ``escape_dirs`` > 0 every part may jump (:func:`_moves`): its subtree, or itself
alone, turned to each of ``escape_dirs`` directions or twisted about its own axis; an upper
limb also with the lower one straightened; left and right limbs swapped. Each jump is kept
when d_S falls, and the refinement runs again. On videos of people it is not worth its cost,
so only the benchmark preset :meth:`CandidateSettings.exact_body` turns it on.
"""

from __future__ import annotations

import numpy as np

from engine.body.kinematics import bone_vectors, rotation_about_axis
from engine.body.skeleton import N_PARTS, PART_BONES, PART_PARENT
from engine.render.camera import Camera
from engine.stages.candidates.postures import (
    _SUBTREES,
    ALL_PARTS,
    _from_bones,
    _part_dir,
    _sphere,
    _turn_to,
    _turned,
    _turned_alone,
    limits_ok,
)
from engine.stages.candidates.refinement import _refine
from engine.stages.candidates.scorer import _Scorer
from engine.stages.candidates.settings import CandidateSettings

#: The one child part of each limb part (upper arm -> lower arm, ...), -1 for the others.
_LIMB_CHILD = tuple(
    int(np.flatnonzero(PART_PARENT == p)[0]) if (PART_PARENT == p).sum() == 1 else -1
    for p in range(N_PARTS)
)

#: Left/right pairs of limb parts (upper arm, upper leg), swapped by :func:`_escape`.
_LIMB_PAIRS = ((4, 6), (8, 10))

#: Twists :func:`_moves` tries about a part's own direction: multiples of 30 deg, (11,) rad.
_TWISTS = 2.0 * np.pi * np.arange(1, 12) / 12


def _polish(
    scorer: _Scorer,
    starts: list[np.ndarray],
    camera: Camera,
    s: CandidateSettings,
    ref: np.ndarray,
) -> list[tuple[float, np.ndarray]]:
    """BP's estimate ``starts[0]`` refined (6.4); with the escape on, the escape from every
    start (17, 3). (d_S, posture) pairs sorted by d_S."""
    if s.escape_dirs > 0:
        return _escape_from(scorer, starts, camera, s, ref)
    if s.refine_sweeps > 0:
        q, d = _refine(scorer, starts[0], camera, s, ref)
        return [(d, q)]
    return [(float(scorer.full(starts[0][None])[0]), starts[0])]


def _escape_from(
    scorer: _Scorer,
    starts: list[np.ndarray],
    camera: Camera,
    s: CandidateSettings,
    ref: np.ndarray,
) -> list[tuple[float, np.ndarray]]:
    """``starts`` (each (17, 3)) after refinement, escape and refinement, as (d_S, posture)
    pairs sorted by d_S (the first is the estimate, the others its alternatives).

    After BP, its estimate is one start and the initial posture the other (on the synthetic
    experiment each ends in a wrong basin where the other does not); a restart's estimate is
    the only start.
    """
    found: list[tuple[float, np.ndarray]] = []
    for q in starts:
        q, d = _refine(scorer, q, camera, s, ref)
        q2, d2 = _escape(scorer, q, s.escape_dirs, prefilter=s.escape_prefilter)
        if d2 < d - 1e-9:
            q, d = _refine(scorer, q2, camera, s, ref)
        found.append((d, q))
    found.sort(key=lambda f: f[0])
    return found


def _escape(
    scorer: _Scorer,
    joints: np.ndarray,
    n_dirs: int,
    prefilter: int = 0,
) -> tuple[np.ndarray, float]:
    """Let parts stuck in a wrong basin jump (:func:`_moves`); keep each jump that lowers d_S.

    Parents first; then the left and right arms, and legs, are swapped (a front and a back
    view differ by exactly this). With ``prefilter`` > 0, only the ``prefilter`` jumps of
    each batch with the lowest silhouette term d_A (row spans, no render: much cheaper than
    a full d_S) are scored with d_S. Returns the posture (17, 3) and its d_S.
    """
    cur = joints.copy()
    best = float(scorer.full(cur[None])[0])
    dirs = _sphere(n_dirs)

    def keep(batch: np.ndarray) -> None:
        """Take the best of ``batch`` (n, 17, 3; within the joint limits) if it lowers d_S."""
        nonlocal cur, best
        if not len(batch):
            return
        if 0 < prefilter < len(batch):
            batch = batch[np.argsort(scorer.silhouette(batch), kind="stable")[:prefilter]]
        sc = scorer.full(batch)
        k = int(np.argmin(sc))
        if sc[k] < best - 1e-9:
            cur, best = batch[k], float(sc[k])

    for p in ALL_PARTS:
        keep(_moves(cur, p, dirs))
    swaps = np.stack([_swapped(cur, a, b) for a, b in _LIMB_PAIRS])
    keep(swaps[limits_ok(swaps)])
    return cur, best


def _moves(cur: np.ndarray, p: int, dirs: np.ndarray) -> np.ndarray:
    """The jumps :func:`_escape` tries for part p of ``cur`` (17, 3), shape (n, 17, 3).

    The part's subtree, or the part alone (the parts below keep their directions), twisted
    about the part's direction by each of ``_TWISTS`` and turned to point along each of
    ``dirs`` (unit, (m, 3); not for the root part); an upper limb also with its lower limb
    straightened (moving a bent limb out of the torso can cost as much as it gains).
    """
    d = _part_dir(cur, p)
    R_twist = rotation_about_axis(d, _TWISTS)
    out = [_turned(cur, p, R_twist), _turned_alone(cur, p, R_twist)]
    if p > 0:
        R_dir = _turn_to(d, dirs)
        out += [_turned(cur, p, R_dir), _turned_alone(cur, p, R_dir)]
    c = _LIMB_CHILD[p]
    if c >= 0:
        straight = _turned(cur, c, _turn_to(_part_dir(cur, c), d[None]))[0]
        out.append(_turned(straight, p, _turn_to(d, dirs)))
    batch = np.concatenate(out)
    return batch[limits_ok(batch)]


def _swapped(cur: np.ndarray, a: int, b: int) -> np.ndarray:
    """``cur`` (17, 3) with the bone vectors of limb subtrees a and b exchanged.

    Each limb keeps its attachment joint; a front view and a back view of a body differ
    by exactly this, and a silhouette cannot tell them apart.
    """
    vec = bone_vectors(cur)
    ba = [bb for q in _SUBTREES[a] for bb in PART_BONES[q]]
    bb_ = [bb for q in _SUBTREES[b] for bb in PART_BONES[q]]
    vec[ba], vec[bb_] = vec[bb_].copy(), vec[ba].copy()
    return _from_bones(cur[0], vec)
