"""Stage 3's entry points: the candidates of one frame and of a chunk of frames (thesis 4.6).

:func:`estimate_candidates` wires the estimators and mechanisms of the other modules of this
package together for one frame; :func:`estimate_candidates_chunk` runs it over consecutive
frames, threading the previous frame's candidates through when ``n_prev`` > 0 (6.7).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.measures import d_B
from engine.render.camera import Camera
from engine.render.capsules import Target
from engine.stages.candidates.alternatives import (
    _alternatives,
    _append_distinct,
    _with_alternatives,
)
from engine.stages.candidates.bp import _bp_estimate, _bp_prior
from engine.stages.candidates.escape import _polish
from engine.stages.candidates.flips import generate_candidates
from engine.stages.candidates.in_plane import _in_plane_candidates
from engine.stages.candidates.key_frames import between_settings, carry_deviation
from engine.stages.candidates.occlusion import _reset_occluded
from engine.stages.candidates.postures import _frame_offsets, limits_ok, perturb_parts
from engine.stages.candidates.scorer import _Scorer
from engine.stages.candidates.settings import CandidateSettings


@dataclass(frozen=True)
class FrameCandidates:
    """Posture candidates of one video frame.

    Attributes
    ----------
    candidates : ndarray, shape (K, 17, 3)
        World frame, metres. Candidate 0 has the reference's depth orientation; the flips
        share its projection; with ``settings.alternatives``, the runner-up local optima and
        their flips follow; the initial postures (the reference turned by T_t' and the
        previous frame's best) come last when they respect the joint limits, so the set is
        never worse than the start.
    d_s : ndarray, shape (K,)
        d_S of each candidate against the target region.
    flags : tuple of str
        e.g. ``"occluded:l_wrist"``, ``"reference_far"``.
    history : ndarray, shape (n_iterations + 1,)
        d_S of the connected best posture after each BP iteration (0 = initial).
    prior : ndarray, shape (K,)
        mu d_B(candidate, initial posture) (``settings.prior_weight``); zeros when unused.
    """

    candidates: np.ndarray
    d_s: np.ndarray
    flags: tuple[str, ...] = ()
    history: np.ndarray = field(default_factory=lambda: np.zeros(0))
    prior: np.ndarray | None = None

    @property
    def cost(self) -> np.ndarray:
        """Selection cost d_S + prior of each candidate, shape (K,)."""
        return self.d_s if self.prior is None else self.d_s + self.prior

    @property
    def best(self) -> np.ndarray:
        """The candidate with the lowest :attr:`cost`, shape (17, 3)."""
        return self.candidates[int(np.argmin(self.cost))]


def estimate_candidates(
    target_silhouette: np.ndarray,
    target_edges: np.ndarray,
    camera: Camera,
    shape: BodyShape,
    initial_joints: np.ndarray,
    *,
    settings: CandidateSettings | None = None,
    rng: np.random.Generator,
    prev: FrameCandidates | None = None,
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
) -> FrameCandidates:
    """Posture candidates of one frame (thesis 4.6, eq. 4.12-4.21; 6.4, 6.5, 6.7).

    Parameters
    ----------
    target_silhouette, target_edges : ndarray of bool, shape (H, W)
        The input body region S' and its edges (stage 0).
    camera : Camera
        Stage 1's camera; its (height, width) must be the image's.
    shape : BodyShape
        The performer's body (the reference's by default).
    initial_joints : ndarray, shape (17, 3) or (M, 17, 3)
        Initial estimates, world frame; the first is the reference posture B_C(t') turned by
        T_t' and gives the first candidate's depth orientation.
    settings : CandidateSettings, optional
    rng : numpy.random.Generator
    prev : FrameCandidates, optional
        The previous frame's candidates (extra initial estimates, 6.7).
    keypoints : (ndarray (R, 17, 2), ndarray (R, 17)), optional
        The frame's 2D keypoint readings and confidences
        (:func:`engine.stages.perception.readings`): ``settings.keypoint_weight`` d_K joins
        the image likelihood everywhere (BP, refinement, the candidates' d_s).

    Returns
    -------
    FrameCandidates

    Raises
    ------
    InvalidInput
        Shapes that do not match, an empty silhouette, non-finite postures, bad settings.
    """
    s, init, scorer = _frame_setup(
        target_silhouette, target_edges, camera, shape, initial_joints, settings, keypoints
    )
    if not isinstance(rng, np.random.Generator):
        raise InvalidInput("rng must be a numpy.random.Generator")
    flags: list[str] = []
    ref = init[0]
    pool = init
    if prev is not None and len(prev.candidates):
        pool = np.concatenate([init, prev.candidates[np.argsort(prev.cost)[: s.n_prev]]])
    d0 = scorer.full(pool)
    orient_src = _orientations(pool, len(init), d0, s, flags)
    if s.estimator == "in_plane":
        cands = _in_plane_candidates(scorer, init, orient_src, camera, s)
        return _scored(scorer, cands, ref, s, flags, [float(d0[0])])
    in_plane = None
    if s.estimator == "hybrid":
        in_plane = _in_plane_candidates(scorer, init, orient_src, camera, s)
    offsets = _frame_offsets(ref, shape.offsets)
    cands, history = _bp_candidates(scorer, pool, d0, offsets, orient_src, camera, s, rng, flags)
    # Never worse than the start: the initial postures (the reference turned by T_t' and the
    # previous frame's best) are candidates themselves when they respect the joint limits.
    starts = [q for q in pool[: len(init) + min(1, len(pool) - len(init))] if limits_ok(q)]
    if starts:
        cands = _append_distinct(cands, np.stack(starts), s.n_candidates)
    if in_plane is not None:  # the in-plane estimate and its flips first (hybrid)
        cands = _append_distinct(in_plane[: max(1, s.n_candidates // 2)], cands, s.n_candidates)
    return _scored(scorer, cands, ref, s, flags, history)


def estimate_between(
    target_silhouette: np.ndarray,
    target_edges: np.ndarray,
    camera: Camera,
    shape: BodyShape,
    initial_joints: np.ndarray,
    neighbours: Sequence[tuple[np.ndarray, np.ndarray]],
    *,
    settings: CandidateSettings | None = None,
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
) -> FrameCandidates:
    """Candidates of a frame between key frames: the full search without BP (issue 25).

    Parameters as :func:`estimate_candidates`, and ``neighbours``: for each adjacent key
    frame, its best posture and its first initial posture, both (17, 3). They are carried
    onto this frame's reference (:func:`.key_frames.carry_deviation`); the start that explains
    the image best is refined (6.4) from ``settings.between_step0_deg``, then occluded parts
    are reset (6.5) and flipped (4.6.5) as after BP; with the hybrid estimator the in-plane
    fit is the same as on key frames. No random numbers are drawn.
    """
    s, init, scorer = _frame_setup(
        target_silhouette, target_edges, camera, shape, initial_joints, settings, keypoints
    )
    flags: list[str] = []
    ref = init[0]
    if s.estimator == "in_plane":
        cands = _in_plane_candidates(scorer, init, [ref], camera, s)
        return _scored(scorer, cands, ref, s, flags, [float(scorer.full(ref[None])[0])])
    carried = [carry_deviation(q, r, ref) for q, r in neighbours]
    pool = np.stack([*init, *carried])
    d0 = scorer.full(pool)
    found = _polish(scorer, [pool[int(np.argmin(d0))], ref], camera, between_settings(s), ref)
    offsets = _frame_offsets(ref, shape.offsets)
    est = _reset_occluded(scorer, found[0][1], ref, offsets, s, flags)
    cands = generate_candidates(est, [ref], camera, s)
    starts = [q for q in [init[0], *carried] if limits_ok(q)]
    if starts:
        cands = _append_distinct(cands, np.stack(starts), s.n_candidates)
    if s.estimator == "hybrid":
        in_plane = _in_plane_candidates(scorer, init, [ref], camera, s)
        cands = _append_distinct(in_plane[: max(1, s.n_candidates // 2)], cands, s.n_candidates)
    return _scored(scorer, cands, ref, s, flags, [float(d0.min()), found[0][0]])


def _frame_setup(
    sil: np.ndarray,
    edges: np.ndarray,
    camera: Camera,
    shape: BodyShape,
    initial_joints: np.ndarray,
    settings: CandidateSettings | None,
    keypoints: tuple[np.ndarray, np.ndarray] | None,
) -> tuple[CandidateSettings, np.ndarray, _Scorer]:
    """The checked settings, the initial postures (M, 17, 3) and the frame's scorer."""
    s = settings or CandidateSettings()
    s.validate()
    init = _check_inputs(sil, edges, camera, shape, initial_joints)
    target = Target.from_masks(sil, edges, sigma_px=s.edge_sigma_px, xi=s.edge_xi)
    return s, init, _Scorer(target, shape, camera, init[0], s, keypoints)


def _orientations(
    pool: np.ndarray, n_init: int, d0: np.ndarray, s: CandidateSettings, flags: list[str]
) -> list[np.ndarray]:
    """The postures whose depth orientations seed the candidates, the first for the occluded
    parts too: the reference, and the previous frame's best (``pool[n_init]``) when there is
    one, first when the reference is far from the image (thesis 6.7; flagged)."""
    ref = pool[0]
    if len(pool) == n_init:
        return [ref]
    prev_best = pool[n_init]
    if d0[0] > d0[n_init] + s.far_margin:
        flags.append("reference_far")
        return [prev_best, ref]
    return [ref, prev_best]


def _bp_candidates(
    scorer: _Scorer,
    pool: np.ndarray,
    d0: np.ndarray,
    offsets: np.ndarray,
    orient_src: list[np.ndarray],
    camera: Camera,
    s: CandidateSettings,
    rng: np.random.Generator,
    flags: list[str],
) -> tuple[np.ndarray, list[float]]:
    """Candidates (K, 17, 3) of the ``"bp"`` estimator from the initial postures ``pool``
    (M, 17, 3) with d_S ``d0`` (M,), and BP's d_S history.

    BP (4.6.4), the refinement or escape (6.4), restarts of BP while the image is not
    explained (beyond the thesis), the occluded parts' reset (6.5), the depth flips (4.6.5)
    and the alternative optima (beyond the thesis).
    """
    ref = pool[0]
    prior = _bp_prior(ref, offsets, s)
    est, history = _bp_estimate(scorer, pool, d0, offsets, s, rng, prior)
    found = _polish(scorer, [est, pool[0]], camera, s, ref)
    for _ in range(s.restarts):  # BP again from the estimate shaken
        if found[0][0] <= s.restart_ds:
            break
        est = found[0][1]
        shaken = np.stack([perturb_parts(est, s.restart_deg, rng), est])
        again, _ = _bp_estimate(scorer, shaken, scorer.full(shaken), offsets, s, rng, prior)
        found = sorted(found + _polish(scorer, [again], camera, s, ref), key=lambda f: f[0])

    est = _reset_occluded(scorer, found[0][1], orient_src[0], offsets, s, flags)
    cands = generate_candidates(est, orient_src, camera, s)
    alts = _alternatives(found, s)
    if alts:
        cands = _with_alternatives(cands, alts, orient_src, camera, s)
    return cands, history


def _scored(
    scorer: _Scorer,
    cands: np.ndarray,
    ref: np.ndarray,
    s: CandidateSettings,
    flags: list[str],
    history: list[float],
) -> FrameCandidates:
    """``cands`` (K, 17, 3) with their d_S and prior towards ``ref`` (17, 3)."""
    prior = s.prior_weight * d_B(cands, ref)
    return FrameCandidates(cands, scorer.full(cands), tuple(flags), np.asarray(history), prior)


def _check_inputs(
    sil: np.ndarray, edges: np.ndarray, camera: Camera, shape: BodyShape, init: np.ndarray
) -> np.ndarray:
    """The initial postures as (M, 17, 3) after checking every input of a frame."""
    if not isinstance(camera, Camera):
        raise InvalidInput(f"camera must be a Camera, got {type(camera).__name__}")
    if not isinstance(shape, BodyShape):
        raise InvalidInput(f"shape must be a BodyShape, got {type(shape).__name__}")
    sil = np.asarray(sil)
    edges = np.asarray(edges)
    if sil.ndim != 2 or sil.shape != (camera.height, camera.width):
        raise InvalidInput(
            f"target_silhouette must have shape (H, W) = {(camera.height, camera.width)}, "
            f"got {sil.shape}"
        )
    if edges.shape != sil.shape:
        raise InvalidInput(f"target_edges must have shape {sil.shape}, got {edges.shape}")
    if not sil.any():
        raise InvalidInput("target_silhouette is empty: no body region to match")
    init = np.asarray(init, dtype=float)
    if init.ndim == 2:
        init = init[None]
    if init.ndim != 3 or init.shape[1:] != (17, 3) or init.shape[0] < 1:
        raise InvalidInput(
            f"initial_joints must have shape (17, 3) or (M, 17, 3), got {init.shape}"
        )
    if not np.all(np.isfinite(init)):
        raise InvalidInput("initial_joints contains NaN or infinite values")
    return init


def frame_rngs(seed: int, frames: Sequence[int]) -> list[np.random.Generator]:
    """One random stream per video frame, from the seed and the frame's number.

    What every caller of :func:`estimate_candidates_chunk` passes, so a frame gets the same
    candidates from ``coach analyze``, ``coach candidates`` and any worker's chunk.
    """
    return [np.random.default_rng([int(seed), int(t)]) for t in frames]


def estimate_candidates_chunk(
    target_silhouettes: np.ndarray,
    target_edges: np.ndarray,
    camera: Camera,
    shape: BodyShape,
    initial_joints: np.ndarray,
    *,
    settings: CandidateSettings | None = None,
    rng: np.random.Generator | Sequence[np.random.Generator],
    prev: FrameCandidates | None = None,
    keypoints: tuple[np.ndarray, np.ndarray] | None = None,
    keys: np.ndarray | None = None,
    on_progress: Callable[[str, float], None] | None = None,
) -> list[FrameCandidates]:
    """Candidates of consecutive frames, each using the previous one's (thesis 4.6, 6.7).

    Parameters
    ----------
    target_silhouettes, target_edges : ndarray of bool, shape (N, H, W)
    camera : Camera
    shape : BodyShape
    initial_joints : ndarray, shape (N, 17, 3) or (N, M, 17, 3)
    settings, prev
        As :func:`estimate_candidates`; ``prev`` is the frame before the chunk (with
        ``keys``, the previous key frame's candidates seed the next key frame).
    rng : numpy.random.Generator, or a sequence of N of them
        One stream for the chunk, or one per frame (then, with ``settings.n_prev`` 0, each
        frame's candidates are independent of the chunk it is computed in).
    keypoints : (ndarray (N, R, 17, 2), ndarray (N, R, 17)), optional
        Each frame's keypoint readings and confidences.
    keys : ndarray of bool, shape (N,), optional
        Key frames (:func:`.key_frames.choose_key_frames`); the others are estimated from
        their adjacent key frames by :func:`estimate_between`. All frames by default.
    on_progress : callable (stage, fraction), optional

    Returns
    -------
    list of FrameCandidates, length N

    Raises
    ------
    InvalidInput
        As :func:`estimate_candidates`, and inputs whose numbers of frames differ.
    """
    sils = np.asarray(target_silhouettes)
    edges = np.asarray(target_edges)
    init = np.asarray(initial_joints, float)
    n = _chunk_length(sils, init)
    rngs = [rng] * n if isinstance(rng, np.random.Generator) else list(rng)
    if len(rngs) != n:
        raise InvalidInput(f"rng must be one generator or one per frame ({n})")
    keys = np.ones(n, bool) if keys is None else np.asarray(keys, bool)
    if keys.shape != (n,) or not (keys[0] and keys[-1]):
        raise InvalidInput(f"keys must be {n} flags whose first and last are set")
    out: dict[int, FrameCandidates] = {}
    key_idx = np.flatnonzero(keys)
    # key frames first, in order (``prev`` threads through them), then the frames between
    for t in [int(k) for k in (*key_idx, *np.flatnonzero(~keys))]:
        kp_t = None if keypoints is None else (keypoints[0][t], keypoints[1][t])
        if keys[t]:
            out[t] = prev = estimate_candidates(
                sils[t], edges[t], camera, shape, init[t],
                settings=settings, rng=rngs[t], prev=prev, keypoints=kp_t,
            )  # fmt: skip
        else:
            after = int(np.searchsorted(key_idx, t))
            neighbours = [(out[k].best, _first(init[k])) for k in key_idx[after - 1 : after + 1]]
            out[t] = estimate_between(
                sils[t], edges[t], camera, shape, init[t], neighbours,
                settings=settings, keypoints=kp_t,
            )  # fmt: skip
        if on_progress is not None:
            on_progress("candidates", len(out) / n)
    return [out[t] for t in range(n)]


def _chunk_length(sils: np.ndarray, init: np.ndarray) -> int:
    """The chunk's number of frames, after checking that its inputs agree on it."""
    if sils.ndim != 3:
        raise InvalidInput(f"target_silhouettes must have shape (N, H, W), got {sils.shape}")
    if init.shape[0] != sils.shape[0]:
        raise InvalidInput(
            f"initial_joints must have one entry per frame ({sils.shape[0]}), got {init.shape[0]}"
        )
    return int(sils.shape[0])


def _first(init: np.ndarray) -> np.ndarray:
    """The first initial posture (17, 3) of a frame's (17, 3) or (M, 17, 3) ones."""
    return init if init.ndim == 2 else init[0]
