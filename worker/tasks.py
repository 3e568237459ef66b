"""Celery tasks: thin shells over :mod:`worker.jobs`.

One canvas per analysis, following the engine's stages::

    coach.analyze (entry: builds and launches, never waits)
        -> coach.stage.prepare
        -> chord(group(coach.stage.candidates chunk 0..n-1), coach.stage.select)

Tasks take the job as JSON (ids and paths only) and re-read everything else from the analysis
folder. Each task:

- renews the analysis' heartbeat while it runs (:class:`worker.lease.Heartbeat`); the entry
  task drops its message if another entry task's run of the analysis is alive, so the API's
  recovery may queue an analysis again whenever it looks lost;
- skips its stage if the output exists (done in :mod:`worker.jobs`), so a redelivered message
  (``acks_late``, ``reject_on_worker_lost``) resumes instead of redoing work;
- records engine errors (``InvalidInput``, ``RegistrationFailed``), a stage that killed its
  worker ``max_crashes`` times (``RepeatedCrash``) and cancellation on the analysis and
  re-raises them without retrying, so the chord stops and select never runs;
- retries only :data:`TRANSIENT` errors, with exponential backoff, up to ``max_retries``;
- publishes progress as the custom state ``PROGRESS`` on itself and on the entry task's id
  (the id the API holds), next to status.json.
"""

from __future__ import annotations

import json
import logging
import random
from types import ModuleType

from celery import chain, chord, group
from celery.exceptions import Retry, SoftTimeLimitExceeded
from celery.signals import worker_process_init, worker_shutting_down
from kombu.exceptions import OperationalError

from engine import pipeline as engine_pipeline
from engine.errors import EngineError
from worker import jobs, lease, metrics
from worker.celery_app import app, current_settings
from worker.contract import (
    ANALYZE_TASK,
    CANDIDATES_TASK,
    CAPTURE_TASK,
    PREPARE_TASK,
    PROGRESS_STATE,
    SELECT_TASK,
    AnalysisFolder,
    AnalysisJob,
    CaptureJob,
)

log = logging.getLogger("coach.worker")

try:  # the redis client is present whenever the broker is Redis
    from redis.exceptions import ConnectionError as RedisConnectionError
    from redis.exceptions import TimeoutError as RedisTimeoutError
except ImportError:  # pragma: no cover - embedded-only install
    RedisConnectionError = RedisTimeoutError = OperationalError

#: The only errors worth retrying: the data directory or the broker/result store hiccuped.
#: (OSError covers a briefly unavailable shared volume and select finding a chunk not yet
#: visible; engine errors are never in here.)
TRANSIENT: tuple[type[BaseException], ...] = (
    OSError,
    RedisConnectionError,
    RedisTimeoutError,
    OperationalError,
)

_S = current_settings()

#: The engine these tasks run. Tests of the queue's behaviour start a worker whose app module
#: (``tests/worker/fake_app.py``) sets a fake here, whose stages last a known time.
ENGINE: ModuleType = engine_pipeline


@worker_process_init.connect
def _on_pool_process_start(**_: object) -> None:
    # Celery cancels running tasks with SIGTERM when it loses the broker: let them unwind so
    # the cut-short stage is not counted as one that killed its worker.
    lease.interrupt_on_sigterm()


@worker_shutting_down.connect
def _on_worker_shutting_down(**_: object) -> None:
    """In the worker's master, told to stop (a deploy's SIGTERM): note which pool processes
    run a stage of which analysis, so that the SIGKILL that ends a deploy's grace period is
    not counted as a crash of those analyses (worker.lease.attempt)."""
    from celery.worker import state

    for request in list(state.active_requests):
        job = request.args[0] if request.args else request.kwargs.get("job_json")
        if isinstance(job, dict) and job.get("work_dir") and request.worker_pid:
            lease.note_stopping(job["work_dir"], request.worker_pid)


def _backoff(retries: int) -> float:
    """2, 4, 8, ... s with +-25 % jitter, capped at 10 min (inside the visibility timeout)."""
    return min(600.0, 2.0 * 2**retries) * random.uniform(0.75, 1.25)


def _publisher(task):
    root_id = task.request.root_id

    def publish(meta: dict) -> None:
        if task.request.id is None:  # called directly, not as a task
            return
        # Progress is advice (status.json in the analysis folder is what users see): a
        # result store that cannot take it must not fail the stage that reports it.
        try:
            task.update_state(state=PROGRESS_STATE, meta=meta)
            if root_id and root_id != task.request.id:
                task.update_state(task_id=root_id, state=PROGRESS_STATE, meta=meta)
        except Exception as exc:
            log.warning("progress.publish_failed task=%s error=%r", task.request.id, exc)

    return publish


