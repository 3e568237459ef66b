"""A BVH reference on the 17-joint body: the source joints mapped by name (or by the user's
mapping), file units to metres, the heading normalised and a conversion T-pose detected
(thesis 2.1.1).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from engine.body.kinematics import bone_directions, rot_y
from engine.body.shapes import BodyShape
from engine.body.skeleton import JOINT_INDEX, JOINTS
from engine.errors import InvalidInput
from engine.io._bvh_names import resolve
from engine.io.bvh.kinematics import bvh_forward_kinematics
from engine.io.bvh.parse import BvhFile, BvhLimits, read_bvh
from engine.types import Motion

CMU_UNITS_TO_M = 0.056444

#: Node-frames per forward-kinematics pass (about 25 MB of transforms): memory stays flat
#: however long the file, and files of a few thousand frames still go in one pass.
_FK_NODE_FRAMES = 1 << 17


@dataclass(frozen=True)
class Reference:
    """A reference motion loaded from BVH, on the 17-joint body (thesis 2.1.1: M and H).

    Attributes
    ----------
    motion : Motion
        Joints (T, 17, 3) in the world frame of DESIGN.md: metres, y up, heading-normalised.
    shape : BodyShape
        The expert's body, :meth:`BodyShape.from_rest_joints` of the T-pose frame when the
        file has one, else of frame 0.
    source_joint_names : tuple of str
        Source node mapped to each of the 17 joints, in :data:`JOINTS` order.
    R_world_bvh : ndarray, shape (3, 3)
        Heading rotation applied (about y): world = R_world_bvh @ (units_to_m * bvh).
    units_to_m : float
        Scale from file units to metres that was used.
    profile : str
        Name table that matched ("cmu", "mixamo", "biped", "generic", "coach", "user").
    bvh : BvhFile
        The raw parsed file (for sampling local rotations, :func:`sample_reference`).
    """

    motion: Motion
    shape: BodyShape
    source_joint_names: tuple[str, ...]
    R_world_bvh: np.ndarray
    units_to_m: float
    profile: str
    bvh: BvhFile

    @property
    def heading_rad(self) -> float:
        """Angle of the heading rotation about y, radians."""
        return float(math.atan2(self.R_world_bvh[0, 2], self.R_world_bvh[0, 0]))

    @property
    def has_tpose(self) -> bool:
        return self.motion.first_motion_frame > 0


def load_reference(
    path: str | os.PathLike,
    *,
    mapping: dict[str, str] | None = None,
    units_to_m: float | None = None,
    normalise_heading: bool = True,
    limits: BvhLimits | None = None,
) -> Reference:
    """Load a BVH reference motion onto the 17-joint body (thesis 2.1.1).

    Parameters
    ----------
    path : str or path-like
        The BVH file.
    mapping : dict of str to str, optional
        Our joint name -> source joint name (end sites are ``<parent>/End``), overriding
        the name tables for the joints it names.
    units_to_m : float, optional
        Metres per file unit; guessed from the skeleton's size when omitted (module doc).
    normalise_heading : bool
        Rotate about y (through the origin) so that the body faces +z at frame 0
        (DESIGN.md "Frames of reference"). True for every analysis; False keeps the
        file's own heading.
    limits : BvhLimits, optional
        Refuse files with more frames, joints, channels or a longer duration, before their
        motion is read (:func:`read_bvh`); None reads any file.

    Returns
    -------
    Reference

    Raises
    ------
    InvalidInput
        Malformed file or over ``limits``, unknown names in ``mapping``, joints that
        cannot be mapped (the message names them), or units that cannot be guessed.
    """
    bvh = read_bvh(path, limits)
    idx, profile = _mapping(bvh, mapping)
    if units_to_m is None:
        units_to_m = _guess_units(bvh, idx, Path(path).name)
    elif not (isinstance(units_to_m, int | float) and math.isfinite(units_to_m) and units_to_m > 0):
        raise InvalidInput(f"units_to_m must be a positive number, got {units_to_m!r}")
    joints = _mapped_positions(bvh, idx) * float(units_to_m)
    R = heading_rotation(joints[0]) if normalise_heading else np.eye(3)
    joints = joints @ R.T
    first = 1 if is_tpose(joints[0]) and bvh.frames > 1 else 0
    shape = BodyShape.from_rest_joints(joints[0])
    motion = Motion(joints=joints, fps=bvh.fps, name=Path(path).stem, first_motion_frame=first)
    return Reference(
        motion=motion,
        shape=shape,
        source_joint_names=tuple(bvh.names[i] for i in idx),
        R_world_bvh=R,
        units_to_m=float(units_to_m),
        profile=profile,
        bvh=bvh,
    )


def _mapped_positions(bvh: BvhFile, idx: np.ndarray) -> np.ndarray:
    """World positions (T, len(idx), 3) of the nodes ``idx``, file units, a chunk of frames
    at a time (frames are independent, so the result is the same as in one pass)."""
    step = max(1, _FK_NODE_FRAMES // len(bvh.names))
    chunks = [
        bvh_forward_kinematics(replace(bvh, values=bvh.values[a : a + step]))[:, idx]
        for a in range(0, bvh.frames, step)
    ]
    return np.concatenate(chunks)


def _mapping(bvh: BvhFile, mapping: dict[str, str] | None) -> tuple[np.ndarray, str]:
    found, missing, profile = resolve(bvh.names)
    if mapping:
        unknown = [k for k in mapping if k not in JOINT_INDEX]
        if unknown:
            raise InvalidInput(
                f"mapping names unknown joints {unknown}; our joints are {list(JOINTS)}"
            )
        pos = {n: i for i, n in enumerate(bvh.names)}
        absent = [v for v in mapping.values() if v not in pos]
        if absent:
            raise InvalidInput(f"mapping refers to joints not in the file: {absent}")
        found = dict(found) | {k: pos[v] for k, v in mapping.items()}
        missing = tuple(j for j in JOINTS if j not in found)
        profile = "user" if not missing else profile
    if missing:
        raise InvalidInput(
            "cannot map the BVH skeleton onto the 17-joint body: missing "
            + ", ".join(missing)
            + f" (closest name table: {profile}; the file's joints are "
            + ", ".join(bvh.names)
            + "). Pass a mapping {our_joint: file_joint} for the missing joints."
        )
    return np.array([found[j] for j in JOINTS]), profile


_UNIT_RANGES = (
    (0.4, 3.0, 1.0),
    (12.0, 45.0, CMU_UNITS_TO_M),
    (45.0, 300.0, 0.01),
    (450, 3000, 0.001),
)


_CHAIN = ("l_ankle", "l_knee", "l_hip", "hip", "lower_chest", "upper_chest", "neck", "head_top")


def _guess_units(bvh: BvhFile, idx: np.ndarray, name: str) -> float:
    rest = np.zeros((len(bvh.names), 3))
    for n, p in enumerate(bvh.parents):
        rest[n] = bvh.offsets[n] + (rest[p] if p >= 0 else 0.0)
    pts = rest[idx[[JOINT_INDEX[j] for j in _CHAIN]]]
    length = float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())
    for lo, hi, k in _UNIT_RANGES:
        if lo <= length < hi:
            return k
    raise InvalidInput(
        f"{name}: cannot guess the units (ankle-to-head chain is {length:.4g} file units); "
        "pass units_to_m"
    )


def heading_rotation(joints0: np.ndarray) -> np.ndarray:
    """Rotation about y that turns a posture to face +z (DESIGN.md "Frames of reference").

    Facing is the horizontal part of ``cross(l_hip - r_hip, up)``.

    Parameters
    ----------
    joints0 : ndarray, shape (17, 3)

    Returns
    -------
    R : ndarray, shape (3, 3)
        ``R @ facing`` is along +z.
    """
    f = np.cross(joints0[JOINT_INDEX["l_hip"]] - joints0[JOINT_INDEX["r_hip"]], [0.0, 1.0, 0.0])
    if math.hypot(f[0], f[2]) < 1e-9:
        return np.eye(3)
    return rot_y(math.atan2(-f[0], f[2]))


_ARM_BONES = np.array([9, 10, 12, 13])  # upper and lower arms (bone b ends at joint b + 1)


_LEG_BONES = np.array([1, 2, 4, 5])


def is_tpose(joints: np.ndarray, *, tol_deg: float = 20.0) -> bool:
    """Whether a posture is a conversion T-pose: arms straight out sideways, legs straight down.

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
        Heading-normalised (facing +z, left at +x).
    tol_deg : float
        Largest deviation of any arm or leg bone from its T-pose direction.
    """
    d = bone_directions(np.asarray(joints, dtype=float))
    want = np.zeros((8, 3))
    want[:2, 0], want[2:4, 0], want[4:, 1] = 1.0, -1.0, -1.0
    cos = np.sum(d[np.r_[_ARM_BONES, _LEG_BONES]] * want, axis=1)
    return bool(np.all(cos > math.cos(math.radians(tol_deg))))
