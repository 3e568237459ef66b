"""Stage 0: the performer's body region S'_t' in every frame (thesis 4.1, seed 001 3.1.2-3.1.3).

The thesis finds the body from the difference of consecutive frames and refines it with GrabCut
(4.1.1), then adds skin regions so that arms in front of the torso are known (4.1.2). A
static-camera background estimate (seed 001 3.1.2: "the regions of the video frames that do not
change") is a sturdier seed than a two-frame difference, which vanishes whenever the performer
pauses. Here:

1. Background (:func:`estimate_background`): per-pixel temporal median in CIE L*a*b* over
   sampled frames, then a second median over only the frames where the pixel was *not*
   foreground (GrabCut bodies included), so a performer who stands still for a while does
   not print into the background; a per-pixel noise scale; pixels seen free in too few
   frames are "never seen" and get a local model instead: the colours of the nearest
   known background pixels along their rows.
2. Difference (:func:`segment_frame`, seed 001 3.1.3): weighted L*a*b* distance over a
   per-pixel threshold gives a trimap (sure foreground, ambiguous, sure background);
   morphological clean-up, small blobs dropped, holes filled only when no pixel of the hole
   is clearly background (the gap between the legs stays open).
3. GrabCut (4.1.1, ``cv2.grabCut``) seeded with that trimap instead of a box, run only on
   frames with ambiguous pixels near the body and only on their bounding box.
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
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import cast

import cv2
import numpy as np
from scipy import ndimage

from engine.errors import InvalidInput

ProgressFn = Callable[[str, float], None]

# GrabCut seeded from a mask (GC_INIT_WITH_MASK) takes no rectangle. OpenCV's stubs type
# ``rect`` as Sequence[int] only, but the binding accepts None for it (cv::Rect()).
_NO_RECT = cast(Sequence[int], None)


@dataclass(frozen=True)
class ForegroundSettings:
    """Settings of stage 0 (thesis 4.1), with the defaults used on 320 x 240 video.

    Attributes
    ----------
    background_samples : int
        Frames sampled (evenly) for the background median.
    threshold : float
        Colour distance (weighted CIE L*a*b*, lightness at half weight so that shadows
        count less) above which a pixel is foreground (seed 001 3.1.3 "specified
        threshold"); the threshold of a noisy pixel is raised to ``noise_factor`` times its
        noise scale. Twice the threshold is sure foreground, half of it sure background.
    noise_factor : float
        Per-pixel threshold in units of the background's noise scale
        (:attr:`Background.noise`).
    never_factor : float
        Threshold of never-seen pixels (compared with nearby background colours,
        :attr:`Background.never_samples`) in units of ``threshold``.
    min_free_fraction : float
        See :func:`estimate_background`. 0.1 (3 of 30 samples) rather than 0.3: a performer
        who stays on his spot reveals the wall behind him only while he bends, and that is
        the only chance to learn it. On P2 (a prop of the shirt's colour behind him) the
        region's IoU with the capsule-rendered truth body went 0.66 -> 0.73 and the rank
        correlation of the estimated posture errors -0.06 -> 0.53.
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
        Margin around the ambiguous pixels' bounding box given to GrabCut.
    trust_seen_background : bool
        Body pixels that differ from a background that was seen (not inpainted) are sure
        foreground for GrabCut, which then decides only the weak and never-seen ones.
    min_ambiguous_px : int
        GrabCut runs only on frames with at least this many ambiguous pixels near the body
        (between the sure thresholds, or never seen as background).
    skin : bool
        Detect skin regions (thesis 4.1.2).
    interior_edges : bool
        Add the image's own edges inside the body region (Canny, ``canny_thresholds``) to
        the silhouette and skin contours: clothing seams, an arm's outline over the torso in
        a long-sleeved shirt. Beyond the thesis, whose edges come from skin alone (4.1.2).
        Stage 1 keeps to the outline; stage 3 sees these edges when its ``lambda_e`` > 0.
        Off: on ``benchmarks/cases.py --set '{"foreground": {"interior_edges": true},
        "candidates": {"lambda_e": X}}'`` the mean rank correlation of eps_t' went 0.676 ->
        0.663 (X = 0.1) and 0.620 (0.2), selected error 5.44 -> 5.58 / 5.63 deg. P1 gains
        (rank 0.62 -> 0.71; 0.71 -> 0.81 with the true C and camera at X = 0.2) and P2 loses
        (0.53 -> 0.41 / 0.16), where a prop of the shirt's colour joins the region with its
        own edges.
    canny_thresholds : tuple of float
        Canny's hysteresis thresholds on the blurred grey image.
    moving_camera_fraction : float
        Fraction of the pixels away from the body that differ from the background above
        which the frame is flagged ``camera_moving``.
    fuse_learned : bool
        Fuse the learned person mask (:mod:`engine.stages.perception`) with this evidence
        where the pose model found the person (:func:`fuse_learned_mask`); frames without a
        detection keep the thesis' region. Beyond the thesis.
    learned_core_px, learned_band_px : float
        At 240 rows (scaled with the image): the learned mask eroded by ``learned_core_px`` is
        sure body, and nothing farther than ``learned_band_px`` outside it is body. In the
        band between, the background difference and GrabCut decide (MediaPipe's mask is
        computed at 256 x 256 and is 1-3 px off along the outline, where the difference is
        exact against a seen background).
    learned_max_gap : int
        A frame where the pose model lost the person borrows the learned mask of the nearest
        frame where it found him, up to this many frames away, with its core eroded and its
        band widened by 1 px (at 240 rows) per frame of distance (P3: 38 % of the frames
        lost, the grey clothes barely differ from the wall). Farther, the thesis' region.
    """

    background_samples: int = 30
    threshold: float = 8.0
    noise_factor: float = 4.0
    never_factor: float = 1.0
    min_free_fraction: float = 0.1
    blur_sigma_px: float = 1.0
    min_blob_fraction: float = 0.15
    min_person_fraction: float = 0.005
    grabcut: bool = True
    grabcut_iterations: int = 2
    grabcut_margin_px: int = 6
    trust_seen_background: bool = True
    min_ambiguous_px: int = 30
    skin: bool = True
    interior_edges: bool = False
    canny_thresholds: tuple[float, float] = (30.0, 80.0)
    moving_camera_fraction: float = 0.25
    fuse_learned: bool = True
    learned_core_px: float = 2.0
    learned_band_px: float = 4.0
    learned_max_gap: int = 15


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
    them the scale of stage 1's camera (synthetic cases: -6 %). Blobs over never-seen
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
    # lost in the calibration frame, camera scale -22 %). It decides the never-seen pixels.
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


def _disc(mask: np.ndarray, r: int) -> np.ndarray:
    """``mask`` dilated (r > 0) or eroded (r < 0) by a disc of radius |r| pixels."""
    k = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (2 * abs(r) + 1, 2 * abs(r) + 1))
    m = mask.astype(np.uint8)
    if r > 0:
        return np.asarray(cv2.dilate(m, k)) > 0
    # pixels outside the image count as background, so a body cut by the border erodes there
    return np.asarray(cv2.erode(m, k, borderType=cv2.BORDER_CONSTANT, borderValue=(0,))) > 0


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


def extract_foreground(
    frames: np.ndarray,
    settings: ForegroundSettings = ForegroundSettings(),
    *,
    learned: np.ndarray | None = None,
    on_progress: ProgressFn | None = None,
) -> ForegroundResult:
    """Body regions S'_t' of a static-camera video (thesis 4.1).

    Parameters
    ----------
    frames : ndarray of uint8, shape (T', H, W, 3)
        RGB frames (:attr:`engine.io.video.Video.frames`).
    settings : ForegroundSettings
    learned : ndarray of uint8, shape (T', H, W), optional
        The learned person mask (:attr:`engine.stages.perception.Perception.mask`), fused
        where it found a person when ``settings.fuse_learned``; a frame whose mask is empty
        is flagged ``no_detection`` and keeps the thesis' region.
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
    if learned is not None and np.shape(learned) != f.shape[:3]:
        raise InvalidInput(
            f"learned must be (T', H, W) = {f.shape[:3]} like the frames, got {np.shape(learned)}"
        )
    s = settings
    timing = {"background": 0.0, "difference": 0.0, "grabcut": 0.0, "skin": 0.0}
    t0 = time.perf_counter()
    bg = estimate_background(
        f, samples=s.background_samples, threshold=s.threshold, blur_sigma_px=s.blur_sigma_px,
        min_free_fraction=s.min_free_fraction,
    )  # fmt: skip
    never = bg.never
    timing["background"] = time.perf_counter() - t0
    n, h, w = f.shape[:3]
    sil = np.zeros((n, h, w), bool)
    skin = np.zeros((n, h, w), bool)
    edges = np.zeros((n, h, w), bool)
    flags: list[tuple[str, ...]] = []
    grow = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (15, 15))
    source = _nearest_detection(learned, s.learned_max_gap) if learned is not None else None
    for i in range(n):
        if source is not None and s.fuse_learned and source[i] >= 0:
            j = int(source[i])
            mask, raw, blobs, t = fuse_learned_mask(
                f[i], learned[j], bg, s, slack_px=float(abs(i - j))  # type: ignore[index]
            )
        else:
            mask, raw, blobs, t = segment_frame(f[i], bg, s)
        timing["difference"] += t["difference"]
        timing["grabcut"] += t["grabcut"]
        t0 = time.perf_counter()
        if s.skin and mask.any():
            near = cv2.dilate(mask.astype(np.uint8), grow).astype(bool)
            sk = skin_mask(f[i]) & near & (raw | mask)
            sk = cv2.morphologyEx(sk.astype(np.uint8), cv2.MORPH_OPEN, np.ones((2, 2), np.uint8))
            skin[i] = sk.astype(bool)
            mask = mask | skin[i]
        timing["skin"] += time.perf_counter() - t0
        sil[i] = mask
        edges[i] = outline(mask, skin[i])
        if s.interior_edges:
            edges[i] |= interior_edges(f[i], mask, s.canny_thresholds)
        fl = _flags(mask, raw, blobs, never, s, grow)
        if learned is not None and not learned[i].any():
            fl = (*fl, "no_detection")
        flags.append(fl)
        if on_progress is not None:
            on_progress("foreground", (i + 1) / n)
    return ForegroundResult(sil, edges, skin, bg.image, tuple(flags), timing)


def _nearest_detection(learned: np.ndarray, max_gap: int) -> np.ndarray:
    """For each frame, the nearest frame (itself first) whose learned mask is not empty and
    at most ``max_gap`` frames away; -1 where there is none. (T', H, W) -> (T',) int."""
    found = np.flatnonzero(learned.reshape(len(learned), -1).any(1))
    out = np.full(len(learned), -1)
    if found.size == 0:
        return out
    t = np.arange(len(learned))
    pos = np.clip(np.searchsorted(found, t), 1, max(found.size - 1, 1))
    lo, hi = found[pos - 1], found[np.minimum(pos, found.size - 1)]
    near = np.where(np.abs(t - lo) <= np.abs(hi - t), lo, hi)
    return np.where(np.abs(near - t) <= max_gap, near, -1)


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
