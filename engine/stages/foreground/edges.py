"""Skin regions (thesis 4.1.2) and the edges of a body region: its contour, its skin regions'
contours, optionally the image's own edges inside it.
"""

from __future__ import annotations

import cv2
import numpy as np


def skin_mask(frame: np.ndarray) -> np.ndarray:
    """Skin-coloured pixels (thesis 4.1.2; Chai and Ngan's YCrCb box).

    Parameters
    ----------
    frame : ndarray of uint8, shape (H, W, 3)
        RGB.

    Returns
    -------
    ndarray of bool, shape (H, W)
    """
    ycc = cv2.cvtColor(frame, cv2.COLOR_RGB2YCrCb)
    cr, cb = ycc[..., 1], ycc[..., 2]
    return (cr >= 133) & (cr <= 173) & (cb >= 77) & (cb <= 127) & (ycc[..., 0] > 40)


def contour(mask: np.ndarray) -> np.ndarray:
    """One-pixel inner boundary of a mask, (H, W) bool -> (H, W) bool."""
    m = mask.astype(np.uint8)
    return (m - cv2.erode(m, np.ones((3, 3), np.uint8), borderType=cv2.BORDER_CONSTANT)) > 0


def outline(mask: np.ndarray, skin: np.ndarray) -> np.ndarray:
    """Edges of a body region: its contour and its skin regions' (the arms over the torso),
    (H, W) bool each -> (H, W) bool (thesis 4.1.2)."""
    return contour(mask) | contour(skin)


def interior_edges(
    frame: np.ndarray, mask: np.ndarray, thresholds: tuple[float, float]
) -> np.ndarray:
    """Canny edges of an RGB frame (H, W, 3) at least 2 px inside ``mask`` (H, W) -> bool."""
    grey = cv2.GaussianBlur(cv2.cvtColor(frame, cv2.COLOR_RGB2GRAY), (3, 3), 0)
    edges = cv2.Canny(grey, thresholds[0], thresholds[1]) > 0
    inside = cv2.erode(mask.astype(np.uint8), np.ones((5, 5), np.uint8)) > 0
    return edges & inside
