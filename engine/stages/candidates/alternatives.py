"""Runner-up local optima as candidates, and merging candidate sets (beyond the thesis).

The refinement from BP's estimate, from the initial posture and from each restart ends in a
local optimum of d_S; the thesis keeps only the lowest. d_S barely tells them apart, and one
may have the right depths where the lowest has not, so with ``alternatives`` > 0 (the
benchmark preset :meth:`CandidateSettings.exact_body` only) the others join the candidates
with their own flips.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from engine.measures import d_B
from engine.render.camera import Camera
from engine.stages.candidates.flips import generate_candidates
from engine.stages.candidates.settings import CandidateSettings


def _alternatives(found: list[tuple[float, np.ndarray]], s: CandidateSettings) -> list[np.ndarray]:
    """Up to ``s.alternatives`` other local optima of ``found`` ((d_S, (17, 3)) sorted by d_S),
    in that order, each at least ``s.alternative_min_deg`` from every posture kept before it."""
    if s.alternatives <= 0 or len(found) < 2:
        return []
    kept = [found[0][1]]
    for _, q in found[1:]:
        if len(kept) > s.alternatives:
            break
        if np.degrees(d_B(np.stack(kept), q).min()) >= s.alternative_min_deg:
            kept.append(q)
    return kept[1:]


def _with_alternatives(
    cands: np.ndarray,
    alts: list[np.ndarray],
    orient_src: list[np.ndarray],
    camera: Camera,
    s: CandidateSettings,
) -> np.ndarray:
    """``cands`` (K, 17, 3) with each alternative local optimum and its flips taking an equal
    share (``s.alternative_share`` of the set for all of them) of the last places."""
    each = max(1, int(round(s.n_candidates * s.alternative_share / len(alts))))
    blocks = [
        generate_candidates(a, orient_src, camera, replace(s, n_candidates=each)) for a in alts
    ]
    extra = np.concatenate(blocks)
    keep = max(1, min(len(cands), s.n_candidates - len(extra)))
    return np.concatenate([cands[:keep], extra])[: s.n_candidates]


def _append_distinct(cands: np.ndarray, extra: np.ndarray, n_max: int) -> np.ndarray:
    """``cands`` (K, 17, 3) plus those of ``extra`` (M, 17, 3) not already in it (within 1 mm).

    The extras replace the last candidates when the set is full (they are kept for sure).
    """
    new = [e for e in extra if np.min(np.abs(cands - e).max(axis=(1, 2))) > 1e-3]
    if not new:
        return cands
    keep = max(min(len(cands), n_max - len(new)), 1)
    return np.concatenate([cands[:keep], np.stack(new)])
