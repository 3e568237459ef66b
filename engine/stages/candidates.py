"""Stage 3: posture candidates by nonparametric belief propagation (thesis 4.6, 6.4, 6.5, 6.7).

Per video frame, given the target body region S' (silhouette and edges), the camera and one or
more initial postures (the reference B_C(t') turned by T_t' about the hip, optionally the
previous frame's candidates), the stage

1. runs nonparametric BP over the 12 body parts (4.6.1-4.6.4, private core in ``_bp.py``):
   similarity phi = exp(-beta d_S) with the part at the sample and the other parts at their
   previous-iteration poses (4.6.2), joint constraint psi = J exp(-|x_i - x_j|^2 / sigma^2)
   with the appendix-A angle limits (4.6.3) and the hardening schedule sigma_k = lambda
   sigma_{k-1}, a_k = a_{k-1}^(1/lambda) (4.6.4 step 1);
2. refines the connected best posture by a pattern search on d_S (sub-pixel, 6.4); with
   ``escape_dirs`` (beyond the thesis) also from the initial posture, letting parts jump out
   of wrong basins between two refinements;
3. resets totally occluded parts to the reference and flags them ``occluded:<joint>`` (6.5);
4. generates candidates (4.6.5): the reference's depth orientation per part, then flips of
   n = 1, 2, ... parts about their parent joints (mirror in depth, same projection), dropping
   those that break the joint limits; the previous frame's best candidate (``n_prev`` > 0)
   supplies another orientation and, when the reference is far from the image, the initial
   estimate (6.7).

Beyond the thesis, the default ``estimator="hybrid"`` also fits the reference posture in the
image plane only (each part turned about the viewing direction, the root kept, a prior towards
B_C(t')) and puts that estimate and its depth flips first: a silhouette sees in-plane bends and
hardly sees turns in depth, where BP alone drifts (see :class:`CandidateSettings`).

Frames are independent given stage 2's output, so workers can fan out over frames; with one
random stream per frame and ``n_prev`` 0 (the defaults) a frame's candidates do not depend on
the chunk that computes it. The chunk helper threads the previous frame's candidates through
when ``n_prev`` > 0.

Every candidate carries its d_S; stage 4 weighs it against the distance to the reference
(:attr:`engine.stages.selection.SelectionSettings.image_weight`), so the initial postures
being candidates does not make selection return the reference everywhere. The stage's own
ranking (:attr:`FrameCandidates.cost`, d_S + ``prior_weight`` d_B to the reference) only picks
the previous-frame seeds and the benchmark's "selected" posture.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from engine.body.kinematics import (
    bone_vectors,
    forward_kinematics,
    part_rotations,
    rotation_about_axis,
)
from engine.body.shapes import BodyShape
from engine.body.skeleton import (
    BONE_CHILD,
    BONE_PARENT,
    JOINTS,
    LIMIT_A,
    LIMIT_B,
    LIMIT_JOINT,
    LIMIT_MIN_RAD,
    N_PARTS,
    PART_BONES,
    PART_PARENT,
    PART_ROOT_JOINT,
)
from engine.errors import InvalidInput
from engine.measures import d_B, d_K
from engine.render.camera import Camera
from engine.render.capsules import (
    PART_CAPSULES,
    PartScorer,
    Target,
    WidthTarget,
    d_A_batch,
    d_S_batch,
    width_robust_cost,
)
from engine.stages import _bp

ALL_PARTS = tuple(range(N_PARTS))


@dataclass(frozen=True)
class CandidateSettings:
    """Tuning of stage 3 (thesis 4.6, 5.2.2).

    :meth:`thesis` gives the thesis' own (lambda 0.9, 40 iterations, 300 samples per part, 50
    candidates; 5.2.2). The defaults are for videos of people and are cheaper and NOT as
    accurate on the synthetic experiment 5.2, where the capsule body matches the image
    exactly; :meth:`exact_body` is the cheaper setting for that case.
    ``NUMBA_NUM_THREADS=1 benchmarks/candidates.py --frames 100`` (E_3B mean deg / E_2P px /
    E_2M px / s per frame): thesis 6.31 / 1.44 / 8.5 / 5.1, :meth:`exact_body` 4.52 / 0.68 /
    3.6 / 1.1 (1.5 before d_S's faster outline test, which the thesis' and the defaults'
    times predate; ``--seed 1`` and ``2``, 50 frames: 4.10 and 3.82 deg; before its restarts
    on every poor fit, per-part refinement steps, alternative optima and escape prefilter:
    5.40 / 0.91 / 4.5 / 1.9), these defaults 8.14 / 3.00 / 10.9 / 0.6.
    The defaults keep their priors
    towards the reference because on the public videos the body-model mismatch, not the
    search, limits stage 3: :meth:`exact_body` on P1 with the true C(t') and camera
    (``--case``, frames 20-80) selects postures 24 deg from the truth against 1.7 for the
    defaults, and the escape gained nothing worth its cost there (see ``escape_dirs``).

    Attributes
    ----------
    n_samples : int
        Pose samples per part and iteration, N_l (thesis 300).
    n_iterations : int
        BP iterations, N_k (thesis 40).
    decrease : float
        Hardening factor lambda of 4.6.4 step 1 (thesis 0.9).
    sigma0_m : float
        Initial joint-constraint width sigma, metres (eq. 4.18).
    a0 : float
        Initial joint-angle penalty a (eq. 4.17).
    rot_std0_deg, rot_std_min_deg : float
        Std of the sampling Gaussian on rotations, first and smallest (step 2); it shrinks
        with lambda like sigma.
    pos_std0_m, pos_std_min_m : float
        Same for root-joint positions.
    attach_prob : float
        Probability that a new sample takes its root joint from a parent sample (step 2.1).
    beta : float
        Sharpness of phi = exp(-beta d_S): the scale of lambda_A, lambda_E relative to psi.
    lambda_a, lambda_e, edge_sigma_px, edge_xi : float
        d_S = lambda_A d_A + lambda_E d_E and the truncated chamfer's sigma, xi (eq. 4.3-4.4).
        lambda_E defaults to 0: the rendered capsule edges include every internal part
        outline (an arm over the torso) while stage 0's edges are the silhouette contour and
        skin contours only, so d_E pushes the arms off the torso; on P1 frames 40-45 the
        selected candidate's E_3B was 19 deg with d_E and 13 deg without (both without the
        prior). The thesis setting is 1.
    refine_sweeps : int
        Pattern-search sweeps of the sub-pixel refinement (6.4); 0 disables it.
    refine_per_part : bool
        Beyond the thesis; off by default, on in :meth:`exact_body`. Each part keeps its own
        rotation step, halved when none of its moves lowers d_S, and drops out of the sweeps
        below ``refine_min_step_deg``. With one shared step (off), the step halves only after
        a sweep in which no part improved: on a pixel-exact d_S some part almost always
        gains a few pixels, so the sweeps run to ``refine_sweeps`` at the first step and
        every converged part is scored again each sweep. ``--exact --frames 50`` (before the
        prefilter and the third restart): E_3B 4.26 deg at 1.90 s/frame with it, 4.50 deg at
        2.80 s/frame without.
    refine_step0_deg, refine_min_step_deg : float
        First and smallest rotation step of the refinement. Starting coarse (16 deg, halving
        when a sweep finds nothing) lets a limb stuck in a wrong local minimum after BP
        escape: synthetic benchmark (20 frames) E_2P 2.36 -> 2.05 px, E_2M 12.3 -> 8.4 px
        against 2 deg and 6 sweeps, at 0.57 -> 0.69 s/frame.
    n_candidates : int
        Most candidates per frame, N (thesis 25-50).
    min_flip_deg : float
        Parts whose bones leave the image plane by less than this are not flipped (the flip
        would be a near duplicate).
    occluded_visible_fraction : float
        A part with less than this fraction of its pixels visible is totally occluded (6.5).
    occluded_tolerance : float
        An occluded part takes the reference's pose only if that raises d_S by at most this.
        Infinite by default (the thesis: always): on a clothed body d_S is no judge of a
        hidden part, and 0.01 made ``syn_64_24_2`` of ``benchmarks/cases.py`` worse
        (selected 4.73 -> 5.35 deg, rank 0.77 -> 0.75). :meth:`exact_body` uses 0.01: there
        the image is exact, and a reset that sticks out of the region is wrong.
    n_prev : int
        Previous-frame candidates used as extra initial postures (6.7). 0 by default: it changed
        nothing that matters on the bench cases (``benchmarks/estimators.py``, hybrid, 3 -> 0:
        P1 best E_3B 3.46 -> 3.49, rank 0.57 -> 0.57; P2 6.69 -> 6.72, -0.08 -> -0.10; own
        synthetic case 3.99 -> 3.80, 0.89 -> 0.86), and without it every frame depends only on
        its own image and random stream, so the candidates do not depend on how the video
        is cut into chunks for the workers.
    far_margin : float
        The reference is "far" when its d_S exceeds the previous best candidate's by this.
    prior_weight : float
        mu of the selection cost d_S + mu d_B(candidate, initial posture) (d_B in radians,
        eq. 4.5); see :attr:`FrameCandidates.cost`. 0 ranks by d_S alone (the thesis). The
        capsule body never matches a real (clothed) silhouette exactly: on the public cases
        the true posture has d_A ~ 0.1 while postures 10-25 deg away reach 0.05, so without
        the prior the lowest-d_S candidate is far worse than the reference. 0.5 per radian
        means a candidate must explain ~0.045 more of d_S per 5 deg it departs.
    bp_prior_weight : float
        The same kind of prior inside BP and the refinement (beyond the thesis): each part
        sample's log phi gets -beta mu (its bones' angles to the reference's) / 16, so the
        estimate is the maximum of d_S + mu d_B(., B_C(t')). Without it, directions the
        silhouette cannot see (turns in depth, the head where hair is missing from the body
        region) drift freely: on P1 with the true C the lowest-d_S posture was 20 deg from
        the truth. 0 is the thesis.
    keypoint_weight, keypoint_tau : float
        With 2D keypoints (:mod:`engine.stages.perception`), the image likelihood adds
        ``keypoint_weight`` d_K (:func:`engine.measures.d_K`: swap-invariant, weighted by
        the detector's confidence, saturating at ``keypoint_tau`` of the body's height in
        the image). Beyond the thesis: it sees in-plane limb angles and an arm in front of
        the torso, which the silhouette does not. The keypoints carry the pose model's own
        offsets from our joints measured on the first frames
        (:func:`engine.stages.perception.keypoint_offsets`). ``benchmarks/cases.py --only P``
        (mean of the six public cases; rank of eps_t' / of the bones, reported/true error
        magnitude, 2D joint error % of height): 0 gives 0.48 / 0.00 / 0.18 / 1.80 (the prior
        keeps the reference), 0.3 0.56 / 0.21 / 0.54 / 1.83, 0.5 0.53 / 0.40 / 1.03 / 2.02,
        1 0.57 / 0.55 / 2.96 / 2.60 (the keypoints' own noise becomes reported error).
    ds_weight, width_weight : float
        The image likelihood of BP, the refinement and the candidates' image cost is
        ``ds_weight`` d_S + ``width_weight`` W, W the width-robust cost of
        :func:`engine.render.capsules.width_robust_cost` (beyond the thesis: centreline +
        coverage, insensitive to clothing wider than the capsules). 1, 0 is the thesis' d_S.
    coverage_weight, deep_k : float
        W's coverage weight and its depth factor (``deep_k`` x radius counts as inside).
    estimator : str
        ``"bp"``: the thesis' BP (4.6.4) then the refinement. ``"in_plane"`` (beyond the
        thesis): no BP; the reference posture B_C(t') is refined by the pattern search turning
        each part about the viewing direction only, against the image likelihood +
        ``in_plane_prior`` d_B(., B_C(t')), and the candidates are its depth flips. A
        silhouette sees in-plane directions and barely sees turns in depth, so the estimate
        departs from the reference only where the image says so. ``"hybrid"`` (default):
        both; the first half of the candidates are the in-plane estimate and its flips, the
        rest BP's. ``benchmarks/estimators.py`` (whole pipeline, scorer figures), P1 / P2:
        rank correlation of eps_t' with the truth BP 0.09 / 0.09, in-plane 0.50 / -0.06,
        hybrid 0.50 / -0.06; selected E_3B 3.71 / 6.90, 3.68 / 6.93, 3.68 / 6.93 deg;
        best-candidate E_3B 3.60 / 6.69, 3.33 / 6.87, 3.57 / 6.67 deg. On our own synthetic
        case (``coach synth``) rank BP 0.73, in-plane 0.95, hybrid 0.91. In-plane alone costs
        0.06 s/frame, BP and hybrid ~0.4.
    in_plane_prior, in_plane_step0_deg, in_plane_sweeps : float, float, int
        mu, first step and sweeps of the in-plane search. mu 1 per radian: on P1 (pipeline)
        mu 0.3 gave rank 0.48 and selected 3.82 deg, on P2 rank -0.62 and 7.83 deg.
    in_plane_move_root : bool
        Whether the ``"in_plane"`` search may also shift the root joint in the image. Off, the
        root stays where stages 1-2 put it: the body region misses the dark shoes and some
        hair, so on P1 with the true C and camera the shift moved the whole body 5.3 px down
        (E_2P 4.55 px with it, 1.10 without).
    escape_dirs : int
        Beyond the thesis; 0 (off) by default, 48 in :meth:`exact_body`. After BP, the
        refinement runs from BP's estimate and from the initial posture; from each, every
        part may jump (its subtree, or itself alone, turned to each of ``escape_dirs``
        directions or twisted about its own axis; an upper limb also with the lower one
        straightened; left and right limbs swapped), each jump kept when d_S falls, then the
        refinement runs again; the lower d_S wins. BP and the pattern search are local: a
        forearm that starts on the wrong side of the torso stays there. On videos of people
        it is not worth its cost: the defaults with ``escape_dirs`` 48 and ``refine_alone``
        on ``benchmarks/cases.py`` gave a mean rank of 0.653 against 0.664 (P1 0.62 -> 0.66,
        P2 0.44 -> 0.45, the four synthetic cases 0.01-0.05 lower) in 2.5 times the time.
    escape_prefilter : int
        When > 0, of each part's batch of jumps only the ``escape_prefilter`` with the lowest
        d_A (row spans, no render: 15 us a posture against 145 for d_S) are scored with d_S.
        0 (off) by default, 16 in :meth:`exact_body`, where the escape was a third of the
        time: ``--exact --frames 50`` E_3B 4.26 -> 4.25 deg, 1.90 -> 1.37 s/frame (8: 4.24);
        the time saved pays for a third restart.
    refine_alone : bool
        The refinement also turns each part with children alone, the parts below keeping
        their directions (beyond the thesis; off by default, on in :meth:`exact_body`).
    escape_lookahead, escape_lookahead_ds : int, float
        When the escaped estimate's d_S is still above ``escape_lookahead_ds``, the
        ``escape_lookahead`` best jumps of each torso part are tried as well, each followed
        by the limbs' escape and a refinement (a chest bent the wrong way with both arms
        fitted to it is a basin no single jump leaves). 0 (off) by default.
    subpixel_rows : int
        When > 0, the whole-posture d_A (refinement, escape, candidates' d_S) is measured
        continuously with this many sub-rows per pixel row
        (:func:`~engine.render.capsules.d_A_batch`); BP's per-part scores stay
        pixel-exact. Beyond the thesis; 0 (off). Measured to change little, so it is off:
        ``benchmarks/candidates.py --frames 30 --exact`` E_3B 5.60 -> 5.55 deg, E_2P 0.98 ->
        0.94 px, selected 7.83 -> 8.36 deg, 1.78 -> 2.69 s/frame with 4 sub-rows; on
        ``benchmarks/cases.py`` mean rank 0.664 -> 0.663, selected 5.356 -> 5.362 deg. The
        synthetic depth-angle floor is not the pixel grid's.
    restarts, restart_ds, restart_deg : int, float, float
        Beyond the thesis; 0 restarts by default, 3 in :meth:`exact_body`. While the
        estimate's d_S is above ``restart_ds``, BP runs again (at most ``restarts`` times)
        from the estimate with every part turned by a random angle in +-``restart_deg``
        about its root joint, then the refinement / escape, and the lower d_S wins. BP's
        annealing settles into one basin; a fresh start from near the estimate often lands
        in the right one. :meth:`exact_body` on ``benchmarks/candidates.py --frames 100
        --exact``: frames stuck in a wrong basin (E_2P > 1.5 px) 16 -> 8, E_2P 1.18 -> 0.91
        px, E_2M 5.1 -> 4.5 px, E_3B 6.00 -> 5.40 deg, 1.63 -> 1.94 s/frame (``--seed 1``:
        16 -> 6, 1.26 -> 1.09 px, 6.20 -> 5.69 deg; one restart: E_2P 1.01, E_3B 5.66;
        +-15 deg: 0.89, 5.44). :meth:`exact_body` now restarts below 0.02 as well, down to
        0.01: most synthetic frames sit at d_S 0.005-0.02 however right or wrong their
        depths, and a restart finds a lower basin often enough (``--exact --frames 50``:
        E_3B 4.26 deg at 1.90 s/frame with two, 5.27 at 1.42 without, before the escape's
        prefilter; with it, three against two: 4.19 / 4.25 deg, ``--seed 1`` 4.10 / 4.42,
        1.5 / 1.35 s/frame). The d_S compared is
        the refinement's objective (with ``bp_prior_weight``'s prior when that is > 0).
        Only worth it where a low d_S means a right posture (exact body images): on videos
        of people d_S never falls that low, so every frame would pay.
    alternatives, alternative_min_deg, alternative_share : int, float, float
        Beyond the thesis; 0 (off) by default, 2 in :meth:`exact_body`. The refinement
        from BP's estimate, from the initial posture and from each restart ends in a local
        optimum of d_S; only the lowest gives the candidates, and the others are dropped
        although d_S barely tells them apart (one may have the right depths where the
        lowest has not). Up to ``alternatives`` of them, next lowest first and each at
        least ``alternative_min_deg`` from those kept, join the candidates with their own
        flips, sharing ``alternative_share`` of the set. ``--exact --frames 50``: best E_3B
        4.51 -> 4.26 deg at the same cost (two restarts, no prefilter).
    """

    n_samples: int = 40
    n_iterations: int = 12
    decrease: float = 0.85
    sigma0_m: float = 0.05
    a0: float = 0.5
    rot_std0_deg: float = 8.0
    rot_std_min_deg: float = 0.5
    pos_std0_m: float = 0.02
    pos_std_min_m: float = 0.002
    attach_prob: float = 0.5
    beta: float = 300.0
    lambda_a: float = 1.0
    lambda_e: float = 0.0
    edge_sigma_px: float = 5.0
    edge_xi: float = 1.0
    refine_sweeps: int = 14
    refine_step0_deg: float = 16.0
    refine_min_step_deg: float = 0.2
    n_candidates: int = 25
    min_flip_deg: float = 5.0
    occluded_visible_fraction: float = 0.05
    occluded_tolerance: float = float("inf")
    n_prev: int = 0
    far_margin: float = 0.05
    prior_weight: float = 0.5
    keypoint_weight: float = 0.5
    keypoint_tau: float = 0.1
    bp_prior_weight: float = 0.0
    ds_weight: float = 1.0
    width_weight: float = 0.0
    coverage_weight: float = 1.0
    deep_k: float = 0.5
    estimator: str = "hybrid"
    in_plane_prior: float = 1.0
    in_plane_step0_deg: float = 8.0
    in_plane_sweeps: int = 10
    in_plane_move_root: bool = False
    escape_dirs: int = 0
    refine_alone: bool = False
    escape_lookahead: int = 0
    escape_lookahead_ds: float = 0.04
    subpixel_rows: int = 0
    restarts: int = 0
    restart_ds: float = 0.02
    restart_deg: float = 10.0
    refine_per_part: bool = False
    escape_prefilter: int = 0
    alternatives: int = 0
    alternative_min_deg: float = 3.0
    alternative_share: float = 0.4

    @classmethod
    def thesis(cls) -> CandidateSettings:
        """The thesis' settings (5.2.2): lambda 0.9, 40 iterations, 300 samples, 50 candidates."""
        return cls(
            n_samples=300,
            n_iterations=40,
            decrease=0.9,
            n_candidates=50,
            refine_sweeps=0,
            lambda_e=1.0,
            prior_weight=0.0,
            estimator="bp",
        )

    @classmethod
    def exact_body(cls) -> CandidateSettings:
        """For images the capsule body matches exactly (the synthetic experiment 5.2).

        The defaults' BP with 8 iterations, then the escape, the part-alone refinement with
        a step per part, up to three restarts of BP while the fit is poor and the alternative
        optima as candidates (all beyond the thesis), no prior towards the initial
        posture, d_E on (such images have every part's outline). Not for videos of people:
        there the priors keep the fit near the reference where the body model does not fit
        the image (see ``prior_weight``).
        """
        return cls(
            estimator="bp",
            prior_weight=0.0,
            lambda_e=1.0,
            n_iterations=8,
            escape_dirs=48,
            escape_prefilter=16,
            refine_alone=True,
            refine_step0_deg=4.0,
            refine_per_part=True,
            refine_sweeps=24,
            occluded_tolerance=0.01,
            restarts=3,
            restart_ds=0.01,
            alternatives=2,
        )

    def validate(self) -> None:
        if self.n_samples < 2:
            raise InvalidInput(f"settings.n_samples must be >= 2, got {self.n_samples}")
        if self.n_iterations < 0:
            raise InvalidInput(f"settings.n_iterations must be >= 0, got {self.n_iterations}")
        if not 0.0 < self.decrease <= 1.0:
            raise InvalidInput(f"settings.decrease must be in (0, 1], got {self.decrease}")
        if not 0.0 < self.a0 < 1.0:
            raise InvalidInput(f"settings.a0 must be in (0, 1), got {self.a0}")
        if self.estimator not in ("bp", "in_plane", "hybrid"):
            raise InvalidInput(
                f"settings.estimator must be 'bp', 'in_plane' or 'hybrid', got {self.estimator!r}"
            )
        if self.n_candidates < 1:
            raise InvalidInput(f"settings.n_candidates must be >= 1, got {self.n_candidates}")
        for name in (
            "escape_dirs", "escape_lookahead", "escape_prefilter", "subpixel_rows", "restarts",
            "alternatives",
        ):
            if getattr(self, name) < 0:
                raise InvalidInput(f"settings.{name} must be >= 0, got {getattr(self, name)}")
        if not (self.restart_ds >= 0.0 and self.restart_deg >= 0.0):  # also refuses NaN
            raise InvalidInput(
                f"settings.restart_ds and restart_deg must be >= 0, got {self.restart_ds}, "
                f"{self.restart_deg}"
            )
        if not 0.0 < self.alternative_share <= 1.0:
            raise InvalidInput(
                f"settings.alternative_share must be in (0, 1], got {self.alternative_share}"
            )
        if not self.alternative_min_deg >= 0.0:  # also refuses NaN
            raise InvalidInput(
                f"settings.alternative_min_deg must be >= 0, got {self.alternative_min_deg}"
            )
        if not self.occluded_tolerance >= 0.0:  # also refuses NaN
            raise InvalidInput(
                f"settings.occluded_tolerance must be >= 0, got {self.occluded_tolerance}"
            )


@dataclass(frozen=True)
class FrameCandidates:
    """Posture candidates of one video frame.

    Attributes
    ----------
    candidates : ndarray, shape (K, 17, 3)
        World frame, metres. Candidate 0 has the reference's depth orientation; the flips
        share its projection; with ``settings.alternatives``, the runner-up local optima and
        their flips follow; the initial postures (the reference turned by T_t' and the
        previous frame's best) come last when they respect the joint limits, so the set is
        never worse than the start.
    d_s : ndarray, shape (K,)
        d_S of each candidate against the target region.
    flags : tuple of str
        e.g. ``"occluded:l_wrist"``, ``"reference_far"``.
    history : ndarray, shape (n_iterations + 1,)
        d_S of the connected best posture after each BP iteration (0 = initial).
    prior : ndarray, shape (K,)
        mu d_B(candidate, initial posture) (``settings.prior_weight``); zeros when unused.
    """

    candidates: np.ndarray
    d_s: np.ndarray
    flags: tuple[str, ...] = ()
    history: np.ndarray = field(default_factory=lambda: np.zeros(0))
    prior: np.ndarray | None = None

    @property
    def cost(self) -> np.ndarray:
        """Selection cost d_S + prior of each candidate, shape (K,)."""
        return self.d_s if self.prior is None else self.d_s + self.prior

    @property
    def best(self) -> np.ndarray:
        """The candidate with the lowest :attr:`cost`, shape (17, 3)."""
        return self.candidates[int(np.argmin(self.cost))]


# ------------------------------------------------------------------------------ helpers


def limits_ok(joints: np.ndarray, tol_rad: float = 1e-6) -> np.ndarray:
    """Whether postures (..., 17, 3) respect every joint-angle limit (appendix A), (...)."""
    j = np.asarray(joints, float)
    u = j[..., LIMIT_A, :] - j[..., LIMIT_JOINT, :]
    w = j[..., LIMIT_B, :] - j[..., LIMIT_JOINT, :]
    cos = (u * w).sum(-1) / np.maximum(
        np.linalg.norm(u, axis=-1) * np.linalg.norm(w, axis=-1), 1e-12
    )
    return np.all(np.arccos(np.clip(cos, -1, 1)) >= LIMIT_MIN_RAD - tol_rad, axis=-1)


def _subtree(part: int) -> tuple[int, ...]:
    out = [part]
    for q in range(N_PARTS):
        if q != part and any(p in out for p in _ancestors(q)):
            out.append(q)
    return tuple(sorted(out))


def _ancestors(q: int) -> list[int]:
    out = []
    while PART_PARENT[q] >= 0:
        q = int(PART_PARENT[q])
        out.append(q)
    return out


_SUBTREES = tuple(_subtree(p) for p in range(N_PARTS))
_SUBTREE_JOINTS = tuple(
    np.array(sorted({int(BONE_CHILD[b]) for q in st for b in PART_BONES[q]})) for st in _SUBTREES
)


def _from_bones(root: np.ndarray, vec: np.ndarray) -> np.ndarray:
    """Joints (..., 17, 3) from root (..., 3) and bone vectors (..., 16, 3)."""
    j = np.empty(vec.shape[:-2] + (17, 3))
    j[..., 0, :] = root
    for b in range(16):
        j[..., BONE_CHILD[b], :] = j[..., BONE_PARENT[b], :] + vec[..., b, :]
    return j


def _frame_offsets(ref: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Default-posture bone vectors (16, 3) under which ``ref`` (17, 3) is exactly rigid per part.

    A BVH clavicle moves relative to the spine, so the upper chest is not rigid across frames;
    taking the part shapes from this frame's reference posture makes it reachable exactly.
    """
    R = part_rotations(ref, offsets)
    vec = bone_vectors(ref)
    from engine.body.skeleton import BONE_PART

    return np.einsum("bji,bj->bi", R[BONE_PART], vec)


class _Scorer:
    """d_S against one target region (thesis 4.4.1, eq. 4.4) for the three uses of stage 3.

    ``part`` scores poses of one part with the others at the context posture (BP, 4.6.2;
    incremental :class:`~engine.render.capsules.PartScorer`), ``full`` scores whole postures
    (refinement, candidates; :func:`~engine.render.capsules.d_S_batch`). Both are exact
    renders of the capsule body, so their values agree.
    """

    def __init__(
        self,
        target: Target,
        shape: BodyShape,
        camera: Camera,
        joints: np.ndarray,
        s: CandidateSettings,
        keypoints: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        self.target, self.shape, self.camera = target, shape, camera
        self.kp = None
        if keypoints is not None and s.keypoint_weight > 0 and np.any(keypoints[1] > 0):
            tau_px = s.keypoint_tau * camera.scale * max(float(np.ptp(joints[:, 1])), 0.3)
            self.kp = (keypoints[0], keypoints[1], tau_px, s.keypoint_weight)
        self.lam = (s.lambda_a, s.lambda_e)
        self.ds_w, self.w_w = s.ds_weight, s.width_weight
        self.coverage_weight, self.deep_k = s.coverage_weight, s.deep_k
        self.width = WidthTarget.from_mask(target.silhouette) if s.width_weight > 0 else None
        self.subpixel = s.subpixel_rows
        self.parts = PartScorer(
            target, shape, camera, joints, lambda_A=s.lambda_a, lambda_E=s.lambda_e
        )
        self.n_evals = 0

    def set_pose(self, joints: np.ndarray) -> None:
        self.parts.set_pose(joints)

    def keypoints(self, postures: np.ndarray) -> np.ndarray:
        """The keypoint term w d_K of postures (N, 17, 3), (N,); zeros without keypoints."""
        if self.kp is None:
            return np.zeros(len(postures))
        kp, conf, tau_px, w = self.kp
        return w * d_K(self.camera.project(postures), kp, conf, tau_px=tau_px)

    def _cues(self, postures: np.ndarray) -> np.ndarray:
        """The terms beside d_S: keypoints, and the width-robust cost when weighted."""
        if self.width is None:
            return self.keypoints(postures)
        return self.keypoints(postures) + self.w_w * width_robust_cost(
            postures, self.width, self.shape, self.camera,
            coverage_weight=self.coverage_weight, deep_k=self.deep_k,
        )  # fmt: skip

    def part(self, part: int, samples: np.ndarray) -> np.ndarray:
        self.n_evals += len(samples)
        out = self._cues(samples)
        if self.ds_w > 0:
            out = out + self.ds_w * self.parts.score(part, samples)
        return out

    def full(self, postures: np.ndarray) -> np.ndarray:
        self.n_evals += len(postures)
        out = self._cues(postures)
        if self.ds_w <= 0:
            return out
        lam_a, lam_e = self.lam
        if self.subpixel > 0:  # d_A measured continuously, d_E as rendered
            out = out + self.ds_w * lam_a * d_A_batch(
                postures, self.target, self.shape, self.camera, subpixel_rows=self.subpixel
            )
            lam_a = 0.0
            if lam_e == 0.0:
                return out
        return out + self.ds_w * d_S_batch(
            postures, self.target, self.shape, self.camera, lambda_A=lam_a, lambda_E=lam_e
        )

    def silhouette(self, postures: np.ndarray) -> np.ndarray:
        """d_A alone of ``postures`` (N, 17, 3), from row spans without rendering, (N,)."""
        self.n_evals += len(postures)
        return d_A_batch(postures, self.target, self.shape, self.camera)

    def visible_fraction(self, joints: np.ndarray) -> np.ndarray:
        """Fraction of each part's projected area that is front-most in ``joints``, (12,).

        The part's own area is the capsules' analytic area (2 r l + pi r^2 in pixels; the
        few overlaps inside a part make it a slight overestimate, which only errs towards
        calling a part occluded when it nearly is).
        """
        self.parts.set_pose(joints)
        labels = self.parts.render().labels
        seen = np.bincount(labels[labels >= 0].astype(np.int64), minlength=N_PARTS)
        pc_uv = self.camera.project(joints)
        from engine.body.shapes import CAPSULE_A, CAPSULE_B, CAPSULE_T

        a, b = pc_uv[CAPSULE_A], pc_uv[CAPSULE_B]
        length = np.linalg.norm(b - a, axis=-1) * np.abs(CAPSULE_T[:, 1] - CAPSULE_T[:, 0])
        r = np.asarray(self.shape.radii) * self.camera.scale
        area = 2.0 * r * length + np.pi * r**2
        own = np.array([area[PART_CAPSULES[p]].sum() for p in range(N_PARTS)])
        return seen / np.maximum(own, 1.0)


def _refine(
    scorer: _Scorer,
    joints: np.ndarray,
    camera: Camera,
    s: CandidateSettings,
    ref: np.ndarray | None = None,
    *,
    in_plane: bool = False,
    mu: float | None = None,
    step0_deg: float | None = None,
    sweeps: int | None = None,
    move_root: bool = True,
) -> tuple[np.ndarray, float]:
    """Sub-pixel pattern search on d_S over subtree rotations and root shifts (thesis 6.4).

    With ``ref`` and ``s.bp_prior_weight`` (or ``mu``), the objective is BP's: d_S + mu
    d_B(., ref). ``in_plane`` turns parts about the viewing direction only (the directions a
    silhouette can see), keeping the start's depth. ``move_root`` False keeps the root joint
    where it is.
    """
    if mu is None:
        mu = s.bp_prior_weight if ref is not None else 0.0

    def objective(q: np.ndarray) -> np.ndarray:
        out = scorer.full(q)
        return out + mu * d_B(q, ref) if mu > 0 and ref is not None else out

    cur = joints.copy()
    best = float(objective(cur[None])[0])
    n = camera.view_dir
    step0 = np.radians(s.refine_step0_deg if step0_deg is None else step0_deg)
    min_step = np.radians(s.refine_min_step_deg)
    # a step per part; without s.refine_per_part they all halve together (one shared step)
    steps = np.full(N_PARTS, step0)
    px = 1.0 / camera.scale
    for _ in range(s.refine_sweeps if sweeps is None else sweeps):
        improved = False
        for p in range(N_PARTS):
            step = steps[p]
            if step < min_step:
                continue
            d = _part_dir(cur, p)
            a1 = np.cross(n, d)
            axes = [n, a1] if np.linalg.norm(a1) > 1e-9 and not in_plane else [n]
            if len(PART_BONES[p]) > 1 and not in_plane:
                axes.append(np.cross(n, a1) if np.linalg.norm(a1) > 1e-9 else d)
            Rs = np.stack([rotation_about_axis(ax, sg * step) for ax in axes for sg in (-1.0, 1.0)])
            samples = list(_turned(cur, p, Rs))
            if s.refine_alone and len(_SUBTREES[p]) > 1:
                samples.extend(_turned_alone(cur, p, Rs))
            if p == 0 and move_root:
                for vec in camera.R_cam_world[:2]:
                    for sg in (-1.0, 1.0):
                        samples.append(cur + sg * 0.5 * px * vec * max(step / np.radians(1), 0.5))
            batch = np.stack(samples)
            sc = objective(batch)
            k = int(np.argmin(sc))
            if sc[k] < best - 1e-9 and limits_ok(batch[k]):
                cur, best, improved = batch[k], float(sc[k]), True
            elif s.refine_per_part:
                steps[p] /= 2.0  # this part is converged at this step
        if not s.refine_per_part and not improved:
            steps /= 2.0
        if steps.max() < min_step:
            break
    return cur, best


def perturb_parts(joints: np.ndarray, max_deg: float, rng: np.random.Generator) -> np.ndarray:
    """Every part (with its subtree) turned about its root joint by U[-max, max] deg.

    About a random axis per part (thesis 5.2.2's perturbed initial posture). ``joints`` (17, 3)
    -> (17, 3).
    """
    out = np.array(joints, dtype=float)
    for p in range(N_PARTS):
        J = out[PART_ROOT_JOINT[p]]
        R = rotation_about_axis(rng.normal(size=3), np.radians(rng.uniform(-max_deg, max_deg)))
        sub = _SUBTREE_JOINTS[p]
        out[sub] = J + (out[sub] - J) @ R.T  # not _turned: its einsum rounds differently
    return out


def _sphere(n: int) -> np.ndarray:
    """``n`` nearly even unit directions (Fibonacci lattice), shape (n, 3)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (1.0 + 5.0**0.5) * k
    r = np.sqrt(1.0 - z**2)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _turn_to(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotations taking unit direction a (3,) to each of b (n, 3), shape (n, 3, 3)."""
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=1)
    c = b @ a
    ang = np.arctan2(s, c)
    perp = np.cross(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    axis = np.where(s[:, None] > 1e-9, axis, perp)
    return rotation_about_axis(axis, ang)


def _turned(cur: np.ndarray, p: int, Rs: np.ndarray) -> np.ndarray:
    """``cur`` (17, 3) with part p's subtree turned by each of Rs (n, 3, 3) about its root."""
    J = cur[PART_ROOT_JOINT[p]]
    sub = _SUBTREE_JOINTS[p]
    out = np.repeat(cur[None], len(Rs), axis=0)
    out[:, sub] = J + np.einsum("nij,kj->nki", Rs, cur[sub] - J)
    return out


def _turned_alone(cur: np.ndarray, p: int, Rs: np.ndarray) -> np.ndarray:
    """``cur`` (17, 3) with part p's own bones turned by each of Rs (n, 3, 3); the parts below
    keep their directions and follow by translation, shape (n, 17, 3)."""
    vec = np.repeat(bone_vectors(cur)[None], len(Rs), axis=0)
    own = list(PART_BONES[p])
    vec[:, own] = np.einsum("nij,kj->nki", Rs, vec[0, own])
    return _from_bones(np.repeat(cur[None, 0], len(Rs), axis=0), vec)


def _part_dir(cur: np.ndarray, p: int) -> np.ndarray:
    own = np.array([BONE_CHILD[b] for b in PART_BONES[p]])
    d = (cur[own] - cur[PART_ROOT_JOINT[p]]).mean(0)
    return d / np.linalg.norm(d)


#: The one child part of each limb part (upper arm -> lower arm, ...), -1 for the others.
_LIMB_CHILD = tuple(
    int(np.flatnonzero(PART_PARENT == p)[0]) if (PART_PARENT == p).sum() == 1 else -1
    for p in range(N_PARTS)
)


#: Left/right pairs of limb parts (upper arm, upper leg), swapped by :func:`_escape`.
_LIMB_PAIRS = ((4, 6), (8, 10))


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


#: Twists :func:`_moves` tries about a part's own direction: multiples of 30 deg, (11,) rad.
_TWISTS = 2.0 * np.pi * np.arange(1, 12) / 12

#: Parts whose subtree holds other parts' limbs: a wrong turn of them takes the limbs along.
_TORSO_PARTS = (0, 1, 2)


def _escape(
    scorer: _Scorer,
    joints: np.ndarray,
    n_dirs: int,
    parts: Sequence[int] = ALL_PARTS,
    prefilter: int = 0,
) -> tuple[np.ndarray, float]:
    """Let parts stuck in a wrong basin jump (:func:`_moves`); keep each jump that lowers d_S.

    Beyond the thesis. BP and the pattern search are local: a forearm that starts on the
    wrong side of the torso, pointing at the camera when it hangs down, or a chest turned
    the wrong way, stays there. Parents first; then the left and right arms, and legs, are
    swapped (a front and a back view differ by exactly this). With ``prefilter`` > 0, only
    the ``prefilter`` jumps of each batch with the lowest silhouette term d_A (a twelfth of
    the cost of a full d_S) are scored with d_S.
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

    for p in parts:
        keep(_moves(cur, p, dirs))
    swaps = np.stack([_swapped(cur, a, b) for a, b in _LIMB_PAIRS])
    keep(swaps[limits_ok(swaps)])
    return cur, best


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
    the only start. When the best still explains the
    region poorly (d_S above ``s.escape_lookahead_ds``), the ``s.escape_lookahead`` best
    jumps of each torso part are tried too, each with the limbs re-placed by an escape and
    a refinement: a chest bent the wrong way with both arms fitted to it is a basin no
    single-part jump leaves.
    """
    found: list[tuple[float, np.ndarray]] = []

    def polish(q: np.ndarray, parts: Sequence[int] = ALL_PARTS) -> None:
        q, d = _refine(scorer, q, camera, s, ref)
        q2, d2 = _escape(scorer, q, s.escape_dirs, parts=parts, prefilter=s.escape_prefilter)
        if d2 < d - 1e-9:
            q, d = _refine(scorer, q2, camera, s, ref)
        found.append((d, q))

    for q in starts:
        polish(q)
    found.sort(key=lambda f: f[0])
    if found[0][0] > s.escape_lookahead_ds and s.escape_lookahead > 0:
        dirs = _sphere(s.escape_dirs)
        limbs = [p for p in ALL_PARTS if p not in _TORSO_PARTS]
        base = found[0][1]
        for p in _TORSO_PARTS:
            batch = _moves(base, p, dirs)
            for k in np.argsort(scorer.full(batch))[: s.escape_lookahead]:
                polish(batch[k], limbs)
        found.sort(key=lambda f: f[0])
    return found


def _occluded_parts(scorer: _Scorer, joints: np.ndarray, thr: float) -> list[int]:
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
    then the image, not the reference, has the last word.
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


def _flip(vec: np.ndarray, parts: tuple[int, ...], n: np.ndarray) -> np.ndarray:
    """Mirror the bones of ``parts`` in depth along view direction n (projection kept)."""
    out = vec.copy()
    bones = [b for p in parts for b in PART_BONES[p]]
    out[bones] -= 2.0 * (out[bones] @ n)[:, None] * n
    return out


def _orient_like(vec: np.ndarray, source: np.ndarray, n: np.ndarray, min_sin: float) -> np.ndarray:
    """Give each part of bone vectors ``vec`` the depth orientation of ``source`` (4.6.5 step 3)."""
    flips = []
    for p in range(N_PARTS):
        bones = list(PART_BONES[p])
        z = vec[bones] @ n
        zs = source[bones] @ n
        ls = np.linalg.norm(source[bones], axis=1)
        if np.max(np.abs(zs) / ls) < min_sin:
            continue  # the source has no clear depth orientation for this part
        if float(z @ zs) < 0.0:
            flips.append(p)
    return _flip(vec, tuple(flips), n)


def generate_candidates(
    joints: np.ndarray,
    orientations: list[np.ndarray],
    camera: Camera,
    settings: CandidateSettings,
) -> np.ndarray:
    """Posture candidates from one estimate (thesis 4.6.5 steps 3-5).

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
        The connected best posture.
    orientations : list of ndarray (17, 3)
        Postures whose per-part depth orientation seeds a candidate, the reference first.
    camera : Camera
    settings : CandidateSettings

    Returns
    -------
    candidates : ndarray, shape (K, 17, 3)
        Same projection as ``joints``; only those respecting the joint limits (at least one:
        the first is kept even when it does not, so that a frame always has a candidate).
    """
    n = camera.view_dir
    min_sin = np.sin(np.radians(settings.min_flip_deg))
    vec = bone_vectors(joints)
    root = joints[0]
    seeds = [_orient_like(vec, bone_vectors(o), n, min_sin) for o in orientations]
    base = seeds[0]
    depth_sin = [
        float(
            np.max(
                np.abs(base[list(PART_BONES[p])] @ n)
                / np.linalg.norm(base[list(PART_BONES[p])], axis=1)
            )
        )
        for p in range(N_PARTS)
    ]
    flippable = sorted(
        (p for p in range(N_PARTS) if depth_sin[p] >= min_sin), key=lambda p: depth_sin[p]
    )
    out: list[np.ndarray] = []
    keys: set[tuple[bool, ...]] = set()

    def add(v: np.ndarray) -> None:
        k = tuple(np.round(v @ n, 4))
        if k in keys:
            return
        keys.add(k)
        j = _from_bones(root, v)
        if limits_ok(j) or not out and len(keys) == 1:
            out.append(j)

    for v in seeds:
        add(v)
    add(vec)  # the estimate's own depth orientation, which the edges may have chosen
    for m in range(1, len(flippable) + 1):
        for combo in itertools.combinations(flippable, m):
            if len(out) >= settings.n_candidates:
                break
            add(_flip(base, combo, n))
        if len(out) >= settings.n_candidates:
            break
    if not out:
        out.append(_from_bones(root, base))
    return np.stack(out[: settings.n_candidates])


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


# ------------------------------------------------------------------------------ BP


def _check_inputs(
    sil: np.ndarray, edges: np.ndarray, camera: Camera, shape: BodyShape, init: np.ndarray
) -> np.ndarray:
    if not isinstance(camera, Camera):
        raise InvalidInput(f"camera must be a Camera, got {type(camera).__name__}")
    if not isinstance(shape, BodyShape):
        raise InvalidInput(f"shape must be a BodyShape, got {type(shape).__name__}")
    sil = np.asarray(sil)
    edges = np.asarray(edges)
    if sil.ndim != 2 or sil.shape != (camera.height, camera.width):
        raise InvalidInput(
            f"target_silhouette must have shape (H, W) = {(camera.height, camera.width)}, "
            f"got {sil.shape}"
        )
    if edges.shape != sil.shape:
        raise InvalidInput(f"target_edges must have shape {sil.shape}, got {edges.shape}")
    if not sil.any():
        raise InvalidInput("target_silhouette is empty: no body region to match")
    init = np.asarray(init, dtype=float)
    if init.ndim == 2:
        init = init[None]
    if init.ndim != 3 or init.shape[1:] != (17, 3) or init.shape[0] < 1:
        raise InvalidInput(
            f"initial_joints must have shape (17, 3) or (M, 17, 3), got {init.shape}"
        )
    if not np.all(np.isfinite(init)):
        raise InvalidInput("initial_joints contains NaN or infinite values")
    return init


def estimate_candidates(
    target_silhouette: np.ndarray,
    target_edges: np.ndarray,
    camera: Camera,
    shape: BodyShape,
    initial_joints: np.ndarray,
    *,
    settings: CandidateSettings | None = None,
    rng: np.random.Generator,
    prev: FrameCandidates | None = None,
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
) -> FrameCandidates:
    """Posture candidates of one frame (thesis 4.6, eq. 4.12-4.21; 6.4, 6.5, 6.7).

    Parameters
    ----------
    target_silhouette, target_edges : ndarray of bool, shape (H, W)
        The input body region S' and its edges (stage 0).
    camera : Camera
        Stage 1's camera; its (height, width) must be the image's.
    shape : BodyShape
        The performer's body (the reference's by default).
    initial_joints : ndarray, shape (17, 3) or (M, 17, 3)
        Initial estimates, world frame; the first is the reference posture B_C(t') turned by
        T_t' and gives the first candidate's depth orientation.
    settings : CandidateSettings, optional
    rng : numpy.random.Generator
    prev : FrameCandidates, optional
        The previous frame's candidates (extra initial estimates, 6.7).
    keypoints : (ndarray (R, 17, 2), ndarray (R, 17)), optional
        The readings of the frame's 2D keypoints and their confidences
        (:func:`engine.stages.perception.readings`): ``settings.keypoint_weight`` d_K joins
        the image likelihood everywhere (BP, refinement, the candidates' d_s).

    Returns
    -------
    FrameCandidates

    Raises
    ------
    InvalidInput
        Shapes that do not match, an empty silhouette, non-finite postures, bad settings.
    """
    s = settings or CandidateSettings()
    s.validate()
    init = _check_inputs(target_silhouette, target_edges, camera, shape, initial_joints)
    if not isinstance(rng, np.random.Generator):
        raise InvalidInput("rng must be a numpy.random.Generator")
    flags: list[str] = []
    ref = init[0]
    pool = init
    if prev is not None and len(prev.candidates):
        order = np.argsort(prev.cost)[: s.n_prev]
        pool = np.concatenate([init, prev.candidates[order]])
    offsets = _frame_offsets(ref, shape.offsets)
    target = Target.from_masks(
        target_silhouette, target_edges, sigma_px=s.edge_sigma_px, xi=s.edge_xi
    )
    scorer = _Scorer(target, shape, camera, ref, s, keypoints)
    ref_dirs = bone_vectors(ref)
    ref_dirs = ref_dirs / np.linalg.norm(ref_dirs, axis=-1, keepdims=True)
    off_dirs = offsets / np.maximum(np.linalg.norm(offsets, axis=-1, keepdims=True), 1e-12)

    def prior(p: int, R: np.ndarray) -> np.ndarray:
        """mu x part p's share of d_B(sample, reference) (16 bones), shape (S,)."""
        if s.bp_prior_weight <= 0:
            return np.zeros(len(R))
        ang = sum(
            np.arccos(np.clip(np.einsum("sij,j,i->s", R, off_dirs[b], ref_dirs[b]), -1, 1))
            for b in PART_BONES[p]
        )
        return s.bp_prior_weight * ang / 16.0

    d0 = scorer.full(pool)
    orient_src = [ref]
    if prev is not None and len(pool) > len(init):
        prev_best = pool[len(init)]
        if d0[0] > d0[len(init)] + s.far_margin:
            flags.append("reference_far")  # thesis 6.7: start from the previous frame instead
            orient_src = [prev_best, ref]
        else:
            orient_src = [ref, prev_best]

    in_plane = None
    if s.estimator in ("in_plane", "hybrid"):
        in_plane = _in_plane_candidates(scorer, pool, init, ref, d0, orient_src, camera, s, flags)
        if s.estimator == "in_plane":
            return in_plane

    est, history = _bp_estimate(scorer, pool, d0, offsets, s, rng, prior)
    found = _polish(scorer, [est, pool[0]], camera, s, ref)
    # beyond the thesis: BP again from the estimate shaken, while the image is not explained
    for _ in range(s.restarts):
        if found[0][0] <= s.restart_ds:
            break
        est = found[0][1]
        shaken = np.stack([perturb_parts(est, s.restart_deg, rng), est])
        again, _ = _bp_estimate(scorer, shaken, scorer.full(shaken), offsets, s, rng, prior)
        found = sorted(found + _polish(scorer, [again], camera, s, ref), key=lambda f: f[0])

    # thesis 6.5: totally occluded parts take the reference's pose
    est = _reset_occluded(scorer, found[0][1], orient_src[0], offsets, s, flags)
    cands = generate_candidates(est, orient_src, camera, s)
    alts = _alternatives(found, s)
    if alts:
        cands = _with_alternatives(cands, alts, orient_src, camera, s)
    # Never worse than the start: the initial postures (the reference turned by T_t' and the
    # previous frame's best) are candidates themselves when they respect the joint limits.
    starts = [q for q in pool[: len(init) + min(1, len(pool) - len(init))] if limits_ok(q)]
    if starts:
        cands = _append_distinct(cands, np.stack(starts), s.n_candidates)
    if in_plane is not None:
        keep = in_plane.candidates[: max(1, s.n_candidates // 2)]
        cands = _append_distinct(keep, cands, s.n_candidates)
    d_s = scorer.full(cands)
    prior_cost = s.prior_weight * d_B(cands, ref)
    return FrameCandidates(cands, d_s, tuple(flags), np.asarray(history), prior_cost)


def _bp_estimate(
    scorer: _Scorer,
    pool: np.ndarray,
    d0: np.ndarray,
    offsets: np.ndarray,
    s: CandidateSettings,
    rng: np.random.Generator,
    prior: Callable[[int, np.ndarray], np.ndarray],
) -> tuple[np.ndarray, list[float]]:
    """Nonparametric BP (thesis 4.6.4) from the initial postures ``pool`` (M, 17, 3).

    ``d0`` (M,) is their d_S. Returns the connected best posture (17, 3) and its d_S after each
    iteration (0 = initial).
    """
    # initial samples: drawn from the initial postures weighted by their likelihood
    R0 = part_rotations(pool, offsets)  # (M, 12, 3, 3)
    w = np.exp(-s.beta * (d0 - d0.min()))
    m_of = np.concatenate([np.arange(len(pool)), rng.choice(len(pool), s.n_samples, p=w / w.sum())])
    m_of = m_of[: s.n_samples]
    rot_std = np.radians(s.rot_std0_deg)
    pos_std = s.pos_std0_m
    context = pool[int(np.argmin(d0))]
    scorer.set_pose(context)
    parts: list[_bp.PartSamples] = []
    for p in range(N_PARTS):
        x = pool[m_of, PART_ROOT_JOINT[p]].copy()
        R = R0[m_of, p]
        k = len(pool)
        R = np.concatenate([R[:k], _bp.random_rotations(rng, len(m_of) - k, rot_std) @ R[k:]])
        x[k:] += rng.normal(0.0, pos_std, size=x[k:].shape)
        lphi = -s.beta * (scorer.part(p, _bp.fill_part(context, p, offsets, x, R)) + prior(p, R))
        parts.append(_bp.PartSamples(x, R, lphi, lphi - np.logaddexp.reduce(lphi)))

    def connected() -> np.ndarray:
        return _bp.assemble(offsets, parts, [q.best for q in parts])

    history = [float(scorer.full(connected()[None])[0])]
    sigma, log_a = s.sigma0_m, np.log(s.a0)
    for _ in range(s.n_iterations):
        sigma *= s.decrease  # step 1: harden the constraints
        log_a /= s.decrease
        rot_std = max(rot_std * s.decrease, np.radians(s.rot_std_min_deg))
        pos_std = max(pos_std * s.decrease, s.pos_std_min_m)
        context = connected()
        scorer.set_pose(context)
        new = []
        for p in range(N_PARTS):  # step 2: sample; phi with the others at the last poses
            x, R = _bp.resample(
                offsets, parts, p, s.n_samples, rot_std, pos_std, s.attach_prob, rng
            )
            lphi = -s.beta * (
                scorer.part(p, _bp.fill_part(context, p, offsets, x, R)) + prior(p, R)
            )
            new.append(_bp.PartSamples(x, R, lphi, lphi.copy()))
        _bp.step_messages(offsets, parts, new, sigma, log_a)  # steps 3-4
        parts = new
        history.append(float(scorer.full(connected()[None])[0]))

    return connected(), history


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


def _in_plane_candidates(
    scorer: _Scorer,
    pool: np.ndarray,
    init: np.ndarray,
    ref: np.ndarray,
    d0: np.ndarray,
    orient_src: list[np.ndarray],
    camera: Camera,
    s: CandidateSettings,
    flags: list[str],
) -> FrameCandidates:
    """Candidates of the ``"in_plane"`` estimator (see :class:`CandidateSettings`).

    The search always starts from the unturned reference (the last initial posture): starting
    from the previous frame's estimate (6.7) let errors compound frame to frame (P2 with the
    true C: selected E_3B 18 deg).
    """
    start = init[-1]
    est, _ = _refine(
        scorer, start, camera, s, start, in_plane=True, mu=s.in_plane_prior,
        step0_deg=s.in_plane_step0_deg, sweeps=s.in_plane_sweeps, move_root=s.in_plane_move_root,
    )  # fmt: skip
    cands = generate_candidates(est, [start, *orient_src], camera, s)
    d_s = scorer.full(cands)
    prior = s.prior_weight * d_B(cands, ref)
    return FrameCandidates(cands, d_s, tuple(flags), np.asarray([float(d0[0])]), prior)


def frame_rngs(seed: int, frames: Sequence[int]) -> list[np.random.Generator]:
    """One random stream per video frame, from the seed and the frame's number.

    What every caller of :func:`estimate_candidates_chunk` passes, so a frame gets the same
    candidates from ``coach analyze``, ``coach candidates`` and any worker's chunk.
    """
    return [np.random.default_rng([int(seed), int(t)]) for t in frames]


def estimate_candidates_chunk(
    target_silhouettes: np.ndarray,
    target_edges: np.ndarray,
    camera: Camera,
    shape: BodyShape,
    initial_joints: np.ndarray,
    *,
    settings: CandidateSettings | None = None,
    rng: np.random.Generator | Sequence[np.random.Generator],
    prev: FrameCandidates | None = None,
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
    on_progress: Callable[[str, float], None] | None = None,
) -> list[FrameCandidates]:
    """Candidates of consecutive frames, each using the previous one's (thesis 4.6, 6.7).

    Parameters
    ----------
    target_silhouettes, target_edges : ndarray of bool, shape (N, H, W)
    camera : Camera
    shape : BodyShape
    initial_joints : ndarray, shape (N, 17, 3) or (N, M, 17, 3)
    settings, prev
        As :func:`estimate_candidates`; ``prev`` is the frame before the chunk.
    rng : numpy.random.Generator, or a sequence of N of them
        One stream for the chunk, or one per frame (then, with ``settings.n_prev`` 0, each
        frame's candidates are independent of the chunk it is computed in).
    keypoints : (ndarray (N, R, 17, 2), ndarray (N, R, 17)), optional
        Each frame's keypoint readings and confidences.
    on_progress : callable (stage, fraction), optional

    Returns
    -------
    list of FrameCandidates, length N
    """
    sils = np.asarray(target_silhouettes)
    edges = np.asarray(target_edges)
    init = np.asarray(initial_joints, float)
    if sils.ndim != 3:
        raise InvalidInput(f"target_silhouettes must have shape (N, H, W), got {sils.shape}")
    if init.shape[0] != sils.shape[0]:
        raise InvalidInput(
            f"initial_joints must have one entry per frame ({sils.shape[0]}), got {init.shape[0]}"
        )
    rngs = [rng] * sils.shape[0] if isinstance(rng, np.random.Generator) else list(rng)
    if len(rngs) != sils.shape[0]:
        raise InvalidInput(f"rng must be one generator or one per frame ({sils.shape[0]})")
    out = []
    for t in range(sils.shape[0]):
        kp_t = None if keypoints is None else (keypoints[0][t], keypoints[1][t])
        prev = estimate_candidates(
            sils[t], edges[t], camera, shape, init[t], settings=settings, rng=rngs[t], prev=prev,
            keypoints=kp_t,
        )
        out.append(prev)
        if on_progress is not None:
            on_progress("candidates", (t + 1) / sils.shape[0])
    return out
