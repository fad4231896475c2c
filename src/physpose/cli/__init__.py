"""The `physpose` command line: one subcommand module per stage, registered below."""

from __future__ import annotations

import argparse
import importlib
import sys

from physpose import __version__
from physpose.errors import PhysposeError

# Subcommand modules under physpose.cli; each defines `register(subparsers)` which adds its
# parser and sets `func(args) -> int` as the handler.
SUBCOMMANDS: tuple[str, ...] = (
    "data",
    "observe",
    "demo",
    "body",
    "export",
    "benchmark",
    "compare",
    "reconstruct",
    "fit",
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="physpose",
        description="Physically plausible 3d human motion from a monocular video.",
    )
    parser.add_argument("--version", action="version", version=f"physpose {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for name in SUBCOMMANDS:
        importlib.import_module(f"physpose.cli.{name}").register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except PhysposeError as err:
        print(f"physpose {args.command}: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # the file system refused: a path that is missing, wrong or locked
        where = f"{err.filename}: " if err.filename else ""
        print(f"physpose {args.command}: error: {where}{err.strerror or err}. check that the "
              "path exists, is a folder or a file as the option asks, and that you may read "
              "and write there", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"physpose {args.command}: interrupted; finished work is kept (rerun to resume)",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
