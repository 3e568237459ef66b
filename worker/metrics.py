"""Worker metrics (counters and durations) and their Prometheus text rendering.

Workers are separate processes (often separate containers), so each process keeps its own
numbers in memory and, after every change, replaces one snapshot file
``<metrics_dir>/<host>-<pid>.json`` (temporary name + rename). :func:`render_prometheus` sums
every snapshot in the folder, so the API can expose the workers' metrics on ``/metrics`` by
reading the shared data directory, the way prometheus_client's multiprocess mode does, without
another dependency.
"""

from __future__ import annotations

import json
import os
import socket
import threading
from collections import defaultdict
from pathlib import Path

#: name -> (type, help). Every metric the worker emits is declared here.
METRICS: dict[str, tuple[str, str]] = {
    "coach_stage_runs_total": ("counter", "Engine stage runs by stage and outcome."),
    "coach_stage_skipped_total": ("counter", "Stages skipped because their output existed."),
    "coach_stage_seconds": ("summary", "Wall time of finished engine stages, seconds."),
    "coach_analyses_total": ("counter", "Analyses finished, by final state."),
    "coach_task_retries_total": ("counter", "Task retries after a transient error, by task."),
}

_lock = threading.Lock()
# (name, sorted label items) -> value; summaries keep "<name>_sum" and "<name>_count".
_values: dict[tuple[str, tuple[tuple[str, str], ...]], float] = defaultdict(float)
_dir: Path | None = None


def configure(metrics_dir: str | os.PathLike | None) -> None:
    """Set the folder snapshots are written to (None: keep metrics in memory only)."""
    global _dir
    _dir = Path(metrics_dir) if metrics_dir is not None else None


def _key(name: str, labels: dict[str, str]) -> tuple[str, tuple[tuple[str, str], ...]]:
    if name not in METRICS and name.rsplit("_", 1)[0] not in METRICS:
        raise ValueError(f"unknown metric {name!r}; declare it in worker.metrics.METRICS")
    return name, tuple(sorted((k, str(v)) for k, v in labels.items()))


def inc(name: str, amount: float = 1.0, **labels: str) -> None:
    """Add ``amount`` to a counter."""
    with _lock:
        _values[_key(name, labels)] += amount
    _flush()


def observe(name: str, seconds: float, **labels: str) -> None:
    """Record one duration in a summary (``_sum`` and ``_count`` series)."""
    with _lock:
        _values[_key(name + "_sum", labels)] += seconds
        _values[_key(name + "_count", labels)] += 1
    _flush()


def snapshot() -> list[dict]:
    with _lock:
        return [{"name": n, "labels": dict(lbl), "value": v} for (n, lbl), v in _values.items()]


def reset() -> None:
    """Forget this process' numbers (tests)."""
    with _lock:
        _values.clear()


def _flush() -> None:
    if _dir is None:
        return
    try:
        _dir.mkdir(parents=True, exist_ok=True)
        path = _dir / f"{socket.gethostname()}-{os.getpid()}.json"
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(snapshot()))
        os.replace(tmp, path)
    except OSError:
        # Metrics must never fail an analysis; a missed snapshot is replaced by the next one.
        pass


def _escape(value: str) -> str:
    return value.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n")


def render_prometheus(metrics_dir: str | os.PathLike | None = None) -> str:
    """Prometheus text exposition (format 0.0.4) of every worker's metrics.

    Parameters
    ----------
    metrics_dir
        Folder of worker snapshots (``WorkerSettings.metrics_dir``); all are summed. None: this
        process' in-memory numbers only.
    """
    totals: dict[tuple[str, tuple[tuple[str, str], ...]], float] = defaultdict(float)
    if metrics_dir is None:
        rows = snapshot()
    else:
        rows = []
        for path in sorted(Path(metrics_dir).glob("*.json")):
            try:
                rows.extend(json.loads(path.read_text()))
            except (OSError, ValueError):
                continue  # being replaced right now or truncated: skip this scrape
    for row in rows:
        totals[(row["name"], tuple(sorted(row["labels"].items())))] += float(row["value"])
    lines: list[str] = []
    for name, (kind, help_text) in METRICS.items():
        series = sorted(k for k in totals if k[0] == name or k[0].rsplit("_", 1)[0] == name)
        lines.append(f"# HELP {name} {help_text}")
        lines.append(f"# TYPE {name} {kind}")
        for series_name, labels in series:
            label_text = ",".join(f'{k}="{_escape(v)}"' for k, v in labels)
            label_text = "{" + label_text + "}" if label_text else ""
            lines.append(f"{series_name}{label_text} {totals[(series_name, labels)]:g}")
    return "\n".join(lines) + "\n"
