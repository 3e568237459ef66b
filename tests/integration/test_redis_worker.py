"""End to end through a real redis-server and real `celery worker` subprocesses.

Most tests use the fake pipeline (``tests/worker/fake_pipeline.py``) so a stage lasts a known
time; ``test_engine_end_to_end`` runs the real engine on a 16-frame cut of a bench case.
"""

from __future__ import annotations

import time

import pytest

from tests.integration.conftest import (
    finished,
    make_job,
    result_without_timing,
    wait_for,
)
from tests.worker import fake_pipeline
from worker import celery_app, jobs
from worker.contract import PROGRESS_STATE, AnalysisFolder

pytestmark = pytest.mark.integration

#: Engine settings that keep a 16-frame analysis to seconds (coarse sampling, few iterations).
ENGINE_CHEAP_SETTINGS: dict = {
    "preset": "fast",
    "candidates": {"n_samples": 8, "n_iterations": 3, "refine_sweeps": 1, "n_candidates": 4},
}


#: The worker app whose tasks run the fake engine (stages of a known length).
FAKE_APP = "tests.worker.fake_app"


def test_canvas_end_to_end_with_progress(worker_env, workers, tmp_path, short_video):
    workers.start(app=FAKE_APP, concurrency=2)
    job = make_job(
        tmp_path, short_video, "a-canvas", {"fake_frames": 12, "fake_seconds_per_frame": 0.1}
    )
    task_id = celery_app.enqueue(job)
    states = set()
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not finished(jobs.read_status(job.work_dir) or {}):
        states.add(celery_app.app.AsyncResult(task_id).state)
        time.sleep(0.05)
    status = wait_for(job.work_dir, finished, 5, workers)
    assert status["state"] == "done", status
    assert PROGRESS_STATE in states
    root = celery_app.app.AsyncResult(task_id)
    assert root.state == "SUCCESS" and root.result["result_path"].endswith("result.json")
    paths = AnalysisFolder(job.work_dir)
    assert paths.prepared.exists() and all(p.exists() for p in paths.chunks(2))
    result = result_without_timing(paths.result)
    expected_dir = tmp_path / "expected"
    expected = make_job(tmp_path, short_video, "expected", job.settings)
    expected = type(job)(**{**expected.to_json(), "work_dir": str(expected_dir)})
    jobs.run_all(expected, 2, pipeline=fake_pipeline)
    assert result == {
        **result_without_timing(AnalysisFolder(expected_dir).result),
        "analysis_id": "a-canvas",
    }
    logs = workers.logs()
    for stage in ("prepare", "candidates", "select"):
        assert f"analysis.stage_done stage={stage} analysis_id=a-canvas" in logs


def test_worker_killed_mid_stage_then_restarted_completes(
    worker_env, workers, tmp_path, short_video
):
    # Redis redelivers an unacknowledged message only after the visibility timeout; keep it
    # short here (longer than any single fake stage: 6 frames x 0.3 s).
    worker_env["COACH_VISIBILITY_TIMEOUT_S"] = "4"
    worker_env["COACH_RESTORE_INTERVAL_S"] = "1"
    settings = {"fake_frames": 12, "fake_seconds_per_frame": 0.3}
    first = workers.start(app=FAKE_APP, concurrency=1, name="first")
    job = make_job(tmp_path, short_video, "a-kill", settings)
    celery_app.enqueue(job)
    wait_for(
        job.work_dir, lambda s: s.get("stage") == "candidates" and s["progress"] > 0.4, 60, workers
    )
    workers.kill(first)
    paths = AnalysisFolder(job.work_dir)
    assert not paths.result.exists()
    before = {p.name for p in paths.stages.glob("*.npz")}
    assert "prepare.npz" in before and len(before) < 3  # killed inside stage 3
    workers.start(app=FAKE_APP, concurrency=1, name="second")
    status = wait_for(job.work_dir, finished, 60, workers)
    assert status["state"] == "done", status
    expected = make_job(tmp_path / "x", short_video, "expected", settings)
    jobs.run_all(expected, 2, pipeline=fake_pipeline)
    assert result_without_timing(paths.result) == {
        **result_without_timing(AnalysisFolder(expected.work_dir).result),
        "analysis_id": "a-kill",
    }
    second_log = (workers.log_dir / "second.log").read_text()
    assert "analysis.stage_done stage=prepare" not in second_log  # resumed, not redone


