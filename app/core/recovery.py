"""Recovery that needs no one: analyses nobody is working on are queued again (issue 26).

The reflector calls :func:`recover` on every tick. An analysis the database calls queued or
running can be left with nobody working on it in three ways:

=============================  ===================================  ============================
what happened                  what is left                         queued again after
=============================  ===================================  ============================
the API died between the       the committed row without a task id  ``publish_grace_s`` (30 s)
database commit and the        (the row is the outbox record,
publish, or the broker was     recovery its relay)
down then
Redis restarted                no message at all; running tasks     ``publish_grace_s`` if it
                               were cancelled                       was waiting, else
                                                                    ``lost_after_s`` (60 s)
a whole worker died (SIGKILL,  its message, held unacknowledged     ``lost_after_s``
lost machine)                  until the visibility timeout (2 h)
=============================  ===================================  ============================

A pool process killed by the OOM killer needs none of this: Celery hands its message out again
at once, and ``worker.lease`` fails a stage that keeps killing its worker.

The signs, read from the analysis folder and the broker (``JobQueue.broker_tasks``): while a
task of the analysis runs, its heartbeat is renewed every few seconds. An analysis is lost when
no message of it waits in the queue (that one only waits for a free worker), its heartbeat is
``lost_after_s`` old or absent (the rule the workers apply too: a younger one means a live
run, which would drop the new message as a duplicate), and its last sign of life (heartbeat,
status.json, the row's own times) is older than ``publish_grace_s`` if the broker holds no
message of it, or than ``lost_after_s`` if a worker holds one (that worker is dead). A
worker taking a message counts as a sign of life too (Redis records when): the task has not
started its heartbeat yet.

Queueing again is always safe: stages whose output exists are skipped, and a worker drops an
entry message for an analysis whose heartbeat another run keeps fresh. The row's
``recoveries`` counter is the claim: a conditional update (``WHERE recoveries = n``) lets one
API process of several do it.

Clocks: file ages are read on the storage's clock (``worker.contract.storage_now``: a
``clock`` file in the data directory touched, its time read back, once per tick), row times
on the API's. So a worker or
an API machine whose clock is off neither recovers a live analysis nor leaves a dead one.
"""

from __future__ import annotations

import logging
import os
import time
from dataclasses import dataclass
from datetime import datetime

from sqlalchemy import update
from sqlalchemy.orm import Session

from app import crud
from app.core.config import Settings
from app.core.queue import JobQueue, QueueUnavailable, analysis_job
from app.core.storage import Storage
from app.models import TERMINAL_STATES, Analysis, Reference, utcnow
from worker.contract import AnalysisFolder, BrokerTasks, file_age_s, storage_now

log = logging.getLogger("app.recovery")

#: Seconds between the two readings of the broker before anything is queued again.
RECHECK_S = 0.2


def _timestamp(value: datetime | None) -> float:
    return value.timestamp() if value is not None else 0.0


@dataclass(frozen=True)
class Clocks:
    """The two clocks an analysis' signs of life are read on: ``api`` for the database row
    (API processes write its times) and ``storage`` for the folder's files (workers write
    them, and the storage stamps them), so API and workers need no synchronised clocks."""

    api: float
    storage: float

    @classmethod
    def read(cls, folder: str | os.PathLike, api_now: float) -> Clocks:
        """``api_now`` and the clock of the storage holding ``folder``."""
        storage = storage_now(folder)
        # No folder (deleted or not yet written): no file to age, any reading will do.
        return cls(api_now, api_now if storage is None else storage)


def quiet_s(analysis: Analysis, clocks: Clocks) -> float | None:
    """Seconds since the analysis last showed life; None if it is finished in its folder
    (done, failed, cancelled: the reflector records that, nothing to recover)."""
    folder = AnalysisFolder(analysis.work_dir)
    if folder.result.exists() or folder.cancel.exists():
        return None
    if (Storage.read_json(folder.status) or {}).get("state") in TERMINAL_STATES:
        return None
    ages = [file_age_s(p, clocks.storage) for p in (folder.heartbeat, folder.status)]
    ages += [clocks.api - _timestamp(analysis.created_at)]
    ages += [clocks.api - _timestamp(analysis.updated_at)]
    return min(a for a in ages if a is not None)


def task_ids(analysis: Analysis) -> set[str]:
    """The analysis' entry task and the stage tasks its canvas launched."""
    ids = {analysis.task_id} if analysis.task_id else set()
    note = Storage.read_json(AnalysisFolder(analysis.work_dir).tasks) or {}
    ids.update(str(i) for i in note.get("stage_task_ids") or [])
    return ids


