"""Worker settings, all from the environment so a container is configured by its compose file.

=========================  ==================================================================
variable                   meaning (default)
=========================  ==================================================================
COACH_DATA_DIR             the data directory shared by api and workers (``./data``)
COACH_BROKER_URL           ``embedded`` (default): kombu's filesystem transport under
                           ``$COACH_DATA_DIR/celery/broker``, no server needed; or a Celery
                           broker URL such as ``redis://redis:6379/0``
COACH_RESULT_BACKEND       default: ``file://$COACH_DATA_DIR/celery/results`` when embedded,
                           the broker URL when it is Redis
COACH_CHUNKS               stage-3 chunks per analysis when the settings do not say (8)
COACH_PROVISIONAL_MIN_WAIT_S  the first segments' provisional result is computed only when
                           the rest of stage 3 is expected to take at least this long, s (5)
COACH_VISIBILITY_TIMEOUT_S Redis visibility timeout, seconds (7200): when Redis hands an
                           unacknowledged message out again by itself; the API's recovery
                           (``app.core.recovery``) acts long before, on the heartbeat
COACH_RESTORE_INTERVAL_S   how often a Redis worker looks for messages a dead worker left
                           unacknowledged past the visibility timeout, seconds (60)
COACH_HEARTBEAT_S          how often a running task renews its analysis' heartbeat, s (5)
COACH_LOST_AFTER_S         a heartbeat older than this means nobody runs the analysis, s (60);
                           the API reads the same variable
COACH_MAX_CRASHES          a stage whose runs killed their worker process this many times is
                           failed instead of run again (2)
COACH_<STAGE>_SOFT_S /     soft and hard time limits per task, seconds, STAGE one of
COACH_<STAGE>_HARD_S       ANALYZE, PREPARE, CANDIDATES, SELECT (see ``DEFAULT_LIMITS_S``)
COACH_MAX_RETRIES          retries of a transient error before the analysis is failed (5)
COACH_SEQUENTIAL           1: the entry task runs every stage itself instead of launching a
                           prepare -> chord(candidates chunks) -> select canvas
                           (default: see ``SEQUENTIAL_WHEN_EMBEDDED``)
=========================  ==================================================================
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

EMBEDDED = "embedded"

#: (soft, hard) time limits per task, seconds. Why each:
#: - analyze: only builds and launches the canvas (milliseconds); in embedded-sequential mode it
#:   runs every stage itself, so it then gets the sum of the stage budgets (see ``limits_for``).
#: - prepare: stages 0-2 on the whole video; stage 2 renders L x rotations silhouettes and
#:   compares L' x band pairs, minutes for a 339-frame clip on one core, so 30 min is a generous
#:   ceiling that still frees a stuck worker within the hour.
#: - candidates: one chunk of stage-3 belief propagation; the dominant cost, spread over chunks,
#:   same ceiling as prepare.
#: - select: a DP over (t', t, l) per segment, cheap next to stage 3; 10 min.
#: - capture: a reference-free capture (pose model + lifting), about 0.05 s per frame; a
#:   two-minute video at 60 fps takes a few minutes, so 15 min.
#: The hard limit is the soft one plus a minute, so the soft-limit handler has time to record the
#: failure in status.json before the process is killed.
DEFAULT_LIMITS_S: dict[str, tuple[int, int]] = {
    "analyze": (60, 120),
    "prepare": (30 * 60, 31 * 60),
    "candidates": (30 * 60, 31 * 60),
    "select": (10 * 60, 11 * 60),
    "capture": (15 * 60, 16 * 60),
}


#: Whether embedded mode runs the stages inside the entry task rather than as a canvas.
SEQUENTIAL_WHEN_EMBEDDED = False


def _env_bool(env: dict, name: str, default: bool) -> bool:
    raw = env.get(name)
    if raw is None or raw == "":
        return default
    return raw.strip().lower() in ("1", "true", "yes", "on")


def _env_float(env: dict, name: str, default: float) -> float:
    raw = env.get(name)
    if raw is None or raw == "":
        return default
    try:
        return float(raw)
    except ValueError:
        raise ValueError(f"{name} must be a number of seconds, got {raw!r}") from None


def _env_int(env: dict, name: str, default: int) -> int:
    raw = env.get(name)
    if raw is None or raw == "":
        return default
    try:
        return int(float(raw))
    except ValueError:
        raise ValueError(f"{name} must be a number of seconds or a count, got {raw!r}") from None


@dataclass(frozen=True)
class WorkerSettings:
    """Resolved worker settings; build with :meth:`from_env`."""

    data_dir: Path
    broker_url: str
    result_backend: str
    # More chunks than cores, so chunks finish one after another from the start of the video
    # and the first segments' provisional result comes early (benchmarks/README.md, "First
    # results"): on P2 8 chunks gave it 12 s before the final result, 4 none, at the same total.
    chunks: int = 8
    visibility_timeout_s: int = 7200
    restore_interval_s: int = 60
    heartbeat_s: float = 5.0
    lost_after_s: float = 60.0
    max_crashes: int = 2
    provisional_min_wait_s: float = 5.0
    max_retries: int = 5
    sequential: bool = False
    limits_s: dict[str, tuple[int, int]] = field(default_factory=lambda: dict(DEFAULT_LIMITS_S))

    @property
    def embedded(self) -> bool:
        return self.broker_url.startswith("filesystem://")

    @property
    def celery_dir(self) -> Path:
        return self.data_dir / "celery"

    @property
    def broker_dir(self) -> Path:
        return self.celery_dir / "broker"

    @property
    def tasks_dir(self) -> Path:
        """Where :func:`worker.celery_app.enqueue` notes task id -> analysis folder for revoke."""
        return self.celery_dir / "tasks"

    @property
    def metrics_dir(self) -> Path:
        return self.data_dir / "metrics"

    def limits_for(self, stage: str) -> tuple[int, int]:
        return self.limits_s[stage]

    def sequential_limits(self) -> tuple[int, int]:
        """Limits of the entry task when it runs every stage itself (embedded mode)."""
        soft = sum(self.limits_s[s][0] for s in ("prepare", "candidates", "select"))
        return soft, soft + 60

    @classmethod
    def from_env(
        cls, env: dict | None = None, *, data_dir: str | os.PathLike | None = None
    ) -> WorkerSettings:
        env = dict(os.environ if env is None else env)
        root = Path(data_dir or env.get("COACH_DATA_DIR") or "data").expanduser().resolve()
        broker = env.get("COACH_BROKER_URL") or EMBEDDED
        if broker == EMBEDDED:
            # A host part keeps kombu from warning "No hostname was supplied" on every connect.
            broker = "filesystem://localhost//"
        backend = env.get("COACH_RESULT_BACKEND") or ""
        if not backend:
            if broker.startswith("filesystem://"):
                backend = f"file://{root / 'celery' / 'results'}"
            else:
                backend = broker
        embedded = broker.startswith("filesystem://")
        limits = {}
        for stage, (soft, hard) in DEFAULT_LIMITS_S.items():
            key = stage.upper()
            soft = _env_int(env, f"COACH_{key}_SOFT_S", soft)
            hard = _env_int(env, f"COACH_{key}_HARD_S", max(hard, soft + 60))
            if hard <= soft:
                raise ValueError(
                    f"COACH_{key}_HARD_S ({hard}) must exceed COACH_{key}_SOFT_S ({soft})"
                )
            limits[stage] = (soft, hard)
        chunks = _env_int(env, "COACH_CHUNKS", 8)
        if chunks < 1:
            raise ValueError(f"COACH_CHUNKS must be >= 1, got {chunks}")
        heartbeat = _env_float(env, "COACH_HEARTBEAT_S", 5.0)
        lost_after = _env_float(env, "COACH_LOST_AFTER_S", 60.0)
        # Several missed beats before "lost": a busy shared volume may delay one or two.
        if not 0 < 3 * heartbeat <= lost_after:
            raise ValueError(
                f"COACH_LOST_AFTER_S ({lost_after}) must be at least three times "
                f"COACH_HEARTBEAT_S ({heartbeat}), which must be > 0"
            )
        max_crashes = _env_int(env, "COACH_MAX_CRASHES", 2)
        if max_crashes < 1:
            raise ValueError(f"COACH_MAX_CRASHES must be >= 1, got {max_crashes}")
        min_wait = _env_float(env, "COACH_PROVISIONAL_MIN_WAIT_S", 5.0)
        if min_wait < 0:
            raise ValueError(f"COACH_PROVISIONAL_MIN_WAIT_S must be >= 0, got {min_wait}")
        return cls(
            data_dir=root,
            broker_url=broker,
            result_backend=backend,
            chunks=chunks,
            visibility_timeout_s=_env_int(env, "COACH_VISIBILITY_TIMEOUT_S", 7200),
            restore_interval_s=_env_int(env, "COACH_RESTORE_INTERVAL_S", 60),
            heartbeat_s=heartbeat,
            lost_after_s=lost_after,
            max_crashes=max_crashes,
            provisional_min_wait_s=min_wait,
            max_retries=_env_int(env, "COACH_MAX_RETRIES", 5),
            sequential=_env_bool(env, "COACH_SEQUENTIAL", SEQUENTIAL_WHEN_EMBEDDED and embedded),
            limits_s=limits,
        )
