"""Stage 0 over a whole video: the background, then each frame's region, skin, edges and
quality flags.
"""

from __future__ import annotations

import time
from collections.abc import Callable

import cv2
import numpy as np

from engine.errors import InvalidInput
from engine.stages.foreground.background import Background, estimate_background
from engine.stages.foreground.edges import interior_edges, outline, skin_mask
from engine.stages.foreground.segment import fuse_learned_mask, segment_frame
from engine.stages.foreground.settings import ForegroundResult, ForegroundSettings
from engine.threads import map_in_threads

ProgressFn = Callable[[str, float], None]


#: The default settings, one frozen instance (the argument default of :func:`extract_foreground`).
_DEFAULTS = ForegroundSettings()


def extract_foreground(
    frames: np.ndarray,
    settings: ForegroundSettings = _DEFAULTS,
    *,
    learned: np.ndarray | None = None,
    background: Background | None = None,
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
    background : Background, optional
        :func:`background_of` these frames, when the caller computed it already (beside the
        pose model, :func:`engine.pipeline.prepare`).
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
    f = _checked_frames(frames, learned)
    s = settings
    timing = {"background": 0.0, "difference": 0.0, "grabcut": 0.0, "skin": 0.0}
    t0 = time.perf_counter()
    bg = background_of(f, s) if background is None else background
    timing["background"] = time.perf_counter() - t0
    n, h, w = f.shape[:3]
    sil = np.zeros((n, h, w), bool)
    skin = np.zeros((n, h, w), bool)
    edges = np.zeros((n, h, w), bool)
    flags: list[tuple[str, ...]] = []
    grow = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (15, 15))
    source = _nearest_detection(learned, s.learned_max_gap) if learned is not None else None

    def frame(i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[str, ...], dict]:
        """Frame i's region, skin, edges (H, W) and flags, and the seconds per step."""
        t: dict[str, float] = {"difference": 0.0, "grabcut": 0.0, "skin": 0.0}
        mask, raw, blobs = _region(f, i, bg, s, learned, source, t)
        t0 = time.perf_counter()
        sk = np.zeros((h, w), bool)
        if s.skin and mask.any():
            sk = _skin_near(f[i], mask, raw, grow)
            mask = mask | sk
        t["skin"] += time.perf_counter() - t0
        e = outline(mask, sk)
        if s.interior_edges:
            e |= interior_edges(f[i], mask, s.canny_thresholds)
        fl = _flags(mask, raw, blobs, bg.never, s, grow)
        if learned is not None and not learned[i].any():
            fl = (*fl, "no_detection")
        return mask, sk, e, fl, t

    # frames are independent given the background: threads share them (OpenCV's GrabCut
    # and the numpy work release the GIL); the seconds below add up the threads' time
    for i, (mask, sk, e, fl, t) in enumerate(map_in_threads(frame, range(n), s.threads)):
        sil[i], skin[i], edges[i] = mask, sk, e
        flags.append(fl)
        for k, v in t.items():
            timing[k] += v
        if on_progress is not None:
            on_progress("foreground", (i + 1) / n)
    return ForegroundResult(sil, edges, skin, bg.image, tuple(flags), timing)


def background_of(frames: np.ndarray, settings: ForegroundSettings = _DEFAULTS) -> Background:
    """Stage 0's background model of ``frames`` (T', H, W, 3) with ``settings``
    (:func:`~engine.stages.foreground.background.estimate_background`)."""
    s = settings
    return estimate_background(
        frames, samples=s.background_samples, threshold=s.threshold,
        blur_sigma_px=s.blur_sigma_px, min_free_fraction=s.min_free_fraction,
    )  # fmt: skip


def _checked_frames(frames: np.ndarray, learned: np.ndarray | None) -> np.ndarray:
    """The frames as an array (T', H, W, 3), or InvalidInput naming the bad parameter."""
    f = np.asarray(frames)
    if f.ndim != 4 or f.shape[-1] != 3 or f.dtype != np.uint8 or f.shape[0] < 2:
        raise InvalidInput(
            f"frames must be uint8 of shape (T' >= 2, H, W, 3), got {f.dtype} {f.shape}"
        )
    if learned is not None and np.shape(learned) != f.shape[:3]:
        raise InvalidInput(
            f"learned must be (T', H, W) = {f.shape[:3]} like the frames, got {np.shape(learned)}"
        )
    return f


def _region(
    f: np.ndarray,
    i: int,
    bg: Background,
    s: ForegroundSettings,
    learned: np.ndarray | None,
    source: np.ndarray | None,
    timing: dict[str, float],
) -> tuple[np.ndarray, np.ndarray, int]:
    """Frame i's body region (H, W), thresholded difference (H, W) and blob count: fused
    with the learned mask of the nearest frame that has one (``source``, (T',)), else the
    thesis' own; adds the seconds spent to ``timing``."""
    if source is not None and s.fuse_learned and source[i] >= 0:
        j = int(source[i])
        mask, raw, blobs, t = fuse_learned_mask(
            f[i], learned[j], bg, s, slack_px=float(abs(i - j))  # type: ignore[index]
        )  # fmt: skip
    else:
        mask, raw, blobs, t = segment_frame(f[i], bg, s)
    timing["difference"] += t["difference"]
    timing["grabcut"] += t["grabcut"]
    return mask, raw, blobs


def _skin_near(
    frame: np.ndarray, mask: np.ndarray, raw: np.ndarray, grow: np.ndarray
) -> np.ndarray:
    """Skin regions (H, W) of a frame near its body region ``mask`` (within ``grow``) and
    differing from the background or inside the region (thesis 4.1.2)."""
    near = cv2.dilate(mask.astype(np.uint8), grow).astype(bool)
    sk = skin_mask(frame) & near & (raw | mask)
    sk = cv2.morphologyEx(sk.astype(np.uint8), cv2.MORPH_OPEN, np.ones((2, 2), np.uint8))
    return sk.astype(bool)


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
