"""A reference learnt from several takes of one action (seed 002, sections 3.4-5).

    1. every take as posture vectors, and the action space of them all (section 2);
    2. every take synchronised to every other (section 3); the take with the smallest summed
       synchronisation distance is the median take, the time pattern (eq. 19);
    3. a take far from the others is left out and named: another action, or a failed capture;
    4. the kept takes warped onto the median's frames, and from them the mean performance
       (eq. 21), the spread of every bone at every frame (eq. 22) and the mean direction of
       motion (eq. 23).

The spread is measured as the analysis measures errors (:func:`engine.measures.bone_angles`,
the angle between world bone directions): the root mean square angle of the takes' bones
about the mean bone is eq. 22 in degrees, so an analysis can divide an error by it (z-score).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from engine.body.kinematics import bone_directions, facing_turn, joints_from_bones, rot_y
from engine.body.shapes import BodyShape
from engine.body.skeleton import BONE_NAMES
from engine.errors import InvalidInput
from engine.io.bvh import BvhLimits, Reference, load_reference
from engine.io.bvh.sampling import resample
from engine.measures import bone_angles
from engine.reference.posture_space import ActionSpace, posture_vectors
from engine.reference.synchronisation import Synchronisation, synchronise, warp
from engine.types import Motion

#: Default floor on the spread a z-score divides by: below about 5 deg a bone's error is
#: within what the engine itself measures on the public cases (docs/accuracy.md).
SD_FLOOR_DEG = 5.0


@dataclass(frozen=True)
class TakesSettings:
    """How a reference is learnt from several takes.

    Attributes
    ----------
    share : float
        Share of the postures' variance the action space keeps (eq. 4; seed 002: 0.93-0.95).
    mu : float or None
        Smoothness weight of the synchronisation (eq. 12); eq. 20's rule of thumb when None.
    band : float
        Largest disparity of the synchronisation as a share of the median take's frames
        (:func:`engine.reference.synchronisation.synchronise`).
    window : int
        Frames over which the direction of motion is averaged (eq. 23's d).
    far_deg : float
        A take whose synchronised bones differ from the median take's by more than this on
        average is another action (or a failed capture) and is left out. Measured on the CMU
        takes (benchmarks/README.md): takes of one action by one person differ by 3-11 deg
        (golf swings 63_*, bend-downs 64_29/64_30, a stoop against them 10-11); a squat
        differs from the bend-downs by 15-21 and from the swings by 40-45. A ratio to the
        other takes' differences cannot tell these apart with three takes (a slower swing
        differs from two close ones 2.5 times as much as they differ, like a squat from two
        bend-downs), so the test is absolute.
    max_frames : int
        Longest take accepted (50 s at 120 fps): a take is one performance, and the
        synchronisation's trellis grows as frames x band x frames.
    """

    share: float = 0.95
    mu: float | None = None
    band: float = 0.1
    window: int = 5
    far_deg: float = 13.0
    max_frames: int = 6000


@dataclass(frozen=True)
class Take:
    """One expert take: joints (F, 17, 3) in the world frame of DESIGN.md, its body."""

    name: str
    joints: np.ndarray
    fps: float
    shape: BodyShape
    tpose: np.ndarray | None = None  # (17, 3) the file's conversion T-pose, turned likewise

    @classmethod
    def from_reference(cls, reference: Reference) -> Take:
        """A loaded BVH's motion without its conversion T-pose frame (kept aside)."""
        m = reference.motion
        tpose = m.joints[0] if m.first_motion_frame else None
        return cls(
            name=m.name, joints=m.joints[m.first_motion_frame :], fps=m.fps,
            shape=reference.shape, tpose=tpose,
        )  # fmt: skip


