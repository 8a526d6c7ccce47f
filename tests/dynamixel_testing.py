"""What the tests that run the SDK against the emulated bus in one process share."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager


@contextmanager
def fast_gil_handoff() -> Iterator[None]:
    """The host (the SDK polls the port in a busy loop) and the emulated bus share this
    process's GIL in these tests; with the default 5 ms switch interval a sync read can outlast
    the SDK's ~34 ms packet timeout. (In use the bus runs in a process of its own.)"""
    before = sys.getswitchinterval()
    sys.setswitchinterval(0.0005)
    try:
        yield
    finally:
        sys.setswitchinterval(before)
