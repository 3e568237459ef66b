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

    settings    ForegroundSettings, ForegroundResult
    background  the background model (step 1)
    regions     GrabCut from a trimap, clean-up of a mask (steps 2-3)
    segment     one frame's region: the difference and GrabCut, or the learned mask fused
    edges       skin (step 4) and edges (step 5)
    extract     extract_foreground: the whole video, with quality flags
"""

from engine.stages.foreground.background import Background, estimate_background
from engine.stages.foreground.edges import contour, interior_edges, outline, skin_mask
from engine.stages.foreground.extract import background_of, extract_foreground
from engine.stages.foreground.regions import grabcut_seeded
from engine.stages.foreground.segment import fuse_learned_mask, segment_frame
from engine.stages.foreground.settings import ForegroundResult, ForegroundSettings

__all__ = [
    "Background",
    "background_of",
    "ForegroundResult",
    "ForegroundSettings",
    "contour",
    "estimate_background",
    "extract_foreground",
    "fuse_learned_mask",
    "grabcut_seeded",
    "interior_edges",
    "outline",
    "segment_frame",
    "skin_mask",
]
