"""The registration pipeline (thesis chapter 4) as three resumable steps and one call.

    prepare     stages 0-2: foreground, calibration, approximate alignment (4.1, 4.2, 4.5)
    candidates  stage 3 on a range of video frames (4.6): independent across chunks given
                prepare's output, so workers can fan chunks out
    select      stage 4 (4.7): boundaries, selection, refined C, errors -> the result JSON
    analyze     all of it in one process

Each step's output is a small object that saves to one file (:mod:`engine.io.stagefiles`),
so a service can store it in the analysis folder and skip the step when it is redone.
Progress goes out through ``on_progress(stage, fraction)``; nothing here knows who listens.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.io.stagefiles import load_arrays, pack_masks, save_arrays, unpack_masks
from engine.render.camera import Camera
from engine.settings import Settings
from engine.stages.selection import Selection, SelectionSettings
from engine.types import Segments

ProgressFn = Callable[[str, float], None]
PathLike = str | os.PathLike


def _settings(settings: Settings | dict | None) -> Settings:
    if isinstance(settings, Settings):
        return settings
    return Settings.from_dict(settings)


@dataclass(frozen=True)
class Prepared:
    """Output of stages 0-2 and everything later stages need, without re-reading files.

    Attributes
    ----------
    reference_path, video_path : str
    reference_name : str
    reference_fps : float
    first_motion_frame : int
        Reference frame the motion starts at (1 after a conversion T-pose).
    reference_joints : ndarray, shape (T, 17, 3)
        Every frame of the BVH as given (frame numbers count the file's frames).
    shape : BodyShape
        The performer's body: the reference's bones, capsule radii fitted to the calibration
        frame (stage 1, :func:`engine.stages.calibration.fit_body_shape`).
    video : dict
        ``frames``, ``fps``, ``width``, ``height`` (working resolution), ``original_width``,
        ``original_height``.
    camera : Camera
    silhouettes, edges : ndarray of bool, shape (T', H, W)
    C : ndarray of int, shape (T',)
        Approximate correspondence (reference frame per video frame).
    rotations : ndarray, shape (T', 3, 3)
        Global rotation T_t' about the hip.
    segments : Segments
        Reference segments, in the file's frame numbers.
    flags : tuple of tuple of str
        Stage-0 quality flags per video frame.
    timing_s : dict
    keypoints : ndarray, shape (T', 17, 2), or None
        The pose model's 2D keypoints (working pixels; NaN where none), when perception ran.
    keypoint_confidence : ndarray, shape (T', 17), or None
    keypoint_offsets : ndarray, shape (17, 2), or None
        The pose model's offset from each joint (working pixels), removed from its readings.
    perception_model : str
        Name and version of the pose model ("" when none ran).
    """

    reference_path: str
    video_path: str
    reference_name: str
    reference_fps: float
    first_motion_frame: int
    reference_joints: np.ndarray
    shape: BodyShape
    video: dict
    camera: Camera
    silhouettes: np.ndarray
    edges: np.ndarray
    C: np.ndarray
    rotations: np.ndarray
    segments: Segments
    flags: tuple[tuple[str, ...], ...]
    timing_s: dict
    keypoints: np.ndarray | None = None
    keypoint_confidence: np.ndarray | None = None
    keypoint_offsets: np.ndarray | None = None
    perception_model: str = ""

    @property
    def n_frames(self) -> int:
        return int(self.C.shape[0])

    def chunks(self, n_chunks: int) -> list[range]:
        """Split the video frames into at most ``n_chunks`` contiguous ranges."""
        if n_chunks < 1:
            raise InvalidInput(f"n_chunks must be >= 1, got {n_chunks}")
        edges = np.linspace(0, self.n_frames, min(n_chunks, self.n_frames) + 1).round()
        return [range(int(a), int(b)) for a, b in zip(edges[:-1], edges[1:], strict=True)]

    def initial_postures(self, frames: range) -> np.ndarray:
        """Initial estimates of stage 3 per frame, shape (N, 2, 17, 3).

        First B_C(t') turned by T_t' about the hip (thesis 4.6.4), then B_C(t') itself.
        Stage 2 samples T_t' on a coarse grid and a turn in depth barely changes the
        silhouette: on P1 (truth: no turn) it chose 10 deg in most frames, which alone made
        the initial posture 7.2 deg from B_C(t'). With both as starts (and candidates),
        stage 4 weighs the turn's image evidence against its d_B.
        """
        idx = np.asarray(frames)
        ref = self.reference_joints[self.C[idx]]
        hip = ref[:, :1]
        turned = np.einsum("nij,nkj->nki", self.rotations[idx], ref - hip) + hip
        return np.stack([turned, ref], axis=1)

    def save(self, path: PathLike) -> None:
        sil, sil_shape = pack_masks(self.silhouettes)
        edg, _ = pack_masks(self.edges)
        arrays = {
            "reference_joints": self.reference_joints, "offsets": self.shape.offsets,
            "radii": self.shape.radii, "silhouettes": sil, "edges": edg, "C": self.C,
            "rotations": self.rotations,
        }  # fmt: skip
        if self.keypoints is not None and self.keypoint_confidence is not None:
            arrays["keypoints"] = self.keypoints
            arrays["keypoint_confidence"] = self.keypoint_confidence
            arrays["keypoint_offsets"] = (
                np.zeros((17, 2)) if self.keypoint_offsets is None else self.keypoint_offsets
            )
        meta = {
            "reference_path": self.reference_path, "video_path": self.video_path,
            "reference_name": self.reference_name, "reference_fps": self.reference_fps,
            "first_motion_frame": self.first_motion_frame, "video": self.video,
            "camera": self.camera.to_dict(), "mask_shape": list(sil_shape),
            "segments": {"starts": list(self.segments.starts), "end": self.segments.end,
                         "names": list(self.segments.names)},
            "flags": [list(f) for f in self.flags], "timing_s": self.timing_s,
            "perception_model": self.perception_model,
        }  # fmt: skip
        save_arrays(path, arrays, meta)

    @classmethod
    def load(cls, path: PathLike) -> Prepared:
        a, m = load_arrays(path)
        shape = tuple(m["mask_shape"])
        seg = m["segments"]
        return cls(
            reference_path=m["reference_path"], video_path=m["video_path"],
            reference_name=m["reference_name"], reference_fps=float(m["reference_fps"]),
            first_motion_frame=int(m["first_motion_frame"]),
            reference_joints=a["reference_joints"],
            shape=BodyShape(offsets=a["offsets"], radii=a["radii"]), video=m["video"],
            camera=Camera.from_dict(m["camera"]),
            silhouettes=unpack_masks(a["silhouettes"], shape),
            edges=unpack_masks(a["edges"], shape), C=a["C"], rotations=a["rotations"],
            segments=Segments(tuple(seg["starts"]), int(seg["end"]), tuple(seg["names"])),
            flags=tuple(tuple(f) for f in m["flags"]), timing_s=m["timing_s"],
            keypoints=a.get("keypoints"), keypoint_confidence=a.get("keypoint_confidence"),
            keypoint_offsets=a.get("keypoint_offsets"),
            perception_model=str(m.get("perception_model", "")),
        )  # fmt: skip

    def frame_keypoints(self, frames: range) -> tuple[np.ndarray, np.ndarray] | None:
        """The keypoint readings (N, 2, 17, 2) and confidences (N, 2, 17) of ``frames``
        (:func:`engine.stages.perception.readings`, offsets removed); None without them."""
        from engine.stages.perception import readings

        if self.keypoints is None or self.keypoint_confidence is None:
            return None
        idx = np.asarray(frames)
        return readings(self.keypoints[idx], self.keypoint_confidence[idx],
                        self.keypoint_offsets)  # fmt: skip


@dataclass(frozen=True)
class CandidateChunk:
    """Stage-3 output for a range of video frames.

    Attributes
    ----------
    frames : ndarray of int, shape (N,)
    candidates : list of ndarray, shape (K_t', 17, 3) each
    d_s : list of ndarray, shape (K_t',) each
        d_S of each candidate against its frame's body region: stage 4's image evidence
        (``candidate_d_s`` of :func:`engine.stages.selection.select_and_refine`).
    flags : tuple of tuple of str
    seconds : float
    """

    frames: np.ndarray
    candidates: list[np.ndarray]
    d_s: list[np.ndarray]
    flags: tuple[tuple[str, ...], ...]
    seconds: float

    def save(self, path: PathLike) -> None:
        counts = np.array([len(c) for c in self.candidates])
        arrays = {
            "frames": self.frames, "counts": counts,
            "candidates": np.concatenate(self.candidates or [np.zeros((0, 17, 3))]),
            "d_s": np.concatenate(self.d_s or [np.zeros(0)]),
        }  # fmt: skip
        save_arrays(path, arrays, {"flags": [list(f) for f in self.flags], "seconds": self.seconds})

    @classmethod
    def load(cls, path: PathLike) -> CandidateChunk:
        a, m = load_arrays(path)
        split = np.cumsum(a["counts"])[:-1]
        return cls(
            frames=a["frames"], candidates=np.split(a["candidates"], split),
            d_s=np.split(a["d_s"], split), flags=tuple(tuple(f) for f in m["flags"]),
            seconds=float(m["seconds"]),
        )  # fmt: skip


def _reference_segments(reference: Any, reference_path: PathLike) -> Segments:
    """Reference segments (thesis 2.1.1 item 4), set, named and tuned by the domain file (6.8)."""
    from engine.reference.domain import find_domain, reference_segments

    return reference_segments(reference.motion, find_domain(reference_path))


def prepare(
    reference_path: PathLike,
    video_path: PathLike,
    settings: Settings | dict | None = None,
    *,
    frames: tuple[int, int] | None = None,
    mapping: dict[str, str] | None = None,
    units_to_m: float | None = None,
    on_progress: ProgressFn | None = None,
) -> Prepared:
    """Stages 0-2 (thesis 4.1, 4.2, 4.5) from files.

    ``frames = (a, b)`` analyses video frames a..b-1 only; result frame numbers still count
    the file's frames. ``mapping`` and ``units_to_m`` say how to read the BVH
    (:func:`engine.io.bvh.load_reference`).

    Raises
    ------
    InvalidInput
        Unreadable/unmappable BVH, unreadable or over-limit video, bad settings.
    RegistrationFailed
        No usable camera or body region.
    """
    from engine.io.bvh import load_reference
    from engine.io.video import read_video
    from engine.stages import run_stages_0_2_full

    s = _settings(settings)
    t0 = time.perf_counter()
    reference = load_reference(reference_path, mapping=mapping, units_to_m=units_to_m)
    video = read_video(video_path, height=s.working_height, limits=s.video)
    offset = 0
    if frames is not None:
        a, b = frames
        if not 0 <= a < b <= video.n_frames or b - a < 2:
            raise InvalidInput(f"frames must be a range of >= 2 frames within 0..{video.n_frames}")
        video = dataclasses.replace(
            video, frames=video.frames[a:b], timestamps_s=video.timestamps_s[a:b]
        )
        offset = a
    segments = _reference_segments(reference, reference_path)
    load_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    perception = None
    if s.perception.enabled:
        from engine.stages.perception import MediaPipePose, perceive

        model = MediaPipePose(min_detection_confidence=s.perception.min_detection_confidence)
        perception = perceive(video.frames, model, on_progress=on_progress)
    perceive_s = time.perf_counter() - t0
    r = run_stages_0_2_full(
        reference, video, s.foreground, s.calibration, s.alignment, perception=perception,
        min_person_fraction=s.perception.min_detected_fraction, on_progress=on_progress,
    )  # fmt: skip
    fg, camera, aligned, timing = r.foreground, r.camera, r.alignment, r.timing_s
    h, w = video.frames.shape[1:3]
    return Prepared(
        reference_path=str(reference_path), video_path=str(video_path),
        reference_name=reference.motion.name or os.path.basename(str(reference_path)),
        reference_fps=float(reference.motion.fps),
        first_motion_frame=int(reference.motion.first_motion_frame),
        reference_joints=reference.motion.joints, shape=r.shape,
        video={"frames": int(video.n_frames), "fps": float(video.fps), "width": int(w),
               "height": int(h), "original_width": int(video.original_width),
               "original_height": int(video.original_height), "offset": offset},
        camera=camera, silhouettes=fg.silhouettes, edges=fg.edges,
        C=np.asarray(aligned.C, dtype=int), rotations=np.asarray(aligned.rotations, float),
        segments=segments, flags=tuple(tuple(f) for f in fg.flags),
        timing_s={"load": load_s, "perception": perceive_s,
                  **{k: float(v) for k, v in timing.items()}},
        keypoints=None if perception is None else perception.keypoints,
        keypoint_confidence=None if perception is None else perception.confidence,
        keypoint_offsets=None if perception is None else r.keypoint_offsets,
        perception_model="" if perception is None else perception.model,
    )  # fmt: skip


def candidates(
    prepared: Prepared,
    frames: range | None = None,
    settings: Settings | dict | None = None,
    *,
    on_progress: ProgressFn | None = None,
) -> CandidateChunk:
    """Stage 3 (thesis 4.6) on ``frames`` (all by default).

    Each frame has its own random stream (from the seed and its frame number), so with the
    default ``candidates.n_prev`` 0 a frame's candidates are the same whichever chunk computes
    it, on any worker, in any order.
    """
    from engine.stages.candidates import estimate_candidates_chunk, frame_rngs

    s = _settings(settings)
    frames = range(prepared.n_frames) if frames is None else frames
    if len(frames) == 0 or frames.start < 0 or frames.stop > prepared.n_frames:
        raise InvalidInput(f"frames must be a non-empty range within 0..{prepared.n_frames}")
    idx = np.asarray(frames)
    t0 = time.perf_counter()
    out = estimate_candidates_chunk(
        prepared.silhouettes[idx], prepared.edges[idx], prepared.camera, prepared.shape,
        prepared.initial_postures(frames), settings=s.candidates,
        rng=frame_rngs(s.seed, frames), keypoints=prepared.frame_keypoints(frames),
        on_progress=on_progress,
    )  # fmt: skip
    return CandidateChunk(
        frames=idx, candidates=[f.candidates for f in out], d_s=[f.d_s for f in out],
        flags=tuple(
            tuple(prepared.flags[t]) + tuple(f.flags) for t, f in zip(idx, out, strict=True)
        ),
        seconds=time.perf_counter() - t0,
    )  # fmt: skip


def select(
    prepared: Prepared,
    chunks: Sequence[CandidateChunk],
    settings: Settings | dict | None = None,
    *,
    on_progress: ProgressFn | None = None,
) -> dict:
    """Stage 4 (thesis 4.7) over all chunks -> the DESIGN.md result document.

    The candidates' d_S travel with them, so selection weighs image evidence against the
    distance to the reference (beyond the thesis, see ``SelectionSettings.image_weight``).
    """
    from engine.io.result import build_result
    from engine.reference.domain import find_domain
    from engine.stages.selection import select_and_refine

    s = _settings(settings)
    domain = find_domain(prepared.reference_path)
    sel_settings = s.selection
    if domain is not None and domain.boundary_joints:
        sel_settings = dataclasses.replace(sel_settings, boundary_joints=domain.boundary_joints)
    if domain is not None and domain.direction_change_deg is not None:
        sel_settings = dataclasses.replace(
            sel_settings, direction_change_deg=domain.direction_change_deg
        )
    order = sorted(chunks, key=lambda c: int(c.frames[0]))
    frames = np.concatenate([c.frames for c in order])
    if not np.array_equal(frames, np.arange(prepared.n_frames)):
        raise InvalidInput("candidate chunks must cover every video frame exactly once")
    cands = [k for c in order for k in c.candidates]
    flags = [f for c in order for f in c.flags]
    d_s = [d for c in order for d in c.d_s]
    t0 = time.perf_counter()
    selection = select_and_refine(
        cands, prepared.reference_joints, prepared.segments, prepared.C.astype(float),
        settings=sel_settings, fps_ratio=prepared.reference_fps / prepared.video["fps"],
        video_fps=prepared.video["fps"], candidate_flags=flags, candidate_d_s=d_s,
        on_progress=on_progress,
    )  # fmt: skip
    selection = flag_image_misfit(selection, d_s, sel_settings.misfit_margin)
    timing = dict(prepared.timing_s)
    timing["candidates"] = float(sum(c.seconds for c in order))
    timing["selection"] = time.perf_counter() - t0
    timing["total"] = float(sum(timing.values()))
    v = prepared.video
    camera = original_pixels(prepared.camera, v["original_width"], v["original_height"])
    doc = build_result(
        reference_name=prepared.reference_name,
        reference_frames=int(prepared.reference_joints.shape[0]),
        reference_fps=prepared.reference_fps,
        video={"frames": v["frames"], "fps": v["fps"], "width": v["original_width"],
               "height": v["original_height"]},
        camera=camera, selection=selection, candidates=cands, timing_s=timing, domain=domain,
        video_frame_offset=int(v.get("offset", 0)),
    )  # fmt: skip
    add_image_best(doc, cands, d_s, camera)
    add_uncertainty(doc, cands, d_s, prepared.reference_joints[selection.C],
                    sel_settings.uncertainty_margin)  # fmt: skip
    chosen = np.stack([c[int(k)] for c, k in zip(cands, selection.selected, strict=True)])
    assess_fit(doc, chosen, prepared, sel_settings)
    return doc


def add_uncertainty(
    doc: dict,
    candidates: Sequence[np.ndarray],
    d_s: Sequence[np.ndarray],
    reference: np.ndarray,
    margin: float,
) -> None:
    """How sure each bone's error is: its range over the candidates the video cannot tell
    from the reported one (beyond the thesis).

    A candidate whose image evidence (d_S + keypoints, the candidates' ``d_s``) is within
    ``margin`` of the best one's explains the video as well: one camera cannot choose
    between them. Its depth flips (thesis 4.6.5) project to the same image, so a bone bent
    in depth gets a wide range and an in-plane one a narrow range.

    Adds to every frame ``bone_error_range_deg`` ([lo, hi] per bone, the reported error
    always inside) and to every segment ``bone_uncertainty_deg`` (mean width per bone over
    the frames it owns).

    Parameters
    ----------
    doc : dict
        The result document, changed in place.
    candidates : list of ndarray, shape (K_t', 17, 3) each
    d_s : list of ndarray, shape (K_t',) each
    reference : ndarray, shape (T', 17, 3)
        The reference posture at C(t') of each frame.
    margin : float
    """
    from engine.measures import bone_angles

    widths = []
    for f, cands, d, ref in zip(doc["frames"], candidates, d_s, reference, strict=True):
        near = d <= d.min() + margin
        ang = np.degrees(bone_angles(cands[near], ref[None]))  # (K, 16)
        own = np.asarray(f["bone_errors_deg"], float)
        lo, hi = np.minimum(ang.min(0), own), np.maximum(ang.max(0), own)
        f["bone_error_range_deg"] = np.round(np.stack([lo, hi], -1), 2).tolist()
        widths.append(hi - lo)
    w = np.array(widths)
    t0 = doc["frames"][0]["t"] if doc["frames"] else 0
    for seg in doc["segments"]:
        a, b = seg["performer_start"] - t0, seg["performer_end"] - t0
        part = w[max(a, 0) : max(b, a + 1)]
        seg["bone_uncertainty_deg"] = np.round(part.mean(0), 2).tolist() if len(part) else []


def assess_fit(
    doc: dict, postures: np.ndarray, prepared: Prepared, settings: SelectionSettings
) -> None:
    """How well the reported postures explain the video; ``poor_fit`` when they do not.

    Two checks, each with its own plain message (beyond the thesis):

    1. **The body region.** Per frame, 1 - Dice overlap (d_A, thesis eq. 4.1) of the
       reported posture's capsule body with stage 0's region. Where the region is the
       performer this stays near 0.1-0.25 (the capsules are not clothes); where stage 0 could
       not separate him from the background it is a blob of wall that no posture explains.
       Poor when the median exceeds ``settings.poor_fit_region``.
    2. **The keypoints.** Per frame, the worst confident keypoint's distance to the reported
       joint (the better left/right reading, the detector's offsets removed), as a fraction
       of the body's height. On the six public cases under 0.3 in 0-3 % of the frames;
       where the video holds several repetitions of a one-repetition reference, or another
       motion, the reported postures leave the body (the real squat clips: 25 % and 38 %).
       Poor when more than ``settings.poor_fit_frames`` of the frames exceed
       ``settings.poor_fit_joint``.

    Parameters
    ----------
    doc : dict
        The result document, changed in place: ``summary.fit`` and, if poor, the status
        and a first message.
    postures : ndarray, shape (T', 17, 3)
        The reported (selected) postures.
    prepared : Prepared
    settings : SelectionSettings
    """
    from engine.render.capsules import Target, d_A_batch

    d_a = np.array([
        d_A_batch(p[None], Target.from_masks(sil, edg), prepared.shape, prepared.camera)[0]
        for p, sil, edg in zip(postures, prepared.silhouettes, prepared.edges, strict=True)
    ])  # fmt: skip
    far = _worst_keypoint(postures, prepared)
    summary = doc["summary"]
    summary["fit"] = {
        "region_mismatch_median": round(float(np.median(d_a)), 4),
        "region_mismatch_per_frame": np.round(d_a, 4).tolist(),
        "poor_frames": int(np.count_nonzero(d_a > settings.poor_fit_region)),
    }  # fmt: skip
    message = None
    if np.median(d_a) > settings.poor_fit_region:
        share = 100 * float(np.mean(d_a > settings.poor_fit_region))
        message = (
            "We could not separate you from the background well enough to measure your "
            f"posture (the body found in the video matches no posture in {share:.0f} % "
            "of the frames). Film in front of a plain wall, in clothes that differ from it, "
            "with the whole body in view and the camera still."
        )
    if far is not None:
        off = np.nan_to_num(far, nan=0.0) > settings.poor_fit_joint
        # JSON has no NaN: a frame without a confident keypoint says null
        summary["fit"]["keypoint_worst_per_frame"] = [
            round(float(x), 3) if np.isfinite(x) else None for x in far
        ]
        summary["fit"]["keypoint_off_frames"] = int(off.sum())
        if message is None and off.mean() > settings.poor_fit_frames:
            message = (
                f"Your body and the expert's motion part ways in {100 * off.mean():.0f} % of "
                "the frames: the video may hold several repetitions, or another motion than "
                "the reference. Trim it to one repetition of the reference's motion, from its "
                "first posture to its last."
            )
    if message is not None:
        summary["status"] = "poor_fit"
        summary["messages"] = [message, *summary["messages"]]


def _worst_keypoint(postures: np.ndarray, prepared: Prepared) -> np.ndarray | None:
    """Per frame, the largest distance from a confident keypoint (> 0.5) to its reported
    joint as a fraction of the body's height in the image, over the better of the two
    readings, (T',); NaN without confident keypoints; None without perception."""
    readings = prepared.frame_keypoints(range(prepared.n_frames))
    if readings is None:
        return None
    kp, conf = readings  # (T', 2, 17, 2), (T', 2, 17)
    ok = (conf > 0.5) & np.isfinite(kp).all(-1)
    d = np.linalg.norm(prepared.camera.project(postures)[:, None] - np.nan_to_num(kp), axis=-1)
    mean = (d * ok).sum(-1) / np.maximum(ok.sum(-1), 1)
    best = np.argmin(np.where(ok.any(-1), mean, np.inf), axis=1)  # (T',)
    rows = np.arange(len(postures))
    worst = np.where(ok[rows, best], d[rows, best], -np.inf).max(-1)
    height_px = prepared.camera.scale * float(
        np.ptp(prepared.reference_joints[prepared.first_motion_frame][:, 1])
    )
    return np.where(np.isfinite(worst), worst / max(height_px, 1e-9), np.nan)


def add_image_best(
    doc: dict, candidates: Sequence[np.ndarray], d_s: Sequence[np.ndarray], camera: Camera
) -> None:
    """In ``image_misfit`` frames, the candidate that explains the video best (beyond the thesis).

    Adds ``image_best`` (its index in ``candidates``) and ``image_best_joints_2d`` (its
    projection, video pixels) to those frames of the result ``doc``, so a coach can see what
    the video suggests where it disagrees with the reported posture (a lifted foot the prior
    keeps down). Its depth is as uncertain as any single-view posture's.

    Parameters
    ----------
    doc : dict
        The result document (DESIGN.md), changed in place.
    candidates : list of ndarray, shape (K_t', 17, 3) each
    d_s : list of ndarray, shape (K_t',) each
    camera : Camera
        In the video file's pixels (the result's ``joints_2d``).
    """
    for f, cands, d in zip(doc["frames"], candidates, d_s, strict=True):
        if "image_misfit" not in f["flags"]:
            continue
        k = int(np.argmin(d))
        f["image_best"] = k
        f["image_best_joints_2d"] = np.round(camera.project(cands[k]), 2).tolist()


def flag_image_misfit(
    selection: Selection, d_s: Sequence[np.ndarray], margin: float
) -> Selection:
    """Flag frames whose selected posture the video does not confirm (beyond the thesis).

    The calibration frame (video frame 0, whose posture is the reference's by the thesis'
    assumption B'_0 = B_0) sets the d_S a correct posture reaches on this video; a frame
    whose selected candidate scores worse by more than ``margin`` gets ``image_misfit``,
    and a summary message says how many, so a coach never reads a small error there as
    certain.

    Parameters
    ----------
    selection : Selection
    d_s : list of ndarray, shape (K_t',) each
        d_S of every candidate, indices matching ``selection.selected``.
    margin : float
    """
    chosen = np.array([d[int(k)] for d, k in zip(d_s, selection.selected, strict=True)])
    bad = chosen > chosen[0] + margin
    if not bad.any():
        return selection
    flags = tuple(
        (*f, "image_misfit") if b else tuple(f)
        for f, b in zip(selection.flags, bad, strict=True)
    )
    n, total = int(bad.sum()), len(bad)
    message = (
        f"The video matches the reported posture poorly in {n} of {total} frames (flag "
        "image_misfit, shaded on the error plot): the errors shown there may be "
        "underestimated, so look at those frames yourself."
    )
    return dataclasses.replace(selection, flags=flags, messages=(*selection.messages, message))


def original_pixels(camera: Camera, width: int, height: int) -> Camera:
    """The working-resolution camera re-expressed in the video file's own pixels.

    Pixel centres sit on integers at both resolutions, so u_file = (u_work + 0.5) / k - 0.5.
    """
    k = camera.height / height
    if abs(k - 1.0) < 1e-12:
        return camera
    return Camera(
        scale=camera.scale / k, theta_z=camera.theta_z, cx=(camera.cx + 0.5) / k - 0.5,
        cy=(camera.cy + 0.5) / k - 0.5, azimuth=camera.azimuth, width=width, height=height,
        distance=camera.distance,
    )


def analyze(
    reference_path: PathLike,
    video_path: PathLike,
    settings: Settings | dict | None = None,
    *,
    frames: tuple[int, int] | None = None,
    mapping: dict[str, str] | None = None,
    units_to_m: float | None = None,
    on_progress: ProgressFn | None = None,
) -> dict:
    """The whole registration (thesis chapter 4) in this process -> the result document.

    Parameters as :func:`prepare`."""
    s = _settings(settings)
    prepared = prepare(reference_path, video_path, s, frames=frames, mapping=mapping,
                       units_to_m=units_to_m, on_progress=on_progress)  # fmt: skip
    chunks = [
        candidates(prepared, r, s, on_progress=on_progress)
        for r in prepared.chunks(max(1, -(-prepared.n_frames // s.chunk_frames)))
    ]
    return select(prepared, chunks, s, on_progress=on_progress)
