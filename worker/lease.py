"""Who runs an analysis, and whether its stages kill their worker: files in its folder.

Two questions the broker cannot answer reliably (a Redis restart forgets every message; a
SIGKILLed worker's message waits out the visibility timeout, 2 h by default), answered through
:class:`worker.contract.AnalysisFolder`:

- *Is anybody running the analysis?* While any of its tasks runs, :class:`Heartbeat` renews the
  ``heartbeat`` file every ``heartbeat_s``. One older than ``lost_after_s`` means nobody does:
  the API's recovery (``app.core.recovery``) then queues the analysis again, and it resumes
  from its last finished stage. So re-queueing is always safe, the entry task drops a message
  for an analysis another entry task is running (:func:`running_elsewhere`). The heartbeat's
  time is set and read on the storage's clock (``worker.contract.storage_now``), never a
  machine's own, so the lease holds between machines whose clocks differ.
- *Does a stage kill its worker?* :func:`attempt` counts the runs of a stage that started and
  never came back (the process was OOM-killed or crashed: no Python code ran to say so). At
  ``max_crashes`` the stage fails with :class:`RepeatedCrash` instead of running again, so a
  poison job stops instead of taking down worker after worker. A run that ends any way Python
  sees does not count: a result, an error, a retry, or SIGTERM, which is how Celery cancels a
  task when it loses the broker (:func:`interrupt_on_sigterm`). Nor does a run SIGKILLed
  after its worker was told to stop (a deploy: :func:`note_stopping`).
"""

from __future__ import annotations

import json
import logging
import os
import signal
import socket
import threading
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from types import FrameType

from worker.contract import AnalysisFolder

log = logging.getLogger("worker.lease")


class RepeatedCrash(Exception):
    """A stage's runs killed their worker process ``max_crashes`` times: failed for good."""

    @classmethod
    def after(cls, crashes: int) -> RepeatedCrash:
        # The message is the only argument, so Celery can store and rebuild the exception.
        times = {1: "once", 2: "twice"}.get(crashes, f"{crashes} times")
        return cls(
            f"the analysis stopped its worker {times} (out of memory or a crash); it will not "
            "be retried — try a shorter or smaller video"
        )


class Interrupted(BaseException):
    """SIGTERM reached a pool process mid-task (Celery cancelled the task).

    A BaseException, so that no handler of the task's own errors records it as the analysis'
    failure: the task is cut short, not wrong, and recovery runs it again.
    """


def _write_atomic(path: Path, text: str) -> None:
    # Readers must never see half a file; these are a few bytes, so no fsync.
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.name}.{uuid.uuid4().hex[:8]}.tmp")
    tmp.write_text(text)
    os.replace(tmp, path)


def _touch(path: Path, ahead_s: float = 0.0) -> None:
    """Renew ``path``'s modification time to the storage's now (plus ``ahead_s``): the
    storage's clock, not this machine's, which may differ from the API's."""
    try:
        os.utime(path, None)
        if ahead_s:
            when = path.stat().st_mtime + ahead_s
            os.utime(path, (when, when))
    except OSError:
        pass  # the folder was removed (analysis deleted): nothing left to keep alive


class Heartbeat:
    """Context manager: renews the analysis' heartbeat every ``every_s`` while its body runs.

    ``owner`` is the entry task's id (the Celery root id): a redelivery of the same run
    carries the same one, a re-queue by recovery a new one.
    """

    def __init__(self, work_dir: str | os.PathLike, owner: str, every_s: float) -> None:
        self.path = AnalysisFolder(work_dir).heartbeat
        self.owner, self.every_s = owner, every_s
        self.hold_s = 0.0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._beat, name="coach-heartbeat", daemon=True)

    def hold(self, seconds: float) -> None:
        """Keep the lease ``seconds`` past the exit: a retry's countdown, during which the
        message waits in a worker and nothing runs, must not look like a lost analysis."""
        self.hold_s = seconds

    def __enter__(self) -> Heartbeat:
        owner = {"owner": self.owner, "host": socket.gethostname(), "pid": os.getpid()}
        try:
            _write_atomic(self.path, json.dumps(owner))
        except OSError:
            pass  # the task reports the missing folder itself
        self._thread.start()
        return self

    def _beat(self) -> None:
        while not self._stop.wait(self.every_s):
            _touch(self.path)

    def __exit__(self, *exc_info: object) -> None:
        self._stop.set()
        self._thread.join()
        _touch(self.path, self.hold_s)


