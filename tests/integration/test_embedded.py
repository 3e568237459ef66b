"""Embedded mode end to end: filesystem broker, file result backend, a worker subprocess
started by worker.embedded (what `coach serve` does). No Redis."""

from __future__ import annotations

import os

import pytest

from tests.integration.conftest import REPO, finished, make_job, wait_for
from tests.integration.test_redis_worker import ENGINE_CHEAP_SETTINGS
from worker import celery_app, embedded
from worker.contract import AnalysisFolder
from worker.settings import WorkerSettings

pytestmark = pytest.mark.integration


@pytest.fixture
def embedded_worker(tmp_path, monkeypatch):
    for name in ("COACH_BROKER_URL", "COACH_RESULT_BACKEND"):
        monkeypatch.delenv(name, raising=False)
    monkeypatch.setenv("COACH_CHUNKS", "2")
    monkeypatch.setenv("PYTHONPATH", str(REPO))
    data = tmp_path / "data"
    proc = embedded.start(data, concurrency=2)
    yield data, proc
    embedded.stop(timeout=5)
    celery_app.configure(WorkerSettings.from_env(dict(os.environ)))


def test_embedded_end_to_end(embedded_worker, tmp_path, short_video):
    data, proc = embedded_worker
    assert celery_app.current_settings().embedded
    assert embedded.running()
    # the worker yields the CPU to the API in the parent (status polls stay fast)
    assert os.getpriority(os.PRIO_PROCESS, proc.pid) >= embedded.WORKER_NICENESS
    job = make_job(tmp_path, short_video, "e-1", dict(ENGINE_CHEAP_SETTINGS))
    task_id = celery_app.enqueue(job)
    status = wait_for(job.work_dir, finished, 150)
    assert status["state"] == "done", (status, (data / "logs" / "worker.log").read_text()[-3000:])
    paths = AnalysisFolder(job.work_dir)
    assert paths.result.exists() and all(p.exists() for p in paths.chunks(2))
    root = celery_app.app.AsyncResult(task_id)
    assert root.state == "SUCCESS"  # the chord ran on the file backend (celery.chord_unlock)
    assert (data / "celery" / "broker" / "queue").is_dir()
    embedded.stop(timeout=5)
    assert proc.poll() is not None and not embedded.running()
