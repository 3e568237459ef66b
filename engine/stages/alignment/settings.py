"""The tuning of stage 2 (thesis 4.5, experiments 5.1) and its output."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.measures import LAMBDA_A, LAMBDA_E


@dataclass(frozen=True)
class AlignmentSettings:
    """Settings of stage 2 (thesis 4.5, experiments 5.1).

    The benchmark figures behind the defaults beyond the thesis are in
    ``benchmarks/README.md`` ("Design figures", stage 2).

    Attributes
    ----------
    k : float
        Window factor: the path advances at most w = ceil(k L / L') reference frames per
        video frame. Thesis 5.1.3: optimal from k = 7-10.
    band_fraction : float
        beta / L, half-width of the band around the diagonal. Thesis 5.1.4: optimal from
        16-20 %; 0.25 leaves room for uneven pacing.
    yaw_deg : tuple of float
        Sampled rotations about the vertical (wide).
    tilt_deg : tuple of float
        Sampled small pitch and roll angles (each used alone, with yaw 0). With the default
        yaws this gives the thesis' 10 samples.
    lambda_A, lambda_E : float
        Weights of d_S (eq. 4.4).
    compare_height : int
        Image height used for the comparisons (thesis: 240), at most the image's. The full
        height lowered the mean C error over the cases of ``benchmarks/cases.py`` against
        half of it, most on the synthetic cases.
    skin_edges : bool
        Whether skin contours (stage 0, thesis 4.1.2) join the silhouette's as input edges.
        Off: with ``realign`` the mean C error was lower without them.
    realign : bool
        Run stage 2 a second time with the camera polished on its first correspondence
        (``CalibrationSettings.refine_frames``) and the performer's fitted body: one more
        round of the alternation camera <- C <- camera (beyond the thesis). It lowers the
        mean C error, most on the public cases, and costs one more pass of this stage.
    coarse_stride : int
        Reference-frame stride of the coarse pass (1 disables coarse-to-fine).
    refine_radius : int
        Reference frames either side of the coarse path evaluated in the fine pass.
    fine_samples : int
        Rotation samples re-scored with d_S in the fine pass (the best ones by d_A at the
        nearest coarse entry); 0 re-scores all of them.
    float_start, float_end : int
        How far C(0) may move after the calibration frame and C(L') before L (thesis 6.3).
    slope_weight : float
        mu of the step cost mu * log((i + 1/2) / (r + 1/2))^2 for a step of i reference
        frames when the mean is r = L / L' (beyond the thesis; 0 = the thesis' DP). In units
        of d; the default measured best on the public cases, and its neighbours do almost
        as well.
    one_to_one : bool
        Thesis: C strictly increasing. False (the default) allows a reference frame to
        repeat at the price of the step cost; when True and the corridor admits no strictly
        increasing path, the DP falls back to repeats and says so in ``relaxed``.
    keypoint_weight, keypoint_tau : float
        With 2D keypoints (:mod:`engine.stages.perception`), d(t', t) = min_s d_S +
        ``keypoint_weight`` d_K (:func:`engine.measures.d_K`, saturating at ``keypoint_tau``
        of the body's height in the image; swap-invariant, confidence-weighted). Beyond the
        thesis: a silhouette hardly tells the frames of a slow passage apart, and a posture
        deviation fits an earlier or later reference frame, while the limbs' keypoints move.
    keypoint_offsets : bool
        Remove the pose model's offsets measured on the first frames
        (:func:`engine.stages.perception.keypoint_offsets`) from the keypoints here and in the
        camera's polish too, not only in stage 3. Off: on the public cases the mean timing
        error grew with them, most on P4.
    repetitions : bool
        When the keypoints show several whole performances of the reference (a set of
        squats), align only the first of them, with the rest the reference holds before and
        after it, and list them all in the result
        (:func:`engine.stages.repetitions.performances`). Beyond the thesis, whose stage 2
        stretches one performance over the whole video. Needs the pose model; the user may
        still pick frames himself (``coach analyze --frames``), which turns this off.
    threads : int
        Threads sharing the video frames of the cost matrix (0: every core this process may
        use; :mod:`engine.threads`). The result does not depend on it.
    """

    k: float = 10.0
    band_fraction: float = 0.25
    yaw_deg: tuple[float, ...] = (-45.0, -30.0, -15.0, 0.0, 15.0, 30.0, 45.0)
    tilt_deg: tuple[float, ...] = (-10.0, 10.0)
    lambda_A: float = LAMBDA_A
    lambda_E: float = LAMBDA_E
    compare_height: int = 240
    coarse_stride: int = 2
    refine_radius: int = 12
    fine_samples: int = 2
    float_start: int = 0
    float_end: int = 0
    slope_weight: float = 0.2
    one_to_one: bool = False
    skin_edges: bool = False
    realign: bool = True
    keypoint_weight: float = 1.0
    keypoint_tau: float = 0.1
    keypoint_offsets: bool = False
    repetitions: bool = True
    threads: int = 0


@dataclass(frozen=True)
class AlignmentResult:
    """Approximate temporal correspondence (thesis 4.5).

    Attributes
    ----------
    C : ndarray of int, shape (T',)
        Reference frame of each video frame.
    rotations : ndarray, shape (T', 3, 3)
        Global rotation T_t' (about the hip joint, world frame) of the best sample.
    cost : ndarray, shape (T', T)
        d(t', t); ``inf`` where it was not evaluated.
    sample : ndarray of int, shape (T', T)
        Index of the best rotation sample per entry (-1 where not evaluated).
    samples : ndarray, shape (S, 3, 3)
        The rotation samples.
    E_C : float
        Mean cost along the path (eq. 4.10).
    timing_s : dict
    relaxed : bool
        True when C repeats a reference frame somewhere (not one-to-one: allowed by
        ``one_to_one=False``, or forced because no strictly increasing path fitted).
    """

    C: np.ndarray
    rotations: np.ndarray
    cost: np.ndarray
    sample: np.ndarray
    samples: np.ndarray
    E_C: float
    timing_s: dict
    relaxed: bool = False
