"""The `coach` command: engine subcommands plus those the packages declare.

``serve``, ``worker`` (app) and ``view`` (web) come from the ``coach.commands`` entry points
in pyproject.toml, so this module imports no package above the engine by name, and a package
whose extra is not installed simply adds no command.
"""

from __future__ import annotations

import argparse
from importlib.metadata import entry_points

from worker.engine_surface import add_engine_commands, run_parsed

#: Entry-point group of ``register(subparsers)`` functions that add subcommands.
COMMANDS = "coach.commands"


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="coach", description="Motion coach: register a video against a 3D reference motion."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    add_engine_commands(sub)
    for ep in sorted(entry_points(group=COMMANDS), key=lambda e: e.name):
        try:
            register = ep.load()
        except ImportError:  # that package's extra is not installed
            continue
        register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    return run_parsed(build_parser().parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
