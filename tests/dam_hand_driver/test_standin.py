"""The stand-in's command line, port file and stop, with real child processes
(dam_hand_driver.standin)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from dam_hand_driver.errors import HandDriverError
from dam_hand_driver.standin import (
    START_TIMEOUT_S,
    STOP_TIMEOUT_S,
    await_port_file,
    new_port_file,
    signal_standin,
    standin_command,
    stop_standin,
)

EXE = Path('/opt/example/lib/dam_sim_bridge/sim_bridge')


class _Log:
    def __init__(self) -> None:
        self.warnings: list[str] = []

    def warning(self, message: str) -> bool:
        self.warnings.append(message)
        return True


def test_the_command_line_passes_the_configuration_on(tmp_path: Path) -> None:
    base = tmp_path / 'dam.yaml'
    base.write_text('{}\n', encoding='utf-8')
    cmd = standin_command(EXE, f'{base} + {tmp_path / "zero.yaml"}',
                          [str(tmp_path / 'zero.yaml')], 'mug', gui=True, sim_time=False)
    assert cmd == [str(EXE), '--ros-args', '-r', '__node:=hand_driver_sim',
                   '-p', 'gui:=true', '-p', 'use_sim_time:=false',
                   '-p', f'config_file:={base}',
                   '-p', f'config_overlay:={tmp_path / "zero.yaml"}',
                   '-p', 'object:=mug']


def test_a_source_that_is_no_file_is_not_passed_and_a_port_file_asks_for_the_bus(
        tmp_path: Path) -> None:
    cmd = standin_command(EXE, 'built-in defaults', [], 'cylinder', gui=False, sim_time=True,
                          port_file=str(tmp_path / 'port'))
    assert cmd == [str(EXE), '--ros-args', '-r', '__node:=hand_driver_sim',
                   '-p', 'gui:=false', '-p', 'use_sim_time:=true', '-p', 'object:=cylinder',
                   '-p', 'bus:=dynamixel', '-p', f'port_file:={tmp_path / "port"}']


def test_a_new_port_file_is_a_free_temporary_path() -> None:
    first, second = new_port_file(), new_port_file()
    assert first != second
    for path in (first, second):
        assert not os.path.exists(path)
        assert Path(path).parent == Path(tempfile.gettempdir())
        assert Path(path).name.startswith('dam_dynamixel_port_')


@pytest.fixture
def children() -> Iterator[list[subprocess.Popen[bytes]]]:
    started: list[subprocess.Popen[bytes]] = []
    yield started
    for child in started:
        if child.poll() is None:
            child.kill()
        child.wait()


def _python(children: list[subprocess.Popen[bytes]], code: str) -> subprocess.Popen[bytes]:
    child = subprocess.Popen([sys.executable, '-c', code], stdout=subprocess.PIPE)
    children.append(child)
    return child


def test_the_port_is_read_from_the_file_the_stand_in_writes(children) -> None:
    port_file = new_port_file()
    child = _python(children, 'import sys, time\n'
                              'time.sleep(0.2)\n'
                              f'open({port_file!r}, "w").write("/dev/pts/7\\n")\n'
                              'time.sleep(60)\n')
    assert await_port_file(child, port_file, time.monotonic() + 600.0) == '/dev/pts/7'
    assert not os.path.exists(port_file)  # removed once read


def test_a_stand_in_that_exits_first_or_is_late_is_an_error(children) -> None:
    port_file = new_port_file()
    quitter = _python(children, 'raise SystemExit(3)')
    with pytest.raises(HandDriverError, match='exited with code 3 before serving its port'):
        await_port_file(quitter, port_file, time.monotonic() + 600.0)
    sleeper = _python(children, 'import time; time.sleep(60)')
    with pytest.raises(HandDriverError, match=f'served no port within {START_TIMEOUT_S} s'):
        await_port_file(sleeper, port_file, time.monotonic() - 1.0)
    assert sleeper.poll() is None  # left to the caller


def test_a_stand_in_stops_on_sigterm_without_a_word(children) -> None:
    child = _python(children, 'import time; time.sleep(60)')
    log = _Log()
    stop_standin(child, log)
    assert child.returncode == -signal.SIGTERM
    assert log.warnings == []
    signal_standin(child)  # ended: nothing to signal, no error
    signal_standin(None)


def test_a_stand_in_that_ignores_sigterm_is_killed_with_a_warning(children) -> None:
    child = _python(children, 'import signal, sys, time\n'
                              'signal.signal(signal.SIGTERM, signal.SIG_IGN)\n'
                              'print("ready", flush=True)\n'
                              'time.sleep(60)\n')
    assert child.stdout is not None and child.stdout.readline() == b'ready\n'
    log = _Log()
    stop_standin(child, log)
    assert child.returncode == -signal.SIGKILL
    assert log.warnings == [f'the stand-in (PID {child.pid}) did not stop within '
                            f'{STOP_TIMEOUT_S:g} s: killed']
