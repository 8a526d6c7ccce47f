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
        # 0.1 s, in one Sync Write after the others (no answer: the bus takes it a moment on)
        assert _eventually(lambda: all(_field(standin, j, 'bus_watchdog') == 5
                                       for j in range(9)))
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
    # Nine servos wait 4.5 ms of the 5.6 ms cycle: the fix is the delay, not the baud rate
    # (451 bytes take 1.13 ms at 4 Mbit/s, within the 4 ms of 250 Hz).
    cycle = [line for line in device.rate_report if line.startswith('one cycle takes')]
    assert len(cycle) == 1, device.rate_report
    assert 'plus 4.50 ms of Return Delay Time' in cycle[0], cycle[0]
    assert 'write 0 to Return Delay Time' in cycle[0] and 'baud rate' not in cycle[0].split(
        ': ')[-1], cycle[0]


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


# -------------------------------------------------------------------------------------------
# Arming, the Bus Watchdog, the Alert bit, a failing port (issue: a real hand a lab can trust)


@pytest.fixture
def realtime_standin(cfg: DamConfig, tmp_path: Path) -> Iterator[object]:
    """The emulated bus in real time (its Bus Watchdog runs on the wall clock), behind a
    symlink (a fixed name, as /dev/serial/by-id/... for an adapter)."""
    from dam_sim_bridge.dynamixel_standin import DynamixelStandIn

    with fast_gil_handoff():
        bus = DynamixelStandIn(cfg, link_path=str(tmp_path / 'ttyDXL'))
        thread = threading.Thread(target=bus.run, daemon=True)
        thread.start()
        yield bus
        bus.close()
        thread.join(2.0)


def _hold_cycles(device, duration_s: float) -> list:
    """Run the driver's bus cycle (read, then HOLD every joint) for ``duration_s`` [s]; the
    samples read."""
    import time

    n = device.n
    samples = []
    deadline = time.monotonic() + duration_s
    while time.monotonic() < deadline:
        sample = device.receive(0.2)
        if sample is None:
            continue
        samples.append(sample)
        device.send(sample, np.full(n, H), np.zeros(n), np.zeros(n), np.zeros(n))
    return samples


def _tripped(bus) -> list[int]:
    with bus.lock:
        return [s.servo_id for s in bus.servos if s.watchdog_tripped]


def test_arming_with_slow_answers_leaves_no_servo_tripped(cfg: DamConfig,
                                                          realtime_standin) -> None:
    """Every status packet 20 ms late: arming nine servos takes most of a second, five times
    the 100 ms Bus Watchdog. A watchdog set servo by servo runs out while the others are
    armed (packets to other IDs need not feed it); set in one Sync Write at the end, none
    does, and the cycles that follow keep every servo fed."""
    import time

    from dam_hand_driver.dynamixel_device import DynamixelDevice

    device = DynamixelDevice(cfg, realtime_standin.link_path)
    try:
        sample = device.receive(1.0)
        assert sample is not None
        realtime_standin.status_delay_s = 0.02
        started = time.monotonic()
        device.arm(sample)
        arming_s = time.monotonic() - started
        assert arming_s > 2.0 * cfg.dynamixel.bus_watchdog_s, arming_s
        samples = _hold_cycles(device, 0.6)
        assert len(samples) > 5
        assert _tripped(realtime_standin) == []
        assert all(s.fault == '' for s in samples), samples[-1].fault
        with realtime_standin.lock:
            assert all(s.torque_enabled and s.get('bus_watchdog') == 5
                       for s in realtime_standin.servos)
    finally:
        device.close()


def test_a_host_stall_longer_than_the_watchdog_is_a_fault_naming_the_servos(
        cfg: DamConfig, realtime_standin) -> None:
    """The host stops for 0.3 s (three watchdog periods): every servo trips and refuses its
    goals. The next checks say so (the driver goes to ERROR), and recovery arms the hand
    again with no servo tripped."""
    import time

    from dam_hand_driver.dynamixel_device import CHECK_EVERY, DynamixelDevice

    device = DynamixelDevice(cfg, realtime_standin.link_path)
    try:
        sample = device.receive(1.0)
        device.arm(sample)
        assert all(s.fault == '' for s in _hold_cycles(device, 0.3))
        time.sleep(0.3)  # the host stalls
        assert len(_tripped(realtime_standin)) == 9
        faults = []
        for _ in range(CHECK_EVERY + 3):
            sample = device.receive(0.5)
            if sample is not None and sample.fault:
                faults.append(sample.fault)
                break
        assert faults, 'a tripped watchdog went unnoticed'
        # One line for the nine, not nine times the same sentence.
        assert faults[0].startswith('servos ID 1-9: Bus Watchdog tripped (no packet from the '
                                    'host for 0.1 s'), faults[0]
        assert device.diagnostics()['bus_watchdog_trips'] == '9'
        device.disarm()
        assert device.recover() == ''
        sample = device.receive(1.0)
        device.arm(sample)
        assert all(s.fault == '' for s in _hold_cycles(device, 0.3))
        assert _tripped(realtime_standin) == []
    finally:
        device.close()


