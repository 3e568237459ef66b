"""worker.lease: the heartbeat, duplicate entry messages, and stages that kill their worker.

A crash is a process that dies inside :func:`lease.attempt` without running any Python code
on the way out; the tests make one with ``os._exit`` in a forked child.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import time
from pathlib import Path

import pytest

from tests.worker import fake_pipeline
from worker import jobs, lease
from worker.contract import AnalysisFolder, AnalysisJob

FORK = multiprocessing.get_context("fork")


@pytest.fixture
def job(tmp_path: Path) -> AnalysisJob:
    ref, video = tmp_path / "reference.bvh", tmp_path / "video.mp4"
    ref.write_bytes(b"HIERARCHY reference")
    video.write_bytes(b"fake video bytes")
    return AnalysisJob(
        analysis_id="a1", reference_path=str(ref), video_path=str(video),
        work_dir=str(tmp_path / "analysis"), settings={"fake_frames": 6},
    )  # fmt: skip


def _crash_inside(work_dir: str, output: Path) -> None:
    with lease.attempt(work_dir, output, max_crashes=2):
        os._exit(1)  # no finally, no atexit: what the OOM killer leaves


def _run_child(target, *args) -> int:
    child = FORK.Process(target=target, args=args)
    child.start()
    child.join(10)
    return child.exitcode


def test_a_stage_that_killed_its_worker_twice_is_refused(tmp_path):
    output = AnalysisFolder(tmp_path).prepared
    for _ in range(2):
        assert _run_child(_crash_inside, str(tmp_path), output) == 1
    with pytest.raises(lease.RepeatedCrash, match="stopped its worker twice"):
        with lease.attempt(tmp_path, output, max_crashes=2):
            pytest.fail("a third run must not start")


def _killed_by_a_deploy(work_dir: Path, output: Path, *, told: bool) -> None:
    """A run SIGKILLed mid-stage, its master told to stop first (``told``) or not."""
    started = work_dir / "started"
    started.unlink(missing_ok=True)
    child = FORK.Process(target=_sigterm_inside, args=(str(work_dir), output, str(started), False))
    child.start()
    deadline = time.monotonic() + 10
    while not started.exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    if told:
        lease.note_stopping(work_dir, child.pid)
    os.kill(child.pid, signal.SIGKILL)
    child.join(10)


def test_runs_killed_after_their_worker_was_told_to_stop_are_not_crashes(tmp_path):
    output = AnalysisFolder(tmp_path).prepared
    for _ in range(3):  # three deploys in the same stage
        _killed_by_a_deploy(tmp_path, output, told=True)
    with lease.attempt(tmp_path, output, max_crashes=2):
        pass  # runs: none of the three counted
    for _ in range(2):  # the OOM killer gives no notice
        _killed_by_a_deploy(tmp_path, output, told=False)
    with pytest.raises(lease.RepeatedCrash), lease.attempt(tmp_path, output, max_crashes=2):
        pass


def test_a_notice_older_than_the_run_does_not_excuse_it(tmp_path):
    """A notice left by a worker stopped earlier (its run finished within the grace period)
    must not excuse a later crash of a run that happens to have the same name."""
    output = AnalysisFolder(tmp_path).prepared
    _killed_by_a_deploy(tmp_path, output, told=False)
    _, runner = lease._read_ledger(AnalysisFolder(tmp_path).attempts(output))
    notice = AnalysisFolder(tmp_path).stopping(runner)
    notice.parent.mkdir(exist_ok=True)
    notice.touch()
    os.utime(notice, (time.time() - 60,) * 2)
    _killed_by_a_deploy(tmp_path, output, told=False)
    with pytest.raises(lease.RepeatedCrash), lease.attempt(tmp_path, output, max_crashes=2):
        pass


def test_repeated_crash_survives_celery_storing_it():
    exc = lease.RepeatedCrash.after(2)
    assert str(type(exc)(*exc.args)) == str(exc)  # rebuilt from its args, as Celery does


def test_runs_that_come_back_are_not_crashes(tmp_path):
    output = AnalysisFolder(tmp_path).prepared
    for _ in range(3):
        with pytest.raises(ValueError), lease.attempt(tmp_path, output, max_crashes=2):
            raise ValueError("an engine error, a retry: the process saw it end")
        with lease.attempt(tmp_path, output, max_crashes=2):
            pass
    assert not AnalysisFolder(tmp_path).attempts(output).exists()


def _sigterm_inside(work_dir: str, output: Path, started: str, handle: bool) -> None:
    if handle:
        lease.interrupt_on_sigterm()
    with lease.attempt(work_dir, output, max_crashes=2):
        Path(started).touch()
        time.sleep(10)


@pytest.mark.parametrize("handle", [True, False])
def test_sigterm_unwinds_the_running_stage(tmp_path, handle):
    """How Celery cancels a task when it loses the broker: not a crash once handled."""
    output, started = AnalysisFolder(tmp_path).prepared, tmp_path / "started"
    child = FORK.Process(target=_sigterm_inside, args=(str(tmp_path), output, str(started), handle))
    child.start()
    deadline = time.monotonic() + 10
    while not started.exists() and time.monotonic() < deadline:
        time.sleep(0.01)
    os.kill(child.pid, signal.SIGTERM)
    child.join(10)
    assert child.exitcode != 0
    assert AnalysisFolder(tmp_path).attempts(output).exists() is not handle


def test_heartbeat_is_renewed_while_running_and_held_through_a_countdown(tmp_path):
    folder = AnalysisFolder(tmp_path)
    assert folder.heartbeat_age_s() is None
    with lease.Heartbeat(tmp_path, "root-1", every_s=0.05) as heartbeat:
        os.utime(folder.heartbeat, (time.time() - 100, time.time() - 100))
        time.sleep(0.3)
        assert folder.heartbeat_age_s() < 0.2
        heartbeat.hold(30)
    assert -31 < folder.heartbeat_age_s() < -29  # the lease runs to the retry's end


def test_a_second_entry_message_for_a_live_run_is_a_duplicate(tmp_path):
    with lease.Heartbeat(tmp_path, "root-1", every_s=1):
        assert lease.running_elsewhere(tmp_path, "root-2", lost_after_s=60)
        assert not lease.running_elsewhere(tmp_path, "root-1", lost_after_s=60)  # redelivered
    stale = time.time() - 61
    os.utime(AnalysisFolder(tmp_path).heartbeat, (stale, stale))
    assert not lease.running_elsewhere(tmp_path, "root-2", lost_after_s=60)
    assert not lease.running_elsewhere(tmp_path / "never-ran", "root-2", lost_after_s=60)


@pytest.mark.parametrize("clock_off_s", [-600.0, 600.0])
def test_the_lease_holds_on_a_worker_whose_clock_is_off(tmp_path, monkeypatch, clock_off_s):
    """The lease is set and read on the storage's clock: a worker 10 min off still sees a
    live run as live, and still holds the lease through a retry's countdown."""
    real = time.time
    monkeypatch.setattr(time, "time", lambda: real() + clock_off_s)
    with lease.Heartbeat(tmp_path, "root-1", every_s=1) as heartbeat:
        assert lease.running_elsewhere(tmp_path, "root-2", lost_after_s=60)
        heartbeat.hold(30)
    assert -31 < AnalysisFolder(tmp_path).heartbeat_age_s() < -29


def test_repeated_crash_fails_the_analysis_and_stops_its_other_messages(job):
    jobs.run_prepare(job, pipeline=fake_pipeline)
    paths = AnalysisFolder(job.work_dir)
    for _ in range(2):
        assert _run_child(_crash_inside, job.work_dir, paths.chunk(0, 2)) == 1
    with pytest.raises(lease.RepeatedCrash):
        jobs.run_all(job, 2, pipeline=fake_pipeline)
    status = jobs.read_status(job.work_dir)
    assert status["state"] == "failed" and "stopped its worker twice" in status["error"]
    assert paths.cancel.exists()
    with pytest.raises(jobs.Cancelled):  # a sibling chunk's message, delivered later
        jobs.run_candidates(job, 1, 2, pipeline=fake_pipeline)
    assert jobs.read_status(job.work_dir)["state"] == "failed"
    assert not jobs.start(job)  # and a late entry message
