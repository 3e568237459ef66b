"""The tuning of stage 4 (thesis 4.7, 5.5.3, 6.6-6.7): one frozen settings object."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SelectionSettings:
    """Tuning of stage 4; defaults are the thesis' values where it gives them.

    The benchmark figures behind the defaults beyond the thesis are in
    ``benchmarks/README.md`` ("Design figures", stage 4).

    Attributes
    ----------
    window_k : float
        Window factor k of the per-segment DP, w = k L_i / L'_i (thesis 5.5.3: k = 10).
    band : float
        Normalised bandwidth beta_i / L_i around the segment diagonal (thesis 5.5.3: 25 %).
    boundary_window : int
        Half-width omega of the boundary search window, video frames (thesis 4.7.1 step 2).
        Stage 2's C is already close, and a wide window lets the velocity condition latch onto
        a neighbouring direction change: narrowing it lowered the boundary error on the
        public and synthetic cases.
    smooth_threshold_deg : float
        Largest d_B between consecutive candidates of a "smooth" sequence (4.7.1 step 3).
    boundary_joints : tuple of str
        Joints whose velocity direction change marks a boundary (5.4.2: the right wrist).
    direction_change_deg : float
        Minimum direction change at a boundary: tau = cos(this) (2.1.1 item 4; 60 deg Taichi,
        120 deg golf).
    pause_speed : float
        Joint speed (metres per video frame, relative to the hip) below which the performer is
        considered still (2.1.3 item 4).
    missing_tempo : float
        A segment whose tempo is below this fraction of the median tempo, or shorter than
        ``min_segment_frames``, is reported missing (6.6).
    extra_tempo : float
        A segment whose tempo is above this multiple of the median tempo is reported as
        containing extraneous motion (6.6).
    min_segment_frames : int
        Fewest video frames a performed segment spans (end - start).
    large_error_deg : float
        Mean posture error above which the performance is "very different" (6.7).
    image_weight : float
        mu of the image-evidence term of the candidate cost, radians of d_B per unit of d_S
        (beyond the thesis): d_c'(t', t, l) = d_B(B_t, B'_t'l) + mu (d_S(B'_t'l) - min_k
        d_S(B'_t'k)). The thesis' d_c (eq. 4.25) alone picks the candidate closest to the
        reference; when the initial posture (the reference itself) is among the candidates it
        always wins and no error is ever detected. The term makes a candidate pay for
        explaining the image worse than the best one. 0 gives the thesis' cost. Used only when
        ``candidate_d_s`` is given.
    image_margin : float
        Candidates whose d_S exceeds their frame's best by more than this are not
        image-consistent and are dropped from selection (never the frame's best). The
        default keeps every candidate: on the public cases the capsule body's lowest d_S
        lies far from the truth and below the true posture's, so a tight margin drops the
        only right candidate.
    misfit_margin : float
        A frame whose selected posture explains the image worse (d_S) than the calibration
        frame's by more than this is flagged ``image_misfit``: the posture reported there is not
        confirmed by the video, and its errors may be underestimated (beyond the thesis).
        At the default the flagged frames were the worse ones on every case of
        ``benchmarks/cases.py``; a larger margin flagged good frames or hardly any. Where the
        reported error is smallest, on the demo's lifted foot, the flag is what tells the
        coach to look.
    anchor_deg_per_frame : float
        Cost (degrees of d_B) per video frame that C(t') departs from stage 2's C, and
        likewise per video frame a performer boundary departs from stage 2's (4.7.1 step 4);
        beyond the thesis. The thesis' DP (eq. 4.24) lets C wander wherever the candidates
        fit a little better; with the capsule body's noisy candidates C got worse than stage
        2's, and the anchor keeps it near. Larger values stop the DP from correcting a rough
        C with good candidates (the synthetic test with stage 2's uniform-speed C needs
        <= ~2). 0 gives the thesis' DP.
    error_smoothing_s, error_median_frames : float, int
        Each bone's error is smoothed over time within each performer segment: a running
        median of ``error_median_frames`` (odd; 1 disables it), then a Gaussian of std
        ``error_smoothing_s`` seconds (0 disables it). The thesis asks for a small rate of
        change of eps_t' within a segment (2.1.3 item 6, 2.1.6 D) through d_s in the DP
        (eq. 4.24); this also smooths the reported errors themselves. A performer's
        deviation persists for tenths of a second, while the selected candidates flicker
        between neighbouring solutions, and now and then one frame's candidate jumps alone:
        the median drops such a spike, which the Gaussian alone would spread over its
        neighbours. Only the errors are smoothed; the selected postures are the frames' own.
        A longer Gaussian blurs errors that change fast within a short segment.
    uncertainty_margin : float
        Candidates whose image evidence is within this of the frame's best explain the video
        as well; the range of each bone's error over them is its uncertainty
        (:func:`engine.pipeline.add_uncertainty`).
    poor_fit_region : float
        When the median over frames of 1 - Dice between the reported posture's body and
        stage 0's region exceeds this, the result's status is ``poor_fit``
        (:func:`engine.pipeline.assess_fit`): the region is not the performer. Beyond the
        thesis.
    poor_fit_joint, poor_fit_frames : float
        When more than ``poor_fit_frames`` of the frames have a confident keypoint farther
        than ``poor_fit_joint`` of the body's height from its reported joint, the status is
        ``poor_fit`` too: the reported motion leaves the body (several repetitions, another
        motion; :func:`engine.pipeline.assess_fit`). The default lies between the share of
        such frames on the public cases and on real clips of several repetitions.
    """

    window_k: float = 10.0
    band: float = 0.25
    boundary_window: int = 1
    smooth_threshold_deg: float = 25.0
    boundary_joints: tuple[str, ...] = ("l_wrist", "r_wrist")
    direction_change_deg: float = 60.0
    pause_speed: float = 0.004
    missing_tempo: float = 0.25
    extra_tempo: float = 3.0
    min_segment_frames: int = 2
    large_error_deg: float = 40.0
    image_weight: float = 2.0
    image_margin: float = 1.0
    anchor_deg_per_frame: float = 1.0
    misfit_margin: float = 0.03
    error_smoothing_s: float = 0.05
    error_median_frames: int = 3
    poor_fit_region: float = 0.45
    poor_fit_joint: float = 0.3
    poor_fit_frames: float = 0.2
    uncertainty_margin: float = 0.01
