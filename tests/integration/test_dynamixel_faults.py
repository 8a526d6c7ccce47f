"""The Dynamixel driver against faults a lab meets first, end to end over DDS with real
processes: the driver (``backend:=dynamixel``, ``port:=`` a fixed name, as
``/dev/serial/by-id/...``) and the emulated bus started alone (``dynamixel_bus --link``), in
real time, so that the servos' Bus Watchdogs run on the wall clock as real servos' do.

1. A second driver on the port is refused with one line naming the port and the first
   driver's PID, and the first one reads on.
2. The driver stalls (SIGSTOP) for 0.3 s, three watchdog periods: every servo trips and
   refuses its goals. Within 1.5 s of SIGCONT the driver is in ERROR (no more /joint_states),
   never ACTIVE with tripped servos; ``~/reset`` arms the hand again.
3. The adapter vanishes (the bus program ends, its pseudo-terminal closes): ERROR naming the
   port within 1 s, no traceback, the process alive; ``~/reset`` fails naming the port until
   it is back, then opens it again and arms.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from dynamixel_testing import DriverClient
from grasp_testing import config_with_free_ports

from dam_common.realtime import die_with_parent
from ros_testing import installed_executable, node_process

# In real time, as real servos (0.1 s Bus Watchdogs on the wall clock): beside another
# worker's stack the driver was once in ERROR where ACTIVE is awaited; so alone
# (scripts/test.sh, marker exclusive).
pytestmark = [pytest.mark.integration, pytest.mark.exclusive]


class _BusProgram:
    """``dynamixel_bus --link LINK`` in real time, until :meth:`stop`."""

    def __init__(self, config: Path, link: Path) -> None:
        self.process = subprocess.Popen(
            [str(installed_executable('dam_sim_bridge', 'dynamixel_bus')), '--config',
             str(config), '--link', str(link)],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, stdin=subprocess.DEVNULL,
            text=True, preexec_fn=die_with_parent)
        line = self.process.stdout.readline()
        assert line.startswith('DYNAMIXEL_PORT '), line

    def stop(self) -> None:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGTERM)
            self.process.wait(timeout=30.0)


@pytest.fixture(scope='module')
def setup(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict]:
    directory = tmp_path_factory.mktemp('dynamixel_faults')
    config = config_with_free_ports(directory)
    link = directory / 'ttyDXL'
    command = [installed_executable('dam_hand_driver', 'hand_driver'), '--ros-args', '-p',
               'backend:=dynamixel', '-p', f'port:={link}', '-p', 'thread_priority:=0']
    env = {'DAM_CONFIG': str(config)}
    state = {'bus': _BusProgram(config, link), 'config': config, 'link': link,
             'command': command, 'env': env}
    try:
        with node_process(command, env=env) as driver:
            client = DriverClient()
            try:
                assert client.wait_state('ACTIVE', 30.0), driver.output()
                yield {**state, 'client': client, 'driver': driver, 'state': state}
            finally:
                client.client.close()
    finally:
        state['bus'].stop()  # the one a test started last


def test_a_second_driver_on_the_port_is_refused_while_the_first_reads_on(setup) -> None:
    client, driver = setup['client'], setup['driver']
    before = client.joint_states
    second = subprocess.run([str(c) for c in setup['command']], env={**os.environ,
                            **setup['env']}, capture_output=True, text=True, timeout=120.0)
    assert second.returncode != 0
    lines = [ln for ln in (second.stdout + second.stderr).splitlines() if ln.strip()]
    refusal = [ln for ln in lines if 'cannot start' in ln]
    assert len(refusal) == 1, lines
    assert f"the Dynamixel port '{setup['link']}' is in use by another program" in refusal[0]
    assert f'PID {driver.pid}' in refusal[0], refusal[0]
    assert 'Traceback' not in second.stderr
    assert client.client.spin_until(lambda: client.joint_states > before + 50, 10.0)
    assert client.wait_state('ACTIVE', 5.0), client.diag


def test_a_stall_of_the_driver_trips_the_watchdogs_and_is_an_error_at_once(setup) -> None:
    client, driver = setup['client'], setup['driver']
    assert client.wait_state('ACTIVE', 5.0)
    os.kill(driver.pid, signal.SIGSTOP)
    time.sleep(0.3)
    os.kill(driver.pid, signal.SIGCONT)
    resumed = time.monotonic()
    assert client.client.spin_until(lambda: client.state() == 'ERROR', 10.0), \
        driver.output()[-3000:]
    client.client.spin_until(lambda: False, 2.0)  # no /joint_states in ERROR
    assert client.last_joint_state_s - resumed < 1.5, client.last_joint_state_s - resumed
    message = client.diag['message']
    assert 'Bus Watchdog tripped' in message or 'no state frame' in message, message
    reset = client.reset()
    assert reset.success, reset.message
    assert client.wait_state('ACTIVE', 5.0)
    client.client.spin_until(lambda: False, 1.5)  # no servo left tripped: it stays ACTIVE
    assert client.state() == 'ACTIVE', client.diag
    assert client.diag['torque_enabled'] == 'True'


def test_the_adapter_vanishing_is_an_error_naming_the_port_and_reset_reopens_it(setup) -> None:
    client, driver, link = setup['client'], setup['driver'], setup['link']
    assert client.wait_state('ACTIVE', 5.0)
    setup['state']['bus'].stop()  # the pseudo-terminal closes, the link goes
    gone = time.monotonic()
    assert client.client.spin_until(lambda: client.state() == 'ERROR', 10.0)
    client.client.spin_until(lambda: False, 1.5)
    assert client.last_joint_state_s - gone < 1.0, client.last_joint_state_s - gone
    assert f"the Dynamixel port '{link}' failed" in client.diag['message'], client.diag
    assert driver.alive()
    failed = client.reset()
    assert not failed.success and f"'{link}'" in failed.message, failed.message
    setup['state']['bus'] = _BusProgram(setup['config'], link)  # plugged in again
    reset = client.reset()
    assert reset.success, reset.message
    assert f'opened {link} again' in reset.message, reset.message
    assert client.wait_state('ACTIVE', 5.0)
    assert driver.alive() and 'Traceback' not in driver.output(), driver.output()[-3000:]

