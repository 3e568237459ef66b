"""Recovery that needs no one (issue 26): real redis-server, real workers, the API's reflector.

Each test creates the analysis the way the create route does (folder, committed row, publish)
and runs the API's :class:`~app.core.reflect.Reflector` with recovery
(:func:`app.core.recovery.recover`), on short heartbeat settings so that a lost analysis is
noticed in seconds rather than a minute; the Redis visibility timeout keeps its default (2 h),
so nothing here is rescued by Redis redelivering on its own.
"""

from __future__ import annotations

import signal
import time
from dataclasses import dataclass
from functools import partial
from pathlib import Path

import pytest
from sqlalchemy.orm import sessionmaker

from app import crud
from app.core import recovery
from app.core.config import Settings
from app.core.db import make_engine, make_sessionmaker, run_migrations
from app.core.queue import CeleryQueue, analysis_job
from app.core.reflect import Reflector
from app.models import TERMINAL_STATES, Analysis, Reference
from tests.integration.conftest import CASE, Workers, result_without_timing
from tests.worker import fake_pipeline
from worker import celery_app, jobs
from worker.contract import AnalysisFolder, AnalysisJob
from worker.settings import WorkerSettings

pytestmark = pytest.mark.integration

FAKE_APP = "tests.worker.fake_app"
FRAMES = 12
#: Stage 3 chunks of 6 frames x 0.4 s: long enough to be caught in the middle.
SECONDS_PER_FRAME = 0.4
#: The API's side of the lease, short: lost after 3 s without a heartbeat (workers beat every
#: 0.5 s), a missing message after 2 s.
LOST_AFTER_S, PUBLISH_GRACE_S, HEARTBEAT_S = 3.0, 2.0, 0.5

CRASH_REASON = (
    "the analysis stopped its worker twice (out of memory or a crash); it will not be "
    "retried — try a shorter or smaller video"
)


@dataclass
class Service:
    """The API's side: its database, settings and queue, and a running reflector."""

    settings: Settings
    sessions: sessionmaker
    club_id: int
    performer_id: int
    reference_id: int

    def create(self, name: str, video: Path, *, publish: bool = True) -> str:
        """The create route's steps: folder and committed row, then the publish, unless the
        API "dies" between the two (``publish=False``)."""
        work_dir = self.settings.data_dir / "analyses" / name
        work_dir.mkdir(parents=True)
        with self.sessions() as session:
            analysis = Analysis(
                id=name, club_id=self.club_id, performer_id=self.performer_id,
                reference_id=self.reference_id, video_path=str(video), work_dir=str(work_dir),
                status="queued",
            )  # fmt: skip
            session.add(analysis)
            session.commit()
            if publish:
                reference = session.get(Reference, self.reference_id)
                analysis.task_id = CeleryQueue().enqueue(analysis_job(analysis, reference))
                session.commit()
        return name

    def row(self, analysis_id: str) -> Analysis:
        with self.sessions() as session:
            return session.get(Analysis, analysis_id)

    def wait_final(
        self, analysis_id: str, timeout: float, workers: Workers, *, revive=None
    ) -> Analysis:
        """Wait for the row to reach a final state; ``revive()`` runs between polls."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            row = self.row(analysis_id)
            if row.status in TERMINAL_STATES:
                return row
            if revive is not None:
                revive()
            time.sleep(0.1)
        raise AssertionError(
            f"not final after {timeout} s: {row.status} {row.message!r} "
            f"recoveries={row.recoveries}\n{workers.logs()[-4000:]}"
        )


@pytest.fixture
def service(tmp_path, worker_env, workers) -> Service:
    worker_env.update(
        COACH_HEARTBEAT_S=str(HEARTBEAT_S),
        COACH_LOST_AFTER_S=str(LOST_AFTER_S),
        FAKE_FRAMES=str(FRAMES),
        FAKE_SECONDS_PER_FRAME=str(SECONDS_PER_FRAME),
    )
    settings = Settings(
        data_dir=tmp_path / "data",
        reflect_interval_s=0,  # the fixture runs its own reflector, with recovery
        lost_after_s=LOST_AFTER_S,
        publish_grace_s=PUBLISH_GRACE_S,
    )
    engine = make_engine(settings.sqlalchemy_url)
    run_migrations(engine)
    sessions = make_sessionmaker(engine)
    with sessions() as session:
        club = crud.create_club(session, name="club")
        session.commit()
        performer = crud.create_user(
            session, club_id=club.id, role="performer", email="p@club.org", display_name="P"
        )
        reference = crud.create_reference(session, club_id=club.id, name="swing")
        reference.bvh_path = str(CASE / "reference.bvh")
        session.commit()
        ids = club.id, performer.id, reference.id
    recover = partial(recovery.recover, settings=settings, queue=CeleryQueue())
    reflector = Reflector(sessions, lambda analysis: None, 0.2, recover)
    reflector.start()
    yield Service(settings, sessions, *ids)
    reflector.stop()
    engine.dispose()


def expected_result(tmp_path: Path, video: Path, analysis_id: str) -> dict:
    """The result of an uninterrupted run of the same job, in this process."""
    job = AnalysisJob(
        analysis_id=analysis_id,
        reference_path=str(CASE / "reference.bvh"),
        video_path=str(video),
        work_dir=str(tmp_path / "expected"),
        settings={"fake_frames": FRAMES},
    )
    jobs.run_all(job, 2, pipeline=fake_pipeline)
    return result_without_timing(AnalysisFolder(job.work_dir).result)


def wait_mid_stage_3(work_dir: str, workers: Workers, timeout: float = 60) -> None:
    """Until the first stage-3 chunk is about a third done (2 of its 6 frames)."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        status = jobs.read_status(work_dir) or {}
        if status.get("stage") == "candidates" and status.get("progress", 0) > 0.44:
            return
        time.sleep(0.02)
    raise AssertionError(f"stage 3 never started: {status}\n{workers.logs()[-3000:]}")


