"""The `physpose` command line: one subcommand module per stage, registered below."""

from __future__ import annotations

import argparse
import errno
import importlib
import os
import re
import select
import signal
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


# Options whose value may start with a minus sign. argparse takes "--person -10,20" for an
# option followed by another option; main() joins such a pair as "--person=-10,20", so the
# value reaches its own check (which says what is wrong with it).
SIGNED_VALUE_OPTIONS = ("--person",)
_SIGNED_VALUE = re.compile(r"^-[\d.]")


def join_signed_values(argv: list[str]) -> list[str]:
    joined: list[str] = []
    for arg in argv:
        if joined and joined[-1] in SIGNED_VALUE_OPTIONS and _SIGNED_VALUE.match(arg):
            joined[-1] = f"{joined[-1]}={arg}"
        else:
            joined.append(arg)
    return joined


def stand_in_for_closed_streams() -> None:
    """Give a process started with stdout or stderr closed (`2>&-`, some schedulers), in which
    Python sets them to None, os.devnull instead: progress bars and messages would otherwise
    crash the run before it writes its files."""
    for name in ("stdout", "stderr"):
        if getattr(sys, name) is None:
            setattr(sys, name, open(os.devnull, "w"))  # noqa: SIM115 (for the process' life)


def stdout_gone() -> bool:
    """Whether stdout is a pipe whose reader has closed it."""
    try:
        fd = sys.stdout.fileno()
    except (AttributeError, OSError, ValueError):
        return False
    poller = select.poll()
    poller.register(fd, select.POLLOUT)
    return any(events & select.POLLERR for _, events in poller.poll(0))


OPENCV_ERRORS_ONLY = 2  # cv2.setLogLevel's level for errors and worse


def quiet_opencv() -> None:
    """Keep OpenCV's own warnings (e.g. "[ WARN:0@11.6] global cap.cpp:215 open
    VIDEOIO(FFMPEG): backend is generally available but can't be used to capture by name"
    before physpose says why a file is not a video) off the terminal; physpose reports what
    went wrong itself. Set by the command line only: a library caller keeps its own level."""
    import cv2  # noqa: PLC0415 (not needed to print help)

    cv2.setLogLevel(OPENCV_ERRORS_ONLY)


def main(argv: list[str] | None = None) -> int:
    stand_in_for_closed_streams()
    argv = sys.argv[1:] if argv is None else argv
    args = build_parser().parse_args(join_signed_values(argv))
    quiet_opencv()
    try:
        return int(args.func(args) or 0)
    except PhysposeError as err:
        print(f"physpose {args.command}: error: {err}", file=sys.stderr)
        return 2
    except OSError as err:  # the file system refused: a path that is missing, wrong or locked
        if isinstance(err, BrokenPipeError) and stdout_gone():
            # Not the file system: the reader of the output went away (`physpose ... | head`).
            # Stop quietly, as a tool that SIGPIPE ends does (the files written so far stay).
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 128 + signal.SIGPIPE
        where = f"{err.filename}: " if err.filename else ""
        remedy = ("free some space there and run the same command again (work finished so "
                  "far is kept)" if err.errno in (errno.ENOSPC, errno.EDQUOT) else
                  "check that the path exists, is a folder or a file as the option asks, and "
                  "that you may read and write there")
        print(f"physpose {args.command}: error: {where}{err.strerror or err}. {remedy}",
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        # On a line of its own: a progress bar may have the cursor.
        print(f"\nphyspose {args.command}: interrupted. Run the same command again to resume: "
              "the stages, kinematic-fit steps and physics windows finished so far are kept",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
