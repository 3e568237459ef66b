"""The registration pipeline (thesis chapter 4): the one place that runs the stages.

    prepare     stages 0-2: foreground, calibration, approximate alignment (4.1, 4.2, 4.5)
    candidates  stage 3 on a range of video frames (4.6): independent across chunks given
                prepare's output, so workers can fan chunks out
    all_candidates  stage 3 on every frame, its chunks on one or several processes
    select      stage 4 (4.7): boundaries, selection, refined C, errors -> the result JSON
    analyze     all of it, stage 3 on ``workers`` processes

Each step's output is a small object that saves to one file (:mod:`engine.stage_outputs`),
so a service can store it in the analysis folder and skip the step when it is redone.
Settings and the reference's domain arrive parsed (:class:`Settings`, :class:`Domain`): the
caller's edge (command line, worker task) parses them once. Progress goes out through
``on_progress(stage, fraction)``; nothing here knows who listens.
"""

from __future__ import annotations

import dataclasses
import multiprocessing
import os
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ProcessPoolExecutor, ThreadPoolExecutor, as_completed

import numpy as np

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.io.bvh import Reference, load_reference
from engine.io.result import add_expert_2d, build_result
from engine.io.video import Video, read_video
from engine.reference.domain import Domain, check_variation, parse_domain, reference_segments
from engine.render.camera import Camera
from engine.settings import Settings
from engine.stage_outputs import AnalysedVideo, CandidateChunk, Prepared, Stages02
from engine.stages.alignment import AlignmentResult, align
from engine.stages.assessment import (
    add_image_best,
    add_uncertainty,
    assess_fit,
    flag_image_misfit,
    note_framing,
    note_repetitions,
)
from engine.stages.calibration import (
    CalibrationSettings,
    calibrate,
    fit_body_shape,
    mirror_azimuth,
    refine_on_frames,
)
from engine.stages.candidates import estimate_candidates_chunk, frame_rngs
from engine.stages.candidates.key_frames import choose_key_frames, key_span
from engine.stages.foreground import (
    Background,
    ForegroundResult,
    background_of,
    extract_foreground,
    outline,
)
from engine.stages.framing import first_frame_problems
from engine.stages.perception import (
    Perception,
    calibration_keypoints,
    check_person_found,
    offsets_on_first_frames,
    readings,
)
from engine.stages.selection import SelectionSettings, select_and_refine
from engine.threads import thread_count

# What a service calls: the three steps, their outputs, and the parsers of its inputs.
__all__ = [
    "CandidateChunk", "Prepared", "Settings", "Stages02", "all_candidates", "analyze", "candidates",
    "parse_domain", "prepare", "run_stages_0_2", "select",
]  # fmt: skip

ProgressFn = Callable[[str, float], None]
PathLike = str | os.PathLike
#: A camera's keypoint readings for stages 1-2: (T', 2, 17, 2) positions, (T', 2, 17) weights
Readings = tuple[np.ndarray, np.ndarray]


# ---------------------------------------------------------------------------------------------
# the steps


