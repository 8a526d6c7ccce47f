"""Tests of the simulated device over real UDP sockets on loopback (lockstep, no ROS)."""

from __future__ import annotations

import socket
from collections.abc import Iterator

import numpy as np
import pytest

from dam_common.config import DamConfig, load_config
from dam_common.device_protocol import (
    Calibration,
    DeviceStatus,
    FrameDecoder,
    FrameKind,
    JointFault,
    JointMode,
    StateFrame,
    encode_command,
)
from dam_sim_bridge.sim_device import SimDevice
from dam_sim_bridge.world_options import WorldOptions

T, P, H = int(JointMode.TORQUE), int(JointMode.POSITION), int(JointMode.HOLD)
IMP = int(JointMode.IMPEDANCE)


@pytest.fixture(scope='module')
def cfg() -> DamConfig:
    return load_config()


class _Driver:
    """The driver's end of the link: a state socket on a free port."""

    def __init__(self, cfg: DamConfig) -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.sock.bind(('127.0.0.1', 0))
        self.sock.settimeout(2.0)
        self.port = self.sock.getsockname()[1]
        self.decoder = FrameDecoder(FrameKind.STATE, len(cfg.hand.joint_names))
        self.seq = 0

    def state(self) -> StateFrame:
        frame = self.decoder.decode(self.sock.recv(2048))
        assert frame is not None, self.decoder.last_reject
        assert isinstance(frame, StateFrame)
        return frame

    def send(self, device: SimDevice, modes: list[int], setpoints: np.ndarray,
             stiffness: np.ndarray | None = None, damping: np.ndarray | None = None) -> None:
        self.seq += 1
        self.sock.sendto(encode_command(self.seq, 0, modes, setpoints, stiffness, damping),
                         device.command_address)


@pytest.fixture
def link(cfg: DamConfig) -> Iterator[tuple[SimDevice, _Driver]]:
    driver = _Driver(cfg)
    device = SimDevice(cfg, host='127.0.0.1', command_port=0, state_port=driver.port,
                       lockstep=True)
    yield device, driver
    device.close()
    driver.sock.close()


def test_world_options_follow_config(cfg: DamConfig) -> None:
    opts = WorldOptions.from_config(cfg)
    assert opts.time_step_s == pytest.approx(cfg.sim.time_step_s)
    assert opts.link_masses_kg == pytest.approx(tuple(cfg.hand.link_masses_kg))
    assert opts.torque_limit_nm == pytest.approx(cfg.device.torque_limit_nm)
    assert opts.torque_rate_limit_nm_per_s == pytest.approx(cfg.device.torque_rate_limit_nm_per_s)
    assert opts.object_faces == cfg.sim.object_faces
    assert WorldOptions.from_config(cfg, time_step_s=0.002).time_step_s == 0.002
    with pytest.raises(ValueError, match='no_such_option'):
        WorldOptions.from_config(cfg, no_such_option=1)


def test_states_are_simulated_and_tripped_without_commands(link) -> None:
    device, driver = link
    n = device.world.n_joints
    device.cycle()
    frame = driver.state()
    assert frame.status & DeviceStatus.SIMULATED
    assert frame.status & DeviceStatus.WATCHDOG_TRIPPED
    assert np.all(frame.faults & JointFault.WATCHDOG)
    assert np.all(frame.modes == H)
    cal = Calibration.from_config(device.config)
    q = cal.position_si(frame.position_counts)
    assert q == pytest.approx(device.world.initial_positions(), abs=2e-3)
    assert frame.n_joints == n
    assert device.steps_per_cycle == round(1.0 / device.config.device.rate_hz
                                           / device.world.time_step_s)


