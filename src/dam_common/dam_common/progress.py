"""A line on standard error every few seconds while a command works (no rclpy).

Commands that can be silent for longer than a few seconds (``plan_lift`` waiting for its
answer, ``bag plot`` and ``bag export`` reading a bag, ``lift_map`` computing a friction
angle) say what they are doing, how far they are and for how long, as the sweeps do::

    bag plot: reading messages 412,000 of 1,200,000 (34 %), 10 s
    plan_lift: waiting for the answer of /plan_lift, 15 s

The line comes from a daemon thread every :func:`period_s` seconds (``DAM_PROGRESS_S``,
default 5 s; 0 turns the lines off), so the work itself is not interrupted; nothing is
printed by a command that finishes within the period. A work loop deep inside a library
reports through :func:`current` (the innermost active :class:`Progress` of this thread)
without being handed one.
"""

from __future__ import annotations

import contextvars
import math
import os
import sys
import threading
import time
from typing import TextIO

#: The default time between two lines [s].
DEFAULT_PERIOD_S = 5.0
#: Environment variable with the time between two lines [s]; 0: no lines.
PERIOD_ENV = 'DAM_PROGRESS_S'

_CURRENT: contextvars.ContextVar[Progress | None] = contextvars.ContextVar(
    'dam_progress', default=None)


def period_s() -> float:
    """The time between two progress lines [s]: ``DAM_PROGRESS_S``, else 5 (0: none).

    A value that is not a finite number >= 0 is ignored (the default applies)."""
    text = os.environ.get(PERIOD_ENV, '')
    try:
        value = float(text)
    except ValueError:
        return DEFAULT_PERIOD_S
    return value if math.isfinite(value) and value >= 0.0 else DEFAULT_PERIOD_S


def current() -> Progress | None:
    """The innermost active :class:`Progress` of this thread (``None`` outside any)."""
    return _CURRENT.get()


class Progress:
    """Report a long piece of work on ``stream`` every ``period`` seconds while it runs.

    Use as a context manager::

        with Progress('bag plot', 'working') as progress:
            progress.stage('reading messages', total=n)
            for ...:
                progress.advance()

    Parameters
    ----------
    prog
        The command's name, the line's prefix.
    what
        What it does (``'waiting for the answer of /plan_lift'``).
    total
        How many steps the work has (``None``: unknown; the line then shows no fraction).
    unit
        The steps' unit, for the line (``'messages'``; may be empty).
    period
        Time between two lines [s]; default :func:`period_s`; 0: no lines.
    stream
        Where the lines go (default standard error).
    """

    def __init__(self, prog: str, what: str, total: int | None = None, *,
                 period: float | None = None, stream: TextIO | None = None) -> None:
        self.prog = prog
        self.base = what
        self.what = what
        self.total = total
        self.done = 0
        self.period = period_s() if period is None else float(period)
        self.stream = sys.stderr if stream is None else stream
        self.lines = 0
        self._start = time.monotonic()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._token: contextvars.Token[Progress | None] | None = None

    def stage(self, what: str, total: int | None = None) -> None:
        """Begin a new stage: ``what`` with ``total`` steps (the count restarts at 0)."""
        self.what, self.total, self.done = what, total, 0

    def end_stage(self, note: str = '') -> None:
        """Back to the work's own description, with ``note`` (e.g. what the stage did)."""
        self.what = f'{self.base} ({note})' if note else self.base
        self.total, self.done = None, 0

    def advance(self, steps: int = 1) -> None:
        """``steps`` more steps of the stage done."""
        self.done += steps

    def line(self) -> str:
        """The progress line as it would be printed now."""
        elapsed = time.monotonic() - self._start
        text = f'{self.prog}: {self.what}'
        if self.total:
            text += (f' {self.done:,} of {self.total:,} '
                     f'({100.0 * min(self.done, self.total) / self.total:.0f} %)')
        return f'{text}, {elapsed:.0f} s'

    def _run(self) -> None:
        while not self._stop.wait(self.period):
            try:
                print(self.line(), file=self.stream, flush=True)
            except (OSError, ValueError):  # the stream went away: stop reporting
                return
            self.lines += 1

    def __enter__(self) -> Progress:
        self._start = time.monotonic()
        self._token = _CURRENT.set(self)
        if self.period > 0.0:
            self._thread = threading.Thread(target=self._run, name=f'{self.prog}-progress',
                                            daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *_exc: object) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        if self._token is not None:
            _CURRENT.reset(self._token)
            self._token = None
