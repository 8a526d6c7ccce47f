"""Entry points of the experiments' commands: a signal at any moment is a clean stop.

SIGINT and SIGTERM are caught before anything heavy is imported (numpy, PyBullet, the
analysis, Dask), so that a signal during start-up ends the command with one line and exit
status 130, as one during its work does, never with a traceback from the import machinery.
Each command's own ``main`` handles the signals of its work (kept rows, resumable tables).
"""

from __future__ import annotations

import importlib
import signal
import sys

#: Exit status of a command stopped by SIGINT or SIGTERM (128 + SIGINT, the shell's).
INTERRUPTED = 130


class _Signals:
    """SIGINT and SIGTERM raise :class:`KeyboardInterrupt`; remembers that one came."""

    def __init__(self) -> None:
        self.received = False
        for signum in (signal.SIGINT, signal.SIGTERM):
            signal.signal(signum, self)

    def __call__(self, signum: int, frame: object) -> None:
        self.received = True
        raise KeyboardInterrupt


def _run(module: str, prog: str) -> None:
    signals = _Signals()  # (a background job's ignored SIGINT is caught too: kill -INT works)
    try:
        status = importlib.import_module(module).main()
    except KeyboardInterrupt:
        status = _interrupted(prog)
    except Exception:
        if not signals.received:
            raise
        status = _interrupted(prog)  # the interrupt surfaced as another error (an extension's)
    sys.exit(status)


def _interrupted(prog: str) -> int:
    """The line and status of an interrupt the command's ``main`` did not report itself."""
    sys.stderr.write(f'{prog}: interrupted\n')
    return INTERRUPTED


def dam_experiment() -> None:
    """``ros2 run dam_experiments dam_experiment``."""
    _run('dam_experiments.experiment', 'dam_experiment')


def sweep() -> None:
    """``ros2 run dam_experiments sweep``."""
    _run('dam_experiments.sweep_cli', 'sweep')


def sweep_plot() -> None:
    """``ros2 run dam_experiments sweep_plot``."""
    _run('dam_experiments.sweep_plot', 'sweep_plot')


def sweep_report() -> None:
    """``ros2 run dam_experiments sweep_report``."""
    _run('dam_experiments.sweep_report_cli', 'sweep_report')
