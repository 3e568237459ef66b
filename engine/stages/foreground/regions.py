"""Masks of the body region: GrabCut seeded from a trimap (thesis 4.1.1), the clean-up of a
thresholded difference (small blobs, holes) and morphology helpers.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import cast

import cv2
import numpy as np
from scipy import ndimage

# GrabCut seeded from a mask (GC_INIT_WITH_MASK) takes no rectangle. OpenCV's stubs type
# ``rect`` as Sequence[int] only, but the binding accepts None for it (cv::Rect()).
_NO_RECT = cast(Sequence[int], None)
_GRABCUT_SEED = 0
# blobs this close (fraction of the image height) to the body are part of it (see _clean)
_NEAR_FRACTION = 0.04


def _grabcut(bgr: np.ndarray, labels: np.ndarray, iterations: int) -> bool:
    """``cv2.grabCut`` from a label mask, in place on ``labels`` (H, W); False if it failed.

    GrabCut's colour models start from k-means seeded by OpenCV's per-thread global RNG, which
    every call advances: without resetting it, a video's silhouettes depended on what the
    process had segmented before (a worker's previous jobs).
    """
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    cv2.setRNGSeed(_GRABCUT_SEED)
    try:
        cv2.grabCut(bgr, labels, _NO_RECT, bgd, fgd, iterations, cv2.GC_INIT_WITH_MASK)
    except cv2.error:
        return False
    return True


def grabcut_seeded(frame: np.ndarray, labels: np.ndarray, *, iterations: int = 2) -> np.ndarray:
    """GrabCut (thesis 4.1.1) from a trimap instead of a box.

    Parameters
    ----------
    frame : ndarray of uint8, shape (H, W, 3)
        RGB image (or a crop).
    labels : ndarray of uint8, shape (H, W)
        ``cv2.GC_BGD``, ``GC_FGD``, ``GC_PR_BGD`` or ``GC_PR_FGD`` per pixel: sure labels
        from a clear background difference, probable ones where it is ambiguous or unknown.
    iterations : int

    Returns
    -------
    mask : ndarray of bool, shape (H, W)
        Foreground; the probable-foreground labels when GrabCut cannot build its colour
        models (no background or no foreground sample).
    """
    gc = labels.copy()
    fallback = (gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)
    has_bg = np.any((gc == cv2.GC_BGD) | (gc == cv2.GC_PR_BGD))
    if not has_bg or not fallback.any():
        return fallback
    if not _grabcut(np.ascontiguousarray(frame[..., ::-1]), gc, iterations):
        return fallback  # degenerate colour model (e.g. uniform crop): keep the trimap
    return (gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)


def _clean(
    mask: np.ndarray,
    min_blob_fraction: float,
    sure_bg: np.ndarray | None = None,
    trusted: np.ndarray | None = None,
) -> tuple[np.ndarray, int]:
    """Open, close, drop small blobs, fill holes; returns the mask and the blob count.

    With ``trusted`` (pixels that clearly differ from a background that was seen), a small
    blob is kept when it lies within ``_NEAR_FRACTION`` of the image height of a large one
    and is mostly trusted: a body cut by a thin band the difference misses (trousers
    crossing the line where wall meets floor) would otherwise lose its lower legs, and with
    them the scale of stage 1's camera (too small on synthetic cases). Blobs over never-seen
    background stay dropped: there they are mostly guesses (P2's prop behind the performer).
    The count is of the large blobs.
    """
    m: np.ndarray = mask.astype(np.uint8)
    m = cv2.morphologyEx(m, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3)))
    m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    if n <= 1:
        return np.zeros(mask.shape, bool), 0
    areas = stats[1:, cv2.CC_STAT_AREA]
    keep = np.flatnonzero(areas >= min_blob_fraction * areas.max()) + 1
    out = np.isin(labels, keep)
    if trusted is None:
        return _fill_holes(out, sure_bg), int(len(keep))
    share = np.bincount(labels[trusted], minlength=n) / np.maximum(
        np.bincount(labels.ravel(), minlength=n), 1
    )
    r = max(1, int(round(_NEAR_FRACTION * mask.shape[0])))
    near_kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * r + 1, 2 * r + 1))
    for _ in range(2):  # a foot beyond a lower leg beyond the gap
        near = cv2.dilate(out.astype(np.uint8), near_kernel) > 0
        touching = np.unique(labels[near & (labels > 0) & ~out])
        touching = touching[share[touching] >= 0.5]
        if touching.size == 0:
            break
        out |= np.isin(labels, touching)
    return _fill_holes(out, sure_bg), int(len(keep))


def _fill_holes(mask: np.ndarray, sure_bg: np.ndarray | None = None) -> np.ndarray:
    """Fill holes of the body region: tiny ones always, larger ones (arms meeting the body,
    the gap between the legs closed by the feet) only when none of their pixels is clearly
    background."""
    holes = ndimage.binary_fill_holes(mask) & ~mask
    if not holes.any():
        return mask
    n, labels, stats, _ = cv2.connectedComponentsWithStats(holes.astype(np.uint8), connectivity=4)
    area = stats[:, cv2.CC_STAT_AREA]
    fill = area < 0.0005 * mask.size
    if sure_bg is None:
        fill |= area < 0.01 * mask.size
    else:
        seen_bg = np.bincount(labels[sure_bg], minlength=n) > 0
        fill |= ~seen_bg & (area < 0.01 * mask.size)
    fill[0] = False
    return mask | fill[labels]


def _bbox(mask: np.ndarray, margin: int) -> tuple[int, int, int, int]:
    rows, cols = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    h, w = mask.shape
    return (
        max(rows[0] - margin, 0),
        min(rows[-1] + margin + 1, h),
        max(cols[0] - margin, 0),
        min(cols[-1] + margin + 1, w),
    )


def _disc(mask: np.ndarray, r: int) -> np.ndarray:
    """``mask`` dilated (r > 0) or eroded (r < 0) by a disc of radius |r| pixels."""
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * abs(r) + 1, 2 * abs(r) + 1))
    m = mask.astype(np.uint8)
    if r > 0:
        return np.asarray(cv2.dilate(m, k)) > 0
    # pixels outside the image count as background, so a body cut by the border erodes there
    return np.asarray(cv2.erode(m, k, borderType=cv2.BORDER_CONSTANT, borderValue=(0,))) > 0
