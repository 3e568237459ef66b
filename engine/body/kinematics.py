"""Forward kinematics and its inverse for the 12-part body (thesis 2.1.1, 4.3 step 1).

A posture is the root (hip) position plus one rotation per rigid part, each relative to the
default posture (thesis 2.1.1 item 2): ``R_world_part[p]`` maps the part's default-posture bone
vectors into the world. Rotations are global per part rather than chained local ones because
belief propagation (4.6) samples each part's pose on its own; local angles are derived when
needed (joint limits work directly on joint positions).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from engine.body.skeleton import BONE_CHILD, BONE_PARENT, BONE_PART, N_PARTS, PART_BONES


def forward_kinematics(
    offsets: np.ndarray, root: np.ndarray, R_world_part: np.ndarray
) -> np.ndarray:
    """Joint positions of postures given as root position and per-part rotations.

    Parameters
    ----------
    offsets : ndarray, shape (16, 3)
        Default-posture bone vectors (child minus parent joint), metres.
    root : ndarray, shape (..., 3)
        Hip joint position.
    R_world_part : ndarray, shape (..., 12, 3, 3)
        Rotation of each part relative to the default posture.

    Returns
    -------
    joints : ndarray, shape (..., 17, 3)
    """
    root = np.asarray(root, dtype=float)
    R = np.asarray(R_world_part, dtype=float)
    # bone vectors in the world, all at once: (..., 16, 3)
    vec = np.einsum("...bij,bj->...bi", R[..., BONE_PART, :, :], offsets)
    return joints_from_bones(root, vec)


def joints_from_bones(root: np.ndarray, vec: np.ndarray) -> np.ndarray:
    """Joint positions from the root (..., 3) and world bone vectors (..., 16, 3) ->
    (..., 17, 3): the inverse of :func:`bone_vectors`."""
    joints = np.empty(np.shape(root)[:-1] + (17, 3))
    joints[..., 0, :] = root
    for b in range(16):  # topological order: the parent joint is always set already
        joints[..., BONE_CHILD[b], :] = joints[..., BONE_PARENT[b], :] + vec[..., b, :]
    return joints


def bone_vectors(joints: np.ndarray) -> np.ndarray:
    """Bone vectors child minus parent, (..., 17, 3) -> (..., 16, 3)."""
    return joints[..., BONE_CHILD, :] - joints[..., BONE_PARENT, :]


def bone_directions(joints: np.ndarray) -> np.ndarray:
    """Unit bone directions, (..., 17, 3) -> (..., 16, 3)."""
    v = bone_vectors(joints)
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation taking direction ``a`` onto direction ``b`` (no twist).

    Parameters
    ----------
    a, b : ndarray, shape (..., 3)
        Non-zero vectors (need not be unit).

    Returns
    -------
    R : ndarray, shape (..., 3, 3)
        ``R @ a_hat == b_hat``. Antiparallel inputs rotate by pi about an axis normal to ``a``.
    """
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    v = cross3(a, b)
    c = np.sum(a * b, axis=-1)
    # any axis normal to a, for the antiparallel case
    helper = np.where(np.abs(a[..., :1]) < 0.9, [1.0, 0.0, 0.0], [0.0, 1.0, 0.0])
    n = cross3(a, helper)
    n /= np.linalg.norm(n, axis=-1, keepdims=True)
    anti = c < -1.0 + 1e-9
    K = _skew(v)
    R = np.eye(3) + K + K @ K / (1.0 + np.where(anti, 1.0, c))[..., None, None]
    R_pi = 2.0 * n[..., :, None] * n[..., None, :] - np.eye(3)
    return np.where(anti[..., None, None], R_pi, R)