def test_the_alert_bit_starts_a_check_at_once(cfg: DamConfig, standin) -> None:
    """A hardware error sets the Alert bit of every status packet: the fault is seen within
    two cycles, not at the next periodic check."""
    from dam_hand_driver.dynamixel_device import CHECK_EVERY, DynamixelDevice

    device = DynamixelDevice(cfg, standin.port_path)
    try:
        sample = device.receive(1.0)
        device.arm(sample)
        while device._cycles % CHECK_EVERY != 3:  # just after a periodic check
            device.receive(1.0)
        standin.hardware_error(6, 1 << 5)
        cycles = 0
        while True:
            cycles += 1
            sample = device.receive(1.0)
            if sample is not None and sample.fault:
                break
            assert cycles < CHECK_EVERY - 3, 'the Alert bit was ignored'
        assert cycles <= 2, cycles
        assert 'servo ID 6 (finger2_position_joint): hardware error (overload error)' in \
            sample.fault
        assert device.alerts > 0
    finally:
        device.close()


def test_a_servo_that_refuses_its_goals_is_a_fault(cfg: DamConfig, standin) -> None:
    """Someone lowered a servo's Current Limit: the Goal Current the driver writes is beyond
    it, the servo refuses the whole goal block (Data Limit Error, which a Sync Write does not
    report), and the check finds goals other than the ones written."""
    from dam_hand_driver.dynamixel_device import CHECK_EVERY, DynamixelDevice

    device = DynamixelDevice(cfg, standin.port_path)
    try:
        sample = device.receive(1.0)
        device.arm(sample)
        with standin.lock:
            standin.servos[2].set('current_limit', 10)  # ID 3, current-based position
        n = device.n
        fault = ''
        for k in range(2 * CHECK_EVERY + 2):
            sample = device.receive(1.0)
            if sample.fault:
                fault = sample.fault
                break
            setpoints = np.where(np.arange(n) == 2, 0.01 * k, 0.0)
            device.send(sample, np.where(np.arange(n) == 2, P, H), setpoints, np.zeros(n),
                        np.zeros(n))
        assert 'ID 3 (finger1_position_joint): does not follow its goals' in fault, fault
    finally:
        device.close()


def test_recovery_tries_every_transaction_before_a_servo_counts_as_silent(
        cfg: DamConfig, standin) -> None:
    """A servo that misses one answer (load, a glitch) is not reported missing."""
    from dam_hand_driver.dynamixel_device import DynamixelDevice

    device = DynamixelDevice(cfg, standin.port_path)
    try:
        standin.silent_ids = [4]
        timer = threading.Timer(0.05, lambda: setattr(standin, 'silent_ids', []))
        timer.start()
        assert device.recover() == ''
        timer.join()
        standin.silent_ids = [4]
        with pytest.raises(HandDriverError, match=re.escape(
                'servo ID 4 (finger2_compliant_joint) does not answer')):
            device.recover()
    finally:
        standin.silent_ids = []
        device.close()


def test_a_port_that_fails_is_named_and_recovery_reopens_it(cfg: DamConfig,
                                                            tmp_path: Path) -> None:
    """The adapter goes away while the hand is armed (the pty closes): no exception, the
    device names the port; recovery fails while it is gone and opens it again once it is
    back (a new bus behind the same name), after which the hand arms and reads."""
    from dam_hand_driver.dynamixel_device import DynamixelDevice
    from dam_sim_bridge.dynamixel_standin import DynamixelStandIn

    link = str(tmp_path / 'ttyDXL')

    def start() -> tuple[object, threading.Thread]:
        bus = DynamixelStandIn(cfg, sim_time=True, link_path=link)
        thread = threading.Thread(target=bus.run, daemon=True)
        thread.start()
        return bus, thread

    with fast_gil_handoff():
        bus, thread = start()
        device = DynamixelDevice(cfg, link)
        try:
            device.arm(device.receive(1.0))
            assert device.receive(1.0) is not None
            bus.close()
            thread.join(2.0)
            for _ in range(3):
                assert device.receive(0.05) is None
            assert device.link_lost.startswith(f'the Dynamixel port {link!r} failed')
            assert device.diagnostics()['port_lost'] == device.link_lost
            device.disarm()  # the driver's ERROR: no exception on a dead port
            with pytest.raises(HandDriverError, match=re.escape(f"port {link!r}")):
                device.recover()
            bus, thread = start()
            assert 'opened ' + link + ' again' in device.recover()
            assert device.link_lost == ''
            sample = device.receive(1.0)
            assert sample is not None and sample.fault == ''
            device.arm(sample)
            assert _eventually(lambda: all(_field(bus, j, 'torque_enable') == 1
                                           for j in range(9)))
        finally:
            device.close()
            bus.close()
            thread.join(2.0)