@dataclass(frozen=True)
class ActionModel:
    """The action model of seed 002 eq. 24, with what was learnt on the way.

    Attributes
    ----------
    names : tuple of str
        Every take given, in order.
    kept : ndarray, shape (I,), bool
        Takes that went into the model.
    warnings : tuple of str
        Why each left-out take was left out.
    median : int
        Index of the median take (eq. 19), the time pattern.
    space : ActionSpace
        The aSpace of all the kept takes' postures (eqs. 3-5).
    distances : ndarray, shape (I, I)
        ``distances[n, m]``: synchronisation distance of take m to pattern n (eq. 12, per
        frame); nan on the diagonal.
    syncs : tuple of Synchronisation
        Each take synchronised to the median (identity for the median itself).
    x : tuple of ndarray, shape (F_i, b)
        Each take in the aSpace, as recorded (at the model's frame rate).
    fps : float
    shape : BodyShape
        The median take's body, which the mean performance is drawn with.
    mean_joints : ndarray, shape (P, 17, 3)
        The mean performance (eq. 21) on the median's P frames: mean bone directions of the
        kept takes, the median's bone lengths, the mean root path.
    bone_sd : ndarray, shape (P, 16)
        Radians: RMS angle of the kept takes' bones about the mean bone (eq. 22).
    mean_x, sd_x : ndarray, shape (P, b)
        Eqs. 21-22 in the aSpace, for plots.
    direction : ndarray, shape (P, b)
        Eq. 23: unit mean direction of motion over the last ``window`` frames.
    tpose : ndarray, shape (17, 3), or None
        The median take's conversion T-pose, which the BVH keeps at frame 0.
    """

    names: tuple[str, ...]
    kept: np.ndarray
    warnings: tuple[str, ...]
    median: int
    space: ActionSpace
    distances: np.ndarray
    syncs: tuple[Synchronisation, ...]
    x: tuple[np.ndarray, ...]
    fps: float
    shape: BodyShape
    mean_joints: np.ndarray
    bone_sd: np.ndarray
    mean_x: np.ndarray
    sd_x: np.ndarray
    direction: np.ndarray

    tpose: np.ndarray | None = None

    @property
    def file_joints(self) -> np.ndarray:
        """(F, 17, 3) the mean performance as its BVH holds it: after the median take's
        conversion T-pose when it has one, so frames are numbered as in the median's file."""
        if self.tpose is None:
            return self.mean_joints
        return np.concatenate([self.tpose[None], self.mean_joints])

    @property
    def file_bone_sd(self) -> np.ndarray:
        """(F, 16) the spread on the same frames (the T-pose frame takes the first's)."""
        if self.tpose is None:
            return self.bone_sd
        return np.concatenate([self.bone_sd[:1], self.bone_sd])

    def domain_doc(self, *, sport: str = "", sd_floor_deg: float = SD_FLOOR_DEG) -> dict:
        """The domain document (:mod:`engine.reference.domain`) of the mean performance's
        BVH: its ``variation`` gives the spread at every frame of the file, so that every
        analysis against it also reports errors against the expert's own variation."""
        s = self.summary()
        return {
            "version": 1, "sport": sport,
            "notes": f"built from the takes {', '.join(s['kept'])} (seed 002)",
            "variation": {
                "bone_sd_deg": np.round(np.degrees(self.file_bone_sd), 2).tolist(),
                "sd_floor_deg": float(sd_floor_deg), "z_limit": 3.0,
                "takes": s["kept"], "median_take": s["median_take"],
            },
        }  # fmt: skip

    def arrays(self) -> dict[str, np.ndarray]:
        """Everything learnt, as named arrays (for ``numpy.savez``)."""
        return {
            "names": np.array(self.names), "kept": self.kept, "median": np.array(self.median),
            "aspace_mean": self.space.mean, "aspace_basis": self.space.basis,
            "eigenvalues": self.space.eigenvalues, "distances": self.distances,
            "positions": np.stack([s.positions for s in self.syncs]), "fps": np.array(self.fps),
            "mean_joints": self.mean_joints, "bone_sd": self.bone_sd, "mean_x": self.mean_x,
            "sd_x": self.sd_x, "direction": self.direction,
        }  # fmt: skip

    def summary(self) -> dict:
        """JSON-ready: takes, the median, what was left out and why, the aSpace."""
        return {
            "takes": list(self.names),
            "kept": [self.names[i] for i in np.flatnonzero(self.kept)],
            "median_take": self.names[self.median],
            "warnings": list(self.warnings),
            "frames": int(self.mean_joints.shape[0]),
            "fps": float(self.fps),
            "aspace_dims": self.space.dims,
            "aspace_explained": round(self.space.explained, 4),
            "bone_sd_deg_mean": dict(zip(BONE_NAMES, np.round(np.degrees(self.bone_sd.mean(0)),
                                                              2).tolist(), strict=True)),
            "bone_sd_deg_max": dict(zip(BONE_NAMES, np.round(np.degrees(self.bone_sd.max(0)),
                                                             2).tolist(), strict=True)),
        }  # fmt: skip


