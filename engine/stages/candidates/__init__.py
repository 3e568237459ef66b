"""Stage 3: posture candidates by nonparametric BP (thesis 4.6, 6.4, 6.5, 6.7).

Per video frame, given the target body region S' (silhouette and edges), the camera and one or
more initial postures (the reference B_C(t') turned by T_t' about the hip, optionally the
previous frame's candidates), the stage

1. runs nonparametric BP over the 12 body parts (4.6.1-4.6.4, :mod:`.bp`);
2. refines the connected best posture by a pattern search on d_S (sub-pixel, 6.4,
   :mod:`.refinement`); with ``escape_dirs`` (beyond the thesis, :mod:`.escape`) also from
   the initial posture, letting parts jump out of wrong basins between two refinements;
3. resets totally occluded parts to the reference and flags them ``occluded:<joint>`` (6.5,
   :mod:`.occlusion`);
4. generates candidates (4.6.5, :mod:`.flips`): the reference's depth orientation per part,
   then flips of n = 1, 2, ... parts about their parent joints (mirror in depth, same
   projection), dropping those that break the joint limits; the previous frame's best
   candidate (``n_prev`` > 0) supplies another orientation and, when the reference is far
   from the image, the initial estimate (6.7). Runner-up local optima may join
   (:mod:`.alternatives`, beyond the thesis).

Beyond the thesis, the default ``estimator="hybrid"`` also fits the reference posture in the
image plane only (:mod:`.in_plane`) and puts that estimate and its depth flips first: a
silhouette sees in-plane bends and hardly sees turns in depth, where BP alone drifts.

Frames are independent given stage 2's output, so workers can fan out over frames; with one
random stream per frame and ``n_prev`` 0 (the defaults) a frame's candidates do not depend on
the chunk that computes it (:mod:`.estimate`). With ``key_gap`` > 1 (beyond the thesis,
:mod:`.key_frames`) the full search runs on key frames chosen by the expert's motion, and a
frame between two of them is refined from their solutions without BP; a chunk then also
estimates the key frames just outside it, so this independence holds too.

Every candidate carries its d_S (:mod:`.scorer`); stage 4 weighs it against the distance to
the reference (:attr:`engine.stages.selection.SelectionSettings.image_weight`), so the initial
postures being candidates does not make selection return the reference everywhere. The
stage's own ranking (:attr:`FrameCandidates.cost`, d_S + ``prior_weight`` d_B to the
reference) only picks the previous-frame seeds and the benchmark's "selected" posture.

The settings, one line each, are in this package's ``README.md``.
"""

from engine.stages.candidates.estimate import (
    FrameCandidates,
    estimate_candidates,
    estimate_candidates_chunk,
    frame_rngs,
)
from engine.stages.candidates.flips import generate_candidates
from engine.stages.candidates.postures import ALL_PARTS, limits_ok, perturb_parts
from engine.stages.candidates.settings import CandidateSettings

__all__ = [
    "ALL_PARTS",
    "CandidateSettings",
    "FrameCandidates",
    "estimate_candidates",
    "estimate_candidates_chunk",
    "frame_rngs",
    "generate_candidates",
    "limits_ok",
    "perturb_parts",
]