def _stage_kwargs(task) -> dict:
    """What every stage function gets from its task: the engine, progress, the crash limit."""
    return {"pipeline": ENGINE, "publish": _publisher(task), "max_crashes": _S.max_crashes}


def _run(task, job: AnalysisJob, stage: str, work):
    """Run ``work()`` under the analysis' heartbeat, with the error policy of the module
    docstring."""
    owner = task.request.root_id or task.request.id or job.analysis_id
    with lease.Heartbeat(job.work_dir, owner, _S.heartbeat_s) as heartbeat:
        return _run_policy(task, job, stage, work, heartbeat)


def _run_policy(task, job: AnalysisJob, stage: str, work, heartbeat: lease.Heartbeat):
    try:
        return work()
    except (EngineError, jobs.Cancelled, lease.RepeatedCrash) as exc:
        jobs.record_failure(job, exc, stage=stage)
        _mark_root_failed(task, exc)
        raise
    except SoftTimeLimitExceeded:
        soft = task.soft_time_limit
        exc = jobs.StageTimeout(f"the {stage} stage took longer than its limit of {soft} s")
        jobs.record_failure(job, exc, stage=stage)
        _mark_root_failed(task, exc)
        raise exc from None
    except TRANSIENT as exc:
        if task.request.retries < _S.max_retries:
            metrics.inc("coach_task_retries_total", task=task.name)
            countdown = _backoff(task.request.retries)
            jobs.log_event(
                "analysis.retry",
                analysis_id=job.analysis_id,
                stage=stage,
                error=repr(exc),
                countdown=countdown,
            )
            try:
                raise task.retry(exc=exc, countdown=countdown) from exc
            except Retry:
                # The retry's message waits in a worker for the countdown: keep the lease.
                heartbeat.hold(countdown)
                raise
        jobs.record_failure(job, exc, stage=stage)
        _mark_root_failed(task, exc)
        raise
    except Exception as exc:  # a bug: record it for the user, never retry
        jobs.record_failure(job, RuntimeError(f"internal error in {stage}: {exc!r}"), stage=stage)
        _mark_root_failed(task, exc)
        raise


def _mark_root_failed(task, exc: BaseException) -> None:
    root_id = task.request.root_id
    if root_id and (root_id != task.request.id or task.ignore_result):
        task.backend.mark_as_failure(root_id, exc)


@app.task(
    bind=True,
    name=ANALYZE_TASK,
    # The entry task's own return would land after the stages started publishing PROGRESS on
    # its id; its state is written by the stages instead.
    ignore_result=True,
    # Canvas mode: building and sending the canvas takes milliseconds (analyze limits).
    # Sequential mode: it runs every stage, so it gets their summed budgets.
    soft_time_limit=(_S.sequential_limits() if _S.sequential else _S.limits_for("analyze"))[0],
    time_limit=(_S.sequential_limits() if _S.sequential else _S.limits_for("analyze"))[1],
)
def analyze(self, job_json: dict) -> dict:
    """Entry task: launch prepare -> chord(candidates chunks) -> select for one analysis."""
    job = AnalysisJob.from_json(job_json)
    n_chunks = _S.chunks

    # Before this task's own heartbeat starts: a second entry message for a live run (queued
    # again by recovery, or published twice) is dropped.
    if lease.running_elsewhere(job.work_dir, self.request.id, _S.lost_after_s):
        jobs.log_event("analysis.duplicate_dropped", analysis_id=job.analysis_id)
        return {"analysis_id": job.analysis_id, "launched": False}

    def work() -> dict:
        if not jobs.start(job):
            return {"analysis_id": job.analysis_id, "launched": False}
        if _S.sequential:
            path = jobs.run_all(job, n_chunks, **_stage_kwargs(self),
                                provisional_min_wait_s=_S.provisional_min_wait_s)  # fmt: skip
            self.update_state(state="SUCCESS", meta={"result_path": str(path)})
            return {"analysis_id": job.analysis_id, "result_path": str(path)}
        return launch(job, n_chunks, root_id=self.request.id)

    return _run(self, job, "analyze", work)