def lost_cause(
    analysis: Analysis, broker: BrokerTasks, settings: Settings, now: float,
    clocks: Clocks | None = None,
) -> str | None:  # fmt: skip
    """Why nobody works on the analysis, or None while somebody may (``now``: this API
    process' clock; ``clocks``: read once for many analyses, else from its folder)."""
    clocks = clocks or Clocks.read(analysis.work_dir, now)
    quiet = quiet_s(analysis, clocks)
    if quiet is None or quiet < settings.publish_grace_s:
        return None
    heartbeat = AnalysisFolder(analysis.work_dir).heartbeat_age_s(clocks.storage)
    if heartbeat is not None and heartbeat < settings.lost_after_s:
        return None  # a live run, or one that ended moments ago and left its next message
    ids = task_ids(analysis)
    if ids & broker.waiting:
        return None  # waits for a free worker
    held = broker.held is None or bool(ids & broker.held)
    # A worker that took a message moments ago is alive, though its task has not started
    # the heartbeat yet (the message may have waited long for a free worker). The broker
    # records the worker's clock: a skew shifts only this short sign, bounded by the heartbeat
    # that the task starts at once.
    taken = max((broker.taken_at.get(i, 0.0) for i in ids), default=0.0)
    if held and min(quiet, now - taken) < settings.lost_after_s:
        # A worker took it (or the transport cannot say): only a stale heartbeat proves that
        # worker dead; its task would renew the heartbeat every few seconds.
        return None
    if not analysis.task_id:
        return "never published"
    if broker.held is None:
        return "lost"
    return "worker lost" if held else "message lost"


def recover(
    session: Session, *, settings: Settings, queue: JobQueue, now: float | None = None
) -> list[str]:
    """Queue every lost analysis again; returns their ids."""
    now = time.time() if now is None else now
    # One reading of the storage's clock per tick: every analysis folder is on it.
    clocks = Clocks.read(settings.data_dir, now)
    suspects = [
        a for a in crud.list_active_analyses(session)
        if (q := quiet_s(a, clocks)) is not None and q >= settings.publish_grace_s
    ]  # fmt: skip
    if not suspects:
        return []
    broker = queue.broker_tasks()
    if broker is None:
        return []  # broker unreachable: nothing can be queued now anyway
    # Signs read after the broker: a task that started meanwhile shows in its heartbeat.
    now = max(now, time.time())
    clocks = Clocks.read(settings.data_dir, now)
    lost = [a for a in suspects if lost_cause(a, broker, settings, now, clocks)]
    if not lost:
        return []
    # Redis moves a message from the queue to a worker in two steps; one caught between them
    # is in neither. A second reading a moment later sees it held. (The merged reading only
    # adds signs of life, so only the analyses lost in the first can be lost in it.)
    time.sleep(RECHECK_S)
    again = queue.broker_tasks()
    if again is None:
        return []
    broker = broker.merged(again)
    recovered = []
    for analysis in lost:
        cause = lost_cause(analysis, broker, settings, now, clocks)
        if cause is not None and _requeue(session, settings, queue, analysis, cause):
            recovered.append(analysis.id)
    return recovered


def _requeue(
    session: Session, settings: Settings, queue: JobQueue, analysis: Analysis, cause: str
) -> bool:
    reference = session.get(Reference, analysis.reference_id)
    if reference is None:
        return False
    claim = (
        update(Analysis)
        .where(
            Analysis.id == analysis.id,
            Analysis.recoveries == analysis.recoveries,
            Analysis.status.not_in(TERMINAL_STATES),
        )
        .values(recoveries=analysis.recoveries + 1, updated_at=utcnow())
        # Not applied to the loaded row in Python: it may be the stale one that lost the race.
        .execution_options(synchronize_session=False)
    )
    # updated_at counts as a sign of life: another API process reading the row after this
    # commit waits publish_grace_s before it even considers the analysis again.
    claimed = session.execute(claim).rowcount == 1
    session.commit()
    session.refresh(analysis)
    if not claimed:
        return False
    try:
        task_id = queue.enqueue(analysis_job(analysis, reference, settings.engine_preset))
    except QueueUnavailable as exc:
        log.warning("analysis.recovery_failed analysis=%s error=%s", analysis.id, exc)
        return False
    analysis.task_id = task_id
    session.commit()
    log.warning(
        "analysis.recovered analysis=%s cause=%r recoveries=%d task=%s",
        analysis.id, cause, analysis.recoveries, task_id,
    )  # fmt: skip
    return True
