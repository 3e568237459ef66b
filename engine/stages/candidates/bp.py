"""Nonparametric belief propagation over the body parts (thesis 4.6.1-4.6.4).

A pose sample of part i is its root-joint position x (3,) and its rotation R (3, 3) relative
to the default posture; the part's other joints are x + R @ offsets[b] for its bones b (every
bone of a part starts at the part's root joint). Parts are connected along the part tree
(PART_PARENT); each edge carries the joint constraint psi (eq. 4.18) with the angle limit of
appendix A at the child part's root joint. All weights are kept as logarithms.

:func:`_bp_estimate` runs the whole estimator: similarity phi = exp(-beta d_S) with the part
at the sample and the other parts at their previous-iteration poses (4.6.2), joint
constraint psi = J exp(-|x_i - x_j|^2 / sigma^2) (4.6.3) and the hardening schedule
sigma_k = lambda sigma_{k-1}, a_k = a_{k-1}^(1/lambda) (4.6.4 step 1).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from engine.body.kinematics import (
    bone_vectors,
    kabsch,
    part_rotations,
    rotation_about_axis,
    rotation_between,
)
from engine.body.skeleton import (
    BONE_CHILD,
    JOINT_INDEX,
    JOINT_LIMITS,
    N_PARTS,
    PART_BONES,
    PART_PARENT,
    PART_ROOT_JOINT,
)
from engine.stages.candidates.scorer import _Scorer
from engine.stages.candidates.settings import CandidateSettings

#: Undirected edges of the part tree as (parent part, child part), shape (11, 2).
EDGES = np.array([(int(PART_PARENT[i]), i) for i in range(N_PARTS) if PART_PARENT[i] >= 0])
_LIMIT_BY_JOINT = {JOINT_INDEX[j]: (JOINT_INDEX[b], np.radians(m)) for j, _, b, m in JOINT_LIMITS}

#: A prior term -log p of part p's rotation samples R (S, 3, 3): prior(p, R) -> (S,).
Prior = Callable[[int, np.ndarray], np.ndarray]


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


def logsumexp(a: np.ndarray, axis: int | None = None) -> np.ndarray:
    """log(sum(exp(a))) along ``axis`` (all of ``a`` if None), shifted by the maximum.

    By hand, not ``scipy.special.logsumexp``: its input checks and array-API dispatch cost
    about 0.5 ms a call, and BP makes some 400 calls per frame on arrays of a few hundred
    numbers (profile of P2: 32 s of 250).
    """
    m = np.max(a, axis=axis, keepdims=True)
    m = np.where(np.isfinite(m), m, 0.0)
    with np.errstate(divide="ignore"):  # all -inf: log(0) = -inf, as scipy returns
        out = np.log(np.sum(np.exp(a - m), axis=axis, keepdims=True)) + m
    return out.reshape(()) if axis is None else np.squeeze(out, axis=axis)


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


def _bp_prior(ref: np.ndarray, offsets: np.ndarray, s: CandidateSettings) -> Prior:
    """BP's prior towards ``ref`` (17, 3) (``s.bp_prior_weight``, beyond the thesis).

    Part p's samples pay mu x its bones' share of d_B(sample, reference) (16 bones), so BP
    maximises d_S + mu d_B(., B_C(t')); zeros when mu is 0 (the thesis).
    """
    ref_dirs = bone_vectors(ref)
    ref_dirs = ref_dirs / np.linalg.norm(ref_dirs, axis=-1, keepdims=True)
    off_dirs = offsets / np.maximum(np.linalg.norm(offsets, axis=-1, keepdims=True), 1e-12)

    def prior(p: int, R: np.ndarray) -> np.ndarray:
        """mu x part p's share of d_B(sample, reference) (16 bones), shape (S,)."""
        if s.bp_prior_weight <= 0:
            return np.zeros(len(R))
        ang = sum(
            np.arccos(np.clip(np.einsum("sij,j,i->s", R, off_dirs[b], ref_dirs[b]), -1, 1))
            for b in PART_BONES[p]
        )
        return s.bp_prior_weight * ang / 16.0

    return prior


def _bp_estimate(
    scorer: _Scorer,
    pool: np.ndarray,
    d0: np.ndarray,
    offsets: np.ndarray,
    s: CandidateSettings,
    rng: np.random.Generator,
    prior: Prior,
) -> tuple[np.ndarray, list[float]]:
    """Nonparametric BP (thesis 4.6.4) from the initial postures ``pool`` (M, 17, 3).

    ``d0`` (M,) is their d_S. Returns the connected best posture (17, 3) and its d_S after each
    iteration (0 = initial).
    """
    parts = _initial_samples(scorer, pool, d0, offsets, s, rng, prior)
    rot_std = np.radians(s.rot_std0_deg)
    pos_std = s.pos_std0_m

    def connected() -> np.ndarray:
        return assemble(offsets, parts, [q.best for q in parts])

    context = connected()  # the connected best posture of the latest samples
    history = [float(scorer.full(context[None])[0])]
    sigma, log_a = s.sigma0_m, np.log(s.a0)
    for _ in range(s.n_iterations):
        sigma *= s.decrease  # step 1: harden the constraints
        log_a /= s.decrease
        rot_std = max(rot_std * s.decrease, np.radians(s.rot_std_min_deg))
        pos_std = max(pos_std * s.decrease, s.pos_std_min_m)
        scorer.set_pose(context)
        new = []
        for p in range(N_PARTS):  # step 2: sample; phi with the others at the last poses
            x, R = resample(offsets, parts, p, s.n_samples, rot_std, pos_std, s.attach_prob, rng)
            lphi = -s.beta * (scorer.part(p, fill_part(context, p, offsets, x, R)) + prior(p, R))
            new.append(PartSamples(x, R, lphi, lphi.copy()))
        step_messages(offsets, parts, new, sigma, log_a)  # steps 3-4
        parts = new
        context = connected()
        history.append(float(scorer.full(context[None])[0]))

    return context, history


def _initial_samples(
    scorer: _Scorer,
    pool: np.ndarray,
    d0: np.ndarray,
    offsets: np.ndarray,
    s: CandidateSettings,
    rng: np.random.Generator,
    prior: Prior,
) -> list[PartSamples]:
    """BP's first samples of every part: drawn from the initial postures ``pool`` (M, 17, 3)
    weighted by their likelihood (``d0``, (M,)), each posture itself once, the others moved
    by the first sampling Gaussian (4.6.4 step 2)."""
    R0 = part_rotations(pool, offsets)  # (M, 12, 3, 3)
    w = np.exp(-s.beta * (d0 - d0.min()))
    m_of = np.concatenate([np.arange(len(pool)), rng.choice(len(pool), s.n_samples, p=w / w.sum())])
    m_of = m_of[: s.n_samples]
    rot_std = np.radians(s.rot_std0_deg)
    pos_std = s.pos_std0_m
    context = pool[int(np.argmin(d0))]
    scorer.set_pose(context)
    parts: list[PartSamples] = []
    for p in range(N_PARTS):
        x = pool[m_of, PART_ROOT_JOINT[p]].copy()
        R = R0[m_of, p]
        k = len(pool)
        R = np.concatenate([R[:k], random_rotations(rng, len(m_of) - k, rot_std) @ R[k:]])
        x[k:] += rng.normal(0.0, pos_std, size=x[k:].shape)
        lphi = -s.beta * (scorer.part(p, fill_part(context, p, offsets, x, R)) + prior(p, R))
        parts.append(PartSamples(x, R, lphi, lphi - np.logaddexp.reduce(lphi)))
    return parts
