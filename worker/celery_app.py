"""The Celery application, configured from :mod:`worker.settings`, and the API's calls.

``celery -A worker.celery_app worker`` (or ``coach worker``) runs it. The API calls only
:func:`enqueue`, :func:`revoke` and :func:`broker_tasks` (and reads status.json, result.json and
the heartbeat in the analysis folder).

Delivery guarantees, and why each setting:

- ``task_acks_late`` + ``task_reject_on_worker_lost``: a message is acknowledged only when its
  task finished, so a pool process that dies mid-stage (OOM, segfault) has its message handed
  out again at once. That is safe because every task is idempotent: a stage whose output
  exists is skipped and outputs appear only by atomic rename (:mod:`worker.jobs`); a stage that
  killed its process ``max_crashes`` times is failed instead (:mod:`worker.lease`).
- ``worker_prefetch_multiplier = 1``: stages run for minutes; a worker must not hoard messages
  other idle workers could run.
- Redis ``visibility_timeout`` (default 2 h): Redis redelivers an unacknowledged message once this
  has passed, whether or not the first worker is still running it. It must exceed the longest
  task (31 min hard limit) plus the longest retry countdown (10 min), or long stages would be
  duplicated on a second worker while still running. It no longer bounds recovery: when a
  whole worker dies (SIGKILL, lost machine) or Redis restarts and forgets every message, the
  analysis' heartbeat stops and the API queues it again once the heartbeat is ``lost_after_s``
  old (60 s; a queued analysis Redis forgot after ``publish_grace_s``, 30 s), within one
  reflector tick (``app.core.recovery``).
- ``worker_cancel_long_running_tasks_on_connection_loss``: with late acks a task whose worker lost
  the broker connection is redelivered anyway; cancelling it avoids running it twice.
"""

from __future__ import annotations

import json
import logging
import threading
import uuid
from pathlib import Path

from celery import Celery
from kombu import pools

from worker import metrics
from worker.contract import (
    ANALYZE_TASK,
    CAPTURE_TASK,
    AnalysisFolder,
    AnalysisJob,
    BrokerTasks,
    CaptureJob,
)
from worker.result_backend import celery_url
from worker.settings import WorkerSettings

log = logging.getLogger("coach.worker")

app = Celery("coach", include=["worker.tasks"])
_settings: WorkerSettings | None = None


def configure(settings: WorkerSettings | None = None) -> WorkerSettings:
    """(Re)configure :data:`app` from ``settings`` (default: the environment).

    Call before the first :func:`enqueue` if the data directory is not ``COACH_DATA_DIR``
    (:func:`worker.embedded.start` does).
    """
    global _settings
    settings = settings or WorkerSettings.from_env()
    conf: dict = dict(
        broker_url=settings.broker_url,
        result_backend=celery_url(settings.result_backend),
        task_serializer="json",
        result_serializer="json",
        accept_content=["json"],
        task_default_queue="coach",
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        worker_prefetch_multiplier=1,
        worker_cancel_long_running_tasks_on_connection_loss=True,
        broker_connection_retry_on_startup=True,
        task_track_started=True,
        result_expires=7 * 24 * 3600,
        # status.json carries the user-facing state; the result store only needs a few days.
        worker_hijack_root_logger=False,
    )
    if settings.embedded:
        broker = settings.broker_dir
        for sub in ("queue", "processed", "control"):
            (broker / sub).mkdir(parents=True, exist_ok=True)
        if settings.result_backend.startswith("file://"):
            Path(settings.result_backend.removeprefix("file://")).mkdir(parents=True, exist_ok=True)
        conf["broker_transport_options"] = {
            # Producer and consumer share one folder: the api writes what the worker reads.
            "data_folder_in": str(broker / "queue"),
            "data_folder_out": str(broker / "queue"),
            "processed_folder": str(broker / "processed"),
            "control_folder": str(broker / "control"),
            "store_processed": False,
        }
        # The filesystem transport polls; 0.2 s keeps latency low at negligible cost.
        conf["broker_transport_options"]["polling_interval"] = 0.2
    else:
        conf["broker_transport_options"] = {
            "visibility_timeout": settings.visibility_timeout_s,
            # A message a dead worker held comes back visibility_timeout + at most this later
            # (kombu's default sweep is interval x throttle = 100 s).
            "unacked_restore_interval": settings.restore_interval_s,
            "unacked_restore_throttle": 1,
        }
        conf["result_backend_transport_options"] = {
            "visibility_timeout": settings.visibility_timeout_s
        }
    if _settings is not None:
        _forget_connections()
    app.conf.update(conf)
    metrics.configure(settings.metrics_dir)
    _settings = settings
    return settings


def _forget_connections() -> None:
    """Drop the broker pool and result backend built for the previous configuration.

    Celery caches both on first use and never looks at the configuration again; without this a
    reconfigured process (``embedded.start`` after an import, tests) would publish to the old
    broker.
    """
    # kombu keeps one global pool per connection URL; reset() closes and forgets them, so a
    # later configuration with the same URL gets a fresh pool instead of the closed one.
    pools.reset()
    app._pool = None
    if "amqp" in app.__dict__:  # a cached property: only reset it if it was built
        app.amqp._producer_pool = None
    app._backend_cache = None
    app._local = threading.local()


