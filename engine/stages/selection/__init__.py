"""Stage 4: performer segment boundaries, candidate selection, refined C, posture errors.

Thesis 4.7 (4.7.1 boundaries, 4.7.2 per-segment DP, eq. 4.22-4.30), with the constraints of
2.1.6 (B temporal order, C boundary similarity, D small rate of change of errors) and three
additions from chapter 6:

- 6.6 missing or extraneous segments are *detected and reported* (a performer segment far too
  short is "missing", far too long is "extra_motion") instead of being forced to match;
- 6.7 a performer whose selected postures are far from the reference everywhere gets one
  overall message (``Selection.messages``) rather than a per-bone list of noise;
- 2.1.3 item 4: a performer who pauses at a boundary (a run of unchanged postures) has the
  pause reduced to its first frame, whose in/out motion directions are those around the pause.

Everything here works on joint positions in the world frame, shape (..., 17, 3); errors are in
radians (degrees only in :mod:`engine.io.result`).

    settings    SelectionSettings
    evidence    checks; candidates padded, bone directions, image evidence per candidate
    boundaries  performer segment boundaries (4.7.1), missing and extra segments (6.6)
    paths       the per-segment DP (4.7.2): refined C and the selected candidates
    errors      eps_t' smoothed within segments, flags, segment reports, messages (6.6, 6.7)
    stage       select_and_refine: the stage in one call
"""

from engine.stages.selection.errors import owned_frames, smooth_errors
from engine.stages.selection.paths import refine_segment
from engine.stages.selection.settings import SelectionSettings
from engine.stages.selection.stage import select_and_refine
from engine.types import SegmentReport, Selection

__all__ = [
    "SegmentReport",
    "Selection",
    "SelectionSettings",
    "owned_frames",
    "refine_segment",
    "select_and_refine",
    "smooth_errors",
]
