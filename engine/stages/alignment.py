"""Stage 2: approximate temporal correspondence C and global rotations T_t' (thesis 4.5).

d(t', t) = min over sampled global rotations T of d_S(P(T(B_t)), S'_t') (eq. 4.8-4.9), then the
least-cost one-to-one monotone path through the correspondence matrix by the DP of eq. 4.11:

    D(t', t) = d(t', t) + min_{i = 1..w} D(t' - 1, t - i),       w = ceil(k L / L')

restricted to a band of half-width beta around the straight diagonal, with C(0) = C_0 (the
reference frame the first video frame shows) and C(L') = L. Thesis 6.3 suggests letting the
ends float: ``float_start`` / ``float_end`` let C(0) lie in [C_0, C_0 + f_s] and C(L') in
[L - f_e, L].

Beyond the thesis, a step cost (``slope_weight``) pulls the path's local slope towards the
mean slope L / L': without it the DP happily follows the valleys of d that long still or
repetitive stretches of a motion leave (measured on the public take-vs-take case: 7 video
frames mean error without, under 2 with). With the step cost, a repeated reference frame
(a performer slower than the reference's frame rate for a moment) is allowed but expensive,
so one-to-one is the soft default rather than a hard rule (``one_to_one`` makes it hard).

Speed (beyond the thesis): images are compared at half resolution (160 x 120), d is
evaluated only inside the band, and coarse-to-fine over reference frames: the coarse pass
evaluates the cheap d_A (eq. 4.1) for every rotation sample on every ``coarse_stride``-th
reference frame and runs the same DP (same step rules and step cost, in coarse units); the
fine pass evaluates d_S on every reference frame within ``refine_radius`` of the coarse
path, only for the ``fine_samples`` rotations that were best at the nearest coarse entries,
and the final DP runs on that corridor.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np

from engine.body.kinematics import rotation_about_axis
from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.measures import LAMBDA_A, LAMBDA_E, d_K
from engine.render import capsules
from engine.render.camera import Camera
from engine.stages.foreground import contour

ProgressFn = Callable[[str, float], None]


@dataclass(frozen=True)
class AlignmentSettings:
    """Settings of stage 2 (thesis 4.5, experiments 5.1).

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
        Image height used for the comparisons (thesis: 240), at most the image's. Mean C
        error over the seven cases of ``benchmarks/cases.py`` (video frames, stage 2 as the
        pipeline runs it): 120 -> 240 0.83 -> 0.73 (synthetic cases 0.34 -> 0.19, 0.47 ->
        0.18, 1.50 -> 0.97; P1 1.25 -> 1.33, P2 1.73 -> 1.78).
    skin_edges : bool
        Whether skin contours (stage 0, thesis 4.1.2) join the silhouette's as input edges.
        Off: with ``realign``, mean C error 0.74 -> 0.68 (P1 1.01 -> 1.02, P2 1.97 -> 1.67).
    realign : bool
        Run stage 2 a second time with the camera polished on its first correspondence
        (``CalibrationSettings.refine_frames``) and the performer's fitted body: one more
        round of the alternation camera <- C <- camera (beyond the thesis). Mean C error
        0.73 -> 0.68, P1 1.31 -> 1.02, P2 1.86 -> 1.67 (without skin edges); it costs one
        more pass of this stage.
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
        of d; 0.2 measured best on the public cases (0.1-0.4 all within 0.4 video frames).
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
        camera's polish too, not only in stage 3. Off: on the six public cases the mean
        timing error went 1.71 -> 1.94 video frames with them (P4 4.24 -> 5.70), the other
        cases moving by under 0.3 either way.
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


# ----------------------------------------------------------------------------- the DP


def window_size(k: float, n_ref: int, n_video: int) -> int:
    """w = ceil(k L / L') (thesis 4.5.2), at least 1; L, L' are frame counts minus one."""
    L, Lv = max(n_ref - 1, 1), max(n_video - 1, 1)
    return max(1, int(np.ceil(k * L / Lv - 1e-9)))


def band_mask(
    n_video: int, n_ref: int, beta: float, *, start: int = 0, end: int | None = None
) -> np.ndarray:
    """Entries within ``beta`` reference frames of the straight diagonal (thesis fig. 4.4).

    Returns
    -------
    ndarray of bool, shape (T', T)
    """
    end = n_ref - 1 if end is None else end
    tv = np.arange(n_video)[:, None]
    diag = start + (end - start) * tv / max(n_video - 1, 1)
    return np.abs(np.arange(n_ref)[None, :] - diag) <= beta


