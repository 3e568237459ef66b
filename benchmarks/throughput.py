"""Analyses/min through Redis with 1 and 2 Celery workers; API status-poll latency (issue 6).

Starts its own redis-server on a free port and `celery worker` subprocesses (concurrency 1
each), queues N short analyses (a 16-frame cut of a bench case, cheap engine settings), and
prints the throughput for each worker count.

Then starts the real API (``python -m app.cli serve --no-worker`` on a free loopback port, a
fresh data dir, its broker the same redis-server), uploads one video through
``POST /api/v1/analyses`` (it stays queued: no worker consumes it), and lets ``--clients``
concurrent clients poll ``GET /api/v1/analyses/{id}`` ``--polls`` times each; prints the
p50/p95/p99 latency and the requests per second. The per-key rate limit is raised for this
(the output says so): all clients share the development key. Everything it starts is stopped
on exit.

    .venv/bin/python benchmarks/throughput.py --n 4 --workers 1 2
    .venv/bin/python benchmarks/throughput.py --fake 0.1   # plumbing only: fake 0.1 s/frame
    .venv/bin/python benchmarks/throughput.py --latency-only --clients 50 --polls 20
"""

from __future__ import annotations

import argparse
import asyncio
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
    """Every ``step``-th frame of the case video, ``frames`` of them, at the same frame rate."""
    from engine.io.encode import write_video
    from engine.io.video import read_video

    video = read_video(CASE / "video.mp4", height=0, max_frames=frames * step)
    write_video(out, video.frames[::step][:frames], video.fps)
    return out


