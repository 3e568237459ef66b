"""The candidates of one estimate: its depth orientations and flips (thesis 4.6.5 steps 3-5).

A silhouette shows a bone's projection, not which way it leans in depth; mirroring a part's
bones in depth along the viewing direction keeps the projection (and d_S, up to the
occlusion order) and gives another posture the image cannot rule out.
"""

from __future__ import annotations

import itertools

import numpy as np

from engine.body.kinematics import bone_vectors
from engine.body.skeleton import N_PARTS, PART_BONES
from engine.render.camera import Camera
from engine.stages.candidates.postures import _from_bones, limits_ok
from engine.stages.candidates.settings import CandidateSettings


def generate_candidates(
    joints: np.ndarray,
    orientations: list[np.ndarray],
    camera: Camera,
    settings: CandidateSettings,
) -> np.ndarray:
    """Posture candidates from one estimate (thesis 4.6.5 steps 3-5).

    Parameters
    ----------
    joints : ndarray, shape (17, 3)
        The connected best posture.
    orientations : list of ndarray (17, 3)
        Postures whose per-part depth orientation seeds a candidate, the reference first.
    camera : Camera
    settings : CandidateSettings

    Returns
    -------
    candidates : ndarray, shape (K, 17, 3)
        Same projection as ``joints``; only those respecting the joint limits (at least one:
        the first is kept even when it does not, so that a frame always has a candidate).
    """
    n = camera.view_dir
    min_sin = np.sin(np.radians(settings.min_flip_deg))
    vec = bone_vectors(joints)
    root = joints[0]
    seeds = [_orient_like(vec, bone_vectors(o), n, min_sin) for o in orientations]
    base = seeds[0]
    depth_sin = [
        float(
            np.max(
                np.abs(base[list(PART_BONES[p])] @ n)
                / np.linalg.norm(base[list(PART_BONES[p])], axis=1)
            )
        )
        for p in range(N_PARTS)
    ]
    flippable = sorted(
        (p for p in range(N_PARTS) if depth_sin[p] >= min_sin), key=lambda p: depth_sin[p]
    )
    out: list[np.ndarray] = []
    keys: set[tuple[bool, ...]] = set()

    def add(v: np.ndarray) -> None:
        k = tuple(np.round(v @ n, 4))
        if k in keys:
            return
        keys.add(k)
        j = _from_bones(root, v)
        if limits_ok(j) or not out and len(keys) == 1:
            out.append(j)

    for v in seeds:
        add(v)
    add(vec)  # the estimate's own depth orientation, which the edges may have chosen
    for m in range(1, len(flippable) + 1):
        for combo in itertools.combinations(flippable, m):
            if len(out) >= settings.n_candidates:
                break
            add(_flip(base, combo, n))
        if len(out) >= settings.n_candidates:
            break
    if not out:
        out.append(_from_bones(root, base))
    return np.stack(out[: settings.n_candidates])


def _flip(vec: np.ndarray, parts: tuple[int, ...], n: np.ndarray) -> np.ndarray:
    """Mirror the bones of ``parts`` in depth along view direction n (projection kept)."""
    out = vec.copy()
    bones = [b for p in parts for b in PART_BONES[p]]
    out[bones] -= 2.0 * (out[bones] @ n)[:, None] * n
    return out


def _orient_like(vec: np.ndarray, source: np.ndarray, n: np.ndarray, min_sin: float) -> np.ndarray:
    """Give each part of bone vectors ``vec`` the depth orientation of ``source`` (4.6.5 step 3)."""
    flips = []
    for p in range(N_PARTS):
        bones = list(PART_BONES[p])
        z = vec[bones] @ n
        zs = source[bones] @ n
        ls = np.linalg.norm(source[bones], axis=1)
        if np.max(np.abs(zs) / ls) < min_sin:
            continue  # the source has no clear depth orientation for this part
        if float(z @ zs) < 0.0:
            flips.append(p)
    return _flip(vec, tuple(flips), n)