def running_elsewhere(work_dir: str | os.PathLike, owner: str, lost_after_s: float) -> bool:
    """Whether another entry task (not ``owner``) renewed the analysis' heartbeat within
    ``lost_after_s``: then a new entry message is a duplicate of a live run."""
    folder = AnalysisFolder(work_dir)
    age = folder.heartbeat_age_s()
    if age is None or age >= lost_after_s:
        return False
    try:
        return json.loads(folder.heartbeat.read_text()).get("owner") != owner
    except (OSError, ValueError, AttributeError):
        return False  # unreadable: run it; a duplicate run is safe, a dropped one is not


def runner_id(pid: int | None = None) -> str:
    """Who runs a stage: this machine and the pool process ``pid`` (default: this one). A
    worker's master names its pool processes the same way (:func:`note_stopping`)."""
    return f"{socket.gethostname()}-{os.getpid() if pid is None else pid}"


def note_stopping(work_dir: str | os.PathLike, pid: int) -> None:
    """Record that the worker running a stage of the analysis in pool process ``pid`` was
    told to stop (a deploy's SIGTERM to its master). A deploy SIGKILLs what has not finished
    after its grace period (docker: 10 s): :func:`attempt` then does not count that run as
    one that killed its worker."""
    try:
        _write_atomic(AnalysisFolder(work_dir).stopping(runner_id(pid)), "")
    except OSError:
        pass  # the folder was removed: nothing will run again


def _read_ledger(path: Path) -> tuple[int, str]:
    """A crash ledger: how many runs started and never came back, and who ran the last."""
    try:
        count, _, runner = path.read_text().strip().partition(" ")
        return int(count or 0), runner
    except (OSError, ValueError):
        return 0, ""


def _stopped_by_deploy(folder: AnalysisFolder, ledger: Path, runner: str) -> bool:
    """Whether the last run in ``ledger`` was told to stop after it started: then its death
    was the deploy's SIGKILL, not the stage's doing. Consumes the notice."""
    notice = folder.stopping(runner)
    try:
        told_after_start = notice.stat().st_mtime >= ledger.stat().st_mtime
        notice.unlink()
    except OSError:
        return False
    return told_after_start


@contextmanager
def attempt(work_dir: str | os.PathLike, output: Path, *, max_crashes: int) -> Iterator[None]:
    """Count one run of the stage that writes ``output`` until the body returns or raises.

    A run that never came back counts as a crash, unless its worker was told to stop while
    it ran (:func:`note_stopping`): a deploy's SIGKILL looks the same as the OOM killer's, only
    the SIGTERM before it tells them apart.

    Raises
    ------
    RepeatedCrash
        ``max_crashes`` earlier runs of the stage started and never came back.
    """
    folder = AnalysisFolder(work_dir)
    ledger = folder.attempts(output)
    crashes, runner = _read_ledger(ledger)
    if crashes and runner and _stopped_by_deploy(folder, ledger, runner):
        log.warning("stage run cut short by a worker shutdown, not counted as a crash: %s",
                    output.name)  # fmt: skip
        crashes -= 1
    if crashes >= max_crashes:
        raise RepeatedCrash.after(crashes)
    _write_atomic(ledger, f"{crashes + 1} {runner_id()}")
    try:
        yield
    finally:
        # The run came back (whatever it ended with): it was no crash.
        ledger.unlink(missing_ok=True)


def interrupt_on_sigterm() -> None:
    """In a pool process: turn SIGTERM into :class:`Interrupted`, so the running stage's
    ``finally`` blocks run (its :func:`attempt` is not counted as a crash) before it exits."""

    def handler(signum: int, frame: FrameType | None) -> None:
        raise Interrupted(f"signal {signum}")

    signal.signal(signal.SIGTERM, handler)
