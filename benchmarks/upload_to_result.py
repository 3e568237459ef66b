"""Upload to result through ``coach serve`` (embedded worker, no Redis), as a user waits for it
(issue 25): P2's video against the demo club's reference (64_29), the engine's defaults.

Starts the server on a free port with a fresh data dir, uploads the video with the
development key, polls the analysis every 0.5 s (timing each poll: the API must stay
responsive while the worker uses every core), and prints the seconds from upload to done and
the poll latencies. It also asks for the provisional result (the first whole segments, while
stage 3 runs on the rest) at each poll, and prints when each first came, and the worker's
stage log lines with the second (to the poll, 0.5 s) at which each appeared: where the wait goes.

    .venv/bin/python benchmarks/upload_to_result.py                 # worker concurrency = cores
    .venv/bin/python benchmarks/upload_to_result.py --concurrency 1 # as before issue 25
"""

from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

from throughput import REPO, start_api, stop

VIDEO = REPO.parent / "shared" / "bench" / "cases" / "P2_take_64_30_vs_64_29" / "video.mp4"


def _wait_for_quiet(c, timeout: float) -> float:
    """Wait until no analysis is queued or running (a fresh server's demo analysis), so the
    upload is timed alone, as on a server that has been up a while; returns the seconds."""
    t0 = time.perf_counter()
    while True:
        items = c.get("/api/v1/analyses").raise_for_status().json()["items"]
        if all(a["status"] in ("done", "failed", "cancelled") for a in items):
            return time.perf_counter() - t0
        if time.perf_counter() - t0 > timeout:
            raise SystemExit(f"the server's own analyses still run after {timeout:.0f} s")
        time.sleep(1.0)


def _new_events(log: Path, seen: int, now: float, timeline: list[tuple[float, str]]) -> int:
    """Append the worker's ``analysis.*`` lines written since byte ``seen``; returns the new
    offset."""
    with log.open("rb") as fh:
        fh.seek(seen)
        chunk = fh.read()
    end = chunk.rfind(b"\n") + 1  # a line still being written waits for the next poll
    for line in chunk[:end].decode(errors="replace").splitlines():
        if " analysis." in line:
            timeline.append((now, line.split(" analysis.", 1)[1][:110]))
    return seen + end


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--concurrency", type=int, default=0, help="worker processes (0: cores)")
    ap.add_argument("--video", type=Path, default=VIDEO)
    ap.add_argument("--timeout", type=float, default=1800)
    ap.add_argument("--chunks", type=int, default=0, help="stage-3 chunks (0: the default)")
    args = ap.parse_args()
    import httpx
    import numpy as np

    env = dict(os.environ)
    if args.concurrency:
        env["COACH_WORKER_CONCURRENCY"] = str(args.concurrency)
    if args.chunks:
        env["COACH_CHUNKS"] = str(args.chunks)
    with tempfile.TemporaryDirectory(prefix="coach-u2r-") as tmp:
        proc, base, key = start_api(Path(tmp), env, rate=1000, worker=True)
        try:
            with httpx.Client(base_url=base, headers={"X-API-Key": key}, timeout=60) as c:
                ref = c.get("/api/v1/references").raise_for_status().json()["items"][0]
                who = c.get("/api/v1/performers").raise_for_status().json()["items"][0]
                waited = _wait_for_quiet(c, args.timeout)
                log, timeline = Path(tmp) / "api-data" / "logs" / "worker.log", []
                seen = log.stat().st_size if log.exists() else 0  # the demo's lines are not ours
                t0 = time.perf_counter()
                with args.video.open("rb") as fh:
                    r = c.post(
                        "/api/v1/analyses",
                        data={"reference_id": ref["id"], "performer_id": who["id"]},
                        files={"video": (args.video.name, fh, "video/mp4")},
                    ).raise_for_status()
                url, polls, status = f"/api/v1/analyses/{r.json()['id']}", [], "queued"
                first: dict[int, float] = {}  # segments covered -> seconds after upload
                while status not in ("done", "failed", "cancelled"):
                    if time.perf_counter() - t0 > args.timeout:
                        raise SystemExit(f"not done after {args.timeout:.0f} s")
                    time.sleep(0.5)
                    tp = time.perf_counter()
                    a = c.get(url).raise_for_status().json()
                    polls.append(1000 * (time.perf_counter() - tp))
                    status = a["status"]
                    if status == "running":
                        pr = c.get(url + "/provisional")
                        if pr.status_code == 200:
                            k = pr.json()["provisional"]["segments"]
                            first.setdefault(k, time.perf_counter() - t0)
                    seen = _new_events(log, seen, time.perf_counter() - t0, timeline)
                elapsed = time.perf_counter() - t0
        finally:
            stop(proc)
    p50, p95 = np.percentile(polls, [50, 95])
    workers = args.concurrency or len(os.sched_getaffinity(0))
    print(f"(the first run's demo analysis ran first, {waited:.0f} s; the upload came after it)")
    print(f"{args.video.parent.name}: upload -> {status} in {elapsed:.1f} s "
          f"(embedded worker, {workers} processes); status polls during the analysis: "
          f"p50 {p50:.1f} ms, p95 {p95:.1f} ms over {len(polls)}")  # fmt: skip
    for k, seconds in sorted(first.items()):
        print(f"  first {k} segment(s) on the page after {seconds:.1f} s")
    if not first:
        print("  no provisional result before the final one")
    for seconds, line in timeline:
        print(f"  {seconds:6.1f} s  {line}")
    return 0 if status == "done" else 1


if __name__ == "__main__":
    raise SystemExit(main())
