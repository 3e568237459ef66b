"""Shared types and the axis glossary used in every shape annotation of the engine.

Axis letters (batch and time axes first):

====  =====================================================
T'    video frames (written ``Tv`` in code)
T     reference frames
J     joints (17, order in :mod:`engine.body.skeleton`)
B     bones (16; bone ``b`` ends at joint ``b + 1``)
P     rigid body parts (12)
K     posture candidates per frame
S     samples (rotation samples in stage 2, pose samples in stage 3)
H, W  image rows and columns; images are (row, col); (u, v) = (col, row) pixels
====  =====================================================

Units inside the engine: metres, radians, seconds. Degrees and pixels appear only at the
edges, with a suffix (``_deg``, ``_px``). Transforms are named ``T_a_b`` / ``R_a_b``: they map
points from frame b into frame a.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(frozen=True)
class Motion:
    """A sequence of postures of the 17-joint body, in the world frame of DESIGN.md.

    Attributes
    ----------
    joints : ndarray, shape (T, 17, 3)
        Joint positions in metres, world frame (y up, body facing +z at frame 0).
    fps : float
        Frames per second.
    name : str
        Human-readable name (file stem for BVH imports).
    first_motion_frame : int
        Index of the first frame that belongs to the motion (1 when the file starts with a
        conversion T-pose, else 0). Frame numbers always count the frames as given.
    """

    joints: np.ndarray
    fps: float
    name: str = ""
    first_motion_frame: int = 0

    @property
    def frames(self) -> int:
        return int(self.joints.shape[0])

    @property
    def duration_s(self) -> float:
        return (self.frames - 1) / self.fps if self.frames > 1 else 0.0


@dataclass(frozen=True)
class Segments:
    """Segment boundaries of a motion, as frame indices.

    Attributes
    ----------
    starts : tuple of int
        First frame of each segment; ``starts[0]`` is the motion's first frame.
    end : int
        Last frame of the last segment (inclusive).
    names : tuple of str
        One name per segment (empty strings when unnamed).
    """

    starts: tuple[int, ...]
    end: int
    names: tuple[str, ...] = field(default=())

    def bounds(self) -> list[tuple[int, int]]:
        """(start, end) inclusive pairs, one per segment."""
        ends = [s for s in self.starts[1:]] + [self.end]
        return list(zip(self.starts, ends, strict=True))
