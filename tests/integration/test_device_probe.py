"""scripts/lib/probe_device.py as bringup.sh runs it: a device sending state frames on the
configured state port is told apart as a hand or a simulated stand-in (its SIMULATED status
bit), silence is ``nothing`` after the probe time, and the port is free again afterwards (the
driver binds it next)."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml
from grasp_testing import config_with_free_ports

from ros_testing import FakeStateDevice as _Device

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]
PROBE = REPO_ROOT / 'scripts' / 'lib' / 'probe_device.py'


def _probe(config: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(PROBE), *args], capture_output=True, text=True,
                          timeout=60, env=dict(os.environ, DAM_CONFIG=str(config)),
                          stdin=subprocess.DEVNULL)


@pytest.mark.parametrize(('status', 'kind'), [(0, 'hardware'), (2, 'simulated')])
def test_a_device_that_answers_is_a_hand_or_a_stand_in(tmp_path: Path, status: int,
                                                       kind: str) -> None:
    config = config_with_free_ports(tmp_path)
    device = _Device(config, status)
    try:
        probed = _probe(config, '--timeout', '20')
    finally:
        device.close()
    assert probed.returncode == 0, probed.stderr
    assert probed.stdout.split('\t')[0] == kind, probed.stdout


def test_silence_is_nothing_after_the_probe_time_and_the_port_is_free_again(
        tmp_path: Path) -> None:
    config = config_with_free_ports(tmp_path)
    data = yaml.safe_load(config.read_text(encoding='utf-8'))
    data['device']['probe_timeout_s'] = 0.7
    config.write_text(yaml.safe_dump(data), encoding='utf-8')
    t0 = time.monotonic()
    probed = _probe(config)
    took = time.monotonic() - t0
    assert probed.returncode == 0, probed.stderr
    kind, description = probed.stdout.rstrip('\n').split('\t')
    assert kind == 'nothing', probed.stdout
    assert 'within 0.7 s' in description, description
    assert took >= 0.7, took
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(('127.0.0.1', int(data['device']['state_port'])))  # the driver's turn


def test_a_bound_state_port_is_one_clear_error(tmp_path: Path) -> None:
    config = config_with_free_ports(tmp_path)
    port = int(yaml.safe_load(config.read_text(encoding='utf-8'))['device']['state_port'])
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        sock.bind(('127.0.0.1', port))
        probed = _probe(config)
    assert probed.returncode == 1, probed.stdout
    assert probed.stdout == ''
    assert f'cannot bind the state port {port}' in probed.stderr, probed.stderr
    assert 'is a driver already running?' in probed.stderr, probed.stderr