def run(
    n: int, n_workers: int, env: dict, root: Path, video: Path, settings: dict, app: str
) -> float:
    """Seconds from the first enqueue until all ``n`` analyses are finished, with workers of
    the Celery ``app`` module."""
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
                [sys.executable, "-m", "celery", "-A", app, "worker",
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


def tiny_video(out: Path, frames: int = 16, size: tuple[int, int] = (120, 160)) -> Path:
    """A small mp4 (a block moving over noise) for the upload; polling never decodes it."""
    import cv2
    import numpy as np

    rng = np.random.default_rng(0)
    h, w = size
    bg = rng.integers(0, 255, (h, w, 3), dtype=np.uint8)
    writer = cv2.VideoWriter(str(out), cv2.VideoWriter_fourcc(*"mp4v"), 12.5, (w, h))
    for i in range(frames):
        frame = bg.copy()
        frame[30:90, 10 + 6 * i : 30 + 6 * i] = (40, 80, 200)
        writer.write(frame)
    writer.release()
    return out


def start_api(
    root: Path, env: dict, rate: float, *, worker: bool = False
) -> tuple[subprocess.Popen, str, str]:
    """``coach serve --no-worker`` (or with its embedded worker) on a free port; returns the
    process, base URL and API key."""
    import httpx

    port = free_port()
    api_env = dict(
        env, COACH_RATE_LIMIT_PER_S=str(rate), COACH_RATE_LIMIT_BURST=str(int(rate)),
        COACH_DATABASE_URL="", COACH_ENVIRONMENT="development",
    )  # fmt: skip
    api_env.pop("COACH_DATA_DIR", None)  # --data-dir sets it
    log_path = root / "api.log"
    log = open(log_path, "ab")  # noqa: SIM115 - closed with the process
    proc = subprocess.Popen(
        [sys.executable, "-m", "app.cli", "serve", *([] if worker else ["--no-worker"]),
         "--host", "127.0.0.1", "--port", str(port), "--data-dir", str(root / "api-data")],
        env=api_env, cwd=REPO, stdout=log, stderr=subprocess.STDOUT, start_new_session=True,
    )  # fmt: skip
    log.close()
    base = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + 60
    while True:
        text = log_path.read_text(errors="replace")
        keys = [ln.rsplit(": ", 1)[1].strip() for ln in text.splitlines()
                if "development API key" in ln]  # fmt: skip
        if keys:
            try:
                r = httpx.get(f"{base}/api/v1/references", headers={"X-API-Key": keys[-1]})
                if r.is_success:
                    return proc, base, keys[-1]
            except httpx.TransportError:
                pass
        if proc.poll() is not None or time.monotonic() > deadline:
            stop(proc)
            raise SystemExit(f"the API did not start:\n{text[-3000:]}")
        time.sleep(0.2)


def create_analysis(base: str, key: str, video: Path) -> str:
    import httpx

    headers = {"X-API-Key": key}
    with httpx.Client(base_url=base, headers=headers, timeout=30) as client:
        refs = client.get("/api/v1/references").raise_for_status().json()["items"]
        performers = client.get("/api/v1/performers").raise_for_status().json()["items"]
        if not refs or not performers:
            raise SystemExit("the demo club has no reference or performer (is 64_29.bvh there?)")
        with video.open("rb") as fh:
            r = client.post(
                "/api/v1/analyses",
                data={"reference_id": refs[0]["id"], "performer_id": performers[0]["id"]},
                files={"video": ("short.mp4", fh, "video/mp4")},
            )
        if r.status_code != 201:
            raise SystemExit(f"upload refused: {r.status_code} {r.text[:500]}")
        return r.json()["id"]


async def _poll(base: str, key: str, analysis_id: str, clients: int, polls: int) -> tuple:
    import httpx

    limits = httpx.Limits(max_connections=clients, max_keepalive_connections=clients)
    url = f"/api/v1/analyses/{analysis_id}"
    async with httpx.AsyncClient(
        base_url=base, headers={"X-API-Key": key}, limits=limits, timeout=30
    ) as client:
        # Warm up: open the connections and the server's code paths; not measured.
        await asyncio.gather(*(client.get(url) for _ in range(clients)))
        latencies: list[float] = []
        errors: dict[int, int] = {}

        async def one_client() -> None:
            for _ in range(polls):
                t = time.perf_counter()
                r = await client.get(url)
                latencies.append(time.perf_counter() - t)
                if r.status_code != 200:
                    errors[r.status_code] = errors.get(r.status_code, 0) + 1

        t0 = time.perf_counter()
        await asyncio.gather(*(one_client() for _ in range(clients)))
        return latencies, time.perf_counter() - t0, errors


def poll_latency(root: Path, env: dict, video: Path, clients: int, polls: int) -> None:
    """Print p50/p95/p99 of ``GET /api/v1/analyses/{id}`` under ``clients`` concurrent pollers."""
    import numpy as np

    rate = 1e6
    proc, base, key = start_api(root, env, rate)
    try:
        analysis_id = create_analysis(base, key, video)
        latencies, seconds, errors = asyncio.run(_poll(base, key, analysis_id, clients, polls))
    finally:
        stop(proc)
    ms = 1000.0 * np.asarray(latencies)
    p50, p95, p99 = np.percentile(ms, [50, 95, 99])
    print(
        f"API status polls: {clients} concurrent clients x {polls} GET /api/v1/analyses/{{id}} "
        f"(one uvicorn process, SQLite, loopback; rate limit raised to "
        f"COACH_RATE_LIMIT_PER_S={rate:g}, COACH_RATE_LIMIT_BURST={int(rate)}; one shared key)"
    )
    print(
        f"latency p50 {p50:6.1f} ms  p95 {p95:6.1f} ms  p99 {p99:6.1f} ms  max {ms.max():6.1f} ms  "
        f"{len(ms) / seconds:7.1f} requests/s" + (f"  non-200: {errors}" if errors else ""),
        flush=True,
    )


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
    ap.add_argument("--latency-only", action="store_true", help="only the API status-poll latency")
    ap.add_argument("--clients", type=int, default=50, help="concurrent pollers (default 50)")
    ap.add_argument("--polls", type=int, default=20, help="requests per poller (default 20)")
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
            if args.latency_only:
                poll_latency(root, env, tiny_video(root / "tiny.mp4"), args.clients, args.polls)
                return 0
            settings, app = CHEAP, "worker.celery_app"
            if args.fake is not None:  # the same tasks over the fake engine
                app = "tests.worker.fake_app"
                settings = {"fake_frames": 16, "fake_seconds_per_frame": args.fake}
            video = cut_video(root / "short.mp4")
            print(
                f"{args.n} analyses of a 16-frame video, {args.chunks} chunks each, "
                f"{f'fake {args.fake:.2f} s/frame' if args.fake is not None else 'engine'}; "
                f"{os.cpu_count()} CPUs"
            )
            for n_workers in args.workers:
                seconds = run(args.n, n_workers, env, root, video, settings, app)
                print(
                    f"workers={n_workers}  {seconds:7.1f} s  "
                    f"{60.0 * args.n / seconds:6.2f} analyses/min",
                    flush=True,
                )
            poll_latency(root, env, video, args.clients, args.polls)
        finally:
            stop(redis_proc)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
