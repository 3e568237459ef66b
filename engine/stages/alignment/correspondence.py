"""Stage 2 in one call: the problem set up once, d evaluated coarse to fine inside the band,
and the DP's path C with the rotation T_t' of each of its entries (thesis 4.5).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.render import capsules
from engine.render.camera import Camera
from engine.stages.alignment.costs import (
    _nearest_known,
    cost_entries,
    half_camera,
    make_targets,
    rotate_about_hip,
    rotation_samples,
)
from engine.stages.alignment.dp import _dp_relaxing, band_mask, step_costs, window_size
from engine.stages.alignment.settings import AlignmentResult, AlignmentSettings

ProgressFn = Callable[[str, float], None]

#: The default settings, one frozen instance (the argument default of :func:`align`).
_DEFAULTS = AlignmentSettings()


def align(
    reference_joints: np.ndarray,
    shape: BodyShape,
    camera: Camera,
    silhouettes: np.ndarray,
    skin: np.ndarray | None = None,
    settings: AlignmentSettings = _DEFAULTS,
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
