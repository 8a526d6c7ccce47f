"""What C code writes to standard output, sent to /dev/null while PyBullet connects.

PyBullet prints ``argv[0]=`` from C at every connection, straight to file descriptor 1: a line
per trial in the middle of a sweep's progress bar (:mod:`dam_experiments.sweep`) and of
``dam_experiment``'s table (:mod:`dam_experiments.experiment`). :func:`quiet_stdout` points
descriptor 1 at /dev/null meanwhile. Standard library only.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import threading
from collections.abc import Iterator

_STDOUT_LOCK = threading.Lock()


@contextlib.contextmanager
def quiet_stdout() -> Iterator[None]:
    """Send what C code writes to file descriptor 1 to /dev/null meanwhile: PyBullet prints
    ``argv[0]=`` at every connection, a line per trial in the middle of the progress bar.
    One thread at a time (a Dask worker may run trials in threads)."""
    with _STDOUT_LOCK:
        try:
            sys.stdout.flush()
            saved = os.dup(1)
        except (OSError, ValueError, AttributeError):  # no usable stdout: nothing to protect
            yield
            return
        devnull = os.open(os.devnull, os.O_WRONLY)
        try:
            os.dup2(devnull, 1)
            yield
        finally:
            ctypes.CDLL(None).fflush(None)  # what C buffered goes to /dev/null too
            os.dup2(saved, 1)
            os.close(saved)
            os.close(devnull)
