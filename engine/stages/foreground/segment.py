"""The body region of one frame: the difference to the background as a trimap refined by
GrabCut (thesis 4.1.1, seed 001 3.1.3), or fused with the learned person mask (beyond the
thesis).
"""

from __future__ import annotations

import time

import cv2
import numpy as np

from engine.stages.foreground.background import Background, _distance, _lab
from engine.stages.foreground.regions import _bbox, _clean, _disc, grabcut_seeded
from engine.stages.foreground.settings import ForegroundSettings


def _difference(
    frame: np.ndarray, background: Background, s: ForegroundSettings
) -> tuple[np.ndarray, np.ndarray]:
    """Colour distance of a frame (H, W, 3) to the background and each pixel's threshold,
    both (H, W): ``max(threshold, noise_factor * noise)``, and for never-seen pixels the
    distance to the nearest known background colours against ``never_factor`` x threshold."""
    lab = _lab(frame[None], s.blur_sigma_px)[0]
    d = _distance(lab, background.lab)
    never = background.never
    if never.any():
        d[never] = _distance(lab[never][:, None], background.never_samples).min(1)
    thr = np.maximum(s.threshold, s.noise_factor * background.noise)
    thr[never] = s.threshold * s.never_factor
    return d, thr


def segment_frame(
    frame: np.ndarray, background: Background, settings: ForegroundSettings
) -> tuple[np.ndarray, np.ndarray, int, dict]:
    """Body region of one frame against a background model (thesis 4.1.1, seed 001 3.1.3).

    The colour distance to the background, over a per-pixel threshold
    ``max(threshold, noise_factor * noise)``, gives a trimap: twice the threshold is sure
    foreground, under half of it sure background, in between and the never-seen pixels are
    left to GrabCut, run only on the bounding box of those ambiguous pixels near the body.

    Returns
    -------
    mask : ndarray of bool, shape (H, W)
    raw : ndarray of bool, shape (H, W)
        Thresholded difference (before clean-up).
    blobs : int
    timing : dict
        Seconds in ``difference`` and ``grabcut``.
    """
    s = settings
    t0 = time.perf_counter()
    d, thr = _difference(frame, background, s)
    never = background.never
    raw = d > thr
    strong = d > 2 * thr
    sure_bg = d < 0.5 * thr
    trusted = raw & ~never
    coarse, blobs = _clean(raw, s.min_blob_fraction, sure_bg, trusted)
    timing = {"difference": time.perf_counter() - t0, "grabcut": 0.0}
    if not (s.grabcut and coarse.any()):
        return coarse, raw, blobs, timing
    t0 = time.perf_counter()
    near = cv2.dilate(coarse.astype(np.uint8), np.ones((9, 9), np.uint8)) > 0
    ambiguous = near & ~sure_bg & ~strong
    if ambiguous.sum() < s.min_ambiguous_px:
        timing["grabcut"] = time.perf_counter() - t0
        return coarse, raw, blobs, timing
    r0, r1, c0, c1 = _bbox(coarse | (ambiguous & near), s.grabcut_margin_px)
    crop = (slice(r0, r1), slice(c0, c1))
    gc = np.full((r1 - r0, c1 - c0), cv2.GC_PR_BGD, np.uint8)
    gc[coarse[crop]] = cv2.GC_PR_FGD
    gc[sure_bg[crop]] = cv2.GC_BGD
    gc[~near[crop]] = cv2.GC_BGD
    # Where the background was seen, the difference is trusted: GrabCut's colour models
    # would otherwise drop dark trousers over a dark floor (synthetic cases: both lower legs
    # lost in the calibration frame, and the camera far too small). It decides the
    # never-seen pixels.
    sure = strong | trusted if s.trust_seen_background else strong
    sure_fg = cv2.erode((coarse & sure).astype(np.uint8), np.ones((3, 3), np.uint8))
    gc[sure_fg[crop] > 0] = cv2.GC_FGD
    m = np.zeros_like(coarse)
    m[crop] = grabcut_seeded(frame[crop], gc, iterations=s.grabcut_iterations)
    mask, blobs = _clean(m, s.min_blob_fraction, sure_bg, trusted)
    timing["grabcut"] = time.perf_counter() - t0
    return mask, raw, blobs, timing


def fuse_learned_mask(
    frame: np.ndarray,
    learned: np.ndarray,
    background: Background,
    settings: ForegroundSettings,
    *,
    slack_px: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, int, dict]:
    """Body region from the learned person mask and the thesis' evidence (beyond the thesis).

    The learned mask seeds GrabCut (4.1.1): its core is sure foreground, the image beyond a
    band around it sure background, so a wall of the clothes' colour that the performer never
    leaves, a prop or a passer-by stays out. Inside the band, a clear difference against a
    seen background is sure foreground and a clear match sure background; the rest is
    probable as the learned mask says, and GrabCut's colour models decide it.

    Parameters
    ----------
    frame : ndarray of uint8, shape (H, W, 3)
    learned : ndarray of uint8, shape (H, W)
        Person probability x 255.
    background : Background
    settings : ForegroundSettings
    slack_px : float
        Extra erosion of the core and widening of the band (at 240 rows): the learned mask
        was borrowed from another frame.

    Returns
    -------
    Same as :func:`segment_frame`.
    """
    s = settings
    t0 = time.perf_counter()
    h = frame.shape[0]
    person = learned > 127
    d, thr = _difference(frame, background, s)
    never = background.never
    raw = d > thr
    seen_fg = (d > 2 * thr) & ~never
    seen_bg = (d < 0.5 * thr) & ~never
    k = h / 240.0
    core = _disc(person, -max(1, round((s.learned_core_px + slack_px) * k)))
    near = _disc(person, max(1, round((s.learned_band_px + slack_px) * k)))
    timing = {"difference": time.perf_counter() - t0, "grabcut": 0.0}
    t0 = time.perf_counter()
    gc = np.full(person.shape, cv2.GC_BGD, np.uint8)
    gc[near] = cv2.GC_PR_BGD
    gc[person] = cv2.GC_PR_FGD
    gc[near & seen_fg] = cv2.GC_FGD
    gc[near & ~core & seen_bg] = cv2.GC_BGD
    gc[core] = cv2.GC_FGD
    mask = person | (near & seen_fg)
    if s.grabcut and person.any():
        r0, r1, c0, c1 = _bbox(near, s.grabcut_margin_px)
        crop = (slice(r0, r1), slice(c0, c1))
        mask = np.zeros_like(person)
        mask[crop] = grabcut_seeded(frame[crop], gc[crop], iterations=s.grabcut_iterations)
    mask, blobs = _clean(mask, s.min_blob_fraction, seen_bg & ~core, core)
    timing["grabcut"] = time.perf_counter() - t0
    return mask, raw, blobs, timing
