"""The engine's command-line subcommands (`coach synth`, `coach align`, ...).

Each subcommand lives in its own module under :mod:`engine.commands` with two functions,
``register(subparsers)`` and ``run(args) -> int``; this file only collects them, so adding a
command never touches another's code. The service commands (`serve`, `worker`) are added by
``app.cli``, which is the installed ``coach`` entry point.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

from engine.errors import EngineError


def add_engine_commands(sub: argparse._SubParsersAction) -> None:
    """Register every module of :mod:`engine.commands` on ``sub``."""
    import engine.commands as pkg

    for info in sorted(pkgutil.iter_modules(pkg.__path__), key=lambda i: i.name):
        module = importlib.import_module(f"engine.commands.{info.name}")
        module.register(sub)


def run_parsed(args: argparse.Namespace) -> int:
    """Run a parsed command; engine errors become a one-line message and exit code 2."""
    try:
        return int(args.func(args) or 0)
    except EngineError as exc:
        print(f"coach: error: {exc}", file=sys.stderr)
        return 2


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="coach", description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    add_engine_commands(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    return run_parsed(build_parser().parse_args(argv))
