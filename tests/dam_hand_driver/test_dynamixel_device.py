"""The Dynamixel backend's configuration, control law and bus I/O (no ROS).

The bus I/O runs against the emulated bus (``DynamixelStandIn`` on a pseudo-terminal, lockstep)
through the real SDK; what the servos hold is read back from their emulated control tables and
the world, independently of the driver's code.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
import threading
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml
from dynamixel_testing import fast_gil_handoff

from dam_common.config import DamConfig, config_from_dict, load_config
from dam_common.device_protocol import JointMode
from dam_common.dynamixel_config import POSITION_RAD_PER_COUNT
from dam_common.errors import ConfigError
from dam_hand_driver.dynamixel_goals import ServoTable, goals_raw, state_si
from dam_hand_driver.errors import HandDriverError

REPO_ROOT = Path(__file__).resolve().parents[2]
H, P, T, IMP = (int(JointMode.HOLD), int(JointMode.POSITION), int(JointMode.TORQUE),
                int(JointMode.IMPEDANCE))


@pytest.fixture(scope='module')
def raw_config() -> dict:
    return yaml.safe_load((REPO_ROOT / 'config' / 'dam.yaml').read_text(encoding='utf-8'))


@pytest.fixture(scope='module')
def cfg() -> DamConfig:
    return load_config()


# -------------------------------------------------------------------------------------------
# Configuration


@pytest.mark.parametrize('edit, match', [
    (lambda d: d['servos']['finger2_locked_joint'].update(id=1),
     r'dynamixel\.servos\.finger2_locked_joint\.id: ID 1 is also the servo of '
     r'finger1_compliant_joint'),
    (lambda d: d['servos']['finger1_locked_joint'].update(model='XL320'),
     r'finger1_locked_joint\.model: unknown model .XL320.'),
    (lambda d: d.pop('port'), r'dynamixel\.port: missing key'),
    (lambda d: d['servos'].pop('finger3_position_joint'),
     r'dynamixel\.servos\.finger3_position_joint: missing key'),
    (lambda d: d['servos']['finger1_compliant_joint'].update(direction=2),
     r'finger1_compliant_joint\.direction: expected 1 or -1'),
    (lambda d: d['servos']['finger1_compliant_joint'].update(current_limit_a=5.0),
     r'finger1_compliant_joint\.current_limit_a: 5\.0 A is above the XM430-W350'),
    (lambda d: d.update(baud_rate=12345), r'dynamixel\.baud_rate: 12345'),
    (lambda d: d.update(bus_watchdog_s=0.05), r'bus_watchdog_s: 0\.05 s is not a multiple'),
    (lambda d: d['servos']['finger1_position_joint'].update(zero_offset_counts=4000),
     r'finger1_position_joint\.zero_offset_counts: 4000 puts the joint limits'),
    (lambda d: d['servos'].update(thumb_joint={}), r"no joint named \['thumb_joint'\]"),
])
def test_bad_dynamixel_sections_are_refused_by_key(raw_config, edit, match) -> None:
    data = copy.deepcopy(raw_config)
    edit(data['dynamixel'])
    with pytest.raises(ConfigError, match=match):
        config_from_dict(data)


def test_the_section_is_optional_and_the_shipped_one_maps_every_joint(raw_config) -> None:
    data = copy.deepcopy(raw_config)
    del data['dynamixel']
    assert config_from_dict(data).dynamixel is None
    shipped = config_from_dict(raw_config)
    assert [s.joint for s in shipped.dynamixel.servos] == list(shipped.hand.joint_names)
    assert sorted(s.servo_id for s in shipped.dynamixel.servos) == list(range(1, 10))


# -------------------------------------------------------------------------------------------
# The control law (closed forms)


def test_goals_follow_the_impedance_law_and_the_roles(cfg: DamConfig) -> None:
    table = ServoTable.from_config(cfg.dynamixel)
    n = len(table.ids)
    rng = np.random.default_rng(3)
    q = rng.uniform(-0.3, 0.3, n)
    dq = rng.uniform(-1.0, 1.0, n)
    modes = np.array([IMP, H, P] * 3)
    setpoints = q + 0.02
    k = np.where(modes == IMP, 10.0, 0.0)
    d = np.where(modes == IMP, 0.05, 0.0)
    hold = q - 0.01
    current, position, tau = goals_raw(table, q, dq, modes, setpoints, k, d, hold, 1.0, 5.0, 0.1)
    for j, servo in enumerate(cfg.dynamixel.servos):
        if servo.role == 'compliant':
            expected_tau = 10.0 * 0.02 - 0.05 * dq[j]
            assert tau[j] == pytest.approx(expected_tau)
            unit = servo.torque_constant_nm_per_a * servo.spec.current_unit_a
            assert current[j] == round(expected_tau / (servo.direction * unit))
        else:  # current-based position: the angle, capped by the Current Limit
            angle = hold[j] if modes[j] == H else setpoints[j]
            assert position[j] == round(servo.zero_offset_counts
                                        + servo.direction * angle / POSITION_RAD_PER_COUNT)
            assert current[j] == servo.current_limit_raw
            assert tau[j] == 0.0


def test_torque_is_clipped_and_the_state_converts_back(cfg: DamConfig) -> None:
    table = ServoTable.from_config(cfg.dynamixel)
    n = len(table.ids)
    zeros = np.zeros(n)
    modes = np.full(n, T)
    _, _, tau = goals_raw(table, zeros, zeros, modes, np.full(n, 5.0), zeros, zeros, zeros,
                          1.0, 5.0, 0.1)
    assert np.all(tau[table.current_mode] == 1.0)
    current = np.array([100] * n)
    q, dq, torque = state_si(table, current, np.full(n, 10), np.full(n, 2048 + 512))
    assert q == pytest.approx(np.full(n, math.pi / 4.0))
    assert dq == pytest.approx(np.full(n, 10 * 0.229 * 2.0 * math.pi / 60.0))
    assert torque == pytest.approx(100 * table.torque_per_unit)


# -------------------------------------------------------------------------------------------
# On the emulated bus


@pytest.fixture
def standin(cfg: DamConfig) -> Iterator[object]:
    from dam_sim_bridge.dynamixel_standin import DynamixelStandIn

    with fast_gil_handoff():
        bus = DynamixelStandIn(cfg, sim_time=True)
        thread = threading.Thread(target=bus.run, daemon=True)
        thread.start()
        yield bus
        bus.close()
        thread.join(2.0)


def _eventually(predicate, timeout_s: float = 2.0) -> bool:
    """A sync write has no answer: the bus thread takes it a moment later."""
    import time

    deadline = time.monotonic() + timeout_s
    while not predicate():
        if time.monotonic() > deadline:
            return False
        time.sleep(0.005)
    return True


def _field(bus, j: int, name: str) -> int:
    with bus.lock:
        return int(bus.servos[j].get(name))


def test_the_device_reads_the_world_arms_and_disarms(cfg: DamConfig, standin) -> None:
    from dam_hand_driver.dynamixel_device import DynamixelDevice

    device = DynamixelDevice(cfg, standin.port_path)
    try:
        assert device.rate_report == []  # the emulated hand has no Return Delay Time
        assert [_field(standin, j, 'operating_mode') for j in range(9)] == [0, 5, 5] * 3
        assert all(_field(standin, j, 'torque_enable') == 0 for j in range(9))
        sample = device.receive(1.0)
        assert sample is not None and sample.fault == ''
        with standin.lock:
            world_q = standin.world.joint_states().positions
        assert sample.position == pytest.approx(world_q, abs=POSITION_RAD_PER_COUNT)
        device.arm(sample)
        assert all(_field(standin, j, 'torque_enable') == 1 for j in range(9))
        assert all(_field(standin, j, 'bus_watchdog') == 5 for j in range(9))  # 0.1 s
        items = [(1, T, 0.1, 0.0, 0.0)]  # a torque on a locked joint
        why = device.command_error([_Item(*i) for i in items])
        assert why is not None and 'finger1_locked_joint' in why and 'MODE_TORQUE' in why
        assert device.command_error([_Item(0, IMP, 0.1, 5.0, 0.1)]) is None
        device.disarm()
        assert all(_field(standin, j, 'torque_enable') == 0 for j in range(9))
    finally:
        device.close()


class _Item(tuple):
    def __new__(cls, joint, mode, setpoint, stiffness, damping):
        return super().__new__(cls, (joint, mode, setpoint, stiffness, damping))

    joint = property(lambda self: self[0])
    mode = property(lambda self: self[1])
    stiffness = property(lambda self: self[3])
    damping = property(lambda self: self[4])


def test_a_wrong_model_or_a_missing_servo_is_refused_by_id_and_name(cfg: DamConfig,
                                                                    standin) -> None:
    from dam_hand_driver.dynamixel_device import DynamixelDevice

    servos = list(cfg.dynamixel.servos)
    servos[1] = dataclasses.replace(servos[1], model='XM430-W350', current_limit_a=1.0)
    wrong = dataclasses.replace(cfg, dynamixel=dataclasses.replace(cfg.dynamixel,
                                                                   servos=tuple(servos)))
    with pytest.raises(HandDriverError, match=re.escape(
            'servo ID 2 (finger1_locked_joint) is model number 1240, the configuration says '
            'XM430-W350 (1020)')):
        DynamixelDevice(wrong, standin.port_path)
    standin.silent_ids = [7]
    with pytest.raises(HandDriverError, match=re.escape(
            'servo ID 7 (finger3_compliant_joint) does not answer the ping')):
        DynamixelDevice(cfg, standin.port_path)


def test_rate_caps_are_reported_with_the_fix(cfg: DamConfig) -> None:
    from dam_hand_driver.dynamixel_device import DynamixelDevice
    from dam_sim_bridge.dynamixel_standin import DynamixelStandIn

    bus = DynamixelStandIn(cfg, sim_time=True, return_delay_time_raw=250)
    thread = threading.Thread(target=bus.run, daemon=True)
    thread.start()
    try:
        device = DynamixelDevice(cfg, bus.port_path)
        device.close()
    finally:
        bus.close()
        thread.join(2.0)
    report = ' '.join(device.rate_report)
    assert 'Return Delay Time is not 0' in report and 'write 0 to address 9' in report
    assert 'ID 1 (finger1_compliant_joint): 500 us' in report


def test_a_port_that_does_not_exist_is_named(cfg: DamConfig) -> None:
    from dam_hand_driver.dynamixel_device import DynamixelDevice

    with pytest.raises(HandDriverError, match="cannot open the Dynamixel port '/nonexistent/tty"):
        DynamixelDevice(cfg, '/nonexistent/ttyUSB9')


def test_failed_reads_leave_the_compliant_joints_limp_not_pushing(cfg: DamConfig,
                                                                  standin) -> None:
    """A host law without state must not keep its last current: after three failed reads
    the current servos get zero current, the position servos keep their goal."""
    from dam_hand_driver.dynamixel_device import LIMP_AFTER_FAILED_READS, DynamixelDevice

    device = DynamixelDevice(cfg, standin.port_path)
    try:
        sample = device.receive(1.0)
        device.arm(sample)
        n = len(cfg.dynamixel.servos)
        modes = np.array([T, H, H] * 3)
        setpoints = np.where(modes == T, 0.3, 0.0)
        device.send(sample, modes, setpoints, np.zeros(n), np.zeros(n))
        compliant = [j for j, s in enumerate(cfg.dynamixel.servos) if s.role == 'compliant']
        assert _eventually(lambda: all(_field(standin, j, 'goal_current') != 0
                                       for j in compliant))
        goals = [_field(standin, j, 'goal_position') for j in range(n)]
        standin.silent_ids = [cfg.dynamixel.servos[4].servo_id]
        for _ in range(LIMP_AFTER_FAILED_READS):
            assert device.receive(1.0) is None
        assert 'ID 5 (finger2_locked_joint)' in device.last_failure
        assert _eventually(lambda: all(_field(standin, j, 'goal_current') == 0
                                       for j in compliant))
        assert [_field(standin, j, 'goal_position') for j in range(n)] == goals
        standin.silent_ids = []
        assert device.receive(1.0) is not None
    finally:
        device.close()
    # Closing switched torque off and cleared the watchdog: no servo is left tripped.
    assert all(_field(standin, j, 'torque_enable') == 0 for j in range(9))
    assert all(_field(standin, j, 'bus_watchdog') == 0 for j in range(9))
