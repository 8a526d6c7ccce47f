"""A command whose standard output is closed under it ends quietly.

``dam_experiment ... | head -2`` ended with a ``BrokenPipeError`` traceback: ``head`` exits
after its lines, and the command's next write (or the interpreter's last flush) fails. Every
command-line entry point of the suite runs inside :func:`quiet_when_output_closed`: there a
closed standard output ends the command at once with :data:`OUTPUT_CLOSED` (141, the status a
shell gives a process that SIGPIPE ended) and no traceback, as ``cat``, ``grep`` and the other
Unix tools end. Python ignores SIGPIPE (it raises ``BrokenPipeError`` instead), and the suite
keeps it ignored: SIGPIPE's default action would end a node or a Dask worker on any write to a
closed socket.

Pure Python: the entry points use it before anything heavy is imported.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable
from typing import ParamSpec, TypeVar

#: Exit status of a command whose standard output was closed (128 + SIGPIPE, as a shell says).
OUTPUT_CLOSED = 141

P = ParamSpec('P')
R = TypeVar('R')


def quiet_when_output_closed(entry: Callable[P, R]) -> Callable[P, R]:
    """``entry`` (an entry point or a command's ``main``), ending the process with
    :data:`OUTPUT_CLOSED` and no traceback when its standard output is closed.

    The standard output is flushed before the command returns or exits, so that output still
    buffered meets the closed pipe here, not in the interpreter's last flush (which would
    print "Exception ignored ... BrokenPipeError").
    """

    @functools.wraps(entry)
    def wrapped(*args: P.args, **kwargs: P.kwargs) -> R:
        try:
            try:
                result = entry(*args, **kwargs)
            except SystemExit:
                _flush()
                raise
            _flush()
            return result
        except BrokenPipeError:
            output_closed()

    return wrapped


def output_closed() -> None:
    """End the process with :data:`OUTPUT_CLOSED`: standard output goes to ``/dev/null`` first,
    so that nothing more (the interpreter's last flush) fails on the closed pipe."""
    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError, AttributeError):  # no file descriptor behind sys.stdout
        pass
    raise SystemExit(OUTPUT_CLOSED)


def _flush() -> None:
    stdout = sys.stdout
    if stdout is not None and not stdout.closed:
        stdout.flush()
