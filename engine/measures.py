"""Difference measures (thesis 4.4): between postures (d_B) and between image regions (d_A, d_E).

The image measures over full images live here as the reference implementation; the
rasteriser in :mod:`engine.render.capsules` evaluates the same formulas incrementally.
"""

from __future__ import annotations

import numpy as np

from engine.body.kinematics import bone_directions


def bone_angles(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle between corresponding bones of two postures.

    Parameters
    ----------
    a, b : ndarray, shape (..., 17, 3)
        Joint positions (broadcast against each other).

    Returns
    -------
    angles : ndarray, shape (..., 16)
        Radians, in [0, pi].
    """
    cos = np.sum(bone_directions(np.asarray(a, float)) * bone_directions(np.asarray(b, float)), -1)
    return np.arccos(np.clip(cos, -1.0, 1.0))


def d_B(a: np.ndarray, b: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Posture difference: mean angle between bone directions (thesis 4.4.2, eq. 4.5).

    Global orientation is included (bones are compared in the world frame), translation is
    not (only directions enter).

    Parameters
    ----------
    a, b : ndarray, shape (..., 17, 3)
    weights : ndarray, shape (16,), optional
        Per-bone weights (domain knowledge, thesis 6.8); uniform by default.

    Returns
    -------
    d : ndarray, shape (...)
        Radians.
    """
    ang = bone_angles(a, b)
    if weights is None:
        return ang.mean(-1)
    w = np.asarray(weights, dtype=float)
    return (ang * w).sum(-1) / w.sum()


def d_A(sil: np.ndarray, target: np.ndarray) -> float:
    """Silhouette difference 1 - Dice overlap (thesis 4.4.1, eq. 4.1).

    Parameters
    ----------
    sil, target : ndarray of bool, shape (H, W)
    """
    inter = np.count_nonzero(sil & target)
    total = np.count_nonzero(sil) + np.count_nonzero(target)
    return 1.0 - 2.0 * inter / total if total else 0.0


# ---------------------------------------------------------------------------------------------
# Edge difference d_E and region difference d_S (thesis 4.4.1, eq. 4.2-4.4)
#
# Defaults: d_A lies in [0, 1]; with xi = 1 and d_E normalised by the number of rendered edge
# pixels, d_E also lies in [0, 1] (the mean of min(D^2 / sigma^2, 1)), so equal weights give
# both terms the same range. sigma = 5 px at 320x240 (a body ~200 px tall) means an edge 5 px
# or more away from any input edge costs the maximum; scale it with the image.

#: sigma of eq. 4.3, pixels.
SIGMA_PX = 5.0
#: Truncation xi of eq. 4.3 (the cost of an edge pixel with no input edge near it).
XI = 1.0
#: Weights lambda_A, lambda_E of eq. 4.4.
LAMBDA_A = 1.0
LAMBDA_E = 1.0


def edge_cost_map(edges: np.ndarray, *, sigma_px: float = SIGMA_PX, xi: float = XI) -> np.ndarray:
    """Per-pixel cost min_v d(u, v) of eq. 4.2-4.3 against the input edges E'.

    Parameters
    ----------
    edges : ndarray of bool, shape (H, W)
        Input edge pixels E'.
    sigma_px : float
        sigma of eq. 4.3, pixels.
    xi : float
        Truncation threshold xi of eq. 4.3.

    Returns
    -------
    cost : ndarray of float64, shape (H, W)
        min(D^2 / sigma^2, xi) with D the Euclidean distance to the nearest edge pixel
        (cv2.distanceTransform, exact mask); ``xi`` everywhere if there is no edge pixel.

    Raises
    ------
    InvalidInput
        ``edges`` not 2D, or ``sigma_px`` / ``xi`` not positive and finite.
    """
    import cv2

    from engine.errors import InvalidInput

    e = np.asarray(edges)
    if e.ndim != 2 or e.shape[0] < 1 or e.shape[1] < 1:
        raise InvalidInput(f"edges must be a 2D (H, W) mask, got shape {e.shape}")
    if not (np.isfinite(sigma_px) and sigma_px > 0):
        raise InvalidInput(f"sigma_px must be positive, got {sigma_px!r}")
    if not (np.isfinite(xi) and xi > 0):
        raise InvalidInput(f"xi must be positive, got {xi!r}")
    e = e.astype(bool)
    if not e.any():
        return np.full(e.shape, float(xi))
    # distanceTransform measures the distance to the nearest zero pixel
    dist = cv2.distanceTransform((~e).astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return np.minimum(dist.astype(np.float64) ** 2 / float(sigma_px) ** 2, float(xi))


def d_E(
    edges: np.ndarray, target_edges: np.ndarray, *, sigma_px: float = SIGMA_PX, xi: float = XI
) -> float:
    """Edge difference: truncated chamfer distance from E to E' (thesis eq. 4.2-4.3).

    Normalised by |E| (the sum of eq. 4.2 divided by the number of rendered edge pixels), so
    values are comparable across postures with longer or shorter outlines; ``xi`` when E is
    empty.

    Parameters
    ----------
    edges : ndarray of bool, shape (H, W)
        Edges E of the projected body region.
    target_edges : ndarray of bool, shape (H, W)
        Edges E' of the input body region.
    sigma_px, xi : float
        Parameters of eq. 4.3.

    Raises
    ------
    InvalidInput
        Masks of different shapes, or bad ``sigma_px`` / ``xi``.
    """
    from engine.errors import InvalidInput

    e = np.asarray(edges, dtype=bool)
    if e.shape != np.shape(target_edges):
        raise InvalidInput(
            f"edges {e.shape} and target_edges {np.shape(target_edges)} differ in shape"
        )
    cost = edge_cost_map(target_edges, sigma_px=sigma_px, xi=xi)
    n = np.count_nonzero(e)
    return float(cost[e].sum() / n) if n else float(xi)


def d_S(
    sil: np.ndarray,
    edges: np.ndarray,
    target_sil: np.ndarray,
    target_edges: np.ndarray,
    *,
    lambda_A: float = LAMBDA_A,
    lambda_E: float = LAMBDA_E,
    sigma_px: float = SIGMA_PX,
    xi: float = XI,
) -> float:
    """Region difference d_S = lambda_A d_A + lambda_E d_E (thesis eq. 4.4), full images.

    Reference implementation of what :func:`engine.render.capsules.d_S_batch` computes.

    Parameters
    ----------
    sil, edges : ndarray of bool, shape (H, W)
        Silhouette A and edges E of the projected body region.
    target_sil, target_edges : ndarray of bool, shape (H, W)
        A' and E' of the input body region.
    lambda_A, lambda_E : float
        Weights of eq. 4.4.
    sigma_px, xi : float
        Parameters of eq. 4.3.
    """
    from engine.errors import InvalidInput

    if np.shape(sil) != np.shape(target_sil):
        raise InvalidInput(f"sil {np.shape(sil)} and target_sil {np.shape(target_sil)} differ")
    a = d_A(np.asarray(sil, dtype=bool), np.asarray(target_sil, dtype=bool))
    e = d_E(edges, target_edges, sigma_px=sigma_px, xi=xi)
    return float(lambda_A * a + lambda_E * e)


def d_K(
    projected: np.ndarray,
    keypoints: np.ndarray,
    confidence: np.ndarray,
    *,
    tau_px: float,
) -> np.ndarray:
    """Keypoint difference: robust, confidence-weighted distance of projected joints to the
    detected 2D keypoints, under the best of several readings of the detection (beyond the
    thesis).

    Each joint's distance r counts as min(r / tau, 1): linear near the detection, bounded
    beyond ``tau_px`` so a wrong keypoint costs no more than a missing one. A detection can be
    read several ways, and the best reading counts for each posture: a pose model swaps left
    and right in many frames (66 % on P2), so the labels as given and their mirror
    (:func:`engine.stages.perception.readings`) are a hidden choice per frame and posture.
    Scoring many batches against one detection: :class:`KeypointTarget`.

    Parameters
    ----------
    projected : ndarray, shape (N, 17, 2)
        Pixel positions of the postures' joints.
    keypoints : ndarray, shape (R, 17, 2) or (17, 2)
        Each reading's keypoints; NaN where there is none.
    confidence : ndarray, shape (R, 17) or (17,)
        Weights in [0, 1]; 0 drops a joint.
    tau_px : float
        Distance at which a joint's cost saturates (pixels).

    Returns
    -------
    d : ndarray, shape (N,)
        In [0, 1]; 0 where no keypoint carries weight.
    """
    return KeypointTarget(keypoints, confidence, tau_px=tau_px).d_K(projected)


class KeypointTarget:
    """One detection prepared for :func:`d_K`: its weights are computed once, not per batch
    (stage 3 scores some 500 batches per frame against one detection)."""

    def __init__(self, keypoints: np.ndarray, confidence: np.ndarray, *, tau_px: float) -> None:
        kp = np.asarray(keypoints, float).reshape(-1, 17, 2)
        conf = np.asarray(confidence, float).reshape(-1, 17)
        w = np.where(np.isfinite(kp).all(-1), conf, 0.0)  # (R, 17)
        total = w.sum(-1)
        #: Whether any keypoint carries weight; without, d_K is 0.
        self.any = bool(np.any(total > 0))
        self.tau_px = tau_px
        self._wn = w / (np.maximum(total, 1e-12)[:, None] * tau_px)  # (R, 17)
        self._kp = np.nan_to_num(kp)[None]  # (1, R, 17, 2)
        self._none = total <= 0  # (R,) readings with no keypoint

    def d_K(self, projected: np.ndarray) -> np.ndarray:
        """d_K of postures' projected joints (N, 17, 2) -> (N,)."""
        if not self.any:
            return np.zeros(projected.shape[0])
        diff = projected[:, None] - self._kp  # (N, R, 17, 2)
        r = np.sqrt(np.einsum("nrjk,nrjk->nrj", diff, diff))  # einsum: 37 % faster than norm
        cost = np.einsum("nrj,rj->nr", np.minimum(r, self.tau_px), self._wn)
        cost[:, self._none] = np.inf  # a reading with no keypoint is no reading
        return cost.min(-1)
