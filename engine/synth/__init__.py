"""Synthetic performers with exact ground truth (thesis 2.1.2-2.1.3, table 2.1; 5.2.1).

A performer is made from a reference motion the way the thesis describes how performers differ
from the expert:

- *timing* (2.1.3 item 3): a smooth, strictly monotone time warp C(t') whose speed differs per
  reference segment, pinned to the first and last reference frames (2.1.3 item 4);
- *articulation* (2.1.3 item 5, approach c: B'_t' = A_t'(T_t'(B_C(t')))): in some segments the
  performer is right, in others chosen parts are rotated about their root joint by a given
  amplitude; errors of different segments are independent (item 7, table 2.1) and change
  smoothly (item 6), ramping in and out at the segment's ends;
- an optional global yaw T_t' about the vertical through the hip;
- a fixed scaled orthographic camera (2.1.3 item 1) framing the body at ~80 % of the image
  height, a textured static background and Gaussian sensor noise.

The reference at the fractional frame C(t') is :func:`engine.io.bvh.sample_reference`
(slerp of the file's local rotations), the same sampling the truth's bone errors are
measured against. Every random choice comes from the ``rng`` passed in.

    settings      SynthSettings, SynthCase, the reference it reads (ReferenceLike)
    timing        reference segments and the time warp
    articulation  the wrong segments' part rotations
    film          the camera, the rendered video
    truth         the truth.json dictionary
    performer     synthesize: all of it in one call
"""

from engine.synth.articulation import ARTICULABLE_PARTS, articulate
from engine.synth.film import fit_camera
from engine.synth.performer import synthesize
from engine.synth.settings import ReferenceLike, SynthCase, SynthSettings, resolve_parts
from engine.synth.timing import reference_segments, time_warp

__all__ = [
    "ARTICULABLE_PARTS",
    "ReferenceLike",
    "SynthCase",
    "SynthSettings",
    "articulate",
    "fit_camera",
    "reference_segments",
    "resolve_parts",
    "synthesize",
    "time_warp",
]