def step_costs(window: int, mean_step: float, weight: float) -> np.ndarray:
    """Cost of a step of i = 0..window reference frames: weight * log((i + 1/2) / (r + 1/2))^2.

    Beyond the thesis: a prior on the local slope of C around the mean slope r = L / L'. The
    log makes halving and doubling the pace cost about the same; the 1/2 keeps i = 0 finite.

    Returns
    -------
    ndarray, shape (window + 1,)
    """
    i = np.arange(window + 1, dtype=float)
    return weight * np.log((i + 0.5) / (max(mean_step, 0.0) + 0.5)) ** 2


def dp_path(
    cost: np.ndarray,
    *,
    window: int,
    start: int = 0,
    end: int | None = None,
    float_start: int = 0,
    float_end: int = 0,
    min_step: int = 1,
    step_cost: np.ndarray | None = None,
) -> tuple[np.ndarray, float]:
    """Least-cost monotone path (thesis 4.5.2, eq. 4.11), optionally with a step cost.

        D(t', t) = d(t', t) + min_{i = min_step..w} [D(t' - 1, t - i) + g(i)]

    Parameters
    ----------
    cost : ndarray, shape (T', T)
        d(t', t); ``inf`` marks forbidden entries (outside the band).
    window : int
        w: C(t') - C(t' - 1) in min_step..w.
    start : int
        C(0) (or the earliest C(0) with ``float_start``).
    end : int, optional
        C(L'); the last reference frame by default (or the latest C(L') with ``float_end``).
    float_start, float_end : int
        C(0) in [start, start + float_start], C(L') in [end - float_end, end] (thesis 6.3).
    min_step : int
        1 (thesis: one-to-one) or 0 (a reference frame may repeat).
    step_cost : ndarray, shape (window + 1,), optional
        g(i), added per step of i frames (see :func:`step_costs`); zero by default.

    Returns
    -------
    C : ndarray of int, shape (T',)
    total : float
        Sum of the costs along the path, step costs included.

    Raises
    ------
    InvalidInput
        Bad shapes or parameters, or no path satisfies the constraints (e.g. more video
        frames than reference frames between the pinned ends).
    """
    d = np.asarray(cost, dtype=float)
    if d.ndim != 2 or d.shape[0] < 1 or d.shape[1] < 1:
        raise InvalidInput(f"cost must be a (T', T) matrix, got shape {d.shape}")
    n_v, n_r = d.shape
    end = n_r - 1 if end is None else int(end)
    if not isinstance(window, int | np.integer) or window < 1:
        raise InvalidInput(f"window must be an integer >= 1, got {window!r}")
    if not (0 <= start <= end < n_r):
        raise InvalidInput(
            f"start and end must satisfy 0 <= start <= end < {n_r}, got {start}, {end}"
        )
    if min_step not in (0, 1):
        raise InvalidInput(f"min_step must be 0 or 1, got {min_step!r}")
    if float_start < 0 or float_end < 0:
        raise InvalidInput(
            f"float_start and float_end must be >= 0, got {float_start}, {float_end}"
        )
    if step_cost is None:
        g = np.zeros(window + 1)
    else:
        g = np.asarray(step_cost, dtype=float)
        if g.shape != (window + 1,) or not np.all(np.isfinite(g)):
            raise InvalidInput(
                f"step_cost must be finite with shape ({window + 1},), got shape {g.shape}"
            )
    D = np.full((n_v, n_r), np.inf)
    step = np.zeros((n_v, n_r), dtype=np.int32)
    s_hi = min(start + float_start, n_r - 1)
    D[0, start : s_hi + 1] = d[0, start : s_hi + 1]
    best = np.empty(n_r)
    cand = np.empty(n_r)
    for tv in range(1, n_v):
        best.fill(np.inf)
        arg = step[tv]
        prev = D[tv - 1]
        for i in range(min_step, window + 1):
            if i >= n_r:
                break
            cand[:i] = np.inf
            np.add(prev[: n_r - i], g[i], out=cand[i:])
            better = cand < best
            best[better] = cand[better]
            arg[better] = i
        D[tv] = d[tv] + best
    e_lo = max(end - float_end, 0)
    last = D[-1, e_lo : end + 1]
    if not np.isfinite(last).any():
        raise InvalidInput(
            f"no monotone path of {n_v} video frames fits between reference frames {start} and "
            f"{end} with window {window} inside the band"
        )
    C = np.empty(n_v, dtype=int)
    C[-1] = e_lo + int(np.argmin(last))
    for tv in range(n_v - 1, 0, -1):
        C[tv - 1] = C[tv] - step[tv, C[tv]]
    return C, float(D[-1, C[-1]])


