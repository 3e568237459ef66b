"""The static camera's background (seed 001 3.1.2: "the regions of the video frames that do
not change"): a colour model per pixel in CIE L*a*b*, its noise, and a local model of the
pixels never seen free of the performer.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from engine.stages.foreground.regions import _clean, _grabcut


def _blur(img: np.ndarray, sigma: float) -> np.ndarray:
    return cv2.GaussianBlur(img, (0, 0), sigma) if sigma > 0 else img


#: Weights of (L*, a*, b*) in the colour distance: a cast shadow or a shading change alters
#: lightness far more than chroma, so lightness counts half.
_LAB_WEIGHTS = np.array([0.8, 1.0, 1.0], np.float32)


def _lab(frames: np.ndarray, sigma: float) -> np.ndarray:
    """Blurred CIE L*a*b* (float32, L in 0-100), (N, H, W, 3) uint8 RGB -> (N, H, W, 3)."""
    out = np.empty(frames.shape, np.float32)
    for i, f in enumerate(frames):
        out[i] = cv2.cvtColor(_blur(f, sigma).astype(np.float32) * (1 / 255), cv2.COLOR_RGB2Lab)
    return out


def _distance(lab: np.ndarray, bg_lab: np.ndarray) -> np.ndarray:
    """Weighted L*a*b* distance to the background, (..., H, W, 3) -> (..., H, W) float32."""
    d = (lab - bg_lab) * _LAB_WEIGHTS
    return np.sqrt(np.einsum("...c,...c->...", d, d))


@dataclass(frozen=True)
class Background:
    """Static-camera background model (seed 001 3.1.2).

    Attributes
    ----------
    image : ndarray of uint8, shape (H, W, 3)
        Background colour (RGB); inpainted where never seen.
    lab : ndarray of float32, shape (H, W, 3)
        The same in blurred L*a*b*.
    noise : ndarray of float32, shape (H, W)
        Per-pixel scale of the colour distance between a frame and the background over the
        frames where the pixel showed background (the median distance: compression noise is
        larger on textured and edge pixels).
    never : ndarray of bool, shape (H, W)
        Pixels never seen free of the performer; their colour is a guess and they are left
        compared with ``never_samples`` instead.
    never_samples : ndarray of float32, shape (N, K, 3)
        For each never-seen pixel (row-major order of ``never``), L*a*b* colours of K known
        background pixels nearest to it along its row and the rows 2 px above and below: a
        local, non-parametric background model (a textured wall has several colours, and
        only the nearest ones say which).
    """

    image: np.ndarray
    lab: np.ndarray
    noise: np.ndarray
    never: np.ndarray
    never_samples: np.ndarray


def estimate_background(
    frames: np.ndarray,
    *,
    samples: int = 30,
    threshold: float = 8.0,
    blur_sigma_px: float = 1.0,
    body_frames: int = 30,
    min_free_fraction: float = 0.1,
) -> Background:
    """Background of a static camera (seed 001 3.1.2: the regions that do not change).

    1. A temporal median over ``samples`` evenly spaced frames.
    2. The body in ``body_frames`` of them, found by GrabCut in a full-height box around
       what differs from that median (thesis 4.1.1's 2h/3 x h window): parts of a performer
       who hardly moves (feet planted for a whole golf swing) print into a median, and only
       a colour model tells them from the wall.
    3. A second median over only the frames where each pixel is neither different from the
       first estimate nor inside a body found in step 2; pixels never seen free are
       inpainted (cv2.INPAINT_TELEA) and reported.
    4. The per-pixel noise scale: the median colour distance over the frames used in 3.

    Parameters
    ----------
    frames : ndarray of uint8, shape (T', H, W, 3)
    samples : int
        Frames used for the medians, evenly spaced.
    threshold, blur_sigma_px : float
        As :class:`ForegroundSettings`.
    body_frames : int
        Frames segmented with GrabCut in step 2 (0 skips the step).
    min_free_fraction : float
        A pixel seen free in fewer than this fraction of the samples (and at least 3)
        counts as never seen.

    Returns
    -------
    Background
    """
    import warnings

    idx = np.unique(np.linspace(0, len(frames) - 1, min(samples, len(frames))).round().astype(int))
    sample = frames[idx]
    lab = _lab(sample, blur_sigma_px)
    bg0 = np.median(lab, axis=0)
    diff = _distance(lab, bg0)
    kernel = np.ones((3, 3), np.uint8)
    fg = np.stack([cv2.dilate((d > threshold).astype(np.uint8), kernel) for d in diff]) > 0
    if body_frames > 0:
        for j in np.unique(np.linspace(0, len(idx) - 1, body_frames).round().astype(int)):
            coarse, _ = _clean(diff[j] > threshold, 0.15)
            if coarse.any():
                body = _grabcut_full_height(sample[j], coarse, diff[j] > 2 * threshold)
                fg[j] |= cv2.dilate(body.astype(np.uint8), kernel) > 0
    lab[fg] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        bg_lab = np.nanmedian(lab, axis=0)
        noise = np.nanmedian(_distance(lab, bg_lab), axis=0)
    # a pixel seen free only once or twice is more likely a body part GrabCut missed
    never = (~fg).sum(0) < max(3, min_free_fraction * len(idx))
    never = cv2.dilate(never.astype(np.uint8), kernel) > 0
    bg_lab = np.where(never[..., None], bg0, bg_lab).astype(np.float32)
    image = _lab_to_rgb(bg_lab)
    if never.any():
        image = cv2.inpaint(image, never.astype(np.uint8), 5, cv2.INPAINT_TELEA)
        bg_lab = cv2.cvtColor(image.astype(np.float32) * (1 / 255), cv2.COLOR_RGB2Lab)
    known = noise[~never]
    floor = float(np.median(known)) if known.size else 1.0
    noise = np.where(never | ~np.isfinite(noise), np.inf, np.maximum(noise, floor))
    return Background(image, bg_lab, noise.astype(np.float32), never,
                      _row_samples(bg_lab, never))  # fmt: skip


def _row_samples(bg_lab: np.ndarray, never: np.ndarray, per_side: int = 8) -> np.ndarray:
    """Known background colours nearest each never-seen pixel along rows r-2, r, r+2."""
    h, w = never.shape
    rows, cols = np.nonzero(never)
    k = 2 * per_side * 3
    out = np.zeros((rows.size, k, 3), np.float32)
    known_cols = [np.flatnonzero(~never[r]) for r in range(h)]
    for i, (r, c) in enumerate(zip(rows, cols, strict=True)):
        picked = []
        for rr in (r - 2, r, r + 2):
            kc = known_cols[min(max(rr, 0), h - 1)]
            pos = int(np.searchsorted(kc, c))
            sel = np.concatenate([kc[max(pos - per_side, 0) : pos], kc[pos : pos + per_side]])
            picked.append(bg_lab[min(max(rr, 0), h - 1), sel])
        col = np.concatenate(picked)
        if col.size:
            out[i] = np.resize(col, (k, 3))
        else:  # a whole band never seen: nothing better than the inpainted colour
            out[i] = bg_lab[r, c]
    return out


def _lab_to_rgb(lab: np.ndarray) -> np.ndarray:
    rgb = cv2.cvtColor(np.ascontiguousarray(lab, np.float32), cv2.COLOR_Lab2RGB)
    return np.clip(rgb * 255 + 0.5, 0, 255).astype(np.uint8)


def _grabcut_full_height(
    frame: np.ndarray, coarse: np.ndarray, strong: np.ndarray, *, scale: float = 0.5
) -> np.ndarray:
    """GrabCut in a full-height box spanning the columns of ``coarse`` (thesis 4.1.1 step 1).

    Run at ``scale`` of the image size for speed; returns a (H, W) bool mask.
    """
    h, w = coarse.shape
    cols = np.flatnonzero(coarse.any(0))
    pad = max(h // 40, 3)
    c0, c1 = max(cols[0] - pad, 0), min(cols[-1] + pad + 1, w)
    img = cv2.resize(frame, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)[..., ::-1]
    img = np.ascontiguousarray(img)
    hs, ws = img.shape[:2]
    gc = np.full((hs, ws), cv2.GC_BGD, np.uint8)
    gc[1:-1, int(c0 * scale) : int(np.ceil(c1 * scale))] = cv2.GC_PR_FGD
    sure = cv2.erode((coarse & strong).astype(np.uint8), np.ones((5, 5), np.uint8))
    gc[cv2.resize(sure, (ws, hs), interpolation=cv2.INTER_NEAREST) > 0] = cv2.GC_FGD
    if not (gc == cv2.GC_BGD).any():
        return coarse
    if not _grabcut(img, gc, 3):
        return coarse
    m = ((gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)).astype(np.uint8)
    return cv2.resize(m, (w, h), interpolation=cv2.INTER_NEAREST) > 0
