"""Synthetic test helpers: reference motions from known postures (ground truth by construction)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.kinematics import forward_kinematics, rotation_about_axis
from engine.body.shapes import BodyShape
from engine.types import Motion


@dataclass(frozen=True)
class StubReference:
    """The part of a reference :func:`engine.synth.synthesize` reads: a motion and a body."""

    motion: Motion
    shape: BodyShape


def swing_joints(
    shape: BodyShape, T: int, *, sway_m: float = 0.1, travel_m: float = 0.0
) -> np.ndarray:
    """One cycle of an arm-and-leg swing built with forward kinematics, shape (T, 17, 3).

    Both arms swing and the left forearm bends; the legs swing in opposition. The root sways
    sideways by +- ``sway_m``, bobs by 2 cm and travels ``travel_m`` along +z (metres).
    """
    s = np.sin(np.linspace(0.0, 2.0 * np.pi, T))
    R = np.broadcast_to(np.eye(3), (T, 12, 3, 3)).copy()
    x, z = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])
    R[:, 4] = rotation_about_axis(z, -1.2 + 0.6 * s)
    R[:, 5] = rotation_about_axis(x, 0.8 + 0.5 * s) @ R[:, 4]
    R[:, 6] = rotation_about_axis(z, 1.2 - 0.6 * s)
    R[:, 7] = R[:, 6]
    R[:, 8] = rotation_about_axis(x, -0.4 * s)
    R[:, 10] = rotation_about_axis(x, 0.4 * s)
    root = np.stack([sway_m * s, 0.95 + 0.02 * s, np.linspace(0.0, travel_m, T)], -1)
    return forward_kinematics(shape.offsets, root, R)
