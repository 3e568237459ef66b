"""Postures as stage 3 moves them: the part tree's subtrees, joint limits, turns of parts.

A posture is its joints (17, 3) in the world frame, metres; a part turns with its subtree
(the parts below it) about its root joint, or alone, the parts below following by
translation. Shared by BP, the refinement, the escape and the candidate generation.
"""

from __future__ import annotations

import numpy as np

from engine.body.kinematics import bone_vectors, cross3, part_rotations, rotation_about_axis
from engine.body.skeleton import (
    BONE_CHILD,
    BONE_PARENT,
    BONE_PART,
    LIMIT_A,
    LIMIT_B,
    LIMIT_JOINT,
    LIMIT_MIN_RAD,
    N_PARTS,
    PART_BONES,
    PART_PARENT,
    PART_ROOT_JOINT,
)

ALL_PARTS = tuple(range(N_PARTS))


def limits_ok(joints: np.ndarray, tol_rad: float = 1e-6) -> np.ndarray:
    """Whether postures (..., 17, 3) respect every joint-angle limit (appendix A), (...)."""
    j = np.asarray(joints, float)
    u = j[..., LIMIT_A, :] - j[..., LIMIT_JOINT, :]
    w = j[..., LIMIT_B, :] - j[..., LIMIT_JOINT, :]
    cos = (u * w).sum(-1) / np.maximum(
        np.linalg.norm(u, axis=-1) * np.linalg.norm(w, axis=-1), 1e-12
    )
    return np.all(np.arccos(np.clip(cos, -1, 1)) >= LIMIT_MIN_RAD - tol_rad, axis=-1)


def _subtree(part: int) -> tuple[int, ...]:
    out = [part]
    for q in range(N_PARTS):
        if q != part and any(p in out for p in _ancestors(q)):
            out.append(q)
    return tuple(sorted(out))


def _ancestors(q: int) -> list[int]:
    out = []
    while PART_PARENT[q] >= 0:
        q = int(PART_PARENT[q])
        out.append(q)
    return out


#: Each part's subtree: itself and the parts below it.
_SUBTREES = tuple(_subtree(p) for p in range(N_PARTS))
#: The joints each part's subtree moves (every joint below its root joint).
_SUBTREE_JOINTS = tuple(
    np.array(sorted({int(BONE_CHILD[b]) for q in st for b in PART_BONES[q]})) for st in _SUBTREES
)


def _from_bones(root: np.ndarray, vec: np.ndarray) -> np.ndarray:
    """Joints (..., 17, 3) from root (..., 3) and bone vectors (..., 16, 3)."""
    j = np.empty(vec.shape[:-2] + (17, 3))
    j[..., 0, :] = root
    for b in range(16):
        j[..., BONE_CHILD[b], :] = j[..., BONE_PARENT[b], :] + vec[..., b, :]
    return j


def _frame_offsets(ref: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Default-posture bone vectors (16, 3) under which ``ref`` (17, 3) is exactly rigid per part.

    A BVH clavicle moves relative to the spine, so the upper chest is not rigid across frames;
    taking the part shapes from this frame's reference posture makes it reachable exactly.
    """
    R = part_rotations(ref, offsets)
    vec = bone_vectors(ref)
    return np.einsum("bji,bj->bi", R[BONE_PART], vec)


def perturb_parts(joints: np.ndarray, max_deg: float, rng: np.random.Generator) -> np.ndarray:
    """Every part (with its subtree) turned about its root joint by U[-max, max] deg.

    About a random axis per part (thesis 5.2.2's perturbed initial posture). ``joints`` (17, 3)
    -> (17, 3).
    """
    out = np.array(joints, dtype=float)
    for p in range(N_PARTS):
        J = out[PART_ROOT_JOINT[p]]
        R = rotation_about_axis(rng.normal(size=3), np.radians(rng.uniform(-max_deg, max_deg)))
        sub = _SUBTREE_JOINTS[p]
        out[sub] = J + (out[sub] - J) @ R.T  # not _turned: its einsum rounds differently
    return out


def _sphere(n: int) -> np.ndarray:
    """``n`` nearly even unit directions (Fibonacci lattice), shape (n, 3)."""
    k = np.arange(n) + 0.5
    z = 1.0 - 2.0 * k / n
    phi = np.pi * (1.0 + 5.0**0.5) * k
    r = np.sqrt(1.0 - z**2)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def _turn_to(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotations taking unit direction a (3,) to each of b (n, 3), shape (n, 3, 3)."""
    axis = cross3(a, b)
    s = np.linalg.norm(axis, axis=1)
    c = b @ a
    ang = np.arctan2(s, c)
    perp = cross3(a, [1.0, 0.0, 0.0] if abs(a[0]) < 0.9 else [0.0, 1.0, 0.0])
    axis = np.where(s[:, None] > 1e-9, axis, perp)
    return rotation_about_axis(axis, ang)


def _turned(cur: np.ndarray, p: int, Rs: np.ndarray) -> np.ndarray:
    """``cur`` (17, 3) with part p's subtree turned by each of Rs (n, 3, 3) about its root."""
    J = cur[PART_ROOT_JOINT[p]]
    sub = _SUBTREE_JOINTS[p]
    out = np.repeat(cur[None], len(Rs), axis=0)
    out[:, sub] = J + np.einsum("nij,kj->nki", Rs, cur[sub] - J)
    return out


def _turned_alone(cur: np.ndarray, p: int, Rs: np.ndarray) -> np.ndarray:
    """``cur`` (17, 3) with part p's own bones turned by each of Rs (n, 3, 3); the parts below
    keep their directions and follow by translation, shape (n, 17, 3)."""
    vec = np.repeat(bone_vectors(cur)[None], len(Rs), axis=0)
    own = list(PART_BONES[p])
    vec[:, own] = np.einsum("nij,kj->nki", Rs, vec[0, own])
    return _from_bones(np.repeat(cur[None, 0], len(Rs), axis=0), vec)


def _part_dir(cur: np.ndarray, p: int) -> np.ndarray:
    """Unit direction (3,) from part p's root joint to the mean of its bones' far joints."""
    own = np.array([BONE_CHILD[b] for b in PART_BONES[p]])
    d = (cur[own] - cur[PART_ROOT_JOINT[p]]).mean(0)
    return d / np.linalg.norm(d)
