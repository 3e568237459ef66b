"""Analyses per minute through Redis with 1 and 2 Celery workers (issue 6).

Starts its own redis-server on a free port and `celery worker` subprocesses (concurrency 1
each), queues N short analyses (a 16-frame cut of a bench case, cheap engine settings), and
prints the throughput for each worker count. Everything it starts is stopped on exit.

    .venv/bin/python benchmarks/throughput.py --n 4 --workers 1 2
    .venv/bin/python benchmarks/throughput.py --fake 0.1   # plumbing only: fake 0.1 s/frame
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
CASE = REPO.parent / "shared" / "bench" / "cases" / "P1_warp_64_29"
CHEAP = {
    "preset": "fast",
    "candidates": {"n_samples": 8, "n_iterations": 3, "refine_sweeps": 1, "n_candidates": 4},
}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(proc: subprocess.Popen) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            pass
    try:
        os.killpg(proc.pid, signal.SIGKILL)
    except ProcessLookupError:
        pass
    proc.wait(5)


def cut_video(out: Path, frames: int = 16, step: int = 4) -> Path:
    import cv2

    cap = cv2.VideoCapture(str(CASE / "video.mp4"))
    fps = cap.get(cv2.CAP_PROP_FPS) or 30.0
    writer = None
    for _ in range(frames):
        ok, frame = cap.read()
        for _skip in range(step - 1):
            cap.read()
        if not ok:
            break
        if writer is None:
            h, w = frame.shape[:2]
            writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), fps, (w, h))
        writer.write(frame)
    cap.release()
    writer.release()
    return out


def run(n: int, n_workers: int, env: dict, root: Path, video: Path, settings: dict) -> float:
    """Seconds from the first enqueue until all ``n`` analyses are finished."""
    import redis

    from worker import celery_app, jobs
    from worker.contract import AnalysisJob
    from worker.settings import WorkerSettings

    redis.Redis.from_url(env["COACH_BROKER_URL"]).flushdb()
    celery_app.configure(WorkerSettings.from_env(env))
    procs = []
    try:
        for i in range(n_workers):
            log = open(root / f"worker-{n_workers}-{i}.log", "ab")  # noqa: SIM115
            procs.append(subprocess.Popen(
                [sys.executable, "-m", "celery", "-A", "worker.celery_app", "worker",
                 "--concurrency", "1", "--loglevel", "INFO", "--hostname", f"b{i}@%h",
                 "--without-gossip", "--without-mingle"],
                env=env, cwd=REPO, stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
            ))  # fmt: skip
            log.close()
        time.sleep(3)  # let the workers connect: measure analyses, not start-up
        t0 = time.monotonic()
        work = []
        for k in range(n):
            work_dir = root / "data" / f"w{n_workers}" / f"a{k}"
            job = AnalysisJob(
                f"w{n_workers}-a{k}",
                str(CASE / "reference.bvh"),
                str(video),
                str(work_dir),
                settings,
            )
            celery_app.enqueue(job)
            work.append(work_dir)
        while True:
            states = [(jobs.read_status(w) or {}).get("state") for w in work]
            if all(s in jobs.TERMINAL for s in states):
                break
            time.sleep(0.2)
        seconds = time.monotonic() - t0
        failed = [
            (w.name, jobs.read_status(w)) for w, s in zip(work, states, strict=True) if s != "done"
        ]
        if failed:
            raise SystemExit(f"analyses failed: {json.dumps(failed)[:2000]}")
        return seconds
    finally:
        for proc in procs:
            stop(proc)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=4, help="analyses per run (default 4)")
    ap.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--chunks", type=int, default=2, help="stage-3 chunks per analysis")
    ap.add_argument(
        "--fake",
        type=float,
        default=None,
        metavar="S_PER_FRAME",
        help="use the fake pipeline (tests/worker/fake_pipeline.py) instead",
    )
    args = ap.parse_args(argv)
    server = shutil.which("redis-server")
    if server is None:
        raise SystemExit("redis-server is not installed")
    with tempfile.TemporaryDirectory(prefix="coach-throughput-") as tmp:
        root = Path(tmp)
        port = free_port()
        redis_proc = subprocess.Popen(
            [server, "--port", str(port), "--bind", "127.0.0.1", "--save", "", "--appendonly",
             "no", "--dir", tmp], stdout=subprocess.DEVNULL, start_new_session=True,
        )  # fmt: skip
        try:
            time.sleep(0.5)
            url = f"redis://127.0.0.1:{port}/0"
            env = dict(os.environ, COACH_BROKER_URL=url, COACH_RESULT_BACKEND=url,
                       COACH_DATA_DIR=str(root / "data"), COACH_CHUNKS=str(args.chunks),
                       PYTHONPATH=str(REPO), PYOPENGL_PLATFORM="egl")  # fmt: skip
            settings = CHEAP
            if args.fake is not None:
                env["COACH_PIPELINE_MODULE"] = "tests.worker.fake_pipeline"
                settings = {"fake_frames": 16, "fake_seconds_per_frame": args.fake}
            video = cut_video(root / "short.mp4")
            print(
                f"{args.n} analyses of a 16-frame video, {args.chunks} chunks each, "
                f"{f'fake {args.fake:.2f} s/frame' if args.fake is not None else 'engine'}; "
                f"{os.cpu_count()} CPUs"
            )
            for n_workers in args.workers:
                seconds = run(args.n, n_workers, env, root, video, settings)
                print(
                    f"workers={n_workers}  {seconds:7.1f} s  "
                    f"{60.0 * args.n / seconds:6.2f} analyses/min",
                    flush=True,
                )
        finally:
            stop(redis_proc)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