def build_action_model(takes: Sequence[Take], settings: TakesSettings | None = None) -> ActionModel:
    """Seed 002 sections 2-5 on ``takes`` (at least two of one action).

    Raises
    ------
    InvalidInput
        Fewer than two takes, or fewer than two left once far takes are left out.
    """
    s = settings or TakesSettings()
    _check_takes(takes, s)
    fps = float(takes[0].fps)
    joints = [_at_fps(t, fps) for t in takes]
    psi = [posture_vectors(j, t.shape.offsets) for j, t in zip(joints, takes, strict=True)]
    kept = np.ones(len(takes), dtype=bool)
    warnings: list[str] = []
    # each pass leaves out the far takes; the model is learnt on the takes that remain
    while True:
        sync = _synchronise_kept(joints, psi, kept, s)
        far = _far_takes(sync.warped, sync.median, kept, s)
        if not far:
            break
        for i, why in far:
            kept[i] = False
            warnings.append(f"take {takes[i].name} left out: {why}")
        if kept.sum() < 2:
            raise InvalidInput("fewer than two takes of one action remain: " + "; ".join(warnings))
    return _mean_model(takes, sync, kept, tuple(warnings), s)


def _check_takes(takes: Sequence[Take], s: TakesSettings) -> None:
    if len(takes) < 2:
        raise InvalidInput("a reference from takes needs at least two takes")
    for t in takes:
        if len(t.joints) > s.max_frames or len(t.joints) < 2:
            raise InvalidInput(f"take {t.name}: {len(t.joints)} frames; a take is one "
                               f"performance of 2 to {s.max_frames} frames")  # fmt: skip


@dataclass(frozen=True)
class _Synchronised:
    """One pass over the takes: the space learnt on the kept ones, and every take in it."""

    space: ActionSpace
    x: list[np.ndarray]  # per take (T_i, b): posture coordinates
    distances: np.ndarray  # (I, I)
    median: int
    syncs: tuple[Synchronisation, ...]  # per take: onto the median's timeline
    warped: list[np.ndarray]  # per take (P, 17, 3): on the median's timeline and facing


def _synchronise_kept(
    joints: list[np.ndarray], psi: list[np.ndarray], kept: np.ndarray, s: TakesSettings
) -> _Synchronised:
    """Seed 002 sections 2-4: the action space, distances, median take and the warps."""
    space = ActionSpace.fit(np.concatenate([p for p, k in zip(psi, kept, strict=True) if k]),
                            s.share)  # fmt: skip
    x = [space.project(p) for p in psi]
    D = _distances(x, kept, s)
    median = _median_take(D, kept)
    syncs = tuple(
        _identity(len(x[median])) if i == median
        else synchronise(x[median], x[i], mu=s.mu, band=s.band)
        for i in range(len(joints))
    )  # fmt: skip
    warped = [warp(j, sy) for j, sy in zip(joints, syncs, strict=True)]
    warped = [w @ rot_y(float(facing_turn(w, warped[median]))).T for w in warped]
    return _Synchronised(space, x, D, median, syncs, warped)


def _mean_model(
    takes: Sequence[Take], sync: _Synchronised, kept: np.ndarray, warnings: tuple[str, ...],
    s: TakesSettings,
) -> ActionModel:  # fmt: skip
    """Seed 002 section 5: the mean motion of the kept takes and its variability."""
    k, median = np.flatnonzero(kept), sync.median
    dirs = np.stack([bone_directions(sync.warped[i]) for i in k])  # (I, P, 16, 3)
    mean_dirs = dirs.mean(0)
    mean_dirs /= np.maximum(np.linalg.norm(mean_dirs, axis=-1, keepdims=True), 1e-12)  # eq. 21
    roots = np.stack([sync.warped[i][:, 0] - sync.warped[i][:1, 0] for i in k]).mean(0)
    root = sync.warped[median][:1, 0] + roots
    mean_joints = joints_from_bones(root, mean_dirs * takes[median].shape.lengths[:, None])
    ang = np.stack([_angles(d, mean_dirs) for d in dirs])  # (I, P, 16)
    xs = np.stack([warp(sync.x[i], sync.syncs[i]) for i in k])  # (I, P, b)
    mean_x = xs.mean(0)
    return ActionModel(
        names=tuple(t.name for t in takes), kept=kept, warnings=warnings, median=median,
        space=sync.space, distances=sync.distances, syncs=sync.syncs, x=tuple(sync.x),
        fps=float(takes[0].fps), shape=takes[median].shape, mean_joints=mean_joints,
        bone_sd=np.sqrt((ang**2).mean(0)),  # eq. 22 as an angle
        mean_x=mean_x, sd_x=np.sqrt(((xs - mean_x) ** 2).mean(0)),
        direction=motion_direction(mean_x, s.window), tpose=takes[median].tpose,
    )  # fmt: skip


