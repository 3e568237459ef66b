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
