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

from dam_common.closed_output import quiet_when_output_closed

#: Exit status of a command stopped by SIGINT or SIGTERM (128 + SIGINT, the shell's).
INTERRUPTED = 130


class InterruptOnSignals:
    """Within ``with``: SIGINT and SIGTERM raise :class:`KeyboardInterrupt` (SIGINT too when a
    shell started the command as a background job, which ignores it: ``kill -INT`` stops it as
    it stops a node); ``received`` says one came. The previous handlers are restored after."""

    def __init__(self) -> None:
        self.received = False
        self._previous: dict[int, object] = {}

    def __enter__(self) -> InterruptOnSignals:
        self._previous = {signum: signal.signal(signum, self._interrupt)
                          for signum in (signal.SIGINT, signal.SIGTERM)}
        return self

    def __exit__(self, *exc: object) -> None:
        for signum, handler in self._previous.items():
            signal.signal(signum, handler)

    def _interrupt(self, signum: int, frame: object) -> None:
        self.received = True
        raise KeyboardInterrupt


@quiet_when_output_closed  # `| head`: status 141, no traceback
def _run(module: str, prog: str) -> None:
    with InterruptOnSignals() as signals:
        try:
            status = importlib.import_module(module).main()
        except KeyboardInterrupt:
            status = _interrupted(prog)
        except Exception:
            if not signals.received:
                raise
            status = _interrupted(prog)  # the interrupt surfaced as another error
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


def calibrate_csm() -> None:
    """``ros2 run dam_experiments calibrate_csm``."""
    _run('dam_experiments.calibrate_csm', 'calibrate_csm')
