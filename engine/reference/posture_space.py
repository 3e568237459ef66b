"""Postures as direction cosines and the PCA action space (seed 002, section 2).

A posture is the normalised pelvis height plus, for every bone, the direction cosines of the
bone in its parent part's frame (seed 002 eq. 1, on our 16 bones instead of 12 limbs: 49
numbers). Direction cosines have no singularities, and near postures give near vectors, so
Euclidean distances between them are meaningful. The 49 numbers are redundant (3 for 2
degrees of freedom per bone) and correlated (the body moves as a whole), so they are
projected onto the first ``b`` principal axes of all the postures of an action, the aSpace
(eqs. 3-5); the synchronisation of :mod:`engine.reference.synchronisation` runs there.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.body.kinematics import bone_directions, part_rotations
from engine.body.skeleton import BONE_PART, JOINT_INDEX, PART_PARENT
from engine.errors import InvalidInput

#: Length of one posture vector: pelvis height + 16 bones x 3 direction cosines.
POSTURE_DIMS = 1 + 16 * 3

_ANKLES = [JOINT_INDEX["l_ankle"], JOINT_INDEX["r_ankle"]]


def posture_vectors(joints: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """Seed 002 eq. 1: normalised pelvis height and relative direction cosines of each bone.

    A bone's direction is expressed in its parent part's frame (the part rotations that
    reproduce ``joints`` with these ``offsets``); the abdomen's bones, whose part is the root,
    in the world frame, which :func:`engine.io.bvh.load_reference` turns to face +z at frame 0.
    The pelvis height is the hip's height above the take's lowest ankle, over the leg's length.

    Parameters
    ----------
    joints : ndarray, shape (F, 17, 3)
        One take, metres, world frame.
    offsets : ndarray, shape (16, 3)
        The take's bone offsets (:attr:`engine.body.shapes.BodyShape.offsets`).

    Returns
    -------
    psi : ndarray, shape (F, 49)
        ``[u, cos_x, cos_y, cos_z of bone 0, ..., of bone 15]``.
    """
    joints = np.asarray(joints, dtype=float)
    if joints.ndim != 3 or joints.shape[1:] != (17, 3) or joints.shape[0] < 1:
        raise InvalidInput(f"joints must have shape (F, 17, 3), got {joints.shape}")
    R = part_rotations(joints, offsets)  # (F, 12, 3, 3) world <- part
    parent = PART_PARENT[BONE_PART]  # (16,) part whose frame each bone is expressed in
    R_parent = np.where(
        (parent >= 0)[None, :, None, None], R[:, np.maximum(parent, 0)], np.eye(3)
    )  # (F, 16, 3, 3)
    local = np.einsum("fbji,fbj->fbi", R_parent, bone_directions(joints))  # R^T @ d
    lengths = np.linalg.norm(offsets, axis=-1)
    leg = float(lengths[0] + lengths[1] + lengths[2])  # hip->l_hip, thigh, shin
    floor = joints[:, _ANKLES, 1].min()
    u = (joints[:, 0, 1] - floor) / max(leg, 1e-6)
    return np.concatenate([u[:, None], local.reshape(len(joints), -1)], axis=1)


@dataclass(frozen=True)
class ActionSpace:
    """The aSpace of one action (seed 002 eqs. 3-5).

    Attributes
    ----------
    mean : ndarray, shape (D,)
        Mean posture vector of all the action's postures.
    basis : ndarray, shape (b, D)
        The first ``b`` eigenvectors of their covariance, rows, by decreasing eigenvalue.
    eigenvalues : ndarray, shape (D,)
        All eigenvalues, decreasing.
    """

    mean: np.ndarray
    basis: np.ndarray
    eigenvalues: np.ndarray

    @property
    def dims(self) -> int:
        return int(self.basis.shape[0])

    @property
    def explained(self) -> float:
        """Share of the total variance the kept axes explain (eq. 4)."""
        total = float(self.eigenvalues.sum())
        return float(self.eigenvalues[: self.dims].sum() / total) if total > 0 else 1.0

    @classmethod
    def fit(cls, postures: np.ndarray, share: float = 0.95) -> ActionSpace:
        """Eqs. 3-4: PCA of all ``postures`` (N, D), keeping the smallest ``b`` whose
        eigenvalues sum to at least ``share`` of the total (seed 002 keeps 93-95 %)."""
        X = np.asarray(postures, dtype=float)
        if X.ndim != 2 or X.shape[0] < 2:
            raise InvalidInput("the action space needs at least two postures")
        if not 0.0 < share <= 1.0:
            raise InvalidInput(f"share must be in (0, 1], got {share}")
        mean = X.mean(axis=0)
        lam, vecs = np.linalg.eigh(np.cov(X - mean, rowvar=False))  # eq. 3
        order = np.argsort(lam)[::-1]
        lam, vecs = np.maximum(lam[order], 0.0), vecs[:, order]
        total = lam.sum()
        cum = np.cumsum(lam) / total if total > 0 else np.ones_like(lam)
        b = int(np.searchsorted(cum, share - 1e-12) + 1)  # eq. 4: smallest b reaching share
        return cls(mean=mean, basis=vecs[:, :b].T.copy(), eigenvalues=lam)

    def project(self, postures: np.ndarray) -> np.ndarray:
        """Eq. 5: postures (..., D) -> aSpace coordinates (..., b)."""
        return (np.asarray(postures, dtype=float) - self.mean) @ self.basis.T
