"""Real redis-server and real `celery worker` subprocesses for the integration tests.

Every process a fixture starts is stopped by its finalizer (SIGTERM, then SIGKILL of its
process group), so a failing test leaves nothing running.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.conftest import BENCH_CASES, REPO
from worker import celery_app, jobs
from worker.contract import AnalysisJob
from worker.settings import WorkerSettings

CASE = BENCH_CASES / "P1_warp_64_29"
REDIS_SERVER = shutil.which("redis-server") or "/usr/bin/redis-server"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop_process(proc: subprocess.Popen, timeout: float = 10.0) -> None:
    if proc.poll() is not None:
        return
    try:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout)
    except subprocess.TimeoutExpired:
        pass
    try:
        os.killpg(proc.pid, signal.SIGKILL)  # pool children too
    except ProcessLookupError:
        pass
    proc.wait(5)


class RedisServer:
    """A redis-server subprocess on one port, without persistence (like the compose file's):
    :meth:`restart` gives an empty server on the same address, as a Redis restart does."""

    def __init__(self, workdir: Path, port: int | None = None):
        self.workdir, self.port = workdir, port or free_port()
        self.proc: subprocess.Popen | None = None

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self) -> RedisServer:
        import redis

        self.proc = subprocess.Popen(
            [
                REDIS_SERVER, "--port", str(self.port), "--bind", "127.0.0.1",
                "--save", "", "--appendonly", "no", "--dir", str(self.workdir),
            ],
            stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL,
            start_new_session=True,
        )  # fmt: skip
        client = redis.Redis(port=self.port)
        deadline = time.monotonic() + 10
        while True:
            try:
                client.ping()
                return self
            except redis.exceptions.ConnectionError:
                if time.monotonic() > deadline or self.proc.poll() is not None:
                    raise RuntimeError("redis-server did not start") from None
                time.sleep(0.05)

    def restart(self) -> None:
        """SIGKILL the server (it loses every message) and start an empty one."""
        os.killpg(self.proc.pid, signal.SIGKILL)
        self.proc.wait(5)
        self.start()

    def stop(self) -> None:
        if self.proc is not None:
            stop_process(self.proc)


def _require_redis() -> None:
    if not os.path.exists(REDIS_SERVER):
        pytest.skip("redis-server is not installed (apt-get install redis-server)")


@pytest.fixture(scope="session")
def redis_url(tmp_path_factory) -> str:
    _require_redis()
    server = RedisServer(tmp_path_factory.mktemp("redis"))
    try:
        yield server.start().url
    finally:
        server.stop()


@pytest.fixture
def own_redis(tmp_path) -> RedisServer:
    """A redis-server of this test alone (it may restart it)."""
    _require_redis()
    (tmp_path / "redis").mkdir()
    server = RedisServer(tmp_path / "redis")
    try:
        yield server.start()
    finally:
        server.stop()


class Workers:
    """Starts `celery worker` subprocesses sharing one environment; stops them all at the end."""

    def __init__(self, env: dict, log_dir: Path):
        self.env, self.log_dir, self.procs = env, log_dir, []

    def start(
        self, concurrency: int = 1, name: str | None = None, app: str = "worker.celery_app"
    ) -> subprocess.Popen:
        """A worker process of ``app`` (``tests.worker.fake_app``: the same tasks over the fake
        engine)."""
        name = name or f"w{len(self.procs)}"
        log = open(self.log_dir / f"{name}.log", "ab")  # noqa: SIM115 - closed with the process
        proc = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "celery",
                "-A",
                app,
                "worker",
                "--concurrency",
                str(concurrency),
                "--loglevel",
                "INFO",
                "--hostname",
                f"{name}-{os.getpid()}@%h",
                "--without-gossip",
                "--without-mingle",
            ],
            env=self.env,
            cwd=REPO,
            stdout=log,
            stderr=subprocess.STDOUT,
            start_new_session=True,
        )
        log.close()
        self.procs.append(proc)
        return proc

    def kill(self, proc: subprocess.Popen) -> None:
        """SIGKILL the worker and its pool children: no warm shutdown, no ack, no requeue."""
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(5)

    def logs(self) -> str:
        return "\n".join(p.read_text(errors="replace") for p in sorted(self.log_dir.glob("*.log")))

    def stop_all(self) -> None:
        for proc in self.procs:
            stop_process(proc)


@pytest.fixture
def worker_env(tmp_path, redis_url) -> dict:
    """Environment of the workers and of this process' Celery app (configured here)."""
    data = tmp_path / "data"
    env = dict(os.environ)
    env.update(
        COACH_BROKER_URL=redis_url,
        COACH_RESULT_BACKEND=redis_url,
        COACH_DATA_DIR=str(data),
        PYTHONPATH=os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH", "")) if p),
        PYOPENGL_PLATFORM="egl",
        COACH_CHUNKS="2",
    )
    return env


@pytest.fixture
def workers(worker_env, tmp_path, redis_url):
    import redis

    redis.Redis.from_url(redis_url).flushdb()  # each test starts with an empty queue
    logs = tmp_path / "logs"
    logs.mkdir()
    pool = Workers(worker_env, logs)
    celery_app.configure(WorkerSettings.from_env(worker_env))
    yield pool
    pool.stop_all()
    celery_app.configure(WorkerSettings.from_env())


def wait_for(
    work_dir: str | Path,
    predicate: Callable[[dict], bool],
    timeout: float,
    workers: Workers | None = None,
) -> dict:
    deadline = time.monotonic() + timeout
    status: dict = {}
    while time.monotonic() < deadline:
        status = jobs.read_status(work_dir) or {}
        if predicate(status):
            return status
        time.sleep(0.05)
    logs = workers.logs()[-4000:] if workers else ""
    raise AssertionError(f"timed out after {timeout} s; last status {status}\n{logs}")


def finished(status: dict) -> bool:
    return status.get("state") in jobs.TERMINAL


@pytest.fixture(scope="session")
def short_video(tmp_path_factory) -> Path:
    """16 frames of the P1_warp_64_29 case video (every 4th: the background estimate needs the
    performer to move), re-encoded to tmp."""
    src = CASE / "video.mp4"
    if not src.exists():
        pytest.skip(f"{CASE} is not beside the clone")
    from engine.io.encode import write_video
    from engine.io.video import read_video

    out = tmp_path_factory.mktemp("video") / "short.mp4"
    video = read_video(src, height=0, max_frames=64)
    write_video(out, video.frames[::4][:16], video.fps)
    return out


def make_job(tmp_path: Path, video: Path, name: str, settings: dict) -> AnalysisJob:
    work = tmp_path / "data" / "analyses" / name
    return AnalysisJob(
        analysis_id=name,
        reference_path=str(CASE / "reference.bvh"),
        video_path=str(video),
        work_dir=str(work),
        settings=settings,
    )


def result_without_timing(path: str | Path) -> dict:
    result = json.loads(Path(path).read_text())
    result.pop("timing_s", None)
    return result