def prepare(
    reference_path: PathLike,
    video_path: PathLike,
    settings: Settings | None = None,
    *,
    domain: Domain | None = None,
    mapping: dict[str, str] | None = None,
    units_to_m: float | None = None,
    frames: tuple[int, int] | None = None,
    on_progress: ProgressFn | None = None,
) -> Prepared:
    """Stages 0-2 (thesis 4.1, 4.2, 4.5) from files.

    ``domain`` is the coach's knowledge of the reference (segments, weights; thesis 6.8).
    ``mapping`` and ``units_to_m`` say how to read the BVH
    (:func:`engine.io.bvh.load_reference`). ``frames = (a, b)`` analyses video frames
    a..b-1 only; result frame numbers still count the file's frames.

    Raises
    ------
    InvalidInput
        Unreadable/unmappable BVH, unreadable or over-limit video, bad frame range, domain
        segments outside the reference.
    RegistrationFailed
        No person, no usable camera or body region.
    """
    s = settings or Settings()
    if frames is not None:  # the user chose the frames: no search for performances
        s = dataclasses.replace(s, alignment=dataclasses.replace(s.alignment, repetitions=False))
    t0 = time.perf_counter()
    reference = load_reference(reference_path, mapping=mapping, units_to_m=units_to_m)
    video, offset, file_frames = _read_frames(video_path, s, frames)
    segments = reference_segments(reference.motion, domain)  # thesis 2.1.1 item 4, 6.8
    check_variation(reference.motion, domain)  # seed 002: the takes' spread, frame by frame
    load_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    perception, background = _perceive_beside_background(video, s, on_progress)
    perceive_s = time.perf_counter() - t0
    r = run_stages_0_2(reference, video, s, perception=perception, background=background,
                       on_progress=on_progress)  # fmt: skip
    perception, offset = r.perception, offset + r.first_frame
    h, w = video.frames.shape[1:3]
    return Prepared(
        reference_path=str(reference_path), video_path=str(video_path),
        reference_name=reference.motion.name or os.path.basename(str(reference_path)),
        reference_fps=float(reference.motion.fps),
        first_motion_frame=int(reference.motion.first_motion_frame),
        reference_joints=reference.motion.joints, shape=r.shape,
        video=AnalysedVideo(frames=r.foreground.n_frames, fps=float(video.fps), width=int(w),
                            height=int(h), original_width=int(video.original_width),
                            original_height=int(video.original_height), offset=offset,
                            file_frames=file_frames),
        camera=r.camera, silhouettes=r.foreground.silhouettes, edges=r.foreground.edges,
        C=np.asarray(r.alignment.C, dtype=int),
        rotations=np.asarray(r.alignment.rotations, float), segments=segments, domain=domain,
        flags=tuple(tuple(f) for f in r.foreground.flags),
        timing_s={"load": load_s, "perception": perceive_s,
                  **{k: float(v) for k, v in r.timing_s.items()}},
        keypoints=None if perception is None else perception.keypoints,
        keypoint_confidence=None if perception is None else perception.confidence,
        keypoint_offsets=None if perception is None else r.keypoint_offsets,
        perception_model="" if perception is None else perception.model,
        repetitions=r.repetitions,  # found only in a whole video: its frames are the file's
        framing=_first_frame_framing(perception, int(w), int(h)),
    )  # fmt: skip


def _first_frame_framing(perception: Perception | None, width: int, height: int) -> tuple[str, ...]:
    """:func:`first_frame_problems` of the analysed part's first frame; none without the
    pose model's landmarks."""
    if perception is None or perception.landmarks is None or perception.n_frames == 0:
        return ()
    return first_frame_problems(perception.landmarks[0], bool(perception.detected[0]),
                                width, height)  # fmt: skip


def candidates(
    prepared: Prepared,
    frames: range | None = None,
    settings: Settings | None = None,
    *,
    on_progress: ProgressFn | None = None,
) -> CandidateChunk:
    """Stage 3 (thesis 4.6) on ``frames`` (all by default).

    Each frame has its own random stream (from the seed and its frame number), so with the
    default ``candidates.n_prev`` 0 a frame's candidates are the same whichever chunk computes
    it, on any worker, in any order.
    """
    s = settings or Settings()
    frames = range(prepared.n_frames) if frames is None else frames
    inputs, lead = _chunk_inputs(prepared, frames, s)
    t0 = time.perf_counter()
    out = estimate_candidates_chunk(**inputs, on_progress=on_progress)
    return _chunk(prepared, frames, out[lead : lead + len(frames)], time.perf_counter() - t0)


