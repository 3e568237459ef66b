"""app.core.recovery without workers: what counts as lost, the outbox relay, the claim.

The end-to-end cases (Redis restarted, worker SIGKILLed, a job that kills its worker) run
against real processes in tests/integration/test_recovery.py.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass, field
from datetime import UTC, datetime, timedelta
from pathlib import Path

import pytest

from app import crud
from app.core import recovery
from app.core.queue import PublishFailed, QueueUnavailable, get_queue
from app.models import Analysis
from tests.app.conftest import RecordingQueue, upload
from worker.contract import AnalysisFolder, BrokerTasks


@dataclass
class BrokerQueue(RecordingQueue):
    """A recording queue whose broker holds ``waiting`` and ``held`` task ids; what it
    queues waits there."""

    waiting: set = field(default_factory=set)
    held: set | None = field(default_factory=set)

    def enqueue(self, job) -> str:
        self.jobs.append(job)
        task_id = f"recovered-{len(self.jobs)}"
        self.waiting.add(task_id)
        return task_id

    def broker_tasks(self) -> BrokerTasks:
        held = None if self.held is None else frozenset(self.held)
        return BrokerTasks(frozenset(self.waiting), held)


def _analysis(tmp_path, *, task_id: str | None = "t1", age_s: float = 100.0) -> Analysis:
    then = datetime.now(UTC) - timedelta(seconds=age_s)
    work = tmp_path / "a"
    work.mkdir(exist_ok=True)
    return Analysis(
        id="a", work_dir=str(work), status="running", task_id=task_id, recoveries=0,
        created_at=then, updated_at=then,
    )  # fmt: skip


def _age(path, seconds: float) -> None:
    path.touch()
    os.utime(path, (time.time() - seconds,) * 2)


def _elapse(app, seconds: float) -> None:
    """As if ``seconds`` passed with nobody working: every analysis' row times and files
    made that much older (a future ``now`` would not do: recovery reads the files' ages on
    the storage's clock, not on the API's)."""
    with app.state.sessionmaker() as session:
        for analysis in session.query(Analysis):
            analysis.created_at -= timedelta(seconds=seconds)
            analysis.updated_at -= timedelta(seconds=seconds)
            for path in Path(analysis.work_dir).rglob("*"):
                mtime = path.stat().st_mtime - seconds
                os.utime(path, (mtime, mtime))
        session.commit()


@pytest.mark.parametrize(
    ("heartbeat_age", "waiting", "held", "task_id", "expected"),
    [
        (None, set(), set(), None, "never published"),
        (100, set(), set(), "t1", "message lost"),  # Redis restarted
        (100, set(), {"t1"}, "t1", "worker lost"),  # its worker was SIGKILLed
        (100, set(), None, "t1", "lost"),  # embedded: the broker cannot tell, the heartbeat can
        (100, {"t1-candidates-1"}, set(), "t1", None),  # its next stage waits for a worker
        (10, set(), set(), "t1", None),  # a live run (heartbeat younger than lost_after_s)
        (-30, set(), {"t1"}, "t1", None),  # a retry's countdown holds the lease
    ],
)
def test_what_counts_as_lost(tmp_path, settings, heartbeat_age, waiting, held, task_id, expected):
    analysis = _analysis(tmp_path, task_id=task_id)
    folder = AnalysisFolder(analysis.work_dir)
    folder.tasks.write_text(json.dumps({"stage_task_ids": ["t1-prepare", "t1-candidates-1"]}))
    _age(folder.tasks, 100)
    if heartbeat_age is not None:
        _age(folder.heartbeat, heartbeat_age)
    broker = BrokerTasks(frozenset(waiting), None if held is None else frozenset(held))
    assert recovery.lost_cause(analysis, broker, settings, time.time()) == expected


def test_held_message_waits_out_lost_after_not_the_grace(tmp_path, settings):
    analysis = _analysis(tmp_path, age_s=settings.publish_grace_s + 1)
    held = BrokerTasks(frozenset(), frozenset({"t1"}))
    assert recovery.lost_cause(analysis, held, settings, time.time()) is None
    embedded = BrokerTasks(frozenset(), None)  # its worker may hold it: no telling
    assert recovery.lost_cause(analysis, embedded, settings, time.time()) is None
    gone = BrokerTasks(frozenset(), frozenset())
    assert recovery.lost_cause(analysis, gone, settings, time.time()) == "message lost"


def test_a_message_taken_moments_ago_is_a_live_worker(tmp_path, settings):
    """The message waited long for a free worker, and the heartbeat is the last run's: the
    worker that has just taken it is starting the task, not dead."""
    analysis = _analysis(tmp_path, age_s=settings.lost_after_s * 3)
    _age(AnalysisFolder(analysis.work_dir).heartbeat, settings.lost_after_s * 2)
    now = time.time()
    just_taken = BrokerTasks(frozenset(), frozenset({"t1"}), taken_at={"t1": now - 1})
    assert recovery.lost_cause(analysis, just_taken, settings, now) is None
    long_taken = BrokerTasks(
        frozenset(), frozenset({"t1"}), taken_at={"t1": now - settings.lost_after_s - 1}
    )
    assert recovery.lost_cause(analysis, long_taken, settings, now) == "worker lost"


def test_a_message_caught_between_queue_and_worker_is_not_lost(
    app, client, club_ref, video_file, settings, monkeypatch
):
    """Redis moves a message from the queue to a worker in two steps: a reading between
    them sees it nowhere. Recovery reads the broker again before it queues anything."""
    monkeypatch.setattr(recovery, "RECHECK_S", 0.0)
    upload(client, club_ref, video_file)
    _elapse(app, settings.lost_after_s + 1)
    readings = [BrokerTasks(frozenset(), frozenset())]  # the message in transit

    class InTransit(BrokerQueue):
        def broker_tasks(self) -> BrokerTasks:
            if readings:
                return readings.pop()
            just = time.time() - 1
            return BrokerTasks(frozenset(), frozenset({"task-1"}), taken_at={"task-1": just})

    with app.state.sessionmaker() as session:
        assert recovery.recover(session, settings=settings, queue=InTransit()) == []
        assert recovery.recover(session, settings=settings, queue=BrokerQueue()) != []


@pytest.mark.parametrize("finished", ["result", "cancel", "status"])
def test_finished_folders_are_left_to_the_reflector(tmp_path, settings, finished):
    analysis = _analysis(tmp_path)
    folder = AnalysisFolder(analysis.work_dir)
    if finished == "status":
        folder.status.write_text(json.dumps({"state": "failed"}))
    else:
        getattr(folder, finished).write_text("{}")
    gone = BrokerTasks(frozenset(), frozenset())
    assert recovery.lost_cause(analysis, gone, settings, time.time() + 1000) is None


class FailingQueue(RecordingQueue):
    def __init__(self, exc: Exception):
        super().__init__()
        self.exc = exc

    def enqueue(self, job) -> str:
        raise self.exc


def test_publish_failure_keeps_the_row_and_recovery_publishes_it(
    app, client, club_ref, video_file, settings
):
    app.dependency_overrides[get_queue] = lambda: FailingQueue(PublishFailed("redis down"))
    r = upload(client, club_ref, video_file)
    assert r.status_code == 201, r.text
    analysis_id = r.json()["id"]
    queue = BrokerQueue()
    with app.state.sessionmaker() as session:
        assert session.get(Analysis, analysis_id).task_id is None
        assert recovery.recover(session, settings=settings, queue=queue) == []
    _elapse(app, settings.publish_grace_s + 1)
    with app.state.sessionmaker() as session:
        assert recovery.recover(session, settings=settings, queue=queue) == [analysis_id]
        row = session.get(Analysis, analysis_id)
        assert row.task_id == "recovered-1" and row.recoveries == 1
    assert [j.analysis_id for j in queue.jobs] == [analysis_id]


def test_no_worker_package_is_still_a_503(app, client, club_ref, video_file, settings):
    app.dependency_overrides[get_queue] = lambda: FailingQueue(QueueUnavailable("no worker"))
    r = upload(client, club_ref, video_file)
    assert r.status_code == 503
    with app.state.sessionmaker() as session:
        assert session.query(Analysis).count() == 0


def test_two_api_processes_recover_an_analysis_once(app, client, club_ref, video_file, settings):
    upload(client, club_ref, video_file)  # queued as task-1, which the broker then forgot
    queue = BrokerQueue()
    _elapse(app, settings.lost_after_s + 1)
    later = time.time()
    first, second = app.state.sessionmaker(), app.state.sessionmaker()
    with first, second:
        # Both find it lost before either acts; the claim lets one through.
        rows = [crud.list_active_analyses(s)[0] for s in (first, second)]
        gone = BrokerTasks(frozenset(), frozenset())
        assert [recovery.lost_cause(a, gone, settings, later) for a in rows] == ["message lost"] * 2
        assert recovery._requeue(first, settings, queue, rows[0], "message lost")
        assert not recovery._requeue(second, settings, queue, rows[1], "message lost")
        # The next tick of either sees the new message waiting.
        assert recovery.recover(second, settings=settings, queue=queue) == []
    assert len(queue.jobs) == 1 and rows[0].recoveries == 1


# ---- clocks that differ (issue 26: recovery depended on synchronised clocks)
@pytest.mark.parametrize("api_clock_off_s", [-600.0, 0.0, 600.0])
def test_a_wrong_api_clock_neither_recovers_a_live_run_nor_keeps_a_dead_one(
    tmp_path, settings, api_clock_off_s
):
    """The API's clock is 10 min off the workers' and the storage's: a heartbeat renewed
    just now is still a live run, one renewed 100 s ago still a lost one."""
    api_now = time.time() + api_clock_off_s
    analysis = _analysis(tmp_path)
    analysis.created_at = analysis.updated_at = datetime.fromtimestamp(api_now - 100, UTC)
    folder = AnalysisFolder(analysis.work_dir)
    gone = BrokerTasks(frozenset(), frozenset())
    _age(folder.heartbeat, 0)
    assert recovery.lost_cause(analysis, gone, settings, api_now) is None
    _age(folder.heartbeat, settings.lost_after_s + 40)
    assert recovery.lost_cause(analysis, gone, settings, api_now) == "message lost"


def test_old_uploads_are_told_by_the_storage_clock(tmp_path, monkeypatch):
    from app.core.storage import Storage

    storage = Storage(tmp_path / "data")
    fresh, old = storage.new_tmp_dir(), storage.new_tmp_dir()
    _age(old, 7200)
    monkeypatch.setattr(time, "time", lambda: os.stat(fresh).st_mtime + 7200)  # 2 h ahead
    assert storage.clean_tmp(3600) == 1
    assert fresh.exists() and not old.exists()
