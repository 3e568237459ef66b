"""The tuning of stage 3 (thesis 4.6, 5.2.2): one frozen settings object and its presets."""

from __future__ import annotations

from dataclasses import dataclass

from engine.errors import InvalidInput


@dataclass(frozen=True)
class CandidateSettings:
    """Tuning of stage 3 (thesis 4.6, 5.2.2).

    Every field, with its default, its thesis section (or "beyond the thesis") and what it
    does, is in the table of ``engine/stages/candidates/README.md``; why each default is what
    it is, and the benchmark figures behind it, in ``benchmarks/README.md`` ("Stage 3 design
    figures").

    The defaults are for videos of people: they keep priors towards the reference, because
    there the mismatch between the capsule body and a clothed person, not the search, limits
    stage 3. :meth:`thesis` gives the thesis' own values; :meth:`exact_body` is the benchmark
    preset for images the capsule body matches exactly (experiment 5.2).
    """

    # nonparametric BP (4.6.4)
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
    # image likelihood (4.4.1, 4.6.2)
    beta: float = 300.0
    lambda_a: float = 1.0
    lambda_e: float = 0.0
    edge_sigma_px: float = 5.0
    edge_xi: float = 1.0
    # refinement (6.4)
    refine_sweeps: int = 14
    refine_step0_deg: float = 16.0
    refine_min_step_deg: float = 0.2
    # candidates (4.6.5), occlusion (6.5), previous frame (6.7)
    n_candidates: int = 25
    min_flip_deg: float = 5.0
    occluded_visible_fraction: float = 0.05
    occluded_tolerance: float = float("inf")
    n_prev: int = 0
    far_margin: float = 0.05
    # priors and keypoints (beyond the thesis)
    prior_weight: float = 0.5
    keypoint_weight: float = 0.5
    keypoint_tau: float = 0.1
    bp_prior_weight: float = 0.0
    # estimator (beyond the thesis: in-plane and hybrid)
    estimator: str = "hybrid"
    in_plane_prior: float = 1.0
    in_plane_step0_deg: float = 8.0
    in_plane_sweeps: int = 10
    in_plane_move_root: bool = False
    # escape, restarts, alternatives, sub-pixel d_A (beyond the thesis; off by default)
    escape_dirs: int = 0
    refine_alone: bool = False
    subpixel_rows: int = 0
    restarts: int = 0
    restart_ds: float = 0.02
    restart_deg: float = 10.0
    refine_per_part: bool = False
    escape_prefilter: int = 0
    alternatives: int = 0
    alternative_min_deg: float = 3.0
    alternative_share: float = 0.4
    # key frames (beyond the thesis, issue 25): the full search on key frames only
    key_gap: int = 1
    key_motion_deg: float = 4.0
    between_step0_deg: float = 4.0

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
        """Raise :class:`~engine.errors.InvalidInput` naming the first out-of-range field."""
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
        if self.key_gap < 1:
            raise InvalidInput(f"settings.key_gap must be >= 1, got {self.key_gap}")
        if not (self.key_motion_deg > 0.0 and self.between_step0_deg > 0.0):  # refuses NaN
            raise InvalidInput(
                f"settings.key_motion_deg and between_step0_deg must be > 0, got "
                f"{self.key_motion_deg}, {self.between_step0_deg}"
            )
        if self.n_candidates < 1:
            raise InvalidInput(f"settings.n_candidates must be >= 1, got {self.n_candidates}")
        for name in (
            "escape_dirs",
            "escape_prefilter",
            "subpixel_rows",
            "restarts",
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