def _key_frames(prepared: Prepared, s: Settings) -> np.ndarray:
    """Stage 3's key frames over the whole analysis, shape (T',) of bool (all with
    ``candidates.key_gap`` 1), from the expert's own motion B_C(t'): the turn T_t', sampled
    on a coarse grid, jumps by a few degrees between frames where the body does not move."""
    c = s.candidates
    if c.key_gap == 1:
        return np.ones(prepared.n_frames, bool)
    expert = prepared.initial_postures(range(prepared.n_frames))[:, 1]
    return choose_key_frames(expert, c.key_gap, c.key_motion_deg)


def _chunk_inputs(prepared: Prepared, frames: range, s: Settings) -> tuple[dict, int]:
    """The arguments of :func:`estimate_candidates_chunk` for ``frames``: only their frames'
    data, so a chunk ships to another process cheaply. They cover ``frames`` widened to the
    adjacent key frames (:func:`key_span`); the second value is where ``frames`` start in
    the estimates."""
    if len(frames) == 0 or frames.start < 0 or frames.stop > prepared.n_frames:
        raise InvalidInput(f"frames must be a non-empty range within 0..{prepared.n_frames}")
    keys = _key_frames(prepared, s)
    span = key_span(frames, keys)
    idx = np.asarray(span)
    return dict(
        target_silhouettes=prepared.silhouettes[idx], target_edges=prepared.edges[idx],
        camera=prepared.camera, shape=prepared.shape,
        initial_joints=prepared.initial_postures(span), settings=s.candidates,
        rng=frame_rngs(s.seed, span), keypoints=prepared.frame_keypoints(span),
        keys=keys[idx],
    ), frames.start - span.start  # fmt: skip


def _chunk(prepared: Prepared, frames: range, out: list, seconds: float) -> CandidateChunk:
    idx = np.asarray(frames)
    return CandidateChunk(
        frames=idx, candidates=[f.candidates for f in out], d_s=[f.d_s for f in out],
        flags=tuple(
            tuple(prepared.flags[t]) + tuple(f.flags) for t, f in zip(idx, out, strict=True)
        ),
        seconds=seconds,
    )  # fmt: skip


def _timed_chunk(inputs: dict) -> tuple[list, float]:
    """:func:`estimate_candidates_chunk` in a pool process, with its seconds."""
    t0 = time.perf_counter()
    return estimate_candidates_chunk(**inputs), time.perf_counter() - t0


