"""The sub-pixel refinement of stage 3: a pattern search on d_S (thesis 6.4)."""

from __future__ import annotations

import numpy as np

from engine.body.kinematics import cross3, rotation_about_axis
from engine.body.skeleton import N_PARTS, PART_BONES
from engine.measures import d_B
from engine.render.camera import Camera
from engine.stages.candidates.postures import (
    _SUBTREES,
    _part_dir,
    _turned,
    _turned_alone,
    limits_ok,
)
from engine.stages.candidates.scorer import _Scorer
from engine.stages.candidates.settings import CandidateSettings


def _refine(
    scorer: _Scorer,
    joints: np.ndarray,
    camera: Camera,
    s: CandidateSettings,
    ref: np.ndarray | None = None,
    *,
    in_plane: bool = False,
    mu: float | None = None,
    step0_deg: float | None = None,
    sweeps: int | None = None,
    move_root: bool = True,
) -> tuple[np.ndarray, float]:
    """Sub-pixel pattern search on d_S over subtree rotations and root shifts (thesis 6.4).

    Each sweep tries, part by part, the moves of :func:`_pattern_moves` and keeps the best if
    it lowers the objective and respects the joint limits. The rotation step starts at
    ``step0_deg`` (``s.refine_step0_deg``): starting coarse lets a limb left in a wrong local
    minimum by BP get out. It halves after a sweep in which no part improved, or, with
    ``s.refine_per_part`` (beyond the thesis), per part whenever that part finds nothing, so
    that converged parts drop out instead of being scored again every sweep.

    With ``ref`` and ``s.bp_prior_weight`` (or ``mu``), the objective is BP's: d_S + mu
    d_B(., ref). ``in_plane`` turns parts about the viewing direction only (the directions a
    silhouette can see), keeping the start's depth. ``move_root`` False keeps the root joint
    where it is. Returns the refined posture (17, 3) and its objective.
    """
    if mu is None:
        mu = s.bp_prior_weight if ref is not None else 0.0

    def objective(q: np.ndarray) -> np.ndarray:
        out = scorer.full(q)
        return out + mu * d_B(q, ref) if mu > 0 and ref is not None else out

    cur = joints.copy()
    best = float(objective(cur[None])[0])
    step0 = np.radians(s.refine_step0_deg if step0_deg is None else step0_deg)
    min_step = np.radians(s.refine_min_step_deg)
    # a step per part; without s.refine_per_part they all halve together (one shared step)
    steps = np.full(N_PARTS, step0)
    # The (part, step) pairs that found nothing since ``cur`` last changed. Trying one again
    # would score the same moves of the same posture and find nothing again, so it is skipped:
    # the sweep that ends each step (no part improves) then scores only the parts before the
    # previous sweep's last improvement. The result is the plain search's, for fewer scores.
    stuck: set[tuple[int, float]] = set()
    for _ in range(s.refine_sweeps if sweeps is None else sweeps):
        improved = False
        for p in range(N_PARTS):
            if steps[p] < min_step or (p, steps[p]) in stuck:
                continue
            batch = _pattern_moves(
                cur, p, steps[p], camera, in_plane=in_plane, alone=s.refine_alone,
                move_root=move_root,
            )  # fmt: skip
            sc = objective(batch)
            k = int(np.argmin(sc))
            if sc[k] < best - 1e-9 and limits_ok(batch[k]):
                cur, best, improved = batch[k], float(sc[k]), True
                stuck.clear()
                continue
            stuck.add((p, float(steps[p])))
            if s.refine_per_part:
                steps[p] /= 2.0  # this part is converged at this step
        if not s.refine_per_part and not improved:
            steps /= 2.0
        if steps.max() < min_step:
            break
    return cur, best


def _pattern_moves(
    cur: np.ndarray,
    p: int,
    step: float,
    camera: Camera,
    *,
    in_plane: bool,
    alone: bool,
    move_root: bool,
) -> np.ndarray:
    """The moves the pattern search tries for part p of ``cur`` (17, 3), shape (n, 17, 3).

    Part p's subtree turned by +-``step`` rad about the viewing direction and, unless
    ``in_plane``, about the axes across it (the second only for parts of several bones);
    with ``alone`` (``refine_alone``, beyond the thesis) the part also turned alone, the
    parts below keeping their directions; for the root part with ``move_root``, the whole
    body shifted along the image axes by half a pixel per degree of step (at least a quarter).
    """
    n = camera.view_dir
    d = _part_dir(cur, p)
    a1 = cross3(n, d)
    axes = [n, a1] if np.linalg.norm(a1) > 1e-9 and not in_plane else [n]
    if len(PART_BONES[p]) > 1 and not in_plane:
        axes.append(cross3(n, a1) if np.linalg.norm(a1) > 1e-9 else d)
    # every axis by -step and +step, in one call (the same values as one call each)
    Rs = rotation_about_axis(np.repeat(axes, 2, axis=0), np.tile([-step, step], len(axes)))
    samples = list(_turned(cur, p, Rs))
    if alone and len(_SUBTREES[p]) > 1:
        samples.extend(_turned_alone(cur, p, Rs))
    if p == 0 and move_root:
        px = 1.0 / camera.scale
        for vec in camera.R_cam_world[:2]:
            for sg in (-1.0, 1.0):
                samples.append(cur + sg * 0.5 * px * vec * max(step / np.radians(1), 0.5))
    return np.stack(samples)