def test_torque_command_moves_joint_and_watchdog_zeroes_it(link) -> None:
    device, driver = link
    cal = device.calibration
    n = device.world.n_joints
    j = device.world.joint_names.index('finger1_compliant_joint')
    modes = [H] * n
    modes[j] = T
    tau = np.zeros(n)
    tau[j] = 0.05  # N*m, flexes inward
    raw = cal.setpoints_raw(modes, tau)
    q0 = device.world.joint_states().positions[j]
    for _ in range(20):  # 20 cycles, a command before each
        driver.send(device, modes, raw)
        device.cycle()
        frame = driver.state()
    assert not frame.status & DeviceStatus.WATCHDOG_TRIPPED
    assert frame.modes[j] == T
    assert cal.torque_si(frame.torque_raw)[j] == pytest.approx(0.05, abs=1e-4)
    assert device.world.joint_states().positions[j] > q0 + 1e-3
    assert device.stats.latency_cycles >= 0
    # Commands stop: within 80 ms of device time the torque is zero.
    cycles_80ms = int(0.080 * device.config.device.rate_hz)
    last_command_t = device.now()
    zero_at = None
    for _ in range(cycles_80ms):
        device.cycle()
        frame = driver.state()
        if cal.torque_si(frame.torque_raw)[j] == 0.0 and zero_at is None:
            zero_at = device.now()
    assert zero_at is not None
    assert zero_at - last_command_t <= 0.080
    assert frame.status & DeviceStatus.WATCHDOG_TRIPPED
    assert frame.modes[j] == T  # the safe state keeps torque joints in TORQUE, at zero
    assert device.watchdog.trips == 1


def test_bad_datagrams_are_counted_not_applied(link) -> None:
    device, driver = link
    driver.sock.sendto(b'garbage', device.command_address)
    n = device.world.n_joints
    good = encode_command(5, 0, [P] * n, np.zeros(n, dtype=np.int64))
    corrupt = bytearray(good)
    corrupt[20] ^= 0xFF
    driver.sock.sendto(bytes(corrupt), device.command_address)
    device.cycle()
    driver.state()
    assert device.decoder.counters.short == 1
    assert device.decoder.counters.bad_crc == 1
    assert device.decoder.counters.accepted == 0
    assert device.tripped


def test_command_is_applied_again_after_a_world_reset(link) -> None:
    device, driver = link
    n = device.world.n_joints
    modes = [T] * n
    raw = device.calibration.setpoints_raw(modes, np.full(n, 0.01))
    driver.send(device, modes, raw)
    device.cycle()
    driver.state()
    assert np.all(device.world.joint_modes() == T)
    device.reset_world()
    assert np.all(device.world.joint_modes() == H)
    driver.send(device, modes, raw)  # the same command again
    device.cycle()
    frame = driver.state()
    assert np.all(frame.modes == T)
    assert device.calibration.torque_si(frame.torque_raw) == pytest.approx(np.full(n, 0.01),
                                                                          abs=1e-4)


def test_impedance_command_runs_the_law_on_the_device_and_the_watchdog_zeroes_it(link) -> None:
    """Finger 2's compliant joint in IMPEDANCE over the link, theta_0 = 10 deg above its angle:
    the joint moves towards theta_0, the state frame reports IMPEDANCE, and the torque-sensor
    reading is k (theta_0 - theta) - d theta_dot of the simulated joint (up to one physics
    step and the raw quantisation); without commands it drops to zero torque."""
    device, driver = link
    cal = device.calibration
    n = device.world.n_joints
    j = device.world.joint_names.index('finger2_compliant_joint')
    q0 = device.world.joint_states().positions[j]
    modes = [H] * n
    modes[j] = IMP
    theta_0 = np.zeros(n)
    theta_0[j] = q0 + np.radians(10.0)
    k, d = 1.0, 0.05
    k_raw, d_raw = cal.gains_raw(modes, np.full(n, k), np.full(n, d))
    assert k_raw[j] == round(k / cal.stiffness_scale[j]) and k_raw[0] == 0
    raw = cal.setpoints_raw(modes, theta_0)
    for _ in range(100):  # 0.2 s
        driver.send(device, modes, raw, k_raw, d_raw)
        device.cycle()
        frame = driver.state()
    assert frame.modes[j] == IMP and not frame.status & DeviceStatus.WATCHDOG_TRIPPED
    q, qd, tau = cal.state_si(frame)
    assert q[j] > q0 + np.radians(5.0)
    expected = k * (theta_0[j] - q[j]) - d * qd[j]
    assert tau[j] == pytest.approx(expected, abs=0.02 * k * np.radians(10.0))
    assert abs(tau[j]) > 1e-3
    for _ in range(int(0.080 * device.config.device.rate_hz)):
        device.cycle()
        frame = driver.state()
    assert frame.status & DeviceStatus.WATCHDOG_TRIPPED
    assert frame.modes[j] == T
    assert cal.torque_si(frame.torque_raw)[j] == 0.0