# ----------------------------------------------------------------------------- costs


def rotation_samples(yaw_deg: tuple[float, ...], tilt_deg: tuple[float, ...]) -> np.ndarray:
    """Sampled global rotations (thesis 4.5.1 step 1): yaws, then pitches and rolls alone.

    Returns
    -------
    ndarray, shape (S, 3, 3)
    """
    y = np.radians(np.asarray(yaw_deg, dtype=float))
    t = np.radians(np.asarray(tilt_deg, dtype=float))
    axes = [np.array([0.0, 1.0, 0.0])] * len(y)
    axes += [np.array([1.0, 0.0, 0.0])] * len(t) + [np.array([0.0, 0.0, 1.0])] * len(t)
    angles = np.concatenate([y, t, t])
    if not len(angles):
        return np.eye(3)[None]
    return rotation_about_axis(np.stack(axes), angles)


def rotate_about_hip(joints: np.ndarray, R: np.ndarray) -> np.ndarray:
    """T(B): rotate postures about their hip joint.

    Parameters
    ----------
    joints : ndarray, shape (T, 17, 3)
    R : ndarray, shape (S, 3, 3)

    Returns
    -------
    ndarray, shape (S, T, 17, 3)
    """
    hip = joints[:, :1, :]
    return hip[None] + np.einsum("sij,tkj->stki", R, joints - hip)


def half_camera(camera: Camera, height: int) -> Camera:
    """The camera for images resized to ``height`` rows (pixel centres at integers)."""
    f = height / camera.height
    return Camera(
        scale=camera.scale * f, theta_z=camera.theta_z,
        cx=(camera.cx + 0.5) * f - 0.5, cy=(camera.cy + 0.5) * f - 0.5,
        azimuth=camera.azimuth, width=int(round(camera.width * f)), height=int(height),
        distance=camera.distance,
    )  # fmt: skip


def make_targets(
    silhouettes: np.ndarray, skin: np.ndarray | None, height: int
) -> list[capsules.Target]:
    """Input regions at the comparison resolution, edges = silhouette and skin contours.

    Parameters
    ----------
    silhouettes : ndarray of bool, shape (T', H, W)
    skin : ndarray of bool, shape (T', H, W), optional
    height : int
    """
    n, h, w = silhouettes.shape
    width = int(round(w * height / h))
    out = []
    for i in range(n):
        sil = cv2.resize(silhouettes[i].astype(np.float32), (width, height),
                         interpolation=cv2.INTER_AREA) >= 0.5  # fmt: skip
        edges = contour(sil)
        if skin is not None and skin[i].any():
            sk = cv2.resize(skin[i].astype(np.float32), (width, height),
                            interpolation=cv2.INTER_AREA) >= 0.5  # fmt: skip
            edges |= contour(sk)
        out.append(capsules.Target.from_masks(sil, edges))
    return out


