"""Stage 0: the performer's body region S'_t' in every frame (thesis 4.1, seed 001 3.1.2-3.1.3).

The thesis finds the body from the difference of consecutive frames and refines it with GrabCut
(4.1.1), then adds skin regions so that arms in front of the torso are known (4.1.2). A
static-camera background estimate (seed 001 3.1.2: "the regions of the video frames that do not
change") is a sturdier seed than a two-frame difference, which vanishes whenever the performer
pauses. Here:

1. Background (:func:`estimate_background`): per-pixel temporal median over sampled frames,
   then a second median over only the frames where the pixel was *not* foreground, so a
   performer who stands still for a while (less than the whole video) does not print into the
   background; pixels never uncovered are inpainted (and flagged).
2. Difference and threshold (seed 001 3.1.3), morphological clean-up, small blobs dropped.
3. GrabCut (4.1.1, ``cv2.grabCut``) seeded from that mask, run only on the body's bounding
   box plus a margin (the thesis used a fixed 2h/3 x h window).
4. Skin (4.1.2): the explicit YCrCb skin-colour box of Chai and Ngan (1999),
   ``133 <= Cr <= 173`` and ``77 <= Cb <= 127``, in place of the GMM of Jones and Rehg [JR02]
   whose 32 Gaussians the thesis copies; kept only inside the (dilated) body region.
5. Edges: the silhouette contour and the contours of the skin regions (the arms' outline
   inside the torso), one pixel wide.

Quality flags per frame: ``no_person``, ``several_blobs``, ``cut_by_border``,
``camera_moving`` and, once per video, ``background_incomplete`` on every frame when some
background pixels were never seen.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import cv2
import numpy as np
from scipy import ndimage

from engine.errors import InvalidInput

ProgressFn = Callable[[str, float], None]


@dataclass(frozen=True)
class ForegroundSettings:
    """Settings of stage 0 (thesis 4.1), with the defaults used on 320 x 240 video.

    Attributes
    ----------
    background_samples : int
        Frames sampled (evenly) for the background median.
    threshold : float
        Colour difference (max over RGB channels, 0-255) above which a pixel is foreground
        (seed 001 3.1.3 "specified threshold").
    blur_sigma_px : float
        Gaussian blur before differencing (video noise).
    min_blob_fraction : float
        Blobs smaller than this fraction of the largest one are dropped.
    min_person_fraction : float
        A silhouette smaller than this fraction of the image means ``no_person``.
    grabcut : bool
        Refine with GrabCut (thesis 4.1.1).
    grabcut_iterations : int
        GrabCut iterations (steps 4-7 of 4.1.1 repeated).
    grabcut_margin_px : int
        Margin around the body's bounding box given to GrabCut as probable background.
    skin : bool
        Detect skin regions (thesis 4.1.2).
    moving_camera_fraction : float
        Fraction of the pixels away from the body that differ from the background above
        which the frame is flagged ``camera_moving``.
    """

    background_samples: int = 30
    threshold: float = 28.0
    blur_sigma_px: float = 1.0
    min_blob_fraction: float = 0.15
    min_person_fraction: float = 0.005
    grabcut: bool = True
    grabcut_iterations: int = 2
    grabcut_margin_px: int = 12
    skin: bool = True
    moving_camera_fraction: float = 0.25


@dataclass(frozen=True)
class ForegroundResult:
    """Body regions S'_t' of every frame.

    Attributes
    ----------
    silhouettes : ndarray of bool, shape (T', H, W)
    edges : ndarray of bool, shape (T', H, W)
        Silhouette and skin-region contours.
    skin : ndarray of bool, shape (T', H, W)
    background : ndarray of uint8, shape (H, W, 3)
        The estimated background (RGB).
    flags : tuple of tuple of str
        Quality flags of each frame.
    timing_s : dict
        Seconds spent in ``background``, ``difference``, ``grabcut``, ``skin``.
    """

    silhouettes: np.ndarray
    edges: np.ndarray
    skin: np.ndarray
    background: np.ndarray
    flags: tuple[tuple[str, ...], ...]
    timing_s: dict

    @property
    def n_frames(self) -> int:
        return int(self.silhouettes.shape[0])


def _blur(img: np.ndarray, sigma: float) -> np.ndarray:
    return cv2.GaussianBlur(img, (0, 0), sigma) if sigma > 0 else img


def _difference(frames: np.ndarray, background: np.ndarray, sigma: float) -> np.ndarray:
    """Max-over-channels absolute difference, (N, H, W, 3) -> (N, H, W) float32."""
    bg = _blur(background, sigma).astype(np.int16)
    out = np.empty(frames.shape[:3], dtype=np.float32)
    for i, f in enumerate(frames):
        out[i] = np.abs(_blur(f, sigma).astype(np.int16) - bg).max(-1)
    return out


def estimate_background(
    frames: np.ndarray,
    *,
    samples: int = 30,
    threshold: float = 28.0,
    blur_sigma_px: float = 1.0,
    body_frames: int = 30,
) -> tuple[np.ndarray, np.ndarray]:
    """Background of a static camera (seed 001 3.1.2: the regions that do not change).

    1. A temporal median over ``samples`` evenly spaced frames.
    2. The body in ``body_frames`` of them, found by GrabCut in a full-height box around
       what differs from that median (thesis 4.1.1's 2h/3 x h window): parts of a performer
       who hardly moves (feet planted for a whole golf swing) print into a median, and only
       a colour model tells them from the wall.
    3. A second median over only the frames where each pixel is neither different from the
       first estimate nor inside a body found in step 2; pixels never seen free are
       inpainted (cv2.INPAINT_TELEA) and reported.

    Parameters
    ----------
    frames : ndarray of uint8, shape (T', H, W, 3)
    samples : int
        Frames used for the medians, evenly spaced.
    threshold, blur_sigma_px : float
        As :class:`ForegroundSettings`.
    body_frames : int
        Frames segmented with GrabCut in step 2 (0 skips the step).

    Returns
    -------
    background : ndarray of uint8, shape (H, W, 3)
    never_seen : ndarray of bool, shape (H, W)
        Pixels never observed as background (inpainted).
    """
    import warnings

    idx = np.unique(np.linspace(0, len(frames) - 1, min(samples, len(frames))).round().astype(int))
    sample = frames[idx]
    bg0 = np.median(sample, axis=0).astype(np.uint8)
    diff = _difference(sample, bg0, blur_sigma_px)
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (7, 7))
    fg = np.stack([cv2.dilate((d > threshold).astype(np.uint8), kernel) for d in diff]) > 0
    if body_frames > 0:
        for j in np.unique(np.linspace(0, len(idx) - 1, body_frames).round().astype(int)):
            coarse, _ = _clean(diff[j] > threshold, 0.15)
            if coarse.any():
                body = _grabcut_full_height(sample[j], coarse, diff[j] > 2 * threshold)
                fg[j] |= cv2.dilate(body.astype(np.uint8), kernel) > 0
    data = sample.astype(np.float32)
    data[fg] = np.nan
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        bg = np.nanmedian(data, axis=0)
    never = np.isnan(bg[..., 0])
    bg = np.where(np.isnan(bg), bg0, bg).astype(np.uint8)
    if never.any():
        bg = cv2.inpaint(bg, never.astype(np.uint8), 5, cv2.INPAINT_TELEA)
    return bg, never


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
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    try:
        cv2.grabCut(img, gc, None, bgd, fgd, 3, cv2.GC_INIT_WITH_MASK)
    except cv2.error:
        return coarse
    m = ((gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)).astype(np.uint8)
    return cv2.resize(m, (w, h), interpolation=cv2.INTER_NEAREST) > 0


def _clean(mask: np.ndarray, min_blob_fraction: float) -> tuple[np.ndarray, int]:
    """Open, close, fill holes, drop small blobs; returns the mask and the blob count."""
    m = mask.astype(np.uint8)
    m = cv2.morphologyEx(m, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3)))
    m = cv2.morphologyEx(m, cv2.MORPH_CLOSE, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (5, 5)))
    n, labels, stats, _ = cv2.connectedComponentsWithStats(m, connectivity=8)
    if n <= 1:
        return np.zeros(mask.shape, bool), 0
    areas = stats[1:, cv2.CC_STAT_AREA]
    keep = np.flatnonzero(areas >= min_blob_fraction * areas.max()) + 1
    out = np.isin(labels, keep)
    return _fill_holes(out), int(len(keep))


def _fill_holes(mask: np.ndarray) -> np.ndarray:
    """Fill regions not connected to the image border (the body has no holes... mostly)."""
    holes = ndimage.binary_fill_holes(mask) & ~mask
    # arms meeting the body enclose real background gaps: fill only small holes
    n, labels, stats, _ = cv2.connectedComponentsWithStats(holes.astype(np.uint8), connectivity=4)
    small = np.flatnonzero(stats[1:, cv2.CC_STAT_AREA] < 0.01 * mask.size) + 1
    return mask | np.isin(labels, small)


def _bbox(mask: np.ndarray, margin: int) -> tuple[int, int, int, int]:
    rows, cols = np.flatnonzero(mask.any(1)), np.flatnonzero(mask.any(0))
    h, w = mask.shape
    return (
        max(rows[0] - margin, 0),
        min(rows[-1] + margin + 1, h),
        max(cols[0] - margin, 0),
        min(cols[-1] + margin + 1, w),
    )


def grabcut_refine(
    frame: np.ndarray, seed: np.ndarray, sure: np.ndarray, *, iterations: int = 2, margin: int = 12
) -> np.ndarray:
    """GrabCut (thesis 4.1.1) on the seed's bounding box plus a margin.

    Parameters
    ----------
    frame : ndarray of uint8, shape (H, W, 3)
        RGB image.
    seed : ndarray of bool, shape (H, W)
        Probable foreground; the rest of the box is probable background, outside is
        background.
    sure : ndarray of bool, shape (H, W)
        Certain foreground (strong, eroded difference).
    iterations, margin : int

    Returns
    -------
    mask : ndarray of bool, shape (H, W)
    """
    if not seed.any():
        return seed
    r0, r1, c0, c1 = _bbox(seed, margin)
    crop = np.ascontiguousarray(frame[r0:r1, c0:c1, ::-1])
    gc = np.full(crop.shape[:2], cv2.GC_PR_BGD, np.uint8)
    gc[seed[r0:r1, c0:c1]] = cv2.GC_PR_FGD
    gc[sure[r0:r1, c0:c1]] = cv2.GC_FGD
    # the box border is background: GrabCut needs background samples for its colour model
    gc[[0, -1], :] = np.where(gc[[0, -1], :] == cv2.GC_FGD, cv2.GC_FGD, cv2.GC_BGD)
    gc[:, [0, -1]] = np.where(gc[:, [0, -1]] == cv2.GC_FGD, cv2.GC_FGD, cv2.GC_BGD)
    if not np.any((gc == cv2.GC_BGD) | (gc == cv2.GC_PR_BGD)):
        return seed
    bgd, fgd = np.zeros((1, 65), np.float64), np.zeros((1, 65), np.float64)
    try:
        cv2.grabCut(crop, gc, None, bgd, fgd, iterations, cv2.GC_INIT_WITH_MASK)
    except cv2.error:  # degenerate colour model (e.g. uniform crop): keep the seed
        return seed
    out = np.zeros_like(seed)
    out[r0:r1, c0:c1] = (gc == cv2.GC_FGD) | (gc == cv2.GC_PR_FGD)
    return out


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


def extract_foreground(
    frames: np.ndarray,
    settings: ForegroundSettings = ForegroundSettings(),
    *,
    on_progress: ProgressFn | None = None,
) -> ForegroundResult:
    """Body regions S'_t' of a static-camera video (thesis 4.1).

    Parameters
    ----------
    frames : ndarray of uint8, shape (T', H, W, 3)
        RGB frames (:attr:`engine.io.video.Video.frames`).
    settings : ForegroundSettings
    on_progress : callable(stage, fraction), optional
        Called with ``"foreground"`` and the fraction of frames done.

    Returns
    -------
    ForegroundResult

    Raises
    ------
    InvalidInput
        ``frames`` is not a uint8 (T', H, W, 3) array of at least two frames.
    """
    f = np.asarray(frames)
    if f.ndim != 4 or f.shape[-1] != 3 or f.dtype != np.uint8 or f.shape[0] < 2:
        raise InvalidInput(
            f"frames must be uint8 of shape (T' >= 2, H, W, 3), got {f.dtype} {f.shape}"
        )
    s = settings
    timing = {"background": 0.0, "difference": 0.0, "grabcut": 0.0, "skin": 0.0}
    t0 = time.perf_counter()
    bg, never = estimate_background(
        f, samples=s.background_samples, threshold=s.threshold, blur_sigma_px=s.blur_sigma_px
    )
    timing["background"] = time.perf_counter() - t0
    n, h, w = f.shape[:3]
    sil = np.zeros((n, h, w), bool)
    skin = np.zeros((n, h, w), bool)
    edges = np.zeros((n, h, w), bool)
    flags: list[tuple[str, ...]] = []
    grow = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (15, 15))
    for i in range(n):
        t0 = time.perf_counter()
        diff = _difference(f[i : i + 1], bg, s.blur_sigma_px)[0]
        raw = diff > s.threshold
        coarse, blobs = _clean(raw, s.min_blob_fraction)
        timing["difference"] += time.perf_counter() - t0
        mask = coarse
        if s.grabcut and coarse.any():
            t0 = time.perf_counter()
            sure = cv2.erode(
                (coarse & (diff > 2 * s.threshold)).astype(np.uint8), np.ones((5, 5), np.uint8)
            ).astype(bool)
            mask, blobs = _clean(
                grabcut_refine(
                    f[i], coarse, sure, iterations=s.grabcut_iterations, margin=s.grabcut_margin_px
                ),
                s.min_blob_fraction,
            )
            timing["grabcut"] += time.perf_counter() - t0
        t0 = time.perf_counter()
        if s.skin and mask.any():
            near = cv2.dilate(mask.astype(np.uint8), grow).astype(bool)
            sk = skin_mask(f[i]) & near & (raw | mask)
            sk = cv2.morphologyEx(sk.astype(np.uint8), cv2.MORPH_OPEN, np.ones((2, 2), np.uint8))
            skin[i] = sk.astype(bool)
            mask = mask | skin[i]
        timing["skin"] += time.perf_counter() - t0
        sil[i] = mask
        edges[i] = contour(mask) | contour(skin[i])
        flags.append(_flags(mask, raw, blobs, never, s, grow))
        if on_progress is not None:
            on_progress("foreground", (i + 1) / n)
    return ForegroundResult(sil, edges, skin, bg, tuple(flags), timing)


def _flags(
    mask: np.ndarray,
    raw: np.ndarray,
    blobs: int,
    never: np.ndarray,
    s: ForegroundSettings,
    grow: np.ndarray,
) -> tuple[str, ...]:
    out = []
    if mask.sum() < s.min_person_fraction * mask.size:
        out.append("no_person")
    if blobs > 1:
        out.append("several_blobs")
    if mask[0].any() or mask[-1].any() or mask[:, 0].any() or mask[:, -1].any():
        out.append("cut_by_border")
    away = ~cv2.dilate(mask.astype(np.uint8), grow, iterations=2).astype(bool)
    if away.any() and raw[away].mean() > s.moving_camera_fraction:
        out.append("camera_moving")
    if never.any():
        out.append("background_incomplete")
    return tuple(out)
