"""The stand-in's ``publish_clock`` parameter says what it does (issue 34: ``ros2 param get
/hand_driver_sim publish_clock`` said false while the node published ``/clock``): read over DDS
through its parameter service, as ``ros2 param get`` reads it, beside who publishes
``/clock``. The stand-in runs as the driver starts it (``__node:=hand_driver_sim``)."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest

from ros_testing import RosClient, config_with_free_ports, installed_executable, node_process

pytestmark = pytest.mark.integration

NODE = 'hand_driver_sim'


def _command(*params: str) -> list[str]:
    command = [str(installed_executable('dam_sim_bridge', 'sim_bridge')), '--ros-args',
               '-r', f'__node:={NODE}']
    for param in params:
        command += ['-p', param]
    return command


def _publish_clock(client: RosClient) -> bool:
    from rcl_interfaces.msg import ParameterType
    from rcl_interfaces.srv import GetParameters

    got = client.call(GetParameters, f'/{NODE}/get_parameters',
                      GetParameters.Request(names=['publish_clock']), timeout=10.0, wait=60.0)
    [value] = got.values
    assert value.type == ParameterType.PARAMETER_BOOL, value
    return value.bool_value


def _clock_publishers(client: RosClient) -> list[str]:
    return sorted(info.node_name for info in
                  client.node.get_publishers_info_by_topic('/clock'))


@pytest.mark.parametrize(('params', 'publishes'), [
    (['use_sim_time:=true'], True),            # as the driver starts it on the stand-in
    (['use_sim_time:=false'], False),
    (['use_sim_time:=false', 'publish_clock:=true'], True),
])
def test_publish_clock_says_whether_the_stand_in_publishes_the_clock(
        tmp_path: Path, params: list[str], publishes: bool) -> None:
    config = config_with_free_ports(tmp_path)
    with node_process(_command(*params), env={'DAM_CONFIG': str(config)}) as proc:
        client = RosClient()
        try:
            said = _publish_clock(client)
            if publishes:  # discovery of the publisher may take a moment
                client.spin_until(lambda: NODE in _clock_publishers(client), timeout=30.0)
            publishers = _clock_publishers(client)
        finally:
            client.close()
        assert proc.alive(), proc.output()
    assert said is publishes
    assert (NODE in publishers) is publishes, publishers


def test_publish_clock_false_in_simulated_time_is_refused_at_start(tmp_path: Path) -> None:
    config = config_with_free_ports(tmp_path)
    ran = subprocess.run(_command('use_sim_time:=true', 'publish_clock:=false'),
                         env={**os.environ, 'DAM_CONFIG': str(config)},
                         capture_output=True, text=True, timeout=120)
    assert ran.returncode != 0, ran.stdout + ran.stderr
    assert 'publish_clock:=false with use_sim_time:=true' in ran.stdout + ran.stderr
    assert 'Traceback' not in ran.stdout + ran.stderr
