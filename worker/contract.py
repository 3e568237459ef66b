"""What the API may send to workers and read back: task names and payload schemas.

Only ids, paths and small JSON cross the process boundary; arrays travel as files in the
analysis' own folder. The app enqueues work with this module (and reaches the engine's few
in-process pieces through :mod:`worker.engine_surface`); the worker never imports the app:
it learns everything from the payload and reports through files in the analysis folder and
Celery task states.

The analysis folder (``work_dir``) is written by the worker and read by the app and the web
viewer; :class:`AnalysisFolder` is the only place that spells its file names.
"""

from __future__ import annotations

import os
import re
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path

#: Celery task names (stable strings: they are the wire contract between api and workers).
ANALYZE_TASK = "coach.analyze"
PREPARE_TASK = "coach.stage.prepare"
CANDIDATES_TASK = "coach.stage.candidates"
SELECT_TASK = "coach.stage.select"
CAPTURE_TASK = "coach.capture"

#: The custom Celery state that carries progress meta {"stage", "progress", "message"}.
PROGRESS_STATE = "PROGRESS"

STATES = ("queued", "running", "done", "failed", "cancelled")

#: The probe file :func:`storage_now` touches in a folder.
CLOCK_FILE = "clock"


def storage_now(folder: str | os.PathLike) -> float | None:
    """Now on the clock of the storage that holds ``folder``: the modification time it gives
    a file touched now (on NFS, ``utime(None)`` sets the server's time). The ages of files
    that other machines write are measured against it, so that API and workers need no
    synchronised clocks. None if the folder is gone or read-only.
    """
    probe = Path(folder) / CLOCK_FILE
    try:
        probe.touch()
        return probe.stat().st_mtime
    except OSError:
        return None


def file_age_s(path: str | os.PathLike, now: float | None = None) -> float | None:
    """Seconds since ``path`` was last modified, by the storage's clock (``now``: a reading
    of :func:`storage_now` for its folder); None if the file is absent."""
    path = Path(path)
    try:
        modified = path.stat().st_mtime
    except OSError:
        return None
    if now is None:
        now = storage_now(path.parent)
    return (time.time() if now is None else now) - modified


@dataclass(frozen=True)
class AnalysisJob:
    """Payload of :data:`ANALYZE_TASK`: everything the engine needs, as paths and data.

    Attributes
    ----------
    analysis_id : str
    reference_path, video_path : str
        The reference BVH and the performer's video.
    work_dir : str
        The analysis folder (:class:`AnalysisFolder`).
    settings : dict
        Engine settings as JSON (``engine.settings.Settings.from_dict``), parsed once per
        task by the worker.
    domain : dict or None
        The coach's domain document of the reference (``engine.reference.domain``: segments,
        names, bone weights, tolerances), as stored with the reference.
    reference_mapping : dict or None
        How the BVH's joints map onto ours (our joint -> BVH joint), as the club gave it at
        upload (None: the engine's name tables).
    reference_units_to_m : float or None
        Metres per BVH unit (None: the engine's guess).
    frames : list of two ints, or None
        Analyse video frames ``frames[0]`` .. ``frames[1] - 1`` only (one repetition the user
        chose); None: the whole video.
    """

    analysis_id: str
    reference_path: str
    video_path: str
    work_dir: str
    settings: dict = field(default_factory=dict)
    domain: dict | None = None
    reference_mapping: dict[str, str] | None = None
    reference_units_to_m: float | None = None
    frames: list[int] | None = None

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> AnalysisJob:
        """The job from its JSON; keys of older payloads still queued (``domain_path``)
        are ignored."""
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in known})


