"""What a synthetic performer is made of: the settings, the reference it reads, the case it
gives.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from engine.body.shapes import BodyShape
from engine.body.skeleton import JOINTS, PART_INDEX, PART_ROOT_JOINT, PARTS
from engine.errors import InvalidInput
from engine.render.camera import Camera
from engine.types import Motion


class ReferenceLike(Protocol):
    """What :func:`synthesize` needs of a reference (e.g. :class:`engine.io.bvh.Reference`)."""

    # read-only: a frozen dataclass (engine.io.bvh.Reference) must satisfy the protocol
    @property
    def motion(self) -> Motion: ...

    @property
    def shape(self) -> BodyShape: ...


@dataclass(frozen=True)
class SynthSettings:
    """How a synthetic performer differs from the reference, and how it is filmed.

    Attributes
    ----------
    fps : float
        Video frame rate (thesis: 25-30 typical, 12.5 in 5.4); at most the reference's.
    width, height : int
        Image size in pixels (even, for yuv420p video).
    warp_strength : float
        Standard deviation of the log speed of each segment relative to the reference
        (0 = same timing, only the frame rate changes).
    error_deg : float
        Articulation amplitude of a wrong segment, degrees (thesis 5.2.2 uses up to 20).
    n_wrong : int
        Number of wrong segments (table 2.1: any subset may be wrong).
    parts_per_wrong : int
        Parts articulated in each wrong segment.
    error_parts : tuple of str, optional
        Parts that may be articulated, by part name or root joint name (``"l_elbow"`` means
        the left lower arm); all but the abdomen when omitted.
    yaw_deg : float
        Global rotation of the performer about the vertical through the hip, degrees.
    azimuth_deg : float
        Camera azimuth (0 = facing the body's front, 90 = its left side), degrees.
    theta_z_deg : float
        In-plane camera rotation, degrees.
    noise_sigma : float
        Standard deviation of the Gaussian sensor noise, grey levels (0-255).
    fill : float
        Fraction of the image height the body's extent over the whole motion spans.
    ramp : float
        Fraction of a wrong segment over which its error ramps in (and out), smoothly.
    n_segments : int
        Equal segments to use when the reference comes without segment boundaries and
        :mod:`engine.reference.boundaries` is not available.
    max_frames : int, optional
        Keep only the first ``max_frames`` video frames (the video then ends before the
        reference does; the truth says so in ``notes``).
    background : bool
        Textured wall and floor (True) or plain grey.
    """

    fps: float = 30.0
    width: int = 320
    height: int = 240
    warp_strength: float = 0.25
    error_deg: float = 20.0
    n_wrong: int = 2
    parts_per_wrong: int = 3
    error_parts: tuple[str, ...] | None = None
    yaw_deg: float = 0.0
    azimuth_deg: float = 0.0
    theta_z_deg: float = 0.0
    noise_sigma: float = 2.0
    fill: float = 0.8
    ramp: float = 0.2
    n_segments: int = 4
    max_frames: int | None = None
    background: bool = True

    def __post_init__(self) -> None:
        _check(np.isfinite(self.fps) and self.fps > 0, "fps", "> 0", self.fps)
        for name in ("width", "height"):
            v = getattr(self, name)
            _check(int(v) == v and v >= 16 and v % 2 == 0, name, "an even integer >= 16", v)
        _check(self.warp_strength >= 0, "warp_strength", ">= 0", self.warp_strength)
        _check(0 <= self.error_deg <= 180, "error_deg", "in [0, 180]", self.error_deg)
        _check(self.n_wrong >= 0, "n_wrong", ">= 0", self.n_wrong)
        _check(self.parts_per_wrong >= 1, "parts_per_wrong", ">= 1", self.parts_per_wrong)
        _check(
            np.isfinite(self.noise_sigma) and self.noise_sigma >= 0,
            "noise_sigma",
            ">= 0",
            self.noise_sigma,
        )
        _check(0 < self.fill <= 1, "fill", "in (0, 1]", self.fill)
        _check(0 < self.ramp <= 0.5, "ramp", "in (0, 0.5]", self.ramp)
        _check(self.n_segments >= 1, "n_segments", ">= 1", self.n_segments)
        _check(
            self.max_frames is None or self.max_frames >= 2, "max_frames", ">= 2", self.max_frames
        )
        for name in ("yaw_deg", "azimuth_deg", "theta_z_deg"):
            _check(np.isfinite(getattr(self, name)), name, "finite", getattr(self, name))
        if self.error_parts is not None:
            resolve_parts(self.error_parts)


@dataclass(frozen=True)
class SynthCase:
    """A synthetic performer video with its ground truth.

    Attributes
    ----------
    frames : ndarray of uint8, shape (T', H, W, 3)
        RGB video frames.
    masks : ndarray of bool, shape (T', H, W)
        True body silhouettes S'_t'.
    joints_3d : ndarray, shape (T', 17, 3)
        True performer postures B'_t', world frame, metres.
    warp : ndarray, shape (T',)
        True C(t'), fractional reference frames.
    camera : Camera
    fps : float
    truth : dict
        ``truth.json`` content (DESIGN.md "Synthetic cases").
    """

    frames: np.ndarray
    masks: np.ndarray
    joints_3d: np.ndarray
    warp: np.ndarray
    camera: Camera
    fps: float
    truth: dict = field(repr=False)


def _check(ok: bool, name: str, expected: str, got: object) -> None:
    if not ok:
        raise InvalidInput(f"{name} must be {expected}, got {got!r}")


def resolve_parts(names: tuple[str, ...] | list[str]) -> tuple[int, ...]:
    """Part indices from part names or root joint names.

    Raises
    ------
    InvalidInput
        A name that is neither, naming it and the valid choices.
    """
    root_of = {JOINTS[int(j)]: p for p, j in enumerate(PART_ROOT_JOINT)}
    out = []
    for n in names:
        if n in PART_INDEX:
            out.append(PART_INDEX[n])
        elif n in root_of:
            out.append(root_of[n])
        else:
            raise InvalidInput(
                f"error_parts: unknown part or joint {n!r}; choose from {', '.join(PARTS)} "
                f"or the joints {', '.join(sorted(root_of))}"
            )
    return tuple(out)
