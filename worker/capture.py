"""Running a reference-free capture (issue 23) in a worker: ``engine.capture`` on the
job's video, its files into the capture folder, progress and errors in status.json.

Much lighter than an analysis (a few hundredths of a second per frame): one task, no stages.
A worker that dies mid-capture leaves its message unacknowledged (``acks_late``), so another
worker runs the capture again from the start.
"""

from __future__ import annotations

import time
from pathlib import Path

from engine.capture import CaptureSettings, capture_video
from engine.capture.export import capture_csv, write_capture_bvh
from engine.errors import EngineError
from worker import jobs
from worker.contract import CaptureFolder, CaptureJob


def run_capture(job: CaptureJob) -> Path:
    """Capture the job's video; the summary's path. Engine errors are recorded as the
    capture's failure (with the engine's plain message) and re-raised."""
    folder = CaptureFolder(job.work_dir)

    def running(progress: float, *, force: bool = False) -> None:
        jobs.write_status(job.work_dir, "running", stage="capture", progress=progress,
                          message="finding you in the video", force=force)  # fmt: skip

    running(0.0, force=True)
    started = time.monotonic()
    shown = [-1]

    def progress(stage: str, share: float) -> None:
        if int(20 * share) != shown[0]:  # every 5 %, not every frame
            shown[0] = int(20 * share)
            running(0.9 * share)

    try:
        cap = capture_video(
            job.video_path,
            CaptureSettings(height_m=job.height_m),
            answers=job.answers,
            on_progress=progress,
        )
    except EngineError as exc:
        jobs.write_status(
            job.work_dir, "failed", stage="capture", message=str(exc), error=str(exc), force=True
        )
        raise
    jobs.write_atomic(folder.bvh, lambda tmp: write_capture_bvh(cap, tmp, names="cmu"))
    jobs.write_atomic(folder.bvh_coach, lambda tmp: write_capture_bvh(cap, tmp, names="coach"))
    jobs.write_atomic(folder.csv, lambda tmp: tmp.write_text(capture_csv(cap)))
    summary = cap.summary() | {"answers": job.answers, "seconds": time.monotonic() - started}
    jobs.write_json_atomic(folder.summary, summary)
    n = len(cap.questions)
    jobs.write_status(
        job.work_dir,
        "done",
        stage="done",
        progress=1.0,
        force=True,
        message=f"captured {cap.joints.shape[0]} frames"
        + (f"; {n} question{'s' * (n != 1)} for you" if n else ""),
    )
    return folder.summary
