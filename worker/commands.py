"""`coach worker`: run a Celery worker for the analysis tasks (added by ``app.commands``).

Settings come from the environment (:mod:`worker.settings`): ``COACH_BROKER_URL`` (a Redis URL
when scaled out; ``embedded`` for the local filesystem broker), ``COACH_DATA_DIR``, ...
"""

from __future__ import annotations

import argparse
import os


def register(subparsers: argparse._SubParsersAction) -> None:
    p = subparsers.add_parser(
        "worker",
        help="run a Celery worker for analyses (broker from COACH_BROKER_URL)",
        description="Run a Celery worker for analyses; settings from COACH_* variables.",
    )
    p.add_argument(
        "--concurrency",
        "-c",
        type=int,
        default=None,
        help="worker processes (default: number of CPUs)",
    )
    p.add_argument(
        "--loglevel",
        "-l",
        default="INFO",
        choices=["DEBUG", "INFO", "WARNING", "ERROR", "CRITICAL"],
        type=str.upper,
    )
    p.add_argument("--hostname", "-n", default=None, help="node name (default: celery@%%h)")
    p.add_argument("--data-dir", default=None, help="data directory (default: COACH_DATA_DIR)")
    p.add_argument("--queues", "-Q", default=None, help="comma-separated queues (default: coach)")
    p.set_defaults(func=run)


def worker_argv(args: argparse.Namespace) -> list[str]:
    """The ``celery worker`` arguments for parsed ``coach worker`` arguments."""
    argv = ["worker", "--loglevel", args.loglevel]
    if args.concurrency is not None:
        if args.concurrency < 1:
            raise SystemExit(f"coach worker: --concurrency must be >= 1, got {args.concurrency}")
        argv += ["--concurrency", str(args.concurrency)]
    if args.hostname:
        argv += ["--hostname", args.hostname]
    if args.queues:
        argv += ["--queues", args.queues]
    return argv


def run(args: argparse.Namespace) -> int:
    if args.data_dir:
        os.environ["COACH_DATA_DIR"] = str(args.data_dir)
    from worker import celery_app  # configured from the environment on import

    celery_app.configure()
    celery_app.app.worker_main(worker_argv(args))
    return 0
