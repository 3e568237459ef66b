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


@dataclass(frozen=True)
class SegmentReport:
    """One performed segment (thesis 4.7; 6.6 status).

    Attributes
    ----------
    reference_start, reference_end : int
        Reference boundary frames (inclusive).
    performer_start, performer_end : int
        Performer boundary frames (inclusive).
    initial_performer_start : int
        The stage-2 estimate of ``performer_start`` (4.7.1 step 1).
    name : str
    status : str
        "ok", "missing" or "extra_motion" (6.6).
    boundary_found : bool
        Whether the start boundary satisfied the velocity condition (else best-posture fallback).
    tempo : float
        Performer duration / reference duration (seconds over seconds).
    mean_error : float
        Mean eps_t' over the frames the segment owns (its end frame, when another segment
        starts there, belongs to that one; see
        :func:`engine.stages.selection.owned_frames`), radians.
    bone_mean_errors : ndarray, shape (16,)
        Radians, over the same frames.
    worst_frame : int
        Video frame of the largest eps_t' among them.
    cost : float
        E_F of eq. 4.24 along the chosen path.
    """

    reference_start: int
    reference_end: int
    performer_start: int
    performer_end: int
    initial_performer_start: int
    name: str
    status: str
    boundary_found: bool
    tempo: float
    mean_error: float
    bone_mean_errors: np.ndarray
    worst_frame: int
    cost: float


@dataclass(frozen=True)
class Selection:
    """Output of stage 4 (:func:`engine.stages.selection.select_and_refine`), the shape the
    result writer (:func:`engine.io.result.build_result`) reads.

    Attributes
    ----------
    performer_segments : Segments
        Performer boundaries (video frames), names from the reference segments.
    C : ndarray of int, shape (T',)
        Refined temporal correspondence C(t').
    selected : ndarray of int, shape (T',)
        Selected candidate l(t').
    joints : ndarray, shape (T', 17, 3)
        Selected postures B'_{t' l(t')}.
    posture_error : ndarray, shape (T',)
        eps_t' = d_B(B_C(t'), B'_t'), radians.
    bone_errors : ndarray, shape (T', 16)
        Per-bone angle, radians.
    flags : tuple of tuple of str
        Per video frame.
    segments : tuple of SegmentReport
    messages : tuple of str
        Overall messages for the performer (6.6, 6.7).
    """

    performer_segments: Segments
    C: np.ndarray
    selected: np.ndarray
    joints: np.ndarray
    posture_error: np.ndarray
    bone_errors: np.ndarray
    flags: tuple[tuple[str, ...], ...]
    segments: tuple[SegmentReport, ...]
    messages: tuple[str, ...] = field(default=())