def test_engine_error_is_recorded_not_retried(worker_env, workers, tmp_path, short_video):
    workers.start(app=FAKE_APP)
    job = make_job(tmp_path, short_video, "a-bad", {"fake_fail": "invalid"})
    task_id = celery_app.enqueue(job)
    status = wait_for(job.work_dir, finished, 30, workers)
    assert status["state"] == "failed"
    assert status["error"] == "video short.mp4 has no frames"
    time.sleep(0.5)
    assert "analysis.retry" not in workers.logs()
    assert celery_app.app.AsyncResult(task_id).state == "FAILURE"


def test_cancel_stops_a_running_analysis(worker_env, workers, tmp_path, short_video):
    workers.start(app=FAKE_APP)
    job = make_job(
        tmp_path, short_video, "a-cancel", {"fake_frames": 40, "fake_seconds_per_frame": 0.2}
    )
    task_id = celery_app.enqueue(job)
    wait_for(job.work_dir, lambda s: s.get("state") == "running" and s["progress"] > 0, 30, workers)
    celery_app.revoke(task_id)
    assert jobs.read_status(job.work_dir)["state"] == "cancelled"
    deadline = time.monotonic() + 10
    while "analysis.cancelled" not in workers.logs() and time.monotonic() < deadline:
        time.sleep(0.1)
    assert "analysis.cancelled" in workers.logs()  # the running stage stopped itself
    time.sleep(0.5)
    assert jobs.read_status(job.work_dir)["state"] == "cancelled"
    assert not AnalysisFolder(job.work_dir).result.exists()
    assert not AnalysisFolder(job.work_dir).prepared.exists()


def test_engine_end_to_end(worker_env, workers, tmp_path, short_video):
    workers.start(concurrency=2)
    job = make_job(tmp_path, short_video, "a-engine", dict(ENGINE_CHEAP_SETTINGS))
    celery_app.enqueue(job)
    status = wait_for(job.work_dir, finished, 150, workers)
    assert status["state"] == "done", status
    result = result_without_timing(AnalysisFolder(job.work_dir).result)
    assert len(result["frames"]) == 16
    assert [f["t"] for f in result["frames"]] == list(range(16))


def test_capture_through_a_real_worker(worker_env, workers, tmp_path, short_video):
    """A reference-free capture (issue 23) queued on Redis, run by a real `celery worker`
    with the real engine; then queued again with an answer, which the worker honours."""
    from engine.io.bvh import load_reference
    from worker.contract import CaptureFolder, CaptureJob

    workers.start(concurrency=1)
    work = tmp_path / "data" / "captures" / "c-1"
    job = CaptureJob(capture_id="c-1", video_path=str(short_video), work_dir=str(work))
    task_id = celery_app.enqueue_capture(job)
    assert jobs.read_status(work)["state"] in ("queued", "running", "done")
    status = wait_for(str(work), finished, 120, workers)
    assert status["state"] == "done", status
    assert celery_app.app.AsyncResult(task_id).state == "SUCCESS"
    folder = CaptureFolder(work)
    ref = load_reference(folder.bvh, normalise_heading=False)
    assert ref.profile == "cmu" and ref.motion.joints.shape == (16, 17, 3)
    answer = {"l_forearm@0-16": 1}
    celery_app.enqueue_capture(CaptureJob(**{**job.to_json(), "answers": answer}))
    status = wait_for(str(work), lambda s: finished(s) and s.get("stage") == "done", 120, workers)
    import json

    summary = json.loads(folder.summary.read_text())
    assert summary["answers"] == answer
    assert "l_forearm@0-16" not in {q["id"] for q in summary["questions"]}
