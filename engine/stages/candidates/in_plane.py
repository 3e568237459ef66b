"""The in-plane estimator (beyond the thesis): the reference bent in the image plane only.

A silhouette sees in-plane bends and hardly sees turns in depth, where BP alone drifts. This
estimator refines the reference posture B_C(t') by the pattern search (thesis 6.4) turning
each part about the viewing direction only, against the image likelihood + ``in_plane_prior``
d_B(., B_C(t')), so the estimate departs from the reference only where the image says so;
its candidates are its depth flips (4.6.5). The root joint stays where stages 1-2 put it
unless ``in_plane_move_root``: the body region misses dark shoes and some hair, and a shift
to fill it moves the whole body.
"""

from __future__ import annotations

import numpy as np

from engine.render.camera import Camera
from engine.stages.candidates.flips import generate_candidates
from engine.stages.candidates.refinement import _refine
from engine.stages.candidates.scorer import _Scorer
from engine.stages.candidates.settings import CandidateSettings


def _in_plane_candidates(
    scorer: _Scorer,
    init: np.ndarray,
    orient_src: list[np.ndarray],
    camera: Camera,
    s: CandidateSettings,
) -> np.ndarray:
    """Candidates (K, 17, 3) of the ``"in_plane"`` estimator from the initial postures
    ``init`` (M, 17, 3) and the postures ``orient_src`` giving depth orientations.

    The search always starts from the unturned reference (the last initial posture): starting
    from the previous frame's estimate (6.7) let errors compound from frame to frame.
    """
    start = init[-1]
    est, _ = _refine(
        scorer, start, camera, s, start, in_plane=True, mu=s.in_plane_prior,
        step0_deg=s.in_plane_step0_deg, sweeps=s.in_plane_sweeps, move_root=s.in_plane_move_root,
    )  # fmt: skip
    return generate_candidates(est, [start, *orient_src], camera, s)