def current_settings() -> WorkerSettings:
    return _settings or configure()


def enqueue(job: AnalysisJob) -> str:
    """Queue one analysis; returns the entry task's id (what :func:`revoke` takes).

    Writes status.json ``queued`` first, so the API sees the analysis at once, and notes
    task id -> analysis folder under the data directory so :func:`revoke` can find the folder.
    """
    from worker import jobs  # the engine import stays out of a bare `import worker.celery_app`

    settings = current_settings()
    task_id = uuid.uuid4().hex
    settings.tasks_dir.mkdir(parents=True, exist_ok=True)
    jobs.write_json_atomic(
        settings.tasks_dir / f"{task_id}.json",
        {"analysis_id": job.analysis_id, "work_dir": str(job.work_dir)},
    )
    jobs.write_status(
        job.work_dir, "queued", stage="queued", progress=0.0, message="queued", force=True
    )
    app.send_task(ANALYZE_TASK, args=[job.to_json()], task_id=task_id)
    log.info("analysis.enqueued analysis_id=%s task_id=%s", job.analysis_id, task_id)
    return task_id


def enqueue_capture(job: CaptureJob) -> str:
    """Queue one reference-free capture; returns its task id. Writes status.json ``queued``
    first, as :func:`enqueue` does."""
    from worker import jobs

    task_id = uuid.uuid4().hex
    jobs.write_status(job.work_dir, "queued", stage="queued", progress=0.0,
                      message="waiting for a free worker", force=True)  # fmt: skip
    app.send_task(CAPTURE_TASK, args=[job.to_json()], task_id=task_id)
    log.info("capture.enqueued capture_id=%s task_id=%s", job.capture_id, task_id)
    return task_id


def revoke(task_id: str) -> None:
    """Cancel the analysis started by ``task_id``.

    Writes the cancel marker and status ``cancelled`` in its folder (running stages stop at
    their next progress step; queued ones stop when they start) and revokes the entry task and
    every stage task already launched, so queued messages are dropped by the workers.
    """
    from worker import jobs

    settings = current_settings()
    ids = [task_id]
    note = settings.tasks_dir / f"{task_id}.json"
    try:
        work_dir = json.loads(note.read_text())["work_dir"]
    except (OSError, ValueError, KeyError):
        log.warning("analysis.revoke_unknown task_id=%s (no note; revoking the task only)", task_id)
        work_dir = None
    if work_dir is not None:
        jobs.request_cancel(work_dir)
        try:
            ids += json.loads(AnalysisFolder(work_dir).tasks.read_text()).get("stage_task_ids", [])
        except (OSError, ValueError):
            pass  # the canvas was not launched yet: the entry task will see the marker
    try:
        app.control.revoke(ids)
    except Exception as exc:  # broadcast is best effort; the marker is what guarantees the stop
        log.warning("analysis.revoke_broadcast_failed task_id=%s error=%s", task_id, exc)
    log.info("analysis.revoked task_id=%s work_dir=%s", task_id, work_dir)


def broker_tasks() -> BrokerTasks | None:
    """The ids of the tasks the broker holds now; None when it cannot be asked (down).

    Redis (kombu's transport) keeps waiting messages in a list named after the queue (the
    tasks set no priority, so one list) and delivered, unacknowledged ones in a hash; the
    embedded transport keeps waiting messages as files and forgets delivered ones.
    """
    settings = current_settings()
    try:
        if settings.embedded:
            return BrokerTasks(_folder_task_ids(settings.broker_dir / "queue"), None)
        with app.connection_for_read() as conn:
            channel = conn.default_channel
            pipe = channel.client.pipeline()
            pipe.lrange(app.conf.task_default_queue, 0, -1)
            pipe.hgetall(channel.unacked_key)
            # kombu scores each delivery tag with the time a worker took it.
            pipe.zrange(channel.unacked_index_key, 0, -1, withscores=True)
            waiting, unacked, taken = pipe.execute()
    except Exception as exc:  # kombu/redis raise many types; all mean "cannot tell now"
        log.warning("broker.unreadable error=%s", exc)
        return None
    when = {_text(tag): float(score) for tag, score in taken}
    held: dict[str, float] = {}
    for tag, raw in unacked.items():
        task_id = _task_id(json.loads(raw)[0])  # [message, exchange, routing key]
        if task_id:
            held[task_id] = max(held.get(task_id, 0.0), when.get(_text(tag), 0.0))
    return BrokerTasks(
        frozenset(filter(None, (_task_id(json.loads(raw)) for raw in waiting))),
        frozenset(held),
        taken_at=held,
    )


def _text(value: bytes | str) -> str:
    return value.decode() if isinstance(value, bytes) else value


def _task_id(message: dict) -> str | None:
    headers, properties = message.get("headers") or {}, message.get("properties") or {}
    return headers.get("id") or properties.get("correlation_id")


def _folder_task_ids(folder: Path) -> frozenset[str]:
    ids: set[str | None] = set()
    for path in folder.glob("*.msg"):
        try:
            ids.add(_task_id(json.loads(path.read_bytes())))
        except (OSError, ValueError):
            continue  # taken by a worker while we listed the folder
    return frozenset(i for i in ids if i)


configure()