class AnalysisFolder:
    """Where one analysis keeps its files: the worker writes them, the app and viewer read.

    ::

        status.json      {"state": queued|running|done|failed|cancelled, "stage": str,
                          "progress": 0..1, "message": str, "error": str|null,
                          "updated": iso time}, replaced atomically on every change
        video.<ext>      the performer's upload, as the app stored it
        result.json      the DESIGN.md result, present once the analysis is done
        provisional.json the same for the first whole segments only, with a "provisional"
                         entry (engine.provisional), written while stage 3 runs on the rest
        provisional-claims/<k>  created (exclusively) by the process that computes the
                         provisional result of k segments: two chunks that end together in
                         two processes would both compute the same one
        framing.json     {"problems": [str]}: what the first frame says about the filming
                         (engine.stages.framing), written with stages 0-2's output
        cancel           marker: the analysis was cancelled (or failed for good): messages
                         still queued for it stop
        tasks.json       the Celery task ids of the analysis' canvas
        heartbeat        {"owner": entry task id, "host", "pid"}; its modification time is
                         renewed every few seconds while any task of the analysis runs (the
                         lease: older than ``lost_after_s`` means nobody runs it)
        clock            touched to read the storage's clock (:func:`storage_now`)
        stages/          one output per finished engine stage (a stage whose output exists
                         is skipped):
            prepare.npz                  stages 0-2
            candidates-<i>-of-<n>.npz    stage 3, chunk i of n
        attempts/        per stage output, how many started runs never came back (the
                         worker process died): ``attempts/<output stem>``, "count runner"
        stopping/        ``stopping/<runner>``: that pool process' worker was told to stop
                         while it ran a stage here (``worker.lease.note_stopping``)

    Writers write to a temporary name holding ``.tmp`` and rename (:func:`is_temporary`).
    """

    _CHUNK = re.compile(r"candidates-(\d+)-of-(\d+)\.npz")

    def __init__(self, work_dir: str | os.PathLike):
        self.work_dir = Path(work_dir)
        self.status = self.work_dir / "status.json"
        self.result = self.work_dir / "result.json"
        self.provisional = self.work_dir / "provisional.json"
        self.framing = self.work_dir / "framing.json"
        self.cancel = self.work_dir / "cancel"
        self.tasks = self.work_dir / "tasks.json"
        self.heartbeat = self.work_dir / "heartbeat"
        self.stages = self.work_dir / "stages"
        self.prepared = self.stages / "prepare.npz"

    def provisional_claim(self, segments: int) -> Path:
        """The claim on computing the provisional result of ``segments`` segments."""
        return self.work_dir / "provisional-claims" / str(int(segments))

    def video(self, suffix: str) -> Path:
        """Where the app stores the performer's video (``suffix`` like ``".mp4"``)."""
        return self.work_dir / f"video{suffix}"

    def chunk(self, index: int, n_chunks: int) -> Path:
        """Stage 3's output for chunk ``index`` of ``n_chunks``."""
        return self.stages / f"candidates-{index}-of-{n_chunks}.npz"

    def attempts(self, output: Path) -> Path:
        """The crash count of the stage that writes ``output`` (one of the paths above)."""
        return self.work_dir / "attempts" / output.stem

    def stopping(self, runner: str) -> Path:
        """The notice that ``runner`` (``worker.lease.runner_id``) was told to stop."""
        return self.work_dir / "stopping" / runner

    def heartbeat_age_s(self, now: float | None = None) -> float | None:
        """Seconds since a task of the analysis last renewed its heartbeat, by the storage's
        clock (``now``: a reading of :func:`storage_now`); None if no task ever ran.
        Negative while a retry countdown holds the lease into the future."""
        return file_age_s(self.heartbeat, now)

    def chunks(self, n_chunks: int) -> list[Path]:
        return [self.chunk(i, n_chunks) for i in range(n_chunks)]

    def finished_chunks(self) -> list[Path]:
        """Every stage-3 output present now, in name order, temporary files left out."""
        if not self.stages.is_dir():
            return []
        return sorted(
            p for p in self.stages.iterdir()
            if self._CHUNK.fullmatch(p.name) and not is_temporary(p)
        )  # fmt: skip


@dataclass(frozen=True)
class CaptureJob:
    """Payload of :data:`CAPTURE_TASK`: a reference-free capture (``engine.capture``).

    Attributes
    ----------
    capture_id : str
    video_path, work_dir : str
        The performer's video and the capture's folder (:class:`CaptureFolder`).
    height_m : float
        The performer's height (bone lengths).
    answers : dict of str to int
        The user's answers so far: question id -> -1 (towards the camera) or +1 (away).
    """

    capture_id: str
    video_path: str
    work_dir: str
    height_m: float = 1.75
    answers: dict[str, int] = field(default_factory=dict)

    def to_json(self) -> dict:
        return asdict(self)

    @classmethod
    def from_json(cls, d: dict) -> CaptureJob:
        known = {f.name for f in fields(cls)}
        return cls(**{k: v for k, v in d.items() if k in known})


class CaptureFolder:
    """Where one capture keeps its files::

        status.json      as an analysis' (:class:`AnalysisFolder`)
        video.<ext>      the performer's upload
        capture.json     the capture's summary: frames, fps, questions, timings
        motion.bvh       the motion, CMU joint names, root motion, one frame per video frame
        motion_coach.bvh the same with this project's joint names
        angles.csv       joint positions and angles per frame
        heartbeat        renewed while a worker runs the capture

    A new run (answers given) replaces the files; each is written to a ``.tmp`` name first.
    """

    def __init__(self, work_dir: str | os.PathLike):
        self.work_dir = Path(work_dir)
        self.status = self.work_dir / "status.json"
        self.summary = self.work_dir / "capture.json"
        self.bvh = self.work_dir / "motion.bvh"
        self.bvh_coach = self.work_dir / "motion_coach.bvh"
        self.csv = self.work_dir / "angles.csv"
        self.heartbeat = self.work_dir / "heartbeat"

    def video(self, suffix: str) -> Path:
        return self.work_dir / f"video{suffix}"


@dataclass(frozen=True)
class BrokerTasks:
    """The task ids the broker holds at one moment (:func:`worker.celery_app.broker_tasks`).

    Attributes
    ----------
    waiting : frozenset of str
        Messages in the queue that no worker has taken yet.
    held : frozenset of str or None
        Messages a worker took and has not acknowledged (running, or waiting for a retry's
        countdown); None where the transport cannot tell (the embedded one).
    taken_at : dict of str to float
        When a worker took each held message (Unix seconds), where the transport records it
        (Redis's ``unacked_index``). A message taken moments ago shows a live worker that has
        not started the task yet, though the analysis' last heartbeat is old.
    """

    waiting: frozenset[str]
    held: frozenset[str] | None
    taken_at: Mapping[str, float] = field(default_factory=dict)

    def merged(self, later: BrokerTasks) -> BrokerTasks:
        """What either of two readings saw: a message a worker was taking during the first
        (out of the queue, not yet recorded as held) shows in the second."""
        held = None if self.held is None or later.held is None else self.held | later.held
        taken = {**self.taken_at}
        for task_id, when in later.taken_at.items():
            taken[task_id] = max(taken.get(task_id, 0.0), when)
        return BrokerTasks(self.waiting | later.waiting, held, taken)


def is_temporary(path: Path) -> bool:
    """A file still being written (its writer renames it when complete)."""
    return ".tmp" in path.name