def assert_resumed_and_identical(service, workers, tmp_path, video, name) -> None:
    paths = AnalysisFolder(service.row(name).work_dir)
    assert result_without_timing(paths.result) == expected_result(tmp_path, video, name)
    # Resumed from the last finished stage: prepare ran once in all.
    assert workers.logs().count(f"analysis.stage_done stage=prepare analysis_id={name}") == 1


def test_redis_restart_mid_stage_3_completes_identically(
    worker_env, workers, service, own_redis, tmp_path, short_video
):
    worker_env.update(COACH_BROKER_URL=own_redis.url, COACH_RESULT_BACKEND=own_redis.url)
    celery_app.configure(WorkerSettings.from_env(worker_env))
    workers.start(app=FAKE_APP)
    name = service.create("a-redis", short_video)
    work_dir = service.row(name).work_dir
    wait_mid_stage_3(work_dir, workers)
    restarted = time.monotonic()
    own_redis.restart()  # every message, queued or unacknowledged, is gone
    # The running chunk is cut short (its progress publish fails; Celery also cancels it with
    # SIGTERM) and unwinds: its run is not counted as one that killed its worker. Recovery runs
    # it again only lost_after_s later.
    ledgers = AnalysisFolder(work_dir).work_dir / "attempts"
    deadline = time.monotonic() + LOST_AFTER_S - 0.5
    while ledgers.is_dir() and any(ledgers.iterdir()):
        assert time.monotonic() < deadline, (
            f"the cancelled chunk counts as a crash\n{workers.logs()[-3000:]}"
        )
        time.sleep(0.05)
    row = service.wait_final(name, 90, workers)
    elapsed = time.monotonic() - restarted
    print(f"\nredis restart -> done: {elapsed:.1f} s")
    assert row.status == "done", (row.status, row.error)
    assert row.recoveries == 1
    assert_resumed_and_identical(service, workers, tmp_path, short_video, name)


def test_publish_that_never_happened_is_made_by_recovery(
    worker_env, workers, service, tmp_path, short_video
):
    workers.start(app=FAKE_APP)
    created = time.monotonic()
    name = service.create("a-unpublished", short_video, publish=False)  # the API died here
    row = service.wait_final(name, 60, workers)
    print(f"\nunpublished upload -> done: {time.monotonic() - created:.1f} s")
    assert row.status == "done", (row.status, row.error)
    assert row.recoveries == 1 and row.task_id
    assert result_without_timing(row.result_path) == expected_result(tmp_path, short_video, name)


