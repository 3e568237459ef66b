"""The seam between the API and the workers: enqueue, revoke, and what the broker holds.

Routes get a :class:`JobQueue` through ``QueueDep``; tests override :func:`get_queue` with a
recorder. The Celery client is imported lazily so the API starts (and answers reads) while
the worker package is being installed or its broker is down.
"""

from __future__ import annotations

from typing import Protocol

from app.core.validation import engine_domain
from worker.contract import AnalysisJob, BrokerTasks, CaptureJob


class QueueUnavailable(Exception):
    """The job could not be handed to the workers (no worker package, broker down)."""


class PublishFailed(QueueUnavailable):
    """The broker did not take the job this time (down, restarting); recovery publishes the
    committed analysis once it is back (app.core.recovery)."""


class JobQueue(Protocol):
    def enqueue(self, job: AnalysisJob) -> str: ...

    def enqueue_capture(self, job: CaptureJob) -> str: ...

    def revoke(self, task_id: str) -> None: ...

    def broker_tasks(self) -> BrokerTasks | None: ...


class CeleryQueue:
    """Hands jobs to ``worker.celery_app`` (Celery over Redis or the embedded transport)."""

    def enqueue(self, job: AnalysisJob) -> str:
        try:
            from worker.celery_app import enqueue
        except ImportError as exc:
            raise QueueUnavailable(f"the worker package is not available: {exc}") from exc
        try:
            return str(enqueue(job))
        except Exception as exc:  # kombu/redis raise many types; all mean "not queued"
            raise PublishFailed(f"could not queue the analysis: {exc}") from exc

    def enqueue_capture(self, job: CaptureJob) -> str:
        try:
            from worker.celery_app import enqueue_capture
        except ImportError as exc:
            raise QueueUnavailable(f"the worker package is not available: {exc}") from exc
        try:
            return str(enqueue_capture(job))
        except Exception as exc:  # kombu/redis raise many types; all mean "not queued"
            raise QueueUnavailable(f"could not queue the capture: {exc}") from exc

    def revoke(self, task_id: str) -> None:
        try:
            from worker.celery_app import revoke
        except ImportError as exc:
            raise QueueUnavailable(f"the worker package is not available: {exc}") from exc
        try:
            revoke(task_id)
        except Exception as exc:
            raise QueueUnavailable(f"could not revoke task {task_id}: {exc}") from exc

    def broker_tasks(self) -> BrokerTasks | None:
        """The task ids the broker holds (waiting, held by a worker); None if unknown."""
        try:
            from worker.celery_app import broker_tasks
        except ImportError:
            return None
        return broker_tasks()


def analysis_job(analysis, reference, engine_preset: str = "") -> AnalysisJob:
    """The worker payload of an analysis row: paths, settings, and the reference's domain
    and import options as data (the reference's ``domain_config``, stored once)."""
    config = reference.domain_config or {}
    return AnalysisJob(
        analysis_id=analysis.id,
        reference_path=reference.bvh_path,
        video_path=analysis.video_path,
        work_dir=analysis.work_dir,
        settings={"preset": engine_preset} if engine_preset else {},
        domain=engine_domain(config) if config else None,
        reference_mapping=config.get("mapping") or None,
        reference_units_to_m=config.get("units_to_m"),
        frames=None if analysis.frames_start is None
        else [int(analysis.frames_start), int(analysis.frames_end)],
    )


def purge_embedded_queue() -> int:
    """Drop every message of the embedded (filesystem) broker; returns how many.

    Used at start-up of the embedded deployment, whose transport cannot give a message back
    when its worker is killed: the queue is rebuilt from the database instead.
    """
    try:
        from worker.celery_app import app, current_settings
    except ImportError:
        return 0
    current_settings()
    return int(app.control.purge() or 0)


_queue = CeleryQueue()


def get_queue() -> JobQueue:
    return _queue
