"""The ``dynamixel_bus`` program: the simulated hand as nine Dynamixel servos, without ROS.

``ros2 run dam_sim_bridge dynamixel_bus`` (the console script
:func:`dam_sim_bridge.entry_points.dynamixel_bus`) or ``python -m
dam_sim_bridge.dynamixel_bus_program`` builds a
:class:`~dam_sim_bridge.dynamixel_standin.DynamixelStandIn`, prints ``DYNAMIXEL_PORT <path>``
as the first and only line of its standard output, and serves the bus until SIGINT or SIGTERM.

What the C libraries print while the world is built (PyBullet's ``argv[0]=``) goes to standard
error: file descriptor 1 points there meanwhile, and C stdio's buffers are flushed before it
points back (when standard output is a pipe, C stdio holds such a line until it is flushed).

The module imports nothing heavy at its top (the stand-in, PyBullet and numpy come in
:func:`main`), so that the entry point catches the signals first.
"""

from __future__ import annotations

import argparse
import contextlib
import ctypes
import os
import sys
import threading
from collections.abc import Iterator, Sequence

from dam_common.command_line import CommandLineParser
from dam_sim_bridge.dynamixel_bus import WATCHDOG_FEED_ADDRESSED, WATCHDOG_FEEDS

#: The program's name in its usage and messages.
PROG = 'dynamixel_bus'


def _parser() -> argparse.ArgumentParser:
    parser = CommandLineParser(
        prog=PROG, description='Serve the simulated hand as nine Dynamixel servos on a '
        'pseudo-terminal; print "DYNAMIXEL_PORT <path>" and run until SIGINT or SIGTERM.')
    parser.add_argument('--config', metavar='FILE', help='configuration file (default: the '
                        'installed or source-tree config/dam.yaml)')
    parser.add_argument('--object', metavar='NAME', default='',
                        help='an object of the configuration\'s library')
    parser.add_argument('--link', metavar='PATH', help='also make PATH a symlink to the pty')
    parser.add_argument('--sim-time', action='store_true',
                        help='lockstep: the world steps one period per read of Present '
                        'Position')
    parser.add_argument('--watchdog-feed', choices=WATCHDOG_FEEDS,
                        default=WATCHDOG_FEED_ADDRESSED,
                        help='which instruction packets feed a servo\'s Bus Watchdog: '
                        'addressed (its ID, plain broadcasts, sync and bulk packets that list '
                        'it; the default) or any (every packet on the bus)')
    return parser


def _flush_c_stdio() -> None:
    """``fflush(NULL)``: write out what C code left in its stdio buffers (no-op where the C
    library cannot be loaded)."""
    try:
        libc = ctypes.CDLL(None)
        libc.fflush(None)
    except (OSError, AttributeError):
        pass


@contextlib.contextmanager
def _stdout_to_stderr() -> Iterator[None]:
    """File descriptor 1 goes to stderr meanwhile (C libraries' prints included, their
    buffered output flushed before it comes back)."""
    sys.stdout.flush()
    saved = os.dup(1)
    try:
        os.dup2(2, 1)
        yield
    finally:
        sys.stdout.flush()
        _flush_c_stdio()
        os.dup2(saved, 1)
        os.close(saved)


def main(argv: Sequence[str] | None = None) -> int:
    """``dynamixel_bus``: build the world and the bus, print the port line, serve.

    Stops cleanly on SIGINT and SIGTERM when started by
    :func:`dam_sim_bridge.entry_points.dynamixel_bus` (which catches them).

    Parameters
    ----------
    argv
        The arguments (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        0 after a stop request; 2 for a bad argument or configuration (usage error).
    """
    from dam_common.config import load_config  # noqa: PLC0415
    from dam_common.errors import ConfigError  # noqa: PLC0415
    from dam_common.shutdown import SHUTDOWN  # noqa: PLC0415
    from dam_sim_bridge.dynamixel_standin import DynamixelStandIn  # noqa: PLC0415
    from dam_sim_bridge.errors import WorldConfigError  # noqa: PLC0415

    parser = _parser()
    args = parser.parse_args(sys.argv[1:] if argv is None else argv)
    try:
        config = load_config(args.config)
    except ConfigError as exc:
        parser.error(f'--config {args.config or "(default)"}: {exc}')
    try:
        config = config.with_object(args.object)
    except ConfigError as exc:
        parser.error(f'--object {args.object}: {exc}')
    if getattr(config, 'dynamixel', None) is None:
        parser.error(f'--config {args.config or "(default)"}: no dynamixel: section')
    standin = None
    try:
        try:
            with _stdout_to_stderr():  # PyBullet prints to fd 1: keep stdout one line
                standin = DynamixelStandIn(config, sim_time=args.sim_time,
                                           link_path=args.link,
                                           watchdog_feed=args.watchdog_feed)
        except (FileExistsError, FileNotFoundError, PermissionError,
                NotADirectoryError) as exc:
            parser.error(f'--link {args.link}: {exc}')
        except WorldConfigError as exc:
            parser.error(f'--config {args.config or "(default)"}: {exc}')
        with SHUTDOWN.uninterrupted():
            sys.stdout.write(f'DYNAMIXEL_PORT {standin.port_path}\n')
            sys.stdout.flush()
        SHUTDOWN.started()
        worker = threading.Thread(target=standin.run, name='dynamixel-bus', daemon=True)
        worker.start()
        while worker.is_alive() and not SHUTDOWN.wait(0.1):
            pass
    finally:
        if standin is not None:
            standin.close()
    return 0


if __name__ == '__main__':
    from dam_sim_bridge.entry_points import dynamixel_bus  # noqa: PLC0415

    dynamixel_bus()