def all_candidates(
    prepared: Prepared,
    settings: Settings | None = None,
    *,
    workers: int = 1,
    on_progress: ProgressFn | None = None,
) -> list[CandidateChunk]:
    """Stage 3 on every frame, in chunks of ``settings.chunk_frames``, on ``workers``
    processes.

    Frames are independent given ``prepared`` (see :func:`candidates`), so the chunks give
    the same candidates in any process: more workers change the wall time, not the result.
    With several, progress moves as chunks finish; each chunk's ``seconds`` stay its own
    compute time.
    """
    s = settings or Settings()
    ranges = prepared.chunks(max(1, -(-prepared.n_frames // s.chunk_frames)))
    workers = max(1, min(int(workers), len(ranges)))
    if workers == 1:
        done: list[CandidateChunk] = []
        for i, r in enumerate(ranges):
            done.append(candidates(prepared, r, s, on_progress=_share(on_progress, i, len(ranges))))
        return done
    # spawn, not fork: this process may hold threads (the pose model's, BLAS) that a forked
    # child would inherit in an unknown state.
    context = multiprocessing.get_context("spawn")
    with ProcessPoolExecutor(max_workers=workers, mp_context=context) as pool:
        futures = {}
        for r in ranges:
            inputs, lead = _chunk_inputs(prepared, r, s)
            futures[pool.submit(_timed_chunk, inputs)] = (r, lead)
        chunks = []
        for n_done, future in enumerate(as_completed(futures), start=1):
            out, seconds = future.result()
            r, lead = futures[future]
            chunks.append(_chunk(prepared, r, out[lead : lead + len(r)], seconds))
            if on_progress is not None:
                on_progress("candidates", n_done / len(ranges))
    return sorted(chunks, key=lambda c: int(c.frames[0]))


def select(
    prepared: Prepared,
    chunks: Sequence[CandidateChunk],
    settings: Settings | None = None,
    *,
    on_progress: ProgressFn | None = None,
) -> dict:
    """Stage 4 (thesis 4.7) over all chunks -> the DESIGN.md result document.

    The candidates' d_S travel with them, so selection weighs image evidence against the
    distance to the reference (beyond the thesis, see ``SelectionSettings.image_weight``).
    Then :mod:`engine.stages.assessment` says how far to trust what was selected.
    """
    s = settings or Settings()
    sel_settings = _with_domain(s.selection, prepared.domain)
    order = sorted(chunks, key=lambda c: int(c.frames[0]))
    frames = np.concatenate([c.frames for c in order])
    if not np.array_equal(frames, np.arange(prepared.n_frames)):
        raise InvalidInput("candidate chunks must cover every video frame exactly once")
    cands = [k for c in order for k in c.candidates]
    flags = [f for c in order for f in c.flags]
    d_s = [d for c in order for d in c.d_s]
    v = prepared.video
    t0 = time.perf_counter()
    selection = select_and_refine(
        cands, prepared.reference_joints, prepared.segments, prepared.C.astype(float),
        settings=sel_settings, fps_ratio=prepared.reference_fps / v.fps, video_fps=v.fps,
        candidate_flags=flags, candidate_d_s=d_s, on_progress=on_progress,
    )  # fmt: skip
    selection = flag_image_misfit(selection, d_s, sel_settings.misfit_margin)
    timing = dict(prepared.timing_s)
    timing["candidates"] = float(sum(c.seconds for c in order))
    timing["selection"] = time.perf_counter() - t0
    timing["total"] = float(sum(timing.values()))
    camera = prepared.camera.resized(v.original_width, v.original_height)
    doc = build_result(
        reference_name=prepared.reference_name,
        reference_frames=int(prepared.reference_joints.shape[0]),
        reference_fps=prepared.reference_fps,
        video={"frames": v.file_frames or v.offset + v.frames, "fps": v.fps,
               "width": v.original_width, "height": v.original_height},
        camera=camera, selection=selection, candidates=cands, timing_s=timing,
        domain=prepared.domain, video_frame_offset=v.offset,
    )  # fmt: skip
    add_image_best(doc, cands, d_s, camera)
    add_uncertainty(doc, cands, d_s, prepared.reference_joints[selection.C],
                    sel_settings.uncertainty_margin)  # fmt: skip
    add_expert_2d(doc, prepared.reference_joints[selection.C], selection.joints, camera)
    chosen = np.stack([c[int(k)] for c, k in zip(cands, selection.selected, strict=True)])
    assess_fit(doc, chosen, prepared, sel_settings)
    note_repetitions(doc, prepared.repetitions)
    note_framing(doc, prepared.framing)
    return doc


def analyze(
    reference_path: PathLike,
    video_path: PathLike,
    settings: Settings | None = None,
    *,
    domain: Domain | None = None,
    mapping: dict[str, str] | None = None,
    units_to_m: float | None = None,
    frames: tuple[int, int] | None = None,
    workers: int = 1,
    on_progress: ProgressFn | None = None,
) -> dict:
    """The whole registration (thesis chapter 4) -> the result document.

    Parameters as :func:`prepare`; stage 3 runs on ``workers`` processes
    (:func:`all_candidates`), the rest in this one."""
    s = settings or Settings()
    prepared = prepare(reference_path, video_path, s, domain=domain, mapping=mapping,
                       units_to_m=units_to_m, frames=frames, on_progress=on_progress)  # fmt: skip
    chunks = all_candidates(prepared, s, workers=workers, on_progress=on_progress)
    return select(prepared, chunks, s, on_progress=on_progress)


# ---------------------------------------------------------------------------------------------
# stages 0-2


def run_stages_0_2(
    reference: Reference,
    video: Video,
    settings: Settings | None = None,
    *,
    perception: Perception | None = None,
    background: Background | None = None,
    on_progress: ProgressFn | None = None,
) -> Stages02:
    """Stages 0-2 of the thesis (4.1, 4.2, 4.5) on a loaded reference and video.

    ``background`` is stage 0's background model of the video when the caller has it
    (:func:`engine.stages.foreground.background_of`).

    With ``calibration.check_mirror`` stage 2 runs for the calibrated view and for the best
    view facing the other way, and the one with the lower mean cost E_C is kept (one frame
    hardly tells front from back; the whole motion does). The camera is then polished on
    frames spread over the video and, with ``alignment.realign``, stage 2 runs once more
    with it and the performer's fitted body. With ``alignment.repetitions``, a video whose
    keypoints show several whole performances is cut to the first after stage 1 (the camera
    is the whole video's): stage 2 and everything after it see that one only
    (:attr:`Stages02.first_frame`, :attr:`Stages02.repetitions`).

    Raises
    ------
    InvalidInput
        The calibration frame is out of range (or any stage's own validation).
    RegistrationFailed
        Nobody is found in the video (:func:`check_person_found`), or the camera cannot be
        calibrated.
    """
    s = settings or Settings()
    cal, joints = s.calibration, reference.motion.joints
    c0 = _calibration_frame(reference, video, cal)
    timing: dict[str, float] = {}
    t0 = time.perf_counter()
    fg = extract_foreground(video.frames, s.foreground,
                            learned=None if perception is None else perception.mask,
                            background=background, on_progress=on_progress)  # fmt: skip
    timing["foreground"] = time.perf_counter() - t0
    check_person_found(fg.flags, perception, s.perception.min_detected_fraction)
    t0 = time.perf_counter()
    cameras = _calibrate_views(joints[c0], reference.shape, fg, s, perception, on_progress)
    timing["calibration"] = time.perf_counter() - t0
    first = 0
    found: tuple[dict, ...] = ()
    if s.alignment.repetitions and perception is not None:
        found = _performances(reference, cameras[0], perception, video.fps)
        if found:  # stage 2 and after see the first performance only
            first, end = int(found[0]["start"]), int(found[0]["end"])
            fg, perception = fg.cut(first, end), perception.cut(first, end)
    views = _Views(perception, joints[c0], cal.offset_frames, s.alignment.keypoint_offsets)
    t0 = time.perf_counter()
    passes = len(cameras) + int(s.alignment.realign and cal.refine_frames > 0)
    results = []
    for i, cam in enumerate(cameras):
        aligned = align(joints, reference.shape, cam, fg.silhouettes, fg.skin, s.alignment,
                        start=c0, keypoints=views.readings(cam),
                        on_progress=_share(on_progress, i, passes))  # fmt: skip
        results.append((aligned.E_C, i, cam, aligned))
    # the camera whose view explains the whole video best (CalibrationSettings.check_mirror)
    _, _, camera, result = min(results, key=lambda r: (r[0], r[1]))
    timing["alignment"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if cal.refine_frames > 0:
        camera = _polish_camera(camera, reference, fg, result, cal, views.readings(camera))
    shape: BodyShape = reference.shape
    factors: dict[str, float] = {}
    if cal.fit_width:  # the performer's widths, for the final camera
        k = cal.video_frame
        shape, factors = fit_body_shape(joints[c0], reference.shape, camera, fg.silhouettes[k])
    timing["calibration"] += time.perf_counter() - t0
    if passes > len(cameras):  # AlignmentSettings.realign: C again with the polished camera
        t0 = time.perf_counter()
        result = align(joints, shape, camera, fg.silhouettes, fg.skin, s.alignment, start=c0,
                       keypoints=views.readings(camera),
                       on_progress=_share(on_progress, passes - 1, passes))  # fmt: skip
        timing["alignment"] += time.perf_counter() - t0
    costs = {round(float(np.degrees(r[2].azimuth)), 6): float(r[0]) for r in results}
    return Stages02(fg, camera, shape, factors, result, timing, costs, views.offsets(camera),
                    first, found, perception)  # fmt: skip


def _performances(
    reference: Reference, camera: Camera, perception: Perception, fps: float
) -> tuple[dict, ...]:
    """The whole performances when the video holds several, the first marked analysed
    (``AlignmentSettings.repetitions``); () when it holds one or none."""
    from engine.stages.repetitions import performances

    motion = reference.motion
    ref_2d = camera.project(motion.joints[motion.first_motion_frame :])
    found = performances(perception.keypoints, ref_2d, fps, float(motion.fps))
    return tuple(found.to_dicts(fps, analysed=0))


def _read_frames(
    video_path: PathLike, s: Settings, frames: tuple[int, int] | None
) -> tuple[Video, int, int]:
    """The video at working resolution, cut to ``frames`` (a, b); its first frame; and how
    many frames the file holds."""
    video = read_video(video_path, height=s.working_height, limits=s.video)
    if frames is None:
        return video, 0, int(video.n_frames)
    a, b = frames
    if not 0 <= a < b <= video.n_frames or b - a < 2:
        raise InvalidInput(f"frames must be a range of >= 2 frames within 0..{video.n_frames}")
    cut = dataclasses.replace(video, frames=video.frames[a:b], timestamps_s=video.timestamps_s[a:b])
    return cut, a, int(video.n_frames)


def _perceive_beside_background(
    video: Video, s: Settings, on_progress: ProgressFn | None
) -> tuple[Perception | None, Background | None]:
    """The pose model's output and stage 0's background model, side by side on two threads
    unless ``foreground.threads`` is 1: the model runs on one core and releases the GIL, and
    the background does not need it. (None, None) without perception: the background
    then comes with the rest of stage 0."""
    if not s.perception.enabled:
        return None, None
    if thread_count(s.foreground.threads) == 1:
        return _perceive(video, s, on_progress), None
    with ThreadPoolExecutor(max_workers=1, thread_name_prefix="coach-background") as pool:
        background = pool.submit(background_of, video.frames, s.foreground)
        return _perceive(video, s, on_progress), background.result()


def _perceive(video: Video, s: Settings, on_progress: ProgressFn | None) -> Perception | None:
    """The pose model's masks and keypoints (beyond the thesis), when perception is on."""
    if not s.perception.enabled:
        return None
    from engine.stages.perception import MediaPipePose, perceive  # mediapipe loads on use

    model = MediaPipePose(min_detection_confidence=s.perception.min_detection_confidence)
    return perceive(video.frames, model, on_progress=on_progress)


def _calibration_frame(reference: Reference, video: Video, cal: CalibrationSettings) -> int:
    """The reference frame the calibration frame shows (the motion's first by default)."""
    n = len(reference.motion.joints)
    c0 = reference.motion.first_motion_frame if cal.reference_frame is None else int(
        cal.reference_frame
    )
    if not 0 <= c0 < n:
        raise InvalidInput(f"calibration.reference_frame must be 0..{n - 1}, got {c0}")
    if not 0 <= cal.video_frame < video.frames.shape[0]:
        raise InvalidInput(
            f"calibration.video_frame must be 0..{video.frames.shape[0] - 1}, "
            f"got {cal.video_frame}"
        )
    return c0


def _calibrate_views(
    posture: np.ndarray,
    shape: BodyShape,
    fg: ForegroundResult,
    s: Settings,
    perception: Perception | None,
    on_progress: ProgressFn | None,
) -> list[Camera]:
    """Stage 1 (thesis 4.2) on the calibration frame: the calibrated camera and, with
    ``calibration.check_mirror``, the best one facing the other way.

    ``posture`` (17, 3) is the reference's calibration posture.
    """
    cal, k = s.calibration, s.calibration.video_frame
    # the outline only: interior image edges (ForegroundSettings.interior_edges) are for
    # stage 3's per-part fit; the calibration's capsule body has no clothing seams
    edges_k = outline(fg.silhouettes[k], fg.skin[k])
    kp_k, facing = calibration_keypoints(perception, k, s.foreground.learned_max_gap)
    camera, report = calibrate(posture, shape, fg.silhouettes[k], edges_k, cal,
                               keypoints=kp_k, facing=facing, on_progress=on_progress)  # fmt: skip
    if not cal.check_mirror:
        return [camera]
    alt = mirror_azimuth(report["azimuth_scores"], float(np.degrees(camera.azimuth)))
    if alt is None:
        return [camera]
    mirrored = dataclasses.replace(cal, azimuths_deg=(alt,))
    return [camera, calibrate(posture, shape, fg.silhouettes[k], edges_k, mirrored,
                              keypoints=kp_k)[0]]  # fmt: skip


@dataclasses.dataclass(frozen=True)
class _Views:
    """The pose model's keypoints as stages 1-2 read them through a given camera."""

    perception: Perception | None
    posture: np.ndarray  # (17, 3): the calibration posture the first frames show
    n_frames: int  # CalibrationSettings.offset_frames
    remove_offsets: bool  # AlignmentSettings.keypoint_offsets

    def offsets(self, camera: Camera) -> np.ndarray:
        """The detector's offset from each joint as seen through ``camera``, (17, 2)."""
        if self.perception is None:
            return np.zeros((17, 2))
        return offsets_on_first_frames(self.perception, camera, self.posture, self.n_frames)

    def readings(self, camera: Camera) -> Readings | None:
        """Both readings of every frame (without the offsets unless ``remove_offsets``)."""
        if self.perception is None:
            return None
        used = self.offsets(camera) if self.remove_offsets else np.zeros((17, 2))
        return readings(self.perception.keypoints, self.perception.confidence, used)


def _polish_camera(
    camera: Camera,
    reference: Reference,
    fg: ForegroundResult,
    aligned: AlignmentResult,
    calibration: CalibrationSettings,
    keypoints: Readings | None = None,
) -> Camera:
    """The camera polished on frames spread over the video (``refine_frames``).

    Each frame shows the reference at stage 2's C(t') turned by T_t' about the hip.
    """
    n = len(aligned.C)
    idx = np.unique(np.linspace(0, n - 1, min(calibration.refine_frames, n)).round().astype(int))
    ref = reference.motion.joints[aligned.C[idx]]
    hip = ref[:, :1]
    posed = np.einsum("nij,nkj->nki", aligned.rotations[idx], ref - hip) + hip
    outlines = np.array([outline(fg.silhouettes[i], fg.skin[i]) for i in idx])
    kp = None if keypoints is None else (keypoints[0][idx], keypoints[1][idx])
    camera, _ = refine_on_frames(
        camera, posed, reference.shape, fg.silhouettes[idx], outlines, calibration, keypoints=kp
    )
    return camera


def _with_domain(settings: SelectionSettings, domain: Domain | None) -> SelectionSettings:
    """Stage 4's settings with the domain's boundary joints and threshold (thesis 6.8)."""
    if domain is not None and domain.boundary_joints:
        settings = dataclasses.replace(settings, boundary_joints=domain.boundary_joints)
    if domain is not None and domain.direction_change_deg is not None:
        settings = dataclasses.replace(settings, direction_change_deg=domain.direction_change_deg)
    return settings


def _share(on_progress: ProgressFn | None, i: int, n: int) -> ProgressFn | None:
    """Progress of the i-th of n runs of a stage as a share of the stage's whole progress."""
    if on_progress is None:
        return None
    return lambda stage, f: on_progress(stage, (i + f) / n)
