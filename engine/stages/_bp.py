"""Private core of stage 3: nonparametric belief propagation over body parts (thesis 4.6.1-4.6.4).

A pose sample of part i is its root-joint position x (3,) and its rotation R (3, 3) relative
to the default posture; the part's other joints are x + R @ offsets[b] for its bones b (every
bone of a part starts at the part's root joint). Parts are connected along the part tree
(PART_PARENT); each edge carries the joint constraint psi (eq. 4.18) with the angle limit of
appendix A at the child part's root joint. All weights are kept as logarithms.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Protocol

import numpy as np
from scipy.special import logsumexp

from engine.body.kinematics import kabsch, rotation_about_axis, rotation_between
from engine.body.skeleton import (
    BONE_CHILD,
    JOINT_INDEX,
    JOINT_LIMITS,
    N_PARTS,
    PART_BONES,
    PART_PARENT,
    PART_ROOT_JOINT,
)

#: Undirected edges of the part tree as (parent part, child part), shape (11, 2).
EDGES = np.array([(int(PART_PARENT[i]), i) for i in range(N_PARTS) if PART_PARENT[i] >= 0])
#: Neighbours of each part.
NEIGHBOURS: tuple[tuple[int, ...], ...] = tuple(
    tuple(int(e[0]) if e[1] == p else int(e[1]) for e in EDGES if p in e) for p in range(N_PARTS)
)
_LIMIT_BY_JOINT = {JOINT_INDEX[j]: (JOINT_INDEX[b], np.radians(m)) for j, _, b, m in JOINT_LIMITS}


class Scorer(Protocol):
    def set_pose(self, joints: np.ndarray) -> None: ...

    def score(self, parts: tuple[int, ...] | int, joints_samples: np.ndarray) -> np.ndarray: ...


@dataclass
class PartSamples:
    """Weighted pose samples of one part (thesis 4.6.4: s_ilk with belief weights pi_ilk).

    Attributes
    ----------
    x : ndarray, shape (S, 3)
        Root-joint positions.
    R : ndarray, shape (S, 3, 3)
        Rotations relative to the default posture.
    log_phi : ndarray, shape (S,)
        log similarity, -beta d_S (eq. 4.16).
    log_pi : ndarray, shape (S,)
        Normalised log belief weights (eq. 4.20-4.21).
    msgs : dict of int to ndarray (S,)
        Incoming log contribution weights omega_{j i l k} by sender j (eq. 4.19).
    """

    x: np.ndarray
    R: np.ndarray
    log_phi: np.ndarray
    log_pi: np.ndarray
    msgs: dict[int, np.ndarray] = field(default_factory=dict)

    @property
    def best(self) -> int:
        return int(np.argmax(self.log_pi))


def fill_part(
    joints: np.ndarray, part: int, offsets: np.ndarray, x: np.ndarray, R: np.ndarray
) -> np.ndarray:
    """Copies of ``joints`` (17, 3) with part ``part`` placed at samples (x, R): (S, 17, 3)."""
    out = np.broadcast_to(joints, (x.shape[0], 17, 3)).copy()
    out[:, PART_ROOT_JOINT[part]] = x
    for b in PART_BONES[part]:
        out[:, BONE_CHILD[b]] = x + np.einsum("sij,j->si", R, offsets[b])
    return out


def log_psi(
    offsets: np.ndarray,
    parent: int,
    child: int,
    xp: np.ndarray,
    Rp: np.ndarray,
    xc: np.ndarray,
    Rc: np.ndarray,
    sigma: float,
    log_a: float,
) -> np.ndarray:
    """log psi (thesis eq. 4.17-4.18) between parent samples (P) and child samples (C), (P, C).

    The joint is the child's root joint; the angle limit (appendix A) is measured there between
    the bone back to the parent part and the child's bone towards the limit's far joint.
    """
    j = int(PART_ROOT_JOINT[child])
    bone_in = offsets[j - 1]
    end = xp + np.einsum("sij,j->si", Rp, bone_in)  # parent's copy of the joint
    d2 = ((end[:, None, :] - xc[None, :, :]) ** 2).sum(-1)
    far, min_angle = _LIMIT_BY_JOINT[j]
    u = -np.einsum("sij,j->si", Rp, bone_in / np.linalg.norm(bone_in))
    w_off = offsets[far - 1]
    w = np.einsum("sij,j->si", Rc, w_off / np.linalg.norm(w_off))
    cos = np.clip(u @ w.T, -1.0, 1.0)
    ok = cos <= np.cos(min_angle)
    return np.where(ok, 0.0, log_a) - d2 / sigma**2


def random_rotations(rng: np.random.Generator, n: int, std: float) -> np.ndarray:
    """Small random rotations (n, 3, 3): uniform axis, angle ~ N(0, std)."""
    axis = rng.normal(size=(n, 3))
    return rotation_about_axis(axis, rng.normal(0.0, std, size=n))


def assemble(offsets: np.ndarray, parts: list[PartSamples], idx: list[int]) -> np.ndarray:
    """Connected posture (17, 3) from one sample per part.

    Each joint's position is estimated by the part that ends at it and by the part rooted at
    it (their mean); the skeleton is then built from the root, each part turned to point at
    its joints' estimates (thesis 4.6.5 step 2, "connected to its parent body part"). Chaining
    positions instead of rotations keeps small errors of the inner torso parts from
    accumulating down the chain.
    """
    est = np.zeros((17, 3))
    cnt = np.zeros(17)
    for p, (ps, i) in enumerate(zip(parts, idx, strict=True)):
        r = PART_ROOT_JOINT[p]
        est[r] += ps.x[i]
        cnt[r] += 1
        for b in PART_BONES[p]:
            est[BONE_CHILD[b]] += ps.R[i] @ offsets[b] + ps.x[i]
            cnt[BONE_CHILD[b]] += 1
    est /= cnt[:, None]
    out = np.zeros((17, 3))
    out[0] = parts[0].x[idx[0]]
    for p in range(N_PARTS):
        J = out[PART_ROOT_JOINT[p]]
        bones = list(PART_BONES[p])
        dst = est[BONE_CHILD[bones]] - J
        if len(bones) == 1:
            R = rotation_between(offsets[bones[0]], dst[0])
        else:
            R = kabsch(offsets[bones], dst)
        for b in bones:
            out[BONE_CHILD[b]] = J + R @ offsets[b]
    return out


def step_messages(
    offsets: np.ndarray,
    old: list[PartSamples],
    new: list[PartSamples],
    sigma: float,
    log_a: float,
) -> None:
    """Contribution weights (eq. 4.19) and beliefs (eq. 4.20-4.21) of the new samples, in place."""
    # log of phi_j * prod_{h in Gamma(j)} omega_hj for j's old samples
    full = [o.log_phi + sum(o.msgs.values(), np.zeros_like(o.log_phi)) for o in old]
    for parent, child in EDGES:
        for j, i in ((parent, child), (child, parent)):
            excl = full[j] - old[j].msgs.get(i, 0.0)
            if j == parent:
                lp = log_psi(offsets, j, i, old[j].x, old[j].R, new[i].x, new[i].R, sigma, log_a)
            else:
                lp = log_psi(offsets, i, j, new[i].x, new[i].R, old[j].x, old[j].R, sigma, log_a).T
            m = logsumexp(excl[:, None] + lp, axis=0)
            new[i].msgs[j] = m - m.max()
    for n in new:
        lp = n.log_phi + sum(n.msgs.values(), np.zeros_like(n.log_phi))
        n.log_pi = lp - logsumexp(lp)


def resample(
    offsets: np.ndarray,
    old: list[PartSamples],
    i: int,
    n: int,
    rot_std: float,
    pos_std: float,
    attach_prob: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, np.ndarray]:
    """New samples of part i from its belief and its parent's (thesis 4.6.4 step 2): (x, R).

    The best old sample is kept unperturbed (so the best likelihood cannot be lost); the others
    are drawn from the belief, with the root joint taken from a parent sample drawn from the
    parent's belief with probability ``attach_prob``, then moved by a Gaussian.
    """
    o = old[i]
    w = np.exp(o.log_pi - o.log_pi.max())
    pick = rng.choice(o.x.shape[0], size=n - 1, p=w / w.sum())
    x = o.x[pick].copy()
    R = o.R[pick]
    par = int(PART_PARENT[i])
    jitter = rng.normal(0.0, pos_std, size=x.shape)
    if par >= 0:
        op = old[par]
        wp = np.exp(op.log_pi - op.log_pi.max())
        ppick = rng.choice(op.x.shape[0], size=n - 1, p=wp / wp.sum())
        attach = rng.random(n - 1) < attach_prob
        end = op.x[ppick] + np.einsum("sij,j->si", op.R[ppick], offsets[PART_ROOT_JOINT[i] - 1])
        x = np.where(attach[:, None], end, x + jitter)
    else:
        x = x + jitter
    R = random_rotations(rng, n - 1, rot_std) @ R
    b = o.best
    return np.concatenate([o.x[b : b + 1], x]), np.concatenate([o.R[b : b + 1], R])