def load_takes(
    paths: Sequence[str | os.PathLike],
    limits: BvhLimits | None = None,
    names: Sequence[str] | None = None,
) -> list[Take]:
    """Read BVH takes (refusing files over ``limits`` as they are read), named by ``names``
    (default: the file stems), which error messages use instead of the paths.

    Raises
    ------
    InvalidInput
        A file that is not BVH, cannot be mapped onto the body, or is over the limits; the
        message names the take.
    """
    names = list(names) if names is not None else [Path(p).stem for p in paths]
    takes = []
    for p, name in zip(paths, names, strict=True):
        try:
            take = Take.from_reference(load_reference(p, limits=limits))
        except InvalidInput as exc:
            message = str(exc).replace(str(p), name).replace(Path(p).name, name)
            raise InvalidInput(f"take {name}: {message}") from None
        takes.append(dataclasses.replace(take, name=name))
    return takes


def motion_direction(x: np.ndarray, window: int) -> np.ndarray:
    """Eq. 23: the unit mean of the last ``window`` unit steps of ``x`` (P, b) -> (P, b); the
    first frame takes the first step's direction."""
    step = np.diff(x, axis=0)
    step /= np.maximum(np.linalg.norm(step, axis=-1, keepdims=True), 1e-12)
    step = np.concatenate([step[:1], step])  # frame t's step is t-1 -> t
    c = np.cumsum(np.concatenate([np.zeros((1, x.shape[1])), step]), axis=0)
    lo = np.maximum(np.arange(len(x)) + 1 - window, 0)
    v = c[np.arange(len(x)) + 1] - c[lo]
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _at_fps(take: Take, fps: float) -> np.ndarray:
    if abs(take.fps - fps) < 1e-6:
        return np.asarray(take.joints, dtype=float)
    return resample(Motion(joints=take.joints, fps=take.fps), fps, take.shape).joints


def _distances(x: list[np.ndarray], kept: np.ndarray, s: TakesSettings) -> np.ndarray:
    n = len(x)
    D = np.full((n, n), np.nan)
    for a in range(n):
        for b in range(n):
            if a != b and kept[a] and kept[b]:
                # eq. 19 needs the DP's distance only: no sub-frame refinement
                D[a, b] = synchronise(x[a], x[b], mu=s.mu, band=s.band, refine=False).distance
    return D


def _median_take(D: np.ndarray, kept: np.ndarray) -> int:
    """Eq. 19: the kept take n whose summed synchronisation distance to the others is least."""
    masked = np.where(kept[:, None] & kept[None, :], D, np.nan)
    sums = np.where(kept, np.nansum(masked, axis=1), np.inf)
    return int(np.argmin(sums))


def _far_takes(
    warped: list[np.ndarray], median: int, kept: np.ndarray, s: TakesSettings
) -> list[tuple[int, str]]:
    """Takes to leave out, with the reason: far in posture from the median take once
    synchronised."""
    out = []
    for i in np.flatnonzero(kept):
        deg = float(np.degrees(bone_angles(warped[i], warped[median]).mean()))
        if i != median and deg > s.far_deg:
            out.append((int(i), f"its bones differ from the median take's by {deg:.0f} deg on "
                                f"average (over {s.far_deg:g}): another action, or a failed "
                                "capture?"))  # fmt: skip
    return out


def _angles(d: np.ndarray, mean: np.ndarray) -> np.ndarray:
    """Angles between unit directions (P, 16, 3) -> (P, 16), radians."""
    return np.arccos(np.clip((d * mean).sum(-1), -1.0, 1.0))


def _identity(frames: int) -> Synchronisation:
    return Synchronisation(
        disparity=np.zeros(frames, dtype=int), alpha=1.0, distance=0.0, cost=0.0, mu=0.0
    )
