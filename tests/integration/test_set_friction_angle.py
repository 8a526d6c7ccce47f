"""The simulated hand's ``~/set_friction_angle`` over DDS, against the real sim_bridge process:
a default-constructed request (or a negative angle) puts back the configured friction angle,
never a frictionless contact; the answer reports the coefficient read back from PyBullet."""

from __future__ import annotations

import math
import re
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml

from ros_testing import RosClient, free_udp_ports, installed_executable, node_process

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]
#: Not the shipped 5 deg, so that the test sees the configuration and not a constant.
CONFIGURED_DEG = 7.5
SERVICE = '/friction_sim/set_friction_angle'


@pytest.fixture(scope='module')
def client(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RosClient]:
    data = yaml.safe_load((REPO_ROOT / 'config' / 'dam.yaml').read_text(encoding='utf-8'))
    data['device']['state_port'], data['device']['command_port'] = free_udp_ports(2)
    data['contact']['friction_angle_deg'] = CONFIGURED_DEG
    config_file = tmp_path_factory.mktemp('friction') / 'dam.yaml'
    config_file.write_text(yaml.safe_dump(data), encoding='utf-8')
    command = [installed_executable('dam_sim_bridge', 'sim_bridge'), '--ros-args',
               '-r', '__node:=friction_sim', '-r', '/sim/object_pose:=/friction_sim/pose']
    with node_process(command, env={'DAM_CONFIG': str(config_file)}) as proc:
        ros = RosClient()
        try:
            yield ros
        finally:
            ros.close()
        assert proc.alive(), proc.output()


def _set(client: RosClient, request):
    from dam_interfaces.srv import SetFrictionAngle

    return client.call(SetFrictionAngle, SERVICE, request)


def _coefficient(message: str) -> float:
    match = re.search(r'finger-object coefficient (\S+)$', message)
    assert match, message
    return float(match.group(1))


def test_the_request_default_is_the_idl_default() -> None:
    from dam_interfaces.srv import SetFrictionAngle

    assert SetFrictionAngle.Request().friction_angle == -1.0
    assert SetFrictionAngle.Request.FRICTION_ANGLE_FROM_CONFIG == -1.0


def test_default_constructed_and_negative_requests_restore_the_configured_angle(
        client: RosClient) -> None:
    from dam_interfaces.srv import SetFrictionAngle

    configured = math.tan(math.radians(CONFIGURED_DEG))
    for explicit, restore in ((0.3, SetFrictionAngle.Request()),
                              (0.0, SetFrictionAngle.Request(friction_angle=-0.2)),
                              (1.0, SetFrictionAngle.Request(
                                  friction_angle=SetFrictionAngle.Request
                                  .FRICTION_ANGLE_FROM_CONFIG))):
        changed = _set(client, SetFrictionAngle.Request(friction_angle=explicit))
        assert changed.success is True, changed.message
        assert _coefficient(changed.message) == pytest.approx(math.tan(explicit), rel=1e-6,
                                                              abs=1e-9)
        back = _set(client, restore)
        assert back.success is True, back.message
        assert _coefficient(back.message) == pytest.approx(configured, rel=1e-6)
        assert f'({CONFIGURED_DEG:g} deg, the configured one)' in back.message


@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf, math.pi / 2, 2.0])
def test_malformed_angles_are_rejected_naming_the_value(client: RosClient, bad: float) -> None:
    from dam_interfaces.srv import SetFrictionAngle

    before = _coefficient(_set(client, SetFrictionAngle.Request(friction_angle=0.2)).message)
    response = _set(client, SetFrictionAngle.Request(friction_angle=bad))
    assert response.success is False
    assert 'friction' in response.message and repr(bad) in response.message
    after = _set(client, SetFrictionAngle.Request(friction_angle=0.2))
    assert _coefficient(after.message) == before  # nothing changed in between
