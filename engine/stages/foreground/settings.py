"""The tuning of stage 0 (thesis 4.1) and its output, the body regions of every frame."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class ForegroundSettings:
    """Settings of stage 0 (thesis 4.1), with the defaults used on 320 x 240 video.

    The benchmark figures behind the defaults beyond the thesis are in
    ``benchmarks/README.md`` ("Design figures", stage 0).

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
        the only chance to learn it. On P2 (a prop of the shirt's colour behind him) both
        the region and the estimated posture errors improved clearly.
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
        Off: on the public and synthetic cases together the errors got worse with them. P1
        gains, and P2 loses, where a prop of the shirt's colour joins the region with its
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
        band widened by 1 px (at 240 rows) per frame of distance (P3: many frames lost, the
        grey clothes barely differ from the wall). Farther, the thesis' region.
    threads : int
        Threads sharing the frames once the background is known (0: every core this
        process may use; :mod:`engine.threads`). The result does not depend on it.
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
    threads: int = 0


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

    def cut(self, start: int, end: int) -> ForegroundResult:
        """Frames ``start``..``end - 1`` only (the background is the whole video's)."""
        sl = slice(start, end)
        return dataclasses.replace(
            self, silhouettes=self.silhouettes[sl], edges=self.edges[sl], skin=self.skin[sl],
            flags=self.flags[sl],
        )  # fmt: skip
