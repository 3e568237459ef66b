"""The worker's work, as plain functions callable without Celery.

Each function runs one engine stage for one analysis, reading its inputs from and writing its
output to the analysis folder (:mod:`worker.contract` describes the layout):

=============  =====================================  ==========================================
stage          function                               output (written to a temporary name, then
                                                      renamed; if it exists the stage is skipped)
=============  =====================================  ==========================================
prepare (0-2)  :func:`run_prepare`                    ``stages/prepare.npz``
candidates (3) :func:`run_candidates` (one chunk)     ``stages/candidates-<i>-of-<n>.npz``
select (4)     :func:`run_select`                     ``result.json``
=============  =====================================  ==========================================

:func:`run_all` runs them in order in one process (the embedded sequential mode and tests).
Because finished outputs are skipped, a redelivered or retried task resumes where the last
attempt stopped, and two deliveries of the same task cannot corrupt each other (each writes its
own temporary file; the rename is atomic and both renames carry equivalent content).

Each stage's engine work runs inside :func:`worker.lease.attempt`, which counts runs that
killed their worker: at ``max_crashes`` the stage fails with ``RepeatedCrash`` instead.

Progress goes to ``status.json`` (what the API reads) and to an optional ``publish(meta)``
callback (the Celery task's ``update_state``). A ``cancel`` marker file in the analysis folder
is checked between stages and on every progress callback from the engine, so a cancelled
analysis stops within one progress step.

The engine is :mod:`engine.pipeline`, imported here; every function takes it as the keyword
``pipeline`` too, so tests can pass a fake with the same three steps. The job's settings and
domain are parsed here, once per task, into the engine's typed objects.
"""

from __future__ import annotations

import json
import logging
import os
import time
import uuid
from collections.abc import Callable
from datetime import UTC, datetime
from pathlib import Path
from types import ModuleType
from typing import Any

from engine import pipeline as engine_pipeline
from engine import provisional as engine_provisional
from engine.errors import EngineError
from engine.reference.domain import Domain
from engine.settings import Settings
from worker import lease, metrics
from worker.contract import AnalysisFolder, AnalysisJob, file_age_s, storage_now

log = logging.getLogger("coach.worker")

TERMINAL = ("done", "failed", "cancelled")

#: Share of the overall progress bar each stage covers (prepare, candidates, select).
_SPAN = {"prepare": (0.0, 0.35), "candidates": (0.35, 0.90), "select": (0.90, 1.0)}

#: How often (seconds) engine progress callbacks may rewrite status.json.
_STATUS_INTERVAL_S = 0.5

#: Runs of one stage that may kill their worker before it is failed (worker.settings).
MAX_CRASHES = 2

Publish = Callable[[dict], None]


class Cancelled(Exception):
    """The analysis was cancelled (its cancel marker exists); not an error, not retried."""


class StageTimeout(Exception):
    """A stage ran past its soft time limit; recorded as the analysis' failure, not retried."""


# ---------------------------------------------------------------------------------------------
# files


