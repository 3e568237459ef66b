"""What one pipeline step hands to the next (:mod:`engine.pipeline`), and how it is stored.

    Stages02       stages 0-2 on a loaded reference and video (in memory)
    Prepared       prepare's output: everything stages 3-4 need, without re-reading files
    CandidateChunk stage 3's output for a range of video frames

``Prepared`` and ``CandidateChunk`` save to one file each (:mod:`engine.io.stagefiles`), so a
service keeps them in the analysis folder and a worker on another machine picks them up.
"""

from __future__ import annotations

import os
from dataclasses import asdict, dataclass, field, replace

import numpy as np

from engine.body.shapes import BodyShape
from engine.errors import InvalidInput
from engine.io.stagefiles import load_arrays, pack_masks, save_arrays, unpack_masks
from engine.reference.domain import Domain, parse_domain
from engine.render.camera import Camera
from engine.stages.alignment import AlignmentResult
from engine.stages.foreground import ForegroundResult
from engine.stages.perception import Perception
from engine.types import Segments

PathLike = str | os.PathLike


@dataclass(frozen=True)
class Stages02:
    """Output of stages 0-2 (thesis 4.1, 4.2, 4.5).

    Attributes
    ----------
    foreground : ForegroundResult
        Body regions per video frame (stage 0).
    camera : Camera
        Calibrated camera (stage 1), polished after stage 2 on frames spread over the video
        (``CalibrationSettings.refine_frames``).
    shape : BodyShape
        The performer's body: the reference's bones with capsule radii fitted to the
        calibration frame (:func:`engine.stages.calibration.fit_body_shape`); the
        reference's own shape when the fit is off.
    width_factors : dict
        Fitted radius factor per part group (empty when the fit is off).
    alignment : AlignmentResult
        Approximate temporal correspondence and global rotations (stage 2).
    timing_s : dict
        Seconds per stage ("foreground", "calibration", "alignment").
    view_costs : dict
        Stage 2's mean cost E_C per view azimuth tried (degrees -> E_C): the calibrated one
        and, with ``CalibrationSettings.check_mirror``, the best one facing the other way.
    keypoint_offsets : ndarray, shape (17, 2)
        The pose model's offset from each joint in pixels, measured on the first frames
        (:func:`engine.stages.perception.keypoint_offsets`); zeros without perception.
    first_frame : int
        The video frame the analysed part starts at: 0, or the first whole performance's
        first frame when the video holds several (``AlignmentSettings.repetitions``);
        ``foreground`` and ``perception`` hold the analysed frames only.
    repetitions : tuple of dict
        Every whole performance found (``summary.repetitions`` of the result: frames of
        the video given, seconds, which one is analysed); empty when the video holds one.
    perception : Perception or None
        The pose model's output over the analysed frames.
    """

    foreground: ForegroundResult
    camera: Camera
    shape: BodyShape
    width_factors: dict
    alignment: AlignmentResult
    timing_s: dict
    view_costs: dict = field(default_factory=dict)
    keypoint_offsets: np.ndarray = field(default_factory=lambda: np.zeros((17, 2)))
    first_frame: int = 0
    repetitions: tuple[dict, ...] = ()
    perception: Perception | None = None


