"""The worker writes the first segments' results while stage 3 still runs (real engine)."""

from __future__ import annotations

import json
import logging
import os

import pytest

from tests.engine.test_pipeline import SETTINGS, case_dir  # noqa: F401 - the case fixture
from tests.engine.test_provisional import DOMAIN
from worker import jobs
from worker.contract import AnalysisFolder, AnalysisJob


@pytest.fixture
def job(case_dir, tmp_path) -> AnalysisJob:  # noqa: F811
    return AnalysisJob(
        analysis_id="p1", reference_path=str(case_dir["reference"]),
        video_path=str(case_dir["video"]), work_dir=str(tmp_path / "analysis"),
        settings=SETTINGS, domain=DOMAIN,
    )  # fmt: skip


def test_the_first_segment_is_written_before_the_last_chunk_runs(job, caplog) -> None:
    caplog.set_level(logging.INFO, logger=jobs.log.name)
    paths = AnalysisFolder(job.work_dir)
    jobs.start(job)
    jobs.run_prepare(job)
    seen = []
    for i in range(4):  # this clip's stage 3 takes seconds: a preview at any wait
        jobs.run_candidates(job, i, 4, provisional_min_wait_s=0.0)
        seen.append(jobs.read_json(paths.provisional))
    assert seen[0] is None, "chunk 0 ends before the first segment does"
    doc = seen[1]
    assert doc is not None and doc["analysis_id"] == "p1"
    assert doc["provisional"]["segments"] == 1 and doc["provisional"]["reference_segments"] == 2
    assert doc["provisional"]["frames"] < doc["provisional"]["video_frames"]
    assert [s["name"] for s in doc["segments"]] == ["down"]
    assert seen[3] == doc, "near the end no new provisional result is computed"
    assert "analysis.provisional " in caplog.text
    # what the first frame says about the filming is known from stages 0-2 on
    assert jobs.read_json(paths.framing) == {"problems": []}  # the synthetic body is whole
    final = json.loads(jobs.run_select(job, 4).read_text())
    assert len(final["segments"]) == 2 and "provisional" not in final


def test_a_broken_chunk_file_costs_the_preview_not_the_chunk(job, caplog) -> None:
    caplog.set_level(logging.INFO, logger=jobs.log.name)
    paths = AnalysisFolder(job.work_dir)
    jobs.start(job)
    jobs.run_prepare(job)
    paths.chunk(0, 4).write_bytes(b"not an npz")
    out = jobs.run_candidates(job, 1, 4)
    assert out.exists() and not paths.provisional.exists()
    assert "analysis.provisional_failed" in caplog.text


def test_no_preview_when_the_final_result_is_moments_away(job) -> None:
    paths = AnalysisFolder(job.work_dir)
    jobs.start(job)
    jobs.run_prepare(job)
    for i in range(3):  # chunk 2 completes the first segment, as above
        jobs.run_candidates(job, i, 4, provisional_min_wait_s=3600.0)
    assert not paths.provisional.exists()


def test_the_wait_left_counts_the_running_chunks(job) -> None:
    from engine.pipeline import CandidateChunk, Prepared

    paths = AnalysisFolder(job.work_dir)
    jobs.start(job)
    jobs.run_prepare(job)
    jobs.run_candidates(job, 0, 4)
    prepared = Prepared.load(paths.prepared)
    chunks = [CandidateChunk.load(paths.chunk(0, 4))]
    per_frame = chunks[0].seconds / len(chunks[0].frames)
    sizes = [len(r) for r in prepared.chunks(4)]
    # nothing runs: the three chunks left, one after another
    left = jobs.stage3_left_s(paths, prepared, 4, chunks)
    assert left == pytest.approx(sum(sizes[1:]) * per_frame)
    # chunks 1 and 2 run (their crash ledgers), chunk 1 for long enough to be nearly done
    for i, age in ((1, sizes[1] * per_frame), (2, 0.0)):
        ledger = paths.attempts(paths.chunk(i, 4))
        ledger.parent.mkdir(parents=True, exist_ok=True)
        ledger.write_text("1 test")
        mtime = ledger.stat().st_mtime - age
        os.utime(ledger, (mtime, mtime))
    left = jobs.stage3_left_s(paths, prepared, 4, chunks)
    assert left == pytest.approx((sizes[2] + sizes[3]) * per_frame / 2, rel=0.05, abs=0.05)


def test_a_preview_another_process_claimed_is_not_computed_twice(job) -> None:
    """Two chunks that end together in two processes: the one that claimed the preview of
    k segments computes it, the other does not compute it again."""
    paths = AnalysisFolder(job.work_dir)
    jobs.start(job)
    jobs.run_prepare(job)
    claim = paths.provisional_claim(1)
    claim.parent.mkdir(parents=True)
    claim.touch()  # the process that finished the other chunk is computing it
    for i in range(3):  # chunk 1 completes the first segment (see the first test)
        jobs.run_candidates(job, i, 4, provisional_min_wait_s=0.0)
    assert not paths.provisional.exists()
