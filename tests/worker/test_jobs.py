"""worker.jobs without Celery: stage skipping, atomic writes, failures, progress, cancel."""

from __future__ import annotations

import json
import os
from pathlib import Path

import pytest

from engine.errors import InvalidInput, RegistrationFailed
from tests.worker import fake_pipeline
from worker import jobs, metrics
from worker.contract import AnalysisFolder, AnalysisJob


@pytest.fixture
def job(tmp_path: Path) -> AnalysisJob:
    ref = tmp_path / "reference.bvh"
    video = tmp_path / "video.mp4"
    ref.write_bytes(b"HIERARCHY reference")
    video.write_bytes(b"fake video bytes")
    fake_pipeline.CALLS.clear()
    return AnalysisJob(
        analysis_id="a1",
        reference_path=str(ref),
        video_path=str(video),
        work_dir=str(tmp_path / "analysis"),
        settings={"fake_frames": 10},
    )


def _no_tmp_files(work_dir: str) -> bool:
    return not [p for p in Path(work_dir).rglob("*") if ".tmp" in p.name]


def test_run_all_writes_result_status_and_stage_outputs(job):
    published = []
    path = jobs.run_all(job, 3, pipeline=fake_pipeline, publish=published.append)
    paths = AnalysisFolder(job.work_dir)
    result = json.loads(path.read_text())
    assert [f["t"] for f in result["frames"]] == list(range(10))
    assert result["analysis_id"] == "a1"
    assert paths.prepared.exists() and all(p.exists() for p in paths.chunks(3))
    status = jobs.read_status(job.work_dir)
    assert status["state"] == "done" and status["progress"] == 1.0 and status["error"] is None
    assert {"prepare", "candidates", "select"} <= {m["stage"] for m in published}
    progress = [m["progress"] for m in published]
    assert progress == sorted(progress), "progress must not go backwards in one process"
    assert _no_tmp_files(job.work_dir)


def test_finished_stages_are_skipped(job):
    jobs.run_all(job, 2, pipeline=fake_pipeline)
    first = AnalysisFolder(job.work_dir).result.read_text()
    fake_pipeline.CALLS.clear()
    # A redelivered select after a crash between writing result.json and acking.
    jobs.run_select(job, 2, pipeline=fake_pipeline)
    jobs.run_prepare(job, pipeline=fake_pipeline)
    jobs.run_candidates(job, 1, 2, pipeline=fake_pipeline)
    assert fake_pipeline.CALLS == []
    assert AnalysisFolder(job.work_dir).result.read_text() == first


def test_resume_runs_only_missing_stages(job):
    jobs.run_all(job, 3, pipeline=fake_pipeline)
    paths = AnalysisFolder(job.work_dir)
    first = json.loads(paths.result.read_text())
    paths.result.unlink()
    paths.chunk(1, 3).unlink()
    fake_pipeline.CALLS.clear()
    jobs.run_all(job, 3, pipeline=fake_pipeline)
    assert [c[0] for c in fake_pipeline.CALLS] == ["candidates", "select"]
    assert json.loads(paths.result.read_text()) == first


def test_write_atomic_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "stages" / "prepare.npz"

    def crash(tmp: Path) -> None:
        tmp.write_bytes(b"half")
        raise OSError("disk full")

    with pytest.raises(OSError, match="disk full"):
        jobs.write_atomic(target, crash)
    assert not target.exists()
    assert list(target.parent.iterdir()) == []


def test_write_atomic_keeps_the_suffix_numpy_needs(tmp_path):
    import numpy as np

    target = tmp_path / "x.npz"
    seen = []
    jobs.write_atomic(target, lambda tmp: (seen.append(tmp.name), np.savez(tmp, a=np.arange(3))))
    assert seen[0].endswith(".tmp.npz")
    assert np.load(target)["a"].tolist() == [0, 1, 2]


def test_engine_error_is_recorded_with_its_message(job):
    bad = AnalysisJob(**{**job.to_json(), "settings": {"fake_fail": "invalid"}})
    with pytest.raises(InvalidInput):
        jobs.run_all(bad, 2, pipeline=fake_pipeline)
    status = jobs.read_status(job.work_dir)
    assert status["state"] == "failed"
    assert status["error"] == "video video.mp4 has no frames"
    assert not AnalysisFolder(job.work_dir).result.exists()


def test_registration_failed_in_select_is_recorded(job):
    bad = AnalysisJob(**{**job.to_json(), "settings": {"fake_fail": "registration"}})
    with pytest.raises(RegistrationFailed):
        jobs.run_all(bad, 2, pipeline=fake_pipeline)
    status = jobs.read_status(job.work_dir)
    assert (status["state"], status["stage"]) == ("failed", "select")
    assert "no consistent temporal correspondence" in status["error"]


def test_failed_status_is_sticky_against_late_progress(job):
    jobs.write_status(job.work_dir, "failed", error="boom")
    assert not jobs.write_status(job.work_dir, "running", stage="candidates", progress=0.5)
    assert jobs.read_status(job.work_dir)["state"] == "failed"


def test_cancel_marker_stops_at_next_progress_step(job):
    seen = []

    def publish(meta):
        seen.append(meta)
        if meta["stage"] == "alignment":
            jobs.request_cancel(job.work_dir)

    with pytest.raises(jobs.Cancelled):
        jobs.run_all(job, 2, pipeline=fake_pipeline, publish=publish)
    assert jobs.read_status(job.work_dir)["state"] == "cancelled"
    assert not AnalysisFolder(job.work_dir).prepared.exists()
    # A later delivery of any task sees the marker and does nothing.
    fake_pipeline.CALLS.clear()
    assert not jobs.start(job)
    with pytest.raises(jobs.Cancelled):
        jobs.run_prepare(job, pipeline=fake_pipeline)
    assert fake_pipeline.CALLS == []


def test_status_json_is_replaced_atomically(job, monkeypatch):
    jobs.write_status(job.work_dir, "running", stage="prepare", progress=0.2)
    real_replace = os.replace

    def crash(src, dst):
        raise OSError("crash before rename")

    monkeypatch.setattr(os, "replace", crash)
    with pytest.raises(OSError):
        jobs.write_status(job.work_dir, "running", stage="candidates", progress=0.5)
    monkeypatch.setattr(os, "replace", real_replace)
    status = jobs.read_status(job.work_dir)
    assert (status["stage"], status["progress"]) == ("prepare", 0.2)
    assert set(status) == {"state", "stage", "progress", "message", "error", "updated"}


def test_stage_done_is_logged_with_the_analysis_id(job, caplog):
    caplog.set_level("INFO", logger="coach.worker")
    jobs.run_all(job, 1, pipeline=fake_pipeline)
    lines = [r.getMessage() for r in caplog.records if "analysis.stage_done" in r.getMessage()]
    assert len(lines) == 3
    assert all("analysis_id=a1" in line and "seconds=" in line for line in lines)
    assert lines[0].startswith("analysis.stage_done stage=prepare")


def test_metrics_render_in_prometheus_text(job, tmp_path):
    metrics.reset()
    metrics.configure(tmp_path / "metrics")
    try:
        jobs.run_all(job, 2, pipeline=fake_pipeline)
        text = metrics.render_prometheus(tmp_path / "metrics")
    finally:
        metrics.configure(None)
        metrics.reset()
    assert "# TYPE coach_stage_seconds summary" in text
    assert 'coach_stage_runs_total{outcome="done",stage="candidates"} 2' in text
    assert 'coach_stage_seconds_count{stage="prepare"} 1' in text
    assert 'coach_analyses_total{state="done"} 1' in text
