"""Writing postures of the 17-joint body as a BVH file that
:func:`engine.io.bvh.load_reference` reads back.
"""

from __future__ import annotations

import math
import os
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from engine.body.kinematics import bone_vectors, part_rotations, rotation_between
from engine.body.shapes import BodyShape
from engine.body.skeleton import BONE_PARENT, JOINTS, PARENTS, PART_BONES, PART_ROOT_JOINT
from engine.errors import InvalidInput

#: Joint names of the CMU skeleton (Hahne's conversion, ``../shared/data/cmu``) for our joints:
#: the joints of CMU's that lie where ours do (DESIGN.md's table); the head top is the Head's
#: End Site there and the Head joint itself here, at the same place (our leaves end at zero).
CMU_NAMES: dict[str, str] = {
    "hip": "Hips", "l_hip": "LeftUpLeg", "l_knee": "LeftLeg", "l_ankle": "LeftFoot",
    "r_hip": "RightUpLeg", "r_knee": "RightLeg", "r_ankle": "RightFoot",
    "lower_chest": "Spine", "upper_chest": "Spine1", "l_shoulder": "LeftArm",
    "l_elbow": "LeftForeArm", "l_wrist": "LeftHand", "r_shoulder": "RightArm",
    "r_elbow": "RightForeArm", "r_wrist": "RightHand", "neck": "Neck1", "head_top": "Head",
}  # fmt: skip


def write_bvh(
    path: str | os.PathLike,
    joints: np.ndarray,
    fps: float,
    shape: BodyShape | None = None,
    *,
    names: str = "coach",
) -> Path:
    """Write postures of the 17-joint body as a BVH file (metres, our joint names).

    The hierarchy is the 17-joint skeleton with ``shape.offsets`` as bone offsets (constant
    bone lengths) and zero-rotation default posture; the root (hip) has position channels,
    every joint ``Zrotation Yrotation Xrotation`` (its part's rotation relative to its
    parent part, :func:`engine.body.kinematics.part_rotations`), leaves an End Site at zero
    offset. Postures produced by forward kinematics with ``shape`` are reproduced exactly by
    :func:`load_reference` (to ~1e-9 m). Others (a CMU spine that bends at the pelvis, a mean
    of several takes) do not fit the rigid hip and chest parts: each such bone then gets a
    zero-length joint of its own (``hip_to_lower_chest``, ...) whose rotation turns the rigid
    fit onto the bone, so every bone direction is kept exactly (the CMU golf swing 63_01
    otherwise loses up to 13 deg at the pelvis). Write already heading-normalised postures
    (or load with ``normalise_heading=False``) for an exact round trip.

    Parameters
    ----------
    path : str or path-like
    joints : ndarray, shape (T, 17, 3)
        Metres.
    fps : float
    shape : BodyShape, optional
        Bone offsets of the default posture; ``BodyShape.from_rest_joints(joints[0])``
        when omitted.
    names : {"coach", "cmu"}
        Our joint names, or CMU's (:data:`CMU_NAMES`) so that tools made for the CMU
        library read the file; :func:`load_reference` reads both.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    InvalidInput
        When ``joints`` is not (T, 17, 3) finite, or ``fps`` is not positive.
    """
    J = _checked(joints, fps)
    if names not in ("coach", "cmu"):
        raise InvalidInput(f"names must be 'coach' or 'cmu', got {names!r}")
    if shape is None:
        shape = BodyShape.from_rest_joints(J[0])
    table = CMU_NAMES if names == "cmu" else {j: j for j in JOINTS}
    R_node, node_names, parents, offsets = _nodes(J, shape, table)
    children: dict[int, list[int]] = {j: [] for j in range(len(node_names))}
    for j in range(1, len(node_names)):
        children[parents[j]].append(j)
    out = ["HIERARCHY", *_hierarchy(node_names, offsets, children)]
    order = _dfs_order(children)
    out += ["MOTION", f"Frames: {J.shape[0]}", f"Frame Time: {1.0 / fps:.10g}"]
    euler = _local_euler_deg(R_node, parents)
    cols = np.concatenate([J[:, :1, :], euler[:, order]], axis=1).reshape(J.shape[0], -1)
    out += [" ".join(f"{v:.10g}" for v in row) for row in cols]
    p = Path(path)
    p.write_text("\n".join(out) + "\n")
    return p


#: A bone the rigid part's fit misses by less than this (0.1 deg, radians; what rounding
#: postures to 0.1 mm does to a 10 cm bone) needs no joint of its own.
_EXACT_RAD = float(np.radians(0.1))