def write_atomic(path: str | os.PathLike, write: Callable[[Path], Any]) -> Path:
    """Call ``write(tmp_path)`` then rename ``tmp_path`` to ``path``; return ``path``.

    The temporary name is unique per call and keeps the final suffix (``x.<id>.tmp.npz``)
    because ``numpy.savez`` appends ``.npz`` to names that do not end in it. A crash leaves only
    a ``*.tmp.*`` file that the next attempt ignores; readers never see a partial output.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.stem}.{os.getpid()}-{uuid.uuid4().hex[:8]}.tmp{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def write_json_atomic(path: str | os.PathLike, data: Any) -> Path:
    def write(tmp: Path) -> None:
        with open(tmp, "w") as f:
            json.dump(data, f)
            f.flush()
            os.fsync(f.fileno())

    return write_atomic(path, write)


def read_json(path: Path) -> Any:
    """The JSON document at ``path``; None while it is missing or half-written."""
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def read_status(work_dir: str | os.PathLike) -> dict | None:
    return read_json(AnalysisFolder(work_dir).status)


def write_status(
    work_dir: str | os.PathLike,
    state: str,
    *,
    stage: str = "",
    progress: float = 0.0,
    message: str = "",
    error: str | None = None,
    force: bool = False,
) -> bool:
    """Replace status.json atomically; return False if it was left alone.

    A terminal state (done, failed, cancelled) is sticky: a chunk still running after a sibling
    failed or the user cancelled must not turn the status back to "running", and a second
    failing chunk must not count the analysis twice. ``force`` writes anyway (a new attempt of
    the whole analysis, or a cancel).
    """
    if not force:
        current = read_status(work_dir)
        if current is not None and current.get("state") in TERMINAL:
            return False
    write_json_atomic(
        AnalysisFolder(work_dir).status,
        {
            "state": state,
            "stage": stage,
            "progress": round(min(max(progress, 0.0), 1.0), 4),
            "message": message,
            "error": error,
            "updated": datetime.now(UTC).isoformat(timespec="milliseconds"),
        },
    )
    return True


def request_cancel(work_dir: str | os.PathLike) -> None:
    """Mark the analysis cancelled: the marker stops running stages, status says cancelled."""
    paths = AnalysisFolder(work_dir)
    paths.work_dir.mkdir(parents=True, exist_ok=True)
    paths.cancel.touch()
    current = read_status(work_dir) or {}
    if current.get("state") not in ("done", "failed"):
        write_status(
            work_dir,
            "cancelled",
            stage=current.get("stage", ""),
            progress=current.get("progress", 0.0),
            message="cancelled",
            force=True,
        )


def is_cancelled(work_dir: str | os.PathLike) -> bool:
    return AnalysisFolder(work_dir).cancel.exists()


def check_cancel(job: AnalysisJob) -> None:
    if is_cancelled(job.work_dir):
        raise Cancelled(f"analysis {job.analysis_id} was cancelled")


# ---------------------------------------------------------------------------------------------
# logging, progress


def log_event(event: str, **fields: Any) -> None:
    """One structured line: ``analysis.stage_done stage=prepare analysis_id=... seconds=1.2``."""
    parts = []
    for key, value in fields.items():
        if isinstance(value, float):
            value = f"{value:.3f}"
        value = str(value)
        parts.append(f"{key}={json.dumps(value) if (' ' in value or not value) else value}")
    log.info("%s %s", event, " ".join(parts))


class Progress:
    """The engine's ``on_progress(stage, fraction)``: status.json + publish + cancel check.

    ``lo, hi`` is the span of the overall progress bar this task covers; engine fractions are
    mapped into it. status.json is rewritten at most every 0.5 s (and on every stage change).
    """

    def __init__(
        self,
        job: AnalysisJob,
        task_stage: str,
        lo: float,
        hi: float,
        publish: Publish | None,
        label: str = "",
    ):
        self.job, self.task_stage, self.lo, self.hi, self.publish = job, task_stage, lo, hi, publish
        self.label = label  # e.g. "chunk 2 of 4": the fraction below is this task's, not the bar's
        self._last_write = 0.0
        self._last_stage = ""

    def __call__(self, stage: str, fraction: float) -> None:
        check_cancel(self.job)
        progress = self.lo + (self.hi - self.lo) * min(max(float(fraction), 0.0), 1.0)
        now = time.monotonic()
        if stage == self._last_stage and now - self._last_write < _STATUS_INTERVAL_S:
            return
        self._last_stage, self._last_write = stage, now
        self.report(stage, progress, f"{self.label or stage}: {100 * fraction:.0f} % done")

    def report(self, stage: str, progress: float, message: str) -> None:
        # Parallel chunks each know only their own share: never move the shared bar back.
        current = read_status(self.job.work_dir) or {}
        if current.get("state") == "running":
            progress = max(progress, float(current.get("progress") or 0.0))
        meta = {"stage": stage, "progress": round(progress, 4), "message": message}
        write_status(self.job.work_dir, "running", **meta)
        if self.publish is not None:
            self.publish(meta)


def engine_inputs(
    job: AnalysisJob, pipeline: ModuleType = engine_pipeline
) -> tuple[Settings, Domain | None]:
    """The job's settings and domain as the engine takes them (parsed once per task, here,
    by the engine's own parsers: ``pipeline.Settings.from_dict``, ``pipeline.parse_domain``).

    Raises
    ------
    InvalidInput
        Unknown or ill-typed settings, or an invalid domain document.
    """
    settings = pipeline.Settings.from_dict(job.settings or None)
    domain = None if job.domain is None else pipeline.parse_domain(job.domain)
    return settings, domain


def _stage_done(job: AnalysisJob, stage: str, started: float, **extra: Any) -> None:
    seconds = time.monotonic() - started
    metrics.inc("coach_stage_runs_total", stage=stage, outcome="done")
    metrics.observe("coach_stage_seconds", seconds, stage=stage)
    log_event(
        "analysis.stage_done", stage=stage, analysis_id=job.analysis_id, seconds=seconds, **extra
    )


def _skipped(job: AnalysisJob, stage: str, output: Path) -> Path:
    metrics.inc("coach_stage_skipped_total", stage=stage)
    log_event(
        "analysis.stage_skipped", stage=stage, analysis_id=job.analysis_id, output=output.name
    )
    return output


# ---------------------------------------------------------------------------------------------
# stages


def start(job: AnalysisJob) -> bool:
    """Mark the analysis running; False if it is already finished or cancelled (skip it)."""
    paths = AnalysisFolder(job.work_dir)
    paths.stages.mkdir(parents=True, exist_ok=True)
    if is_cancelled(job.work_dir):
        request_cancel(job.work_dir)
        return False
    if paths.result.exists():
        write_status(job.work_dir, "done", stage="select", progress=1.0, message="done", force=True)
        return False
    if (read_status(job.work_dir) or {}).get("state") == "failed":
        # A late duplicate of a failed run (enqueue resets the status for a deliberate new one).
        return False
    write_status(
        job.work_dir, "running", stage="queued", progress=0.0, message="started", force=True
    )
    log_event("analysis.started", analysis_id=job.analysis_id)
    return True


def run_prepare(
    job: AnalysisJob,
    *,
    pipeline: ModuleType = engine_pipeline,
    publish: Publish | None = None,
    max_crashes: int = MAX_CRASHES,
) -> Path:
    """Stages 0-2 (foreground, calibration, approximate alignment) -> ``stages/prepare.npz``."""
    paths = AnalysisFolder(job.work_dir)
    if paths.prepared.exists():
        return _skipped(job, "prepare", paths.prepared)
    check_cancel(job)
    with lease.attempt(job.work_dir, paths.prepared, max_crashes=max_crashes):
        progress = Progress(job, "prepare", *_SPAN["prepare"], publish)
        progress.report("prepare", _SPAN["prepare"][0], "preparing")
        started = time.monotonic()
        settings, domain = engine_inputs(job, pipeline)
        frames = {"frames": (job.frames[0], job.frames[1])} if job.frames else {}
        prepared = pipeline.prepare(
            job.reference_path, job.video_path, settings, domain=domain,
            mapping=job.reference_mapping, units_to_m=job.reference_units_to_m,
            on_progress=progress, **frames,
        )  # fmt: skip
        check_cancel(job)
        write_atomic(paths.prepared, prepared.save)
        # shown while the rest runs: the upload page could not check a video its browser
        # cannot decode, and API uploads are not checked before they arrive
        write_json_atomic(paths.framing, {"problems": list(prepared.framing)})
    _stage_done(job, "prepare", started)
    return paths.prepared


def run_candidates(
    job: AnalysisJob,
    index: int,
    n_chunks: int,
    *,
    pipeline: ModuleType = engine_pipeline,
    publish: Publish | None = None,
    max_crashes: int = MAX_CRASHES,
    provisional_min_wait_s: float | None = None,
) -> Path:
    """Stage 3 on chunk ``index`` of ``n_chunks`` -> ``stages/candidates-<i>-of-<n>.npz``.

    ``provisional_min_wait_s``: see :func:`write_provisional` (default
    :data:`PROVISIONAL_MIN_WAIT_S`).
    """
    if not 0 <= index < n_chunks:
        raise ValueError(f"chunk index must be in [0, {n_chunks}), got {index}")
    paths = AnalysisFolder(job.work_dir)
    out = paths.chunk(index, n_chunks)
    if out.exists():
        return _skipped(job, "candidates", out)
    check_cancel(job)
    with lease.attempt(job.work_dir, out, max_crashes=max_crashes):
        return _candidates(job, index, n_chunks, pipeline=pipeline, publish=publish,
                           min_wait_s=provisional_min_wait_s)  # fmt: skip


def _candidates(
    job: AnalysisJob,
    index: int,
    n_chunks: int,
    *,
    pipeline: ModuleType,
    publish: Publish | None,
    min_wait_s: float | None,
) -> Path:
    paths = AnalysisFolder(job.work_dir)
    out = paths.chunk(index, n_chunks)
    prepared = pipeline.Prepared.load(paths.prepared)
    ranges = prepared.chunks(n_chunks)
    if index >= len(ranges):
        # A video shorter than n_chunks frames splits into fewer chunks; select expects only
        # len(ranges) outputs, so this chunk has nothing to do.
        log_event("analysis.chunk_empty", analysis_id=job.analysis_id, chunk=index + 1)
        return out
    frames = ranges[index]
    # This chunk's share of the candidates span, offset by the chunks already finished, so
    # parallel chunks move one bar forward instead of each restarting it.
    lo, hi = _SPAN["candidates"]
    done = sum(p.exists() for p in paths.chunks(n_chunks))
    step = (hi - lo) / n_chunks
    label = f"frames {frames.start}-{frames.stop - 1} (part {index + 1} of {n_chunks})"
    progress = Progress(
        job, "candidates", lo + done * step, lo + (done + 1) * step, publish, label=label
    )
    progress.report("candidates", lo + done * step, f"{label}: started")
    started = time.monotonic()
    settings, _ = engine_inputs(job, pipeline)
    chunk = pipeline.candidates(prepared, frames, settings, on_progress=progress)
    check_cancel(job)
    write_atomic(out, chunk.save)
    if pipeline is engine_pipeline:  # a stand-in pipeline of the tests has no stage 4 to run
        write_provisional(job, n_chunks, prepared, settings, min_wait_s=min_wait_s)
    _stage_done(
        job,
        "candidates",
        started,
        chunk=f"{index + 1}/{n_chunks}",
        frames=f"{frames.start}-{frames.stop}",
    )
    return out


def _provisional_segments(paths: AnalysisFolder) -> int:
    """How many segments the provisional result written so far covers (0: none)."""
    old = read_json(paths.provisional)
    return 0 if old is None else int(old["provisional"]["segments"])


def _claim(path: Path) -> bool:
    """Create ``path`` if no process has: True for the one process that did."""
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        path.touch(exist_ok=False)
    except FileExistsError:
        return False
    return True


#: A provisional result is worth its stage-4 run (about 0.5 s on P2) only when the final one is
#: expected at least this many seconds later: a preview that the final result replaces within
#: moments is work for nothing.
PROVISIONAL_MIN_WAIT_S = 5.0


def write_provisional(
    job: AnalysisJob,
    n_chunks: int,
    prepared: Any,
    settings: Settings,
    *,
    min_wait_s: float | None = None,
) -> Path | None:
    """Stage 4 on the whole segments the finished chunks cover -> ``provisional.json``
    (:func:`engine.provisional.select_provisional`), when they cover more segments than the
    one already written and the rest of stage 3 is expected to take at least ``min_wait_s``
    (:func:`stage3_left_s`; default :data:`PROVISIONAL_MIN_WAIT_S`). Never fails the chunk:
    the provisional result is a preview, and the final one does not depend on it."""
    paths = AnalysisFolder(job.work_dir)
    wait = PROVISIONAL_MIN_WAIT_S if min_wait_s is None else min_wait_s
    try:
        done = [p for p in paths.chunks(n_chunks) if p.exists()]
        chunks = [engine_pipeline.CandidateChunk.load(p) for p in done]
        n_done = engine_provisional.finished_prefix(prepared, chunks)
        k, n = engine_provisional.covered_segments(prepared, n_done)
        if paths.result.exists() or stage3_left_s(paths, prepared, n_chunks, chunks) < wait:
            return None
        if k == 0 or _provisional_segments(paths) >= k or not _claim(paths.provisional_claim(k)):
            return None
        started = time.monotonic()
        doc = engine_provisional.select_provisional(prepared, chunks, settings)
        # another process may have written more segments meanwhile: never replace them
        if doc is None or _provisional_segments(paths) >= k:
            return None
        doc.setdefault("analysis_id", job.analysis_id)
        write_json_atomic(paths.provisional, doc)
    except Exception as exc:  # noqa: BLE001 - logged; the chunk's own output is written
        log_event("analysis.provisional_failed", analysis_id=job.analysis_id, error=repr(exc))
        return None
    log_event("analysis.provisional", analysis_id=job.analysis_id, segments=k, frames=n,
              seconds=round(time.monotonic() - started, 2))  # fmt: skip
    return paths.provisional


def stage3_left_s(
    paths: AnalysisFolder, prepared: Any, n_chunks: int, chunks: list[Any]
) -> float:
    """Expected seconds until every chunk of stage 3 is done: each unfinished chunk's frames
    at the finished ``chunks``' seconds per frame, less how long it has run if it runs (the
    age of its crash ledger, :func:`worker.lease.attempt`), shared by the chunks running now
    (at least one). Chunk order and worker count then no longer decide whether a preview
    comes: a frame count cannot tell two chunks just started from two about to end."""
    frames = sum(len(c.frames) for c in chunks)
    per_frame = sum(float(c.seconds) for c in chunks) / max(frames, 1)
    now = storage_now(paths.work_dir)
    work, running = 0.0, 0
    for frames_of, out in zip(prepared.chunks(n_chunks), paths.chunks(n_chunks), strict=False):
        if out.exists():
            continue
        need = len(frames_of) * per_frame
        ran = file_age_s(paths.attempts(out), now)
        if ran is not None:
            running += 1
            need = max(need - ran, 0.0)
        work += need
    return work / max(running, 1)


def run_select(
    job: AnalysisJob,
    n_chunks: int,
    *,
    pipeline: ModuleType = engine_pipeline,
    publish: Publish | None = None,
    on_result: Callable[[Path], None] | None = None,
    max_crashes: int = MAX_CRASHES,
) -> Path:
    """Stage 4 (selection, errors) over every chunk -> ``result.json``; status becomes done.

    ``on_result(path)`` runs after result.json exists and before status.json says done (the
    task stores its success there, so whoever sees "done" also sees the task's result).
    """
    paths = AnalysisFolder(job.work_dir)
    if paths.result.exists():
        _skipped(job, "select", paths.result)
    else:
        check_cancel(job)
        with lease.attempt(job.work_dir, paths.result, max_crashes=max_crashes):
            _select(job, n_chunks, pipeline=pipeline, publish=publish)
    if on_result is not None:
        on_result(paths.result)
    if write_status(job.work_dir, "done", stage="select", progress=1.0, message="done"):
        metrics.inc("coach_analyses_total", state="done")
        log_event("analysis.done", analysis_id=job.analysis_id)
    return paths.result


def _select(
    job: AnalysisJob, n_chunks: int, *, pipeline: ModuleType, publish: Publish | None
) -> None:
    paths = AnalysisFolder(job.work_dir)
    prepared = pipeline.Prepared.load(paths.prepared)
    expected = paths.chunks(n_chunks)[: len(prepared.chunks(n_chunks))]
    missing = [p.name for p in expected if not p.exists()]
    if missing:
        raise FileNotFoundError(f"stage-3 outputs missing: {', '.join(missing)}")
    chunks = [pipeline.CandidateChunk.load(p) for p in expected]
    progress = Progress(job, "select", *_SPAN["select"], publish)
    progress.report("select", _SPAN["select"][0], "selecting")
    started = time.monotonic()
    settings, _ = engine_inputs(job, pipeline)
    result = pipeline.select(prepared, chunks, settings, on_progress=progress)
    check_cancel(job)
    result.setdefault("analysis_id", job.analysis_id)
    write_json_atomic(paths.result, result)
    _stage_done(job, "select", started)


def run_all(
    job: AnalysisJob,
    n_chunks: int,
    *,
    pipeline: ModuleType = engine_pipeline,
    publish: Publish | None = None,
    max_crashes: int = MAX_CRASHES,
    provisional_min_wait_s: float | None = None,
) -> Path:
    """Every stage in order in this process (embedded sequential mode); returns result.json.

    Engine errors, repeated crashes and cancellation are recorded on the analysis before they
    propagate.
    """
    run = {"pipeline": pipeline, "publish": publish, "max_crashes": max_crashes}
    try:
        if not start(job):
            return AnalysisFolder(job.work_dir).result
        run_prepare(job, **run)
        for i in range(n_chunks):
            run_candidates(job, i, n_chunks, **run, provisional_min_wait_s=provisional_min_wait_s)
        return run_select(job, n_chunks, **run)
    except (EngineError, Cancelled, lease.RepeatedCrash) as exc:
        record_failure(job, exc)
        raise


def record_failure(job: AnalysisJob, exc: BaseException, *, stage: str | None = None) -> None:
    """Record a failed (or cancelled) analysis with a message the user can read."""
    current = read_status(job.work_dir) or {}
    stage = stage or current.get("stage", "")
    if isinstance(exc, Cancelled) or is_cancelled(job.work_dir):
        state, error = "cancelled", None
        counted = current.get("state") not in TERMINAL
        request_cancel(job.work_dir)
    else:
        state = "failed"
        error = str(exc) or type(exc).__name__
        counted = write_status(
            job.work_dir,
            state,
            stage=stage,
            progress=current.get("progress", 0.0),
            message=error,
            error=error,
        )
        if isinstance(exc, lease.RepeatedCrash):
            # Messages of the analysis still queued (a sibling chunk, a late redelivery) stop
            # at the marker instead of killing more workers; the status stays failed.
            request_cancel(job.work_dir)
    if counted:  # once per analysis, however many chunks fail
        metrics.inc("coach_analyses_total", state=state)
        metrics.inc("coach_stage_runs_total", stage=stage or "unknown", outcome=state)
    log_event(
        f"analysis.{state}",
        analysis_id=job.analysis_id,
        stage=stage,
        error=error or "",
        error_type=type(exc).__name__,
    )