def test_a_second_program_on_the_port_is_refused_naming_the_holder(cfg: DamConfig,
                                                                   standin) -> None:
    """The port is locked while a device holds it (flock, as pyserial's exclusive=True): a
    second opener is refused with one line naming the port and the holder's PID, before it
    touches the line."""
    import os
    import subprocess
    import sys

    from dam_hand_driver.dynamixel_device import DynamixelDevice
    from dam_hand_driver.dynamixel_port import PortBusyError

    holder = subprocess.Popen(
        [sys.executable, '-c', 'import fcntl, os, sys, time\n'
         f'fd = os.open({standin.port_path!r}, os.O_RDWR | os.O_NOCTTY)\n'
         'fcntl.flock(fd, fcntl.LOCK_EX)\nprint("locked", flush=True)\ntime.sleep(60)'],
        stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout.readline().strip() == 'locked'
        with pytest.raises(PortBusyError) as refused:
            DynamixelDevice(cfg, standin.port_path)
        message = str(refused.value)
        assert f"the Dynamixel port {standin.port_path!r} is in use" in message
        assert f'PID {holder.pid}' in message and '\n' not in message
    finally:
        holder.kill()
        holder.wait()
    device = DynamixelDevice(cfg, standin.port_path)  # free again
    try:
        with pytest.raises(PortBusyError, match=f'PID {os.getpid()}'):
            DynamixelDevice(cfg, standin.port_path)
        assert device.receive(1.0) is not None  # the holder reads on
    finally:
        device.close()


def test_a_late_answer_of_the_longer_check_read_is_never_taken_for_the_state(
        cfg: DamConfig, standin) -> None:
    """The SDK matches a status packet by ID and cuts its data to the length it asked for: a
    late answer of the servo check (56 bytes from address 64) would read as Present Position
    (the velocity gains at 76-79 as 6.5 million counts). Only packets of the block's own
    length are taken."""
    import os

    from dam_hand_driver.dynamixel_device import CHECK_LENGTH, DynamixelDevice
    from dam_sim_bridge.dynamixel_packets import build_status

    device = DynamixelDevice(cfg, standin.port_path)
    try:
        assert device.receive(1.0) is not None
        with standin.lock:
            check_block = bytes(standin.servos[0].table[64:64 + CHECK_LENGTH])
        late = [build_status(1, 0, check_block)]
        dispatch = standin.bus._before_dispatch

        def before_dispatch(packet) -> None:  # the late answer goes out before the real ones
            dispatch(packet)
            if late:
                os.write(standin.bus._master, late.pop())

        standin.bus._before_dispatch = before_dispatch
        assert device.receive(1.0) is None
        assert not late
        assert 'a status packet of another length from ID 1' in device.last_failure
        sample = device.receive(1.0)
        with standin.lock:
            world_q = standin.world.joint_states().positions
        assert sample is not None
        assert sample.position == pytest.approx(world_q, abs=POSITION_RAD_PER_COUNT)
    finally:
        device.close()


def test_recovery_reboots_every_error_and_fails_on_one_that_comes_back(cfg: DamConfig,
                                                                      standin) -> None:
    """Only a reboot clears Hardware Error Status: the recovery reboots a servo in any error
    (an input voltage dip included). An error whose cause is still there is set again after
    the reboot: the recovery fails naming it (the driver stays in ERROR with that reason)."""
    from dam_hand_driver.dynamixel_device import DynamixelDevice

    device = DynamixelDevice(cfg, standin.port_path)
    try:
        standin.hardware_error(5, 0x01)  # a supply dip, over
        standin.hardware_error(8, 0x04)  # overheating, cooled down
        done = device.recover()
        assert 'rebooted servo ID 5 (finger2_locked_joint) (input voltage error)' in done
        assert 'rebooted servo ID 8 (finger3_locked_joint) (overheating error)' in done
        with standin.lock:
            assert standin.servos[4].hardware_error == 0 and standin.servos[7].hardware_error == 0
        servo = standin.servos[4]
        reboot = servo.reboot

        def reboot_low_supply():  # the supply is still too low: the error comes back
            answer = reboot()
            servo.set_hardware_error(0x01)
            return answer

        servo.reboot = reboot_low_supply
        standin.hardware_error(5, 0x01)
        with pytest.raises(HandDriverError, match=re.escape(
                'servo ID 5 (finger2_locked_joint) keeps input voltage error after a reboot')):
            device.recover()
    finally:
        device.close()
