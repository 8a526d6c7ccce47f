"""The simulated stand-in the driver starts when no hand answers (no ROS in this module).

The stand-in is ``dam_sim_bridge sim_bridge``, a child process of the driver
(:mod:`dam_hand_driver.driver_node`): with a UDP device link of its own, or serving an
emulated Dynamixel bus whose port it writes to a file. This module builds its command line,
reads that port file, and stops it.
"""

from __future__ import annotations

import contextlib
import os
import signal
import subprocess
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Protocol

from dam_common.shutdown import SHUTDOWN
from dam_hand_driver.errors import HandDriverError

#: How long the stand-in may take to send its first state frame or serve its port [s].
START_TIMEOUT_S = 20.0
#: How long the stand-in may take to stop cleanly before it is killed [s].
STOP_TIMEOUT_S = 1.5


class Logger(Protocol):
    """What :func:`stop_standin` logs through (an rclpy logger)."""

    def warning(self, message: str) -> object:
        """Log ``message`` as a warning."""


def standin_executable(why: str) -> Path:
    """The installed ``sim_bridge`` program.

    Parameters
    ----------
    why
        Why the stand-in is needed; the start of the error message.

    Raises
    ------
    HandDriverError
        ``dam_sim_bridge`` is not installed, or its program is missing.
    """
    from ament_index_python.packages import PackageNotFoundError, get_package_prefix

    try:
        exe = Path(get_package_prefix('dam_sim_bridge')) / 'lib' / 'dam_sim_bridge' \
            / 'sim_bridge'
    except PackageNotFoundError as exc:
        raise HandDriverError(f'{why}, and dam_sim_bridge is not installed: {exc}') from exc
    if not exe.is_file():
        raise HandDriverError(f'{why}, and the stand-in {str(exe)!r} does not exist')
    return exe


def standin_command(exe: Path, config_source: str, overlays: Sequence[str], object_name: str,
                    gui: bool, sim_time: bool, port_file: str = '') -> list[str]:
    """The stand-in's command line.

    Parameters
    ----------
    exe
        The ``sim_bridge`` program (:func:`standin_executable`).
    config_source
        ``DamConfig.source`` of the driver's configuration: ``FILE``, ``FILE + OVERLAY`` or
        a description that is no file (then the stand-in reads its default configuration).
    overlays
        The driver's configuration overlays, passed on (the stand-in's servos get the same
        offsets).
    object_name
        The object the stand-in puts on the table.
    gui, sim_time
        The stand-in's ``gui`` and ``use_sim_time``.
    port_file
        Non-empty: serve an emulated Dynamixel bus and write its port to this file.
    """
    cmd = [str(exe), '--ros-args', '-r', '__node:=hand_driver_sim', '-p',
           f'gui:={str(gui).lower()}', '-p', f'use_sim_time:={str(sim_time).lower()}']
    base = config_source.split(' + ')[0]  # 'FILE + OVERLAY' with an overlay
    if os.path.isfile(base):
        cmd += ['-p', f'config_file:={base}']
    for overlay in overlays:
        cmd += ['-p', f'config_overlay:={overlay}']
    cmd += ['-p', f'object:={object_name}']
    if port_file:
        cmd += ['-p', 'bus:=dynamixel', '-p', f'port_file:={port_file}']
    return cmd


def new_port_file() -> str:
    """A fresh path for the emulated bus's port file; the file does not exist yet (the
    stand-in writes it when the bus is open)."""
    fd, port_file = tempfile.mkstemp(prefix='dam_dynamixel_port_')
    os.close(fd)
    os.unlink(port_file)
    return port_file


def await_port_file(child: subprocess.Popen[bytes], port_file: str, deadline: float) -> str:
    """The emulated bus's port, from the file the stand-in writes once it serves; the file
    is removed.

    Parameters
    ----------
    child
        The stand-in.
    port_file
        The file it writes (:func:`new_port_file`).
    deadline
        Give up at this time [s, ``time.monotonic``].

    Raises
    ------
    HandDriverError
        The stand-in exited first, or the deadline passed.
    StartupInterrupted
        A stop request (SIGINT, SIGTERM) came meanwhile (:mod:`dam_common.shutdown`).
    """
    try:
        while time.monotonic() < deadline and child.poll() is None:
            SHUTDOWN.raise_if_requested()
            try:
                port = Path(port_file).read_text(encoding='utf-8').strip()
            except OSError:
                port = ''
            if port:
                return port
            time.sleep(0.05)
    finally:
        with contextlib.suppress(OSError):
            os.unlink(port_file)
    if child.poll() is not None:
        raise HandDriverError(f'the emulated Dynamixel bus exited with code '
                              f'{child.returncode} before serving its port')
    raise HandDriverError(f'the emulated Dynamixel bus served no port within '
                          f'{START_TIMEOUT_S} s')


def signal_standin(child: subprocess.Popen[bytes] | None) -> None:
    """Ask the stand-in to stop (it tears down while the driver does); nothing when it has
    ended or there is none."""
    if child is not None and child.poll() is None:
        # SIGTERM: a clean stop once the stand-in handles it, a silent end before that.
        child.send_signal(signal.SIGTERM)


def stop_standin(child: subprocess.Popen[bytes], logger: Logger) -> None:
    """Stop the stand-in and wait for it: SIGTERM, SIGKILL (with a warning) after
    :data:`STOP_TIMEOUT_S`."""
    signal_standin(child)
    try:
        child.wait(timeout=STOP_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        logger.warning(f'the stand-in (PID {child.pid}) did not stop within '
                       f'{STOP_TIMEOUT_S:g} s: killed')
        child.kill()
        child.wait(timeout=5.0)
