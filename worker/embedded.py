"""The embedded worker `coach serve` starts: a local Celery worker subprocess, no Redis, no Docker.

The broker is kombu's filesystem transport and the result store Celery's file backend, both
under ``<data_dir>/celery`` (:mod:`worker.settings`), unless ``COACH_BROKER_URL`` names a real
broker. The same task code runs as in the scaled-out deployment.

Limits of the filesystem transport, and what covers them: it hands a message to one consumer
and deletes it from the folder, so a worker killed with SIGKILL loses the message it held (a
warm stop puts unacknowledged messages back). The analysis folder keeps every finished stage,
so enqueuing the analysis again resumes it: the API's recovery does so once the analysis'
heartbeat is ``lost_after_s`` old (``app.core.recovery``), and ``coach serve`` at start.
"""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
from pathlib import Path

from worker import celery_app
from worker.settings import WorkerSettings

log = logging.getLogger("coach.worker")

_process: subprocess.Popen | None = None
_log_file = None


def start(
    data_dir: str | os.PathLike,
    concurrency: int = 1,
    *,
    loglevel: str = "INFO",
    env: dict | None = None,
) -> subprocess.Popen:
    """Start one local worker subprocess for ``data_dir``; return its process handle.

    Also configures this process' Celery app for the same data directory, so
    :func:`worker.celery_app.enqueue` publishes where the worker consumes. Its output goes to
    ``<data_dir>/logs/worker.log``. Calling it again while the worker runs returns the same one.
    """
    global _process, _log_file
    if _process is not None and _process.poll() is None:
        return _process
    if concurrency < 1:
        raise ValueError(f"concurrency must be >= 1, got {concurrency}")
    data_dir = Path(data_dir).expanduser().resolve()
    child_env = dict(os.environ if env is None else env)
    child_env["COACH_DATA_DIR"] = str(data_dir)
    settings = WorkerSettings.from_env(child_env)
    celery_app.configure(settings)
    logs = data_dir / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    _log_file = open(logs / "worker.log", "ab")  # noqa: SIM115 - lives as long as the worker
    # The child must import this project the way the parent does.
    root = str(Path(__file__).resolve().parents[1])
    child_env["PYTHONPATH"] = os.pathsep.join(
        p for p in (root, child_env.get("PYTHONPATH", "")) if p
    )
    cmd = [
        sys.executable,
        "-m",
        "celery",
        "-A",
        "worker.celery_app",
        "worker",
        "--concurrency",
        str(concurrency),
        "--loglevel",
        loglevel,
        "--hostname",
        f"embedded-{os.getpid()}@%h",
        # No other worker shares the filesystem broker's control folder in embedded mode.
        "--without-gossip",
        "--without-mingle",
    ]
    _process = subprocess.Popen(
        cmd,
        env=child_env,
        stdout=_log_file,
        stderr=subprocess.STDOUT,
        cwd=root,
        start_new_session=True,  # stop() signals the worker and its pool children together
        preexec_fn=_die_with_parent,
    )
    log.info(
        "worker.embedded_started pid=%s data_dir=%s broker=%s",
        _process.pid,
        data_dir,
        settings.broker_url,
    )
    return _process


#: Niceness of the embedded worker: its stages use every core, and the API in the parent
#: process must still answer a status poll at once.
WORKER_NICENESS = 10


def _die_with_parent() -> None:
    """In the child before exec: get SIGTERM when the server process dies (Linux), and yield
    the CPU to the API (:data:`WORKER_NICENESS`).

    stop() covers a clean shutdown; this covers a killed server, which would otherwise leave
    an orphan worker consuming the queue. Elsewhere the call is skipped.
    """
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGTERM)  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass
    os.nice(WORKER_NICENESS)


def running() -> bool:
    return _process is not None and _process.poll() is None


def stop(timeout: float = 10.0) -> None:
    """Stop the worker: a warm shutdown (SIGTERM) for ``timeout`` s, then SIGTERM to its pool
    processes, then SIGKILL.

    A warm shutdown lets the current stage finish only within ``timeout``; anything cut short is
    resumed from its last finished stage when the analysis is enqueued again.
    """
    global _process, _log_file
    proc, _process = _process, None
    if proc is not None and proc.poll() is None:
        try:
            # SIGTERM to the main process only: it stops consuming, waits for its pool's
            # running tasks and puts unacknowledged messages back.
            proc.send_signal(signal.SIGTERM)
            proc.wait(timeout)
        except subprocess.TimeoutExpired:
            _kill_group(proc)
        except ProcessLookupError:
            pass
        log.info("worker.embedded_stopped pid=%s code=%s", proc.pid, proc.returncode)
    if _log_file is not None:
        _log_file.close()
        _log_file = None


def _kill_group(proc: subprocess.Popen) -> None:
    # SIGTERM first: a running stage unwinds (worker.lease), so being stopped does not count
    # as a run that killed its worker; SIGKILL whatever is left.
    for sig, wait_s in ((signal.SIGTERM, 3), (signal.SIGKILL, 5)):
        try:
            os.killpg(proc.pid, sig)
            proc.wait(wait_s)
            return
        except subprocess.TimeoutExpired:
            continue
        except ProcessLookupError:
            return