@dataclass(frozen=True)
class AnalysedVideo:
    """The analysed video: frame count and rate, working and file resolution.

    ``offset`` is the file frame the analysis starts at (``coach analyze --frames A:B``, or
    the first whole performance of several, :class:`Stages02`); ``file_frames`` is how many
    frames the file holds (0 when not recorded: as many as ``frames``).
    """

    frames: int
    fps: float
    width: int
    height: int
    original_width: int
    original_height: int
    offset: int = 0
    file_frames: int = 0


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
        The performer's body (:attr:`Stages02.shape`).
    video : AnalysedVideo
    camera : Camera
        At the working resolution.
    silhouettes, edges : ndarray of bool, shape (T', H, W)
    C : ndarray of int, shape (T',)
        Approximate correspondence (reference frame per video frame).
    rotations : ndarray, shape (T', 3, 3)
        Global rotation T_t' about the hip.
    segments : Segments
        Reference segments, in the file's frame numbers.
    domain : Domain or None
        The coach's domain knowledge of the reference (thesis 6.8), used by selection and
        the result's scores.
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
    repetitions : tuple of dict
        Whole performances of the reference the video holds when several
        (:attr:`Stages02.repetitions`), in the file's frames; empty otherwise.
    framing : tuple of str
        What the first analysed frame says about the filming, one sentence each
        (:func:`engine.stages.framing.first_frame_problems`); empty when it looks right.
    """

    reference_path: str
    video_path: str
    reference_name: str
    reference_fps: float
    first_motion_frame: int
    reference_joints: np.ndarray
    shape: BodyShape
    video: AnalysedVideo
    camera: Camera
    silhouettes: np.ndarray
    edges: np.ndarray
    C: np.ndarray
    rotations: np.ndarray
    segments: Segments
    flags: tuple[tuple[str, ...], ...]
    timing_s: dict
    domain: Domain | None = None
    keypoints: np.ndarray | None = None
    keypoint_confidence: np.ndarray | None = None
    keypoint_offsets: np.ndarray | None = None
    perception_model: str = ""
    repetitions: tuple[dict, ...] = ()
    framing: tuple[str, ...] = ()

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

        First B_C(t') turned by T_t' about the hip (thesis 4.6.4), then B_C(t') itself:
        stage 2 samples T_t' on a coarse grid and a turn in depth barely changes the
        silhouette, so with both as starts (and candidates) stage 4 weighs the turn's image
        evidence against its d_B.
        """
        idx = np.asarray(frames)
        ref = self.reference_joints[self.C[idx]]
        hip = ref[:, :1]
        turned = np.einsum("nij,nkj->nki", self.rotations[idx], ref - hip) + hip
        return np.stack([turned, ref], axis=1)

    def frame_keypoints(self, frames: range) -> tuple[np.ndarray, np.ndarray] | None:
        """The keypoint readings (N, 2, 17, 2) and confidences (N, 2, 17) of ``frames``
        (:func:`engine.stages.perception.readings`, offsets removed); None without them."""
        from engine.stages.perception import readings

        if self.keypoints is None or self.keypoint_confidence is None:
            return None
        idx = np.asarray(frames)
        return readings(self.keypoints[idx], self.keypoint_confidence[idx],
                        self.keypoint_offsets)  # fmt: skip

    def head(self, n_frames: int, segments: Segments) -> Prepared:
        """The first ``n_frames`` video frames only, against the reference ``segments``
        (a leading part of :attr:`segments`): what a provisional stage 4 sees
        (:mod:`engine.provisional`)."""
        if not 1 <= n_frames <= self.n_frames:
            raise InvalidInput(f"n_frames must be in [1, {self.n_frames}], got {n_frames}")
        cut = slice(0, n_frames)

        def part(a: np.ndarray | None) -> np.ndarray | None:
            return None if a is None else a[cut]

        return replace(
            self, silhouettes=self.silhouettes[cut], edges=self.edges[cut], C=self.C[cut],
            rotations=self.rotations[cut], flags=self.flags[cut], segments=segments,
            keypoints=part(self.keypoints), keypoint_confidence=part(self.keypoint_confidence),
            video=replace(self.video, frames=n_frames, file_frames=self.video.file_frames
                          or self.video.offset + self.video.frames),
            repetitions=(),
        )  # fmt: skip

    def save(self, path: PathLike) -> None:
        if self.domain is not None and self.domain.doc is None:
            raise ValueError("a Prepared's domain must come from parse_domain (it keeps its doc)")
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
            "first_motion_frame": self.first_motion_frame, "video": asdict(self.video),
            "camera": self.camera.to_dict(), "mask_shape": list(sil_shape),
            "segments": {"starts": list(self.segments.starts), "end": self.segments.end,
                         "names": list(self.segments.names)},
            "domain": None if self.domain is None else self.domain.doc,
            "flags": [list(f) for f in self.flags], "timing_s": self.timing_s,
            "perception_model": self.perception_model,
            "repetitions": [dict(r) for r in self.repetitions],
            "framing": list(self.framing),
        }  # fmt: skip
        save_arrays(path, arrays, meta)

    @classmethod
    def load(cls, path: PathLike) -> Prepared:
        a, m = load_arrays(path)
        shape = tuple(m["mask_shape"])
        seg = m["segments"]
        domain = m.get("domain")
        return cls(
            reference_path=m["reference_path"], video_path=m["video_path"],
            reference_name=m["reference_name"], reference_fps=float(m["reference_fps"]),
            first_motion_frame=int(m["first_motion_frame"]),
            reference_joints=a["reference_joints"],
            shape=BodyShape(offsets=a["offsets"], radii=a["radii"]),
            video=AnalysedVideo(**m["video"]), camera=Camera.from_dict(m["camera"]),
            silhouettes=unpack_masks(a["silhouettes"], shape),
            edges=unpack_masks(a["edges"], shape), C=a["C"], rotations=a["rotations"],
            segments=Segments(tuple(seg["starts"]), int(seg["end"]), tuple(seg["names"])),
            domain=None if domain is None else parse_domain(domain),
            flags=tuple(tuple(f) for f in m["flags"]), timing_s=m["timing_s"],
            keypoints=a.get("keypoints"), keypoint_confidence=a.get("keypoint_confidence"),
            keypoint_offsets=a.get("keypoint_offsets"),
            perception_model=str(m.get("perception_model", "")),
            repetitions=tuple(m.get("repetitions", ())),
            framing=tuple(str(x) for x in m.get("framing", ())),
        )  # fmt: skip


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