def cross3(a: ArrayLike, b: ArrayLike) -> np.ndarray:
    """Cross product of 3-vectors (..., 3) x (..., 3) -> (..., 3), broadcasting.

    The same products and differences as ``np.cross`` (so the same values), without its axis
    handling, which costs about 0.1 ms a call: stage 3 makes some 130,000 calls on 3-vectors
    per 150-frame video (profile of P2).
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _skew(v: np.ndarray) -> np.ndarray:
    K = np.zeros(v.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -v[..., 2], v[..., 1]
    K[..., 1, 0], K[..., 1, 2] = v[..., 2], -v[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -v[..., 1], v[..., 0]
    return K


def kabsch(src: np.ndarray, dst: np.ndarray) -> np.ndarray:
    """Rotation R minimising sum |R src_i - dst_i|^2 (no translation, no scaling).

    Parameters
    ----------
    src : ndarray, shape (N, 3)
    dst : ndarray, shape (..., N, 3)

    Returns
    -------
    R : ndarray, shape (..., 3, 3)
    """
    H = np.einsum("ni,...nj->...ij", src, dst)
    U, _, Vt = np.linalg.svd(H)
    d = np.sign(np.linalg.det(np.swapaxes(Vt, -1, -2) @ np.swapaxes(U, -1, -2)))
    D = np.zeros(d.shape + (3, 3))
    D[..., 0, 0] = 1.0
    D[..., 1, 1] = 1.0
    D[..., 2, 2] = d
    return np.swapaxes(Vt, -1, -2) @ D @ np.swapaxes(U, -1, -2)


def part_rotations(joints: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Per-part rotations that best reproduce given joint positions (inverse of FK).

    Single-bone parts get the twist-free rotation onto their bone; the multi-bone parts
    (abdomen, upper chest) the least-squares rotation of their bones (Kabsch). FK of the
    result reproduces single-bone directions exactly and multi-bone parts as well as a rigid
    part can.

    Parameters
    ----------
    joints : ndarray, shape (..., 17, 3)
    offsets : ndarray, shape (16, 3)

    Returns
    -------
    R_world_part : ndarray, shape (..., 12, 3, 3)
    """
    vec = bone_vectors(np.asarray(joints, dtype=float))
    out = np.empty(vec.shape[:-2] + (N_PARTS, 3, 3))
    for p, bones in enumerate(PART_BONES):
        if len(bones) == 1:
            out[..., p, :, :] = rotation_between(
                np.broadcast_to(offsets[bones[0]], vec[..., bones[0], :].shape),
                vec[..., bones[0], :],
            )
        else:
            src = offsets[list(bones)]
            dst = vec[..., list(bones), :]
            dst = dst / np.linalg.norm(dst, axis=-1, keepdims=True)
            src = src / np.linalg.norm(src, axis=-1, keepdims=True)
            out[..., p, :, :] = kabsch(src, dst)
    return out


def facing_turn(joints: np.ndarray, target: np.ndarray) -> np.ndarray:
    """The turn about the vertical, radians, that best lays the bones of ``joints`` on those
    of ``target`` (least squares over the bones, closed form; positive as :func:`rot_y`).

    Parameters
    ----------
    joints, target : ndarray, shape (..., F, 17, 3)
        The turn is found over the last two axes' bones together, per leading index: pass
        (F, 17, 3) for one turn over F frames, (F, 1, 17, 3) for one per frame.

    Returns
    -------
    angle : ndarray, shape (...)
    """
    a, b = bone_directions(joints), bone_directions(target)
    num = (a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]).sum((-1, -2))
    den = (a[..., 0] * b[..., 0] + a[..., 2] * b[..., 2]).sum((-1, -2))
    return np.arctan2(num, den)


def rotation_about_axis(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rodrigues rotation, axis (..., 3) (normalised here), angle (...) radians -> (..., 3, 3)."""
    axis = np.asarray(axis, dtype=float)
    axis = axis / np.linalg.norm(axis, axis=-1, keepdims=True)
    angle = np.asarray(angle, dtype=float)[..., None, None]
    K = _skew(axis)
    return np.eye(3) + np.sin(angle) * K + (1.0 - np.cos(angle)) * (K @ K)


def rot_y(angle: np.ndarray | float) -> np.ndarray:
    """Rotation about the vertical (y) axis, angle (...) radians -> (..., 3, 3)."""
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    R = np.zeros(a.shape + (3, 3))
    R[..., 0, 0], R[..., 0, 2] = c, s
    R[..., 1, 1] = 1.0
    R[..., 2, 0], R[..., 2, 2] = -s, c
    return R
