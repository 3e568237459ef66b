"""The correspondence matrix of stage 2 (thesis 4.5.1, eq. 4.8-4.9): the reference under
sampled global rotations, compared with the input regions at the comparison resolution.
"""

from __future__ import annotations

from collections.abc import Callable

import cv2
import numpy as np

from engine.body.kinematics import rotation_about_axis
from engine.body.shapes import BodyShape
from engine.measures import d_K
from engine.render import capsules
from engine.render.camera import Camera
from engine.stages.alignment.settings import AlignmentSettings
from engine.stages.foreground import contour
from engine.threads import map_in_threads


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

    def row(tv: int) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """Video frame tv's evaluated columns, their costs and best samples (K, n)."""
        ts = np.flatnonzero(entries[tv])
        if ts.size == 0:
            return None
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
        return ts, d[order[0], cols], si[order, cols[None, :]]

    # video frames are independent: threads share them (the kernels release the GIL)
    for tv, out in enumerate(map_in_threads(row, range(n_v), settings.threads)):
        if out is not None:
            ts, d_best, s_best = out
            cost[tv, ts], best[tv, ts] = d_best, s_best.T
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