def launch(job: AnalysisJob, n_chunks: int, *, root_id: str | None) -> dict:
    """Build and send the canvas; note its task ids in the folder (for revoke)."""
    payload = job.to_json()
    base = root_id or job.analysis_id
    prepare_sig = prepare.si(payload).set(task_id=f"{base}-prepare")
    chunk_sigs = [
        candidates.si(payload, i, n_chunks).set(task_id=f"{base}-candidates-{i}")
        for i in range(n_chunks)
    ]
    select_sig = select.si(payload, n_chunks).set(task_id=f"{base}-select")
    canvas = chain(prepare_sig, chord(group(chunk_sigs), select_sig))
    ids = [
        f"{base}-prepare",
        *(f"{base}-candidates-{i}" for i in range(n_chunks)),
        f"{base}-select",
    ]
    tasks_note = AnalysisFolder(job.work_dir).tasks
    try:
        if json.loads(tasks_note.read_text()).get("root_id") == root_id:
            # This entry message was delivered again after it launched the canvas (worker died
            # before the ack): the stage messages are already queued.
            return {"analysis_id": job.analysis_id, "launched": False, "stage_task_ids": ids}
    except (OSError, ValueError):
        pass
    canvas.apply_async()
    jobs.write_json_atomic(
        AnalysisFolder(job.work_dir).tasks, {"root_id": root_id, "stage_task_ids": ids}
    )
    jobs.log_event("analysis.launched", analysis_id=job.analysis_id, chunks=n_chunks)
    return {"analysis_id": job.analysis_id, "launched": True, "stage_task_ids": ids}


@app.task(
    bind=True,
    name=PREPARE_TASK,
    # Stages 0-2 over the whole video; see worker.settings.DEFAULT_LIMITS_S for the budget.
    soft_time_limit=_S.limits_for("prepare")[0],
    time_limit=_S.limits_for("prepare")[1],
)
def prepare(self, job_json: dict) -> str:
    job = AnalysisJob.from_json(job_json)
    return str(
        _run(
            self,
            job,
            "prepare",
            lambda: jobs.run_prepare(job, **_stage_kwargs(self)),
        )
    )


@app.task(
    bind=True,
    name=CANDIDATES_TASK,
    # One chunk of stage-3 belief propagation; see worker.settings.DEFAULT_LIMITS_S.
    soft_time_limit=_S.limits_for("candidates")[0],
    time_limit=_S.limits_for("candidates")[1],
)
def candidates(self, job_json: dict, index: int, n_chunks: int) -> str:
    job = AnalysisJob.from_json(job_json)
    return str(
        _run(
            self,
            job,
            "candidates",
            lambda: jobs.run_candidates(
                job, index, n_chunks, **_stage_kwargs(self),
                provisional_min_wait_s=_S.provisional_min_wait_s,
            ),  # fmt: skip
        )
    )


@app.task(
    bind=True,
    name=SELECT_TASK,
    # Stage 4 DP over every chunk; see worker.settings.DEFAULT_LIMITS_S.
    soft_time_limit=_S.limits_for("select")[0],
    time_limit=_S.limits_for("select")[1],
)
def select(self, job_json: dict, n_chunks: int) -> dict:
    job = AnalysisJob.from_json(job_json)
    root_id = self.request.root_id

    def on_result(path) -> None:
        if root_id and root_id != self.request.id:
            self.backend.store_result(root_id, _done(job, path), "SUCCESS")

    path = _run(
        self,
        job,
        "select",
        lambda: jobs.run_select(job, n_chunks, on_result=on_result, **_stage_kwargs(self)),
    )
    return _done(job, path)


def _done(job: AnalysisJob, path) -> dict:
    return {"analysis_id": job.analysis_id, "result_path": str(path)}


@app.task(
    bind=True,
    name=CAPTURE_TASK,
    soft_time_limit=_S.limits_for("capture")[0],
    time_limit=_S.limits_for("capture")[1],
)
def capture(self, job_json: dict) -> dict:
    """A reference-free capture: one task, under the capture folder's heartbeat. Engine
    errors (no person, unreadable video) are recorded in its status and not retried."""
    from worker.capture import run_capture  # the capture's engine modules load on use

    job = CaptureJob.from_json(job_json)
    owner = self.request.id or job.capture_id
    with lease.Heartbeat(job.work_dir, owner, _S.heartbeat_s):
        try:
            path = run_capture(job)
        except EngineError:
            return {"capture_id": job.capture_id, "failed": True}
        except SoftTimeLimitExceeded:
            error = f"the capture took longer than its limit of {self.soft_time_limit} s"
            jobs.write_status(job.work_dir, "failed", stage="capture", error=error, force=True)
            raise
        except Exception as exc:  # a bug: record it for the user, never retry
            error = f"internal error in the capture: {exc!r}"
            jobs.write_status(job.work_dir, "failed", stage="capture", error=error, force=True)
            raise
    return {"capture_id": job.capture_id, "summary_path": str(path)}
