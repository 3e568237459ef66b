"""Forward kinematics of a parsed BVH file over all frames at once (file units, file frame).

Rotation channels apply in the order listed (``Zrotation Yrotation Xrotation`` means
``R_parent_joint = Rz @ Ry @ Rx``); position channels add to the joint's OFFSET.
"""

from __future__ import annotations

import numpy as np

from engine.io.bvh.parse import BvhFile

_AXIS = {"X": 0, "Y": 1, "Z": 2}


def _axis_rotations(axis: int, deg: np.ndarray) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., i, i], R[..., i, j] = c, -s
    R[..., j, i], R[..., j, j] = s, c
    return R


def local_transforms(bvh: BvhFile) -> tuple[np.ndarray, np.ndarray]:
    """Local rotation and translation of every node in every frame.

    Returns
    -------
    R_parent_node : ndarray, shape (T, N, 3, 3)
    t_parent_node : ndarray, shape (T, N, 3)
        Offset plus position channels, file units.
    """
    T, N = bvh.frames, len(bvh.names)
    R = np.broadcast_to(np.eye(3), (T, N, 3, 3)).copy()
    t = np.broadcast_to(bvh.offsets, (T, N, 3)).copy()
    for n, (sl, chans) in enumerate(zip(bvh.channel_slices(), bvh.channels, strict=True)):
        for c, ch in zip(range(sl.start, sl.stop), chans, strict=True):
            axis = _AXIS[ch[0]]
            if ch.endswith("position"):
                t[:, n, axis] += bvh.values[:, c]
            else:
                R[:, n] = R[:, n] @ _axis_rotations(axis, bvh.values[:, c])
    return R, t


def bvh_forward_kinematics(
    bvh: BvhFile, R_local: np.ndarray | None = None, t_local: np.ndarray | None = None
) -> np.ndarray:
    """World positions of every node of a BVH in every frame (file units, file frame).

    Parameters
    ----------
    bvh : BvhFile
    R_local, t_local : ndarray, shape (T, N, 3, 3) and (T, N, 3), optional
        Local transforms (e.g. interpolated ones); from the file's channels when omitted.

    Returns
    -------
    positions : ndarray, shape (T, N, 3)
    """
    if R_local is None or t_local is None:
        R_local, t_local = local_transforms(bvh)
    T, N = R_local.shape[:2]
    R_world = np.empty((T, N, 3, 3))
    pos = np.empty((T, N, 3))
    for n, p in enumerate(bvh.parents):
        if p < 0:
            R_world[:, n] = R_local[:, n]
            pos[:, n] = t_local[:, n]
        else:
            R_world[:, n] = R_world[:, p] @ R_local[:, n]
            pos[:, n] = pos[:, p] + np.einsum("tij,tj->ti", R_world[:, p], t_local[:, n])
    return pos