def cost_entries(
    posed: np.ndarray,
    targets: list[capsules.Target],
    shape: BodyShape,
    camera: Camera,
    entries: np.ndarray,
    settings: AlignmentSettings,
    *,
    measure: str = "S",
    samples: np.ndarray | None = None,
    keep: int = 0,
    keypoints: tuple[np.ndarray, np.ndarray, float] | None = None,
    on_progress: Callable[[float], None] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """d(t', t) = min_s d(P(T_s(B_t)), S'_t') for a set of (t', t) (thesis eq. 4.8-4.9).

    Parameters
    ----------
    posed : ndarray, shape (S, T, 17, 3)
        Reference postures under each rotation sample.
    targets : list of Target, length T'
    entries : ndarray of bool, shape (T', T)
        Which entries to evaluate.
    measure : {"S", "A"}
        d_S (eq. 4.4) or the cheaper silhouette-only d_A (eq. 4.1).
    samples : ndarray of int, shape (T', T, K), optional
        The rotation samples to try per entry (all S by default).
    keep : int
        When > 0, ``best`` holds the ``keep`` best samples per entry, best first.
    keypoints : (ndarray (T', R, 17, 2), ndarray (T', R, 17), float), optional
        The readings of the keypoints in ``camera``'s pixels
        (:func:`engine.stages.perception.readings`), their confidences, and d_K's saturation
        distance in pixels: ``settings.keypoint_weight`` d_K joins the measure.

    Returns
    -------
    cost : ndarray, shape (T', T)
        ``inf`` where not evaluated.
    best : ndarray of int, shape (T', T) or (T', T, keep)
        Best sample index, -1 where not evaluated.
    """
    n_s = posed.shape[0]
    n_v, n_r = entries.shape
    cost = np.full((n_v, n_r), np.inf)
    best = np.full((n_v, n_r, max(keep, 1)), -1, dtype=int)
    for tv in range(n_v):
        ts = np.flatnonzero(entries[tv])
        if ts.size == 0:
            continue
        si = np.broadcast_to(np.arange(n_s)[:, None], (n_s, ts.size)) if samples is None \
            else samples[tv, ts].T  # fmt: skip
        j = posed[si, ts[None, :]].reshape(-1, 17, 3)
        if measure == "A":
            d = capsules.d_A_batch(j, targets[tv], shape, camera)
        else:
            d = capsules.d_S_batch(j, targets[tv], shape, camera, lambda_A=settings.lambda_A,
                                   lambda_E=settings.lambda_E)  # fmt: skip
        if keypoints is not None and settings.keypoint_weight > 0:
            kp, conf, tau_px = keypoints
            d = d + settings.keypoint_weight * d_K(
                camera.project(j), kp[tv], conf[tv], tau_px=tau_px
            )
        d = d.reshape(si.shape)
        order = np.argsort(d, axis=0, kind="stable")[: max(keep, 1)]
        cols = np.arange(ts.size)
        best[tv, ts] = si[order, cols[None, :]].T
        cost[tv, ts] = d[order[0], cols]
        if on_progress is not None:
            on_progress((tv + 1) / n_v)
    return cost, (best if keep > 0 else best[..., 0])


def _nearest_known(known: np.ndarray, want: np.ndarray) -> np.ndarray:
    """For each row, the column of the nearest ``known`` entry to every column (-1: none).

    known : bool (T', T); returns int (T', T).
    """
    n_v, n_r = known.shape
    out = np.full((n_v, n_r), -1, dtype=int)
    for tv in range(n_v):
        k = np.flatnonzero(known[tv])
        ts = np.flatnonzero(want[tv])
        if k.size == 0 or ts.size == 0:
            continue
        pos = np.clip(np.searchsorted(k, ts), 1, max(k.size - 1, 1))
        lo, hi = k[pos - 1], k[np.minimum(pos, k.size - 1)]
        out[tv, ts] = np.where(np.abs(ts - lo) <= np.abs(hi - ts), lo, hi)
    return out


def _dp_relaxing(cost: np.ndarray, *, min_step: int, **kw) -> tuple[np.ndarray, float, bool]:
    """:func:`dp_path`, retried with repeats allowed when no strictly increasing path fits."""
    try:
        C, total = dp_path(cost, min_step=min_step, **kw)
        return C, total, False
    except InvalidInput:
        if min_step == 0:
            raise
        C, total = dp_path(cost, min_step=0, **kw)
        return C, total, True


def align(
    reference_joints: np.ndarray,
    shape: BodyShape,
    camera: Camera,
    silhouettes: np.ndarray,
    skin: np.ndarray | None = None,
    settings: AlignmentSettings = AlignmentSettings(),
    *,
    start: int = 0,
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
    on_progress: ProgressFn | None = None,
) -> AlignmentResult:
    """Approximate temporal correspondence and global rotations (thesis 4.5).

    Parameters
    ----------
    reference_joints : ndarray, shape (T, 17, 3)
        Reference motion B_t, world frame.
    shape : BodyShape
    camera : Camera
        Calibrated camera for the silhouettes' image size (stage 1).
    silhouettes : ndarray of bool, shape (T', H, W)
        Input body regions (stage 0).
    skin : ndarray of bool, shape (T', H, W), optional
        Skin regions (their contours join the input edges with ``settings.skin_edges``).
    settings : AlignmentSettings
    start : int
        C(0): the reference frame the first video frame shows.
    keypoints : (ndarray (T', R, 17, 2), ndarray (T', R, 17)), optional
        Readings of the 2D keypoints (the silhouettes' pixels) and their confidences
        (:func:`engine.stages.perception.readings`); see ``settings.keypoint_weight``.
    on_progress : callable(stage, fraction), optional
        Called with ``"alignment"``.

    Returns
    -------
    AlignmentResult

    Raises
    ------
    InvalidInput
        Bad shapes or settings, or no path fits (see :func:`dp_path`).
    """
    ref, sil = _check_align_inputs(reference_joints, silhouettes, camera, start, settings)
    report = on_progress or (lambda stage, f: None)
    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    pb = _set_up(ref, shape, camera, sil, skin, settings, start, keypoints)
    timing["prepare"] = time.perf_counter() - t0
    if settings.coarse_stride > 1:
        cost, best = _coarse_to_fine(pb, settings, report, timing)
    else:
        t0 = time.perf_counter()
        cost, best = cost_entries(pb.posed, pb.targets, shape, pb.cam, pb.band, settings,
                                  keypoints=pb.kp,
                                  on_progress=lambda f: report("alignment", f))  # fmt: skip
        timing["fine"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    C, _, _ = _dp_relaxing(
        cost, window=pb.window, start=start, float_start=settings.float_start,
        float_end=settings.float_end, min_step=1 if settings.one_to_one else 0,
        step_cost=step_costs(pb.window, pb.mean_step, settings.slope_weight),
    )  # fmt: skip
    relaxed = bool(np.any(np.diff(C) == 0))
    timing["dp"] = time.perf_counter() - t0
    frames = np.arange(sil.shape[0])
    rot = pb.R[best[frames, C]]
    report("alignment", 1.0)
    E_C = float(cost[frames, C].mean())  # eq. 4.10, without the step costs
    return AlignmentResult(C, rot, cost, best, pb.R, E_C, timing, relaxed)


def _check_align_inputs(
    reference_joints: np.ndarray,
    silhouettes: np.ndarray,
    camera: Camera,
    start: int,
    settings: AlignmentSettings,
) -> tuple[np.ndarray, np.ndarray]:
    """The reference (T, 17, 3) as floats and the silhouettes (T', H, W) as bool, or
    InvalidInput naming the parameter."""
    ref = np.asarray(reference_joints, dtype=float)
    if ref.ndim != 3 or ref.shape[1:] != (17, 3) or ref.shape[0] < 2:
        raise InvalidInput(f"reference_joints must be (T >= 2, 17, 3), got {ref.shape}")
    sil = np.asarray(silhouettes, dtype=bool)
    if sil.ndim != 3 or sil.shape[1:] != (camera.height, camera.width):
        raise InvalidInput(
            f"silhouettes must be (T', {camera.height}, {camera.width}) like the camera's "
            f"image, got {sil.shape}"
        )
    if not 0 <= start < ref.shape[0]:
        raise InvalidInput(f"start must be a reference frame 0..{ref.shape[0] - 1}, got {start}")
    if settings.k <= 0 or settings.band_fraction <= 0 or settings.coarse_stride < 1:
        raise InvalidInput("settings.k, band_fraction and coarse_stride must be positive")
    if settings.slope_weight < 0 or settings.fine_samples < 0 or settings.refine_radius < 0:
        raise InvalidInput("settings.slope_weight, fine_samples and refine_radius must be >= 0")
    return ref, sil


@dataclass(frozen=True)
class _Problem:
    """Stage 2 set up once: the posed reference, the targets and the DP's corridor.

    Attributes
    ----------
    R : ndarray, shape (S, 3, 3)
        Sampled global rotations T_s (thesis 4.5.1 step 1).
    posed : ndarray, shape (S, T, 17, 3)
        The reference under each of them, T_s(B_t).
    targets : list of capsules.Target, length T'
        The input regions at the comparison resolution.
    shape : BodyShape
    cam : Camera
        The camera for the comparison resolution.
    kp : (ndarray (T', R, 17, 2), ndarray (T', R, 17), float) or None
        Keypoint readings in ``cam``'s pixels, confidences, d_K's saturation in pixels.
    band : ndarray of bool, shape (T', T)
        The band of half-width beta around the diagonal (thesis 4.5.2).
    window : int
        w = ceil(k L / L').
    mean_step : float
        L / L', reference frames per video frame along the diagonal.
    start : int
        C(0).
    """

    R: np.ndarray
    posed: np.ndarray
    targets: list[capsules.Target]
    shape: BodyShape
    cam: Camera
    kp: tuple[np.ndarray, np.ndarray, float] | None
    band: np.ndarray
    window: int
    mean_step: float
    start: int


def _set_up(
    ref: np.ndarray,
    shape: BodyShape,
    camera: Camera,
    sil: np.ndarray,
    skin: np.ndarray | None,
    settings: AlignmentSettings,
    start: int,
    keypoints: tuple[np.ndarray, np.ndarray] | None,
) -> _Problem:
    """Targets and camera at the comparison height, the rotated reference (T, 17, 3) and
    the band and window of the DP (thesis 4.5.1-4.5.2)."""
    n_v, n_r = sil.shape[0], ref.shape[0]
    height = min(settings.compare_height, camera.height)
    cam = half_camera(camera, height)
    kp = None
    if keypoints is not None and settings.keypoint_weight > 0:
        f = height / camera.height
        tau_px = settings.keypoint_tau * cam.scale * max(float(np.ptp(ref[start, :, 1])), 0.3)
        kp = ((np.asarray(keypoints[0]) + 0.5) * f - 0.5, np.asarray(keypoints[1]), tau_px)
    R = rotation_samples(settings.yaw_deg, settings.tilt_deg)
    return _Problem(
        R=R, posed=rotate_about_hip(ref, R),
        targets=make_targets(sil, skin if settings.skin_edges else None, height),
        shape=shape, cam=cam, kp=kp,
        band=band_mask(n_v, n_r, settings.band_fraction * (n_r - 1 - start), start=start),
        window=window_size(settings.k, n_r - start, n_v),
        mean_step=(n_r - 1 - start) / max(n_v - 1, 1), start=start,
    )  # fmt: skip


def _coarse_corridor(
    pb: _Problem, settings: AlignmentSettings, report: ProgressFn, timing: dict[str, float]
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The coarse pass: d_A on every ``coarse_stride``-th reference frame, the DP there,
    and the corridor of ``refine_radius`` around its path.

    Returns the coarse entries (T', T) bool, their best samples (T', T, K) and the
    corridor (T', T) bool.
    """
    s = settings.coarse_stride
    n_r = pb.band.shape[1]
    t0 = time.perf_counter()
    cols = np.zeros(n_r, bool)
    cols[pb.start :: s] = True
    cols[[pb.start, n_r - 1]] = True
    coarse_entries = pb.band & cols[None, :]
    n_keep = settings.fine_samples if 0 < settings.fine_samples < len(pb.R) else len(pb.R)
    c_cost, c_best = cost_entries(
        pb.posed, pb.targets, pb.shape, pb.cam, coarse_entries, settings, measure="A",
        keep=n_keep, keypoints=pb.kp, on_progress=lambda f: report("alignment", 0.5 * f),
    )  # fmt: skip
    timing["coarse"] = time.perf_counter() - t0
    # the same DP on the coarse columns (steps counted in coarse columns)
    idx = np.flatnonzero(cols)
    cw = max(1, int(np.ceil(pb.window / s)))
    Cc = _dp_relaxing(
        c_cost[:, idx], window=cw, start=0, end=len(idx) - 1,
        float_start=int(np.ceil(settings.float_start / s)),
        float_end=int(np.ceil(settings.float_end / s)), min_step=0,
        step_cost=step_costs(cw, pb.mean_step / s, settings.slope_weight),
    )[0]  # fmt: skip
    near = np.abs(np.arange(n_r)[None, :] - idx[Cc][:, None]) <= settings.refine_radius
    return coarse_entries, c_best, pb.band & near


def _coarse_to_fine(
    pb: _Problem, settings: AlignmentSettings, report: ProgressFn, timing: dict[str, float]
) -> tuple[np.ndarray, np.ndarray]:
    """d (T', T) and the best rotation sample per entry (T', T), coarse to fine.

    The fine pass evaluates d_S only in the coarse path's corridor and only for the
    rotation samples that were best at the nearest coarse entry.
    """
    coarse_entries, c_best, fine = _coarse_corridor(pb, settings, report, timing)
    src = _nearest_known(coarse_entries, fine)
    rows = np.arange(fine.shape[0])[:, None]
    samples = c_best[rows, np.maximum(src, 0)]  # (T', T, K)
    t0 = time.perf_counter()
    cost, best = cost_entries(
        pb.posed, pb.targets, pb.shape, pb.cam, fine, settings, measure="S", samples=samples,
        keypoints=pb.kp, on_progress=lambda f: report("alignment", 0.5 + 0.5 * f),
    )  # fmt: skip
    timing["fine"] = time.perf_counter() - t0
    return cost, best