def test_sigkilled_worker_is_replaced_long_before_the_visibility_timeout(
    worker_env, workers, service, tmp_path, short_video
):
    assert WorkerSettings.from_env(worker_env).visibility_timeout_s == 7200  # the default
    first = workers.start(app=FAKE_APP, name="first")
    name = service.create("a-sigkill", short_video)
    wait_mid_stage_3(service.row(name).work_dir, workers)
    # The broker says which of its stage messages a worker holds, and since when.
    broker = CeleryQueue().broker_tasks()
    held = {i for i in broker.held if i.startswith(service.row(name).task_id)}
    assert held and all(0 <= time.time() - broker.taken_at[i] < 60 for i in held), broker
    killed = time.monotonic()
    workers.kill(first)  # no warm shutdown, no ack: its message stays unacknowledged for 2 h
    workers.start(app=FAKE_APP, name="second")
    row = service.wait_final(name, 120, workers)
    elapsed = time.monotonic() - killed
    print(f"\nworker SIGKILL -> done: {elapsed:.1f} s")
    assert row.status == "done", (row.status, row.error)
    assert elapsed < 120 and row.recoveries == 1
    assert_resumed_and_identical(service, workers, tmp_path, short_video, name)


@pytest.mark.parametrize("die", ["process", "worker"])
def test_a_job_that_kills_its_worker_twice_fails_with_the_reason(
    worker_env, workers, service, short_video, die
):
    """``process``: the OOM killer's usual victim, the pool process; Celery hands its message
    out again at once. ``worker``: the whole worker (a lost machine); recovery queues the
    analysis again each time."""
    worker_env.update(FAKE_DIE=die, COACH_CHUNKS="1")
    procs = [workers.start(app=FAKE_APP)]

    def revive() -> None:  # a supervisor restarting dead workers (compose: restart policy)
        if procs[-1].poll() is not None:
            procs.append(workers.start(app=FAKE_APP))

    name = service.create(f"a-poison-{die}", short_video)
    row = service.wait_final(name, 90, workers, revive=revive)
    assert row.status == "failed" and row.error == CRASH_REASON, (row.status, row.error)
    assert AnalysisFolder(row.work_dir).cancel.exists()  # late messages of it stop
    logs = workers.logs()
    assert f"analysis.stage_done stage=candidates analysis_id={name}" not in logs
    # Each run reached stage 3 and died there: two deaths, then the third run was refused.
    if die == "process":
        assert logs.count("exited with 'signal 9 (SIGKILL)'") == 2 and len(procs) == 1
    else:
        assert len(procs) == 3 and row.recoveries == 2


def test_deploys_that_sigkill_a_stage_twice_do_not_fail_the_analysis(
    worker_env, workers, service, short_video
):
    """A deploy stops a worker as docker does: SIGTERM to the master, SIGKILL of the whole
    container when the grace period ends with the stage still running. Twice in stage 3:
    unlike the OOM killer's two SIGKILLs (the test above), these are not crashes."""
    worker_env.update(COACH_CHUNKS="1")
    name = service.create("a-deploys", short_video)
    work_dir = service.row(name).work_dir
    ledger = AnalysisFolder(work_dir).attempts(AnalysisFolder(work_dir).chunk(0, 1))
    last_run = ""
    for deploy in range(2):
        proc = workers.start(app=FAKE_APP, name=f"release-{deploy}")
        wait_new_run(ledger, last_run, workers)
        last_run = ledger.read_text()
        time.sleep(2 * SECONDS_PER_FRAME)  # well into the chunk
        proc.send_signal(signal.SIGTERM)  # the master waits for the running stage...
        time.sleep(0.5)
        workers.kill(proc)  # ...which the grace period does not outlast
    workers.start(app=FAKE_APP, name="release-2")
    row = service.wait_final(name, 120, workers)
    assert row.status == "done", (row.status, row.error)
    assert row.recoveries == 2
    assert workers.logs().count("not counted as a crash") == 2


def wait_new_run(ledger: Path, last_run: str, workers: Workers, timeout: float = 60) -> None:
    """Until a run of the stage other than ``last_run`` (a ledger's text) has started."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if ledger.read_text() not in ("", last_run):
                return
        except OSError:
            pass
        time.sleep(0.02)
    raise AssertionError(f"no new run of {ledger.name}\n{workers.logs()[-3000:]}")
