"""The `coach` command: engine subcommands plus the service's `serve` and `worker`.

Service modules are imported only when their command runs, so the engine commands work on
an install without the api/worker extras.
"""

from __future__ import annotations

import argparse

from engine.cli import add_engine_commands, run_parsed


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="coach", description="Motion coach: register a video against a 3D reference motion."
    )
    sub = parser.add_subparsers(dest="command", required=True)
    add_engine_commands(sub)
    try:
        from app import commands as service_commands
    except ImportError:  # the api extra is not installed: engine commands only
        service_commands = None
    if service_commands is not None:
        service_commands.register(sub)
    try:
        from web import commands as web_commands
    except ImportError:  # the viewer extra is not installed
        web_commands = None
    if web_commands is not None:
        web_commands.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    return run_parsed(build_parser().parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
