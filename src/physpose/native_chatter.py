"""MediaPipe's native log lines, kept off the terminal.

MediaPipe 0.10.21 and the TensorFlow Lite inside it write informational and warning lines from
C++ straight to file descriptor 2 while a detector's graph starts, from its own threads ("INFO:
Created TensorFlow Lite XNNPACK delegate for CPU.", and absl lines such as "W0000
00:00:1796184456.900044 5344 inference_feedback_manager.cc:114] Feedback manager requires
..."). No Python setting or environment variable of that version silences them; they break
into physpose's progress bars and say nothing a user could act on.

`filtered()` points descriptor 2 at a pipe for the duration of a block, and a thread forwards
what arrives to the real stderr as it comes, less those lines: a progress bar, a warning, an
absl error (E, F) or anything else still reaches the terminal at once. A line that starts as
absl's do ("I" or "W") is held until its end arrives.
"""

from __future__ import annotations

import contextlib
import os
import re
import sys
import threading
from collections.abc import Iterator

STDERR = 2
JOIN_SECONDS = 5.0  # a child process that inherited the pipe may keep it open; stop waiting then

# absl's info and warning lines ("I" or "W", month and day, time of day (before absl is set up:
# 00:00 and the seconds since the epoch), thread, file:line]) and the two fixed lines
# TensorFlow Lite and absl print before absl's logging is set up.
_CHATTER = re.compile(rb"[IW]\d{4} \d\d:\d\d:\d+\.\d+ +\d+ [\w./-]+:\d+\] "
                      rb"|INFO: Created TensorFlow Lite XNNPACK delegate for CPU\."
                      rb"|WARNING: All log messages before absl::InitializeLog\(\) is called "
                      rb"are written to STDERR")
_HELD = (b"I", b"W")  # first bytes of an unfinished line that may turn out to be chatter


def is_chatter(line: bytes) -> bool:
    """Whether a line on stderr is MediaPipe's native info or warning output."""
    return _CHATTER.match(line) is not None


def forward(source: int, sink: int) -> None:
    """Copy descriptor ``source`` to ``sink`` until end of file, dropping chatter lines."""
    pending = b""
    while chunk := os.read(source, 1 << 16):
        *lines, pending = (pending + chunk).split(b"\n")
        out = b"".join(line + b"\n" for line in lines if not is_chatter(line))
        if pending and not pending.startswith(_HELD):
            out, pending = out + pending, b""
        if out:
            os.write(sink, out)
    if pending and not is_chatter(pending):
        os.write(sink, pending)


@contextlib.contextmanager
def filtered() -> Iterator[None]:
    """Run the block with descriptor 2 forwarded through `forward` (see the module's doc).

    Where descriptor 2 cannot be duplicated (closed), the block runs with it untouched.
    """
    _flush_python_stderr()
    try:
        terminal = os.dup(STDERR)
    except OSError:
        yield
        return
    source, pipe_in = os.pipe()
    os.dup2(pipe_in, STDERR)
    os.close(pipe_in)
    forwarder = threading.Thread(target=forward, args=(source, terminal), daemon=True,
                                 name="native-chatter")
    forwarder.start()
    try:
        yield
    finally:
        _flush_python_stderr()
        os.dup2(terminal, STDERR)  # closes the pipe's write end: the forwarder reads its end
        forwarder.join(JOIN_SECONDS)
        if not forwarder.is_alive():  # else left to the daemon thread, which still uses them
            os.close(source)
            os.close(terminal)


def _flush_python_stderr() -> None:
    """Write out what Python buffered for stderr before descriptor 2 changes (none: no stream)."""
    if sys.stderr is not None:
        sys.stderr.flush()