def _nodes(
    J: np.ndarray, shape: BodyShape, table: dict[str, str]
) -> tuple[np.ndarray, list[str], list[int], np.ndarray]:
    """The BVH nodes: the 17 joints, plus a zero-length joint before each bone of a rigid
    multi-bone part (hip, upper chest) that the part's fit does not lay on the bone.

    Returns world rotations (T, N, 3, 3), names (N,), parent indices (N,) and offsets
    (N, 3), the 17 joints first in :data:`JOINTS` order.
    """
    R_world = part_rotations(J, shape.offsets)  # (T, 12, 3, 3)
    # world rotation of each BVH joint: that of the part it is the root of; leaves
    # (ankles, wrists, head top) inherit their parent's, i.e. a zero local rotation
    part_of_joint = np.full(17, -1)
    part_of_joint[PART_ROOT_JOINT] = np.arange(len(PART_ROOT_JOINT))
    R = [np.empty((J.shape[0], 3, 3)) for _ in range(17)]
    for j in range(17):
        R[j] = R_world[:, part_of_joint[j]] if part_of_joint[j] >= 0 else R[PARENTS[j]]
    names, parents = [table[j] for j in JOINTS], [int(p) for p in PARENTS]
    offsets = [np.zeros(3), *shape.offsets]
    vec = bone_vectors(J)
    for bones in (b for b in PART_BONES if len(b) > 1):
        for b in bones:
            head = int(BONE_PARENT[b])
            fitted = np.einsum("tij,j->ti", R[head], shape.offsets[b])
            fix = rotation_between(fitted, vec[:, b])  # (T, 3, 3), world frame
            angle = np.arccos(np.clip((np.trace(fix, axis1=-2, axis2=-1) - 1) / 2, -1, 1))
            if angle.max() <= _EXACT_RAD:
                continue
            names.append(f"{table[JOINTS[head]]}_to_{table[JOINTS[b + 1]]}")
            parents.append(head)
            offsets.append(np.zeros(3))
            R.append(fix @ R[head])
            parents[b + 1] = len(names) - 1  # the bone's joint hangs from its own node
    return np.stack(R, axis=1), names, parents, np.array(offsets)


def _checked(joints: np.ndarray, fps: float) -> np.ndarray:
    """``joints`` as finite floats (T, 17, 3), or InvalidInput naming the bad parameter."""
    J = np.asarray(joints, dtype=float)
    if J.ndim != 3 or J.shape[1:] != (17, 3) or J.shape[0] < 1:
        raise InvalidInput(f"joints must have shape (T, 17, 3), got {J.shape}")
    if not np.all(np.isfinite(J)):
        raise InvalidInput("joints contains NaN or infinite values")
    if not (isinstance(fps, int | float) and math.isfinite(fps) and fps > 0):
        raise InvalidInput(f"fps must be a positive number, got {fps!r}")
    return J


def _local_euler_deg(R_node: np.ndarray, parents: list[int]) -> np.ndarray:
    """Each node's rotation relative to its parent as ZYX Euler angles in degrees,
    (T, N, 3), from world rotations R_node (T, N, 3, 3)."""
    par = np.array(parents[1:])
    R_local = R_node.copy()
    R_local[:, 1:] = np.swapaxes(R_node[:, par], -1, -2) @ R_node[:, 1:]
    T, N = R_node.shape[:2]
    euler = Rotation.from_matrix(R_local.reshape(-1, 3, 3)).as_euler("ZYX", degrees=True)
    return euler.reshape(T, N, 3)


def _hierarchy(names: list[str], offsets: np.ndarray, children: dict[int, list[int]]) -> list[str]:
    """The HIERARCHY section's lines after its keyword: the nodes with their offsets
    (the shape's bone offsets, zero for the extra joints), depth first."""
    out: list[str] = []

    def emit(j: int, depth: int) -> None:
        pad = "\t" * depth
        off = offsets[j]
        out.append(f"{pad}{'ROOT' if j == 0 else 'JOINT'} {names[j]}")
        out.append(f"{pad}{{")
        out.append(f"{pad}\tOFFSET {off[0]:.9f} {off[1]:.9f} {off[2]:.9f}")
        pos = "Xposition Yposition Zposition " if j == 0 else ""
        out.append(f"{pad}\tCHANNELS {6 if j == 0 else 3} {pos}Zrotation Yrotation Xrotation")
        for c in children[j]:
            emit(c, depth + 1)
        if not children[j]:
            out.extend([f"{pad}\tEnd Site", f"{pad}\t{{", f"{pad}\t\tOFFSET 0 0 0", f"{pad}\t}}"])
        out.append(f"{pad}}}")

    emit(0, 0)
    return out


def _dfs_order(children: dict[int, list[int]]) -> list[int]:
    order: list[int] = []

    def visit(j: int) -> None:
        order.append(j)
        for c in children[j]:
            visit(c)

    visit(0)
    return order
