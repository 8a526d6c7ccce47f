"""The stand-in device's torque slew limit, physics step by physics step (no ROS, no network).

Every torque the world applies in TORQUE and IMPEDANCE mode may change by at most
``torque_rate_limit_nm_per_s * time_step_s`` between two physics steps (0.02 N*m with the
shipped configuration), across mode changes and the watchdog's safe stop, and a step command
must still reach its steady state.
"""

from __future__ import annotations

import math
from collections.abc import Iterator

import numpy as np
import pytest

from dam_common.config import DamConfig, load_config
from dam_common.device_protocol import Calibration, DeviceWatchdog, JointMode
from dam_sim_bridge.errors import WorldConfigError
from dam_sim_bridge.world import HandWorld
from dam_sim_bridge.world_options import WorldOptions

T, P, H = int(JointMode.TORQUE), int(JointMode.POSITION), int(JointMode.HOLD)
IMP = int(JointMode.IMPEDANCE)
#: The joint under test: finger 2's compliant joint, with its distal link curled in (position
#: joint at 90 deg) so that it swings freely above the object.
J = 3
POSTURE_RAD = (math.radians(-30.0), 0.0, math.radians(90.0))
#: Rounding slack of the per-step comparison [N*m].
EPS_NM = 1e-12


@pytest.fixture(scope='module')
def cfg() -> DamConfig:
    return load_config()


@pytest.fixture
def world(cfg: DamConfig) -> Iterator[HandWorld]:
    """The configured world (drive inertia, gravity, the shipped slew limit), finger 2 held in
    :data:`POSTURE_RAD` by its servos."""
    w = HandWorld(cfg)
    modes, setpoints = _held(w)
    w.set_joint_commands(modes, setpoints)
    w.step(1000)
    yield w
    w.close()


def _held(world: HandWorld) -> tuple[list[int], list[float]]:
    modes = [H] * world.n_joints
    setpoints = [math.nan] * world.n_joints
    modes[J:J + 3] = [P, P, P]
    setpoints[J:J + 3] = list(POSTURE_RAD)
    return modes, setpoints


def _max_change(world: HandWorld) -> float:
    """The slew limit per physics step [N*m]."""
    return world.options.torque_rate_limit_nm_per_s * world.time_step_s


def _impedance(world: HandWorld, theta_0: float, k: float, d: float) -> None:
    modes, setpoints = _held(world)
    modes[J], setpoints[J] = IMP, theta_0
    stiffness = [math.nan] * world.n_joints
    damping = [math.nan] * world.n_joints
    stiffness[J], damping[J] = k, d
    world.set_joint_commands(modes, setpoints, stiffness, damping)


def _run(world: HandWorld, steps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step one physics step at a time; the torque reading [N*m] of joint J before the first
    step and after every step, its angles [rad] and velocities [rad/s] after every step."""
    torques = [world.joint_states().torques[J]]
    angles, velocities = [], []
    for _ in range(steps):
        world.step(1)
        js = world.joint_states()
        torques.append(js.torques[J])
        angles.append(js.positions[J])
        velocities.append(js.velocities[J])
    return np.array(torques), np.array(angles), np.array(velocities)


def _gravity_bound(cfg: DamConfig, world: HandWorld) -> float:
    """An upper bound of the gravity torque on a compliant joint [N*m]: every link's weight at
    the finger's full length."""
    return (cfg.task.gravity_m_per_s2 * float(np.sum(world.link_masses_kg))
            * float(np.sum(cfg.hand.link_lengths_m)))


def test_a_torque_step_is_slewed_from_the_servo_torque_to_its_setpoint(
        world: HandWorld) -> None:
    step = _max_change(world)
    servo = world.joint_states().torques[J]
    assert abs(servo) > 1e-3  # the servo carries the finger's weight
    modes, setpoints = _held(world)
    modes[J], setpoints[J] = T, 0.3
    world.set_joint_commands(modes, setpoints)
    torques, _, _ = _run(world, 100)
    changes = np.abs(np.diff(torques))
    assert changes.max() <= step + EPS_NM
    assert torques[1] == pytest.approx(servo + step)  # bumpless: from the servo's torque
    ramp = math.ceil((0.3 - servo) / step)
    assert np.all(torques[ramp:] == 0.3)  # the setpoint, exactly, once the ramp is done
    assert np.all(torques[1:ramp] < 0.3)


def test_the_impedance_step_of_the_issue_is_slewed_and_settles(
        world: HandWorld, cfg: DamConfig) -> None:
    """theta_0 0.675 rad from the measured angle with k_theta 10 demands 6.75 N*m at once
    (the actuator limit is 1 N*m): the applied torque still changes by at most the slew limit
    per physics step, and the joint settles where the spring holds the finger's weight."""
    step = _max_change(world)
    k, d = 10.0, cfg.controller.damping_nms_per_rad
    theta_start = world.joint_states().positions[J]
    theta_0 = theta_start + 0.675
    assert k * 0.675 > 5.0 * world.options.torque_limit_nm
    _impedance(world, theta_0, k, d)
    torques, angles, velocities = _run(world, 2000)
    assert np.abs(np.diff(torques)).max() <= step + EPS_NM
    assert torques.max() > 5.0 * step  # the law did drive the joint
    assert velocities.max() > 1.5  # ... fast, towards theta_0
    # At rest, the law's own torque k (theta_0 - theta), which holds the finger's weight: the
    # joint sags below theta_0 by less than the largest gravity torque over k.
    theta, tau = angles[-1], torques[-1]
    assert abs(velocities[-200:]).max() < 1e-3
    assert tau == pytest.approx(k * (theta_0 - theta), abs=1e-4)
    assert 0.0 < theta_0 - theta < _gravity_bound(cfg, world) / k
    assert world.joint_modes()[J] == IMP


def test_a_disturbed_impedance_joint_stays_slewed_and_recovers(
        world: HandWorld, cfg: DamConfig) -> None:
    """A knock of 5 rad/s on a joint resting in IMPEDANCE: the law would change its torque at
    k * 5 = 50 N*m/s, beyond the limit; the applied torque is slewed and the joint comes back
    to rest at its equilibrium instead of oscillating between its limits."""
    step = _max_change(world)
    k, d = 10.0, cfg.controller.damping_nms_per_rad
    theta_0 = world.joint_states().positions[J] + 0.1
    _impedance(world, theta_0, k, d)
    world.step(1500)
    rest = world.joint_states()
    assert abs(rest.velocities[J]) < 1e-3
    world.client.resetJointState(world.hand_id, world.joint_indices[J],
                                 float(rest.positions[J]), 5.0)
    torques, angles, velocities = _run(world, 2000)
    assert np.abs(np.diff(torques)).max() <= step + EPS_NM
    assert np.abs(np.diff(torques)).max() > 0.99 * step  # the slew limit did bite
    lower, upper = world.joint_lower_limits[J], world.joint_upper_limits[J]
    assert lower + 0.05 < angles.min() and angles.max() < upper - 0.05
    assert abs(velocities[-300:]).max() < 1e-3
    assert angles[-1] == pytest.approx(rest.positions[J], abs=math.radians(0.1))
    assert torques[-1] == pytest.approx(rest.torques[J], abs=1e-4)


def test_mode_changes_are_bumpless_and_the_safe_stop_ramps_to_zero(
        world: HandWorld, cfg: DamConfig) -> None:
    """HOLD -> IMPEDANCE -> TORQUE at the actuator limit -> no more commands: every step within
    the slew limit; the watchdog's zero torque is reached limit / rate after the trip."""
    step = _max_change(world)
    now = [0.0]
    watchdog = DeviceWatchdog(world.n_joints, cfg.device.watchdog_s, clock=lambda: now[0])
    cal = Calibration.from_config(cfg)
    limit = world.options.torque_limit_nm
    theta = world.joint_states().positions[J]
    modes, setpoints = _held(world)
    stiffness = np.zeros(world.n_joints)
    damping = np.zeros(world.n_joints)
    phases = []
    imp_modes = np.array(modes)
    imp_modes[J] = IMP
    stiffness[J], damping[J] = 10.0, 0.2
    phases.append((imp_modes, np.where(imp_modes == IMP, theta, np.nan_to_num(setpoints)),
                   stiffness.copy(), damping.copy(), 300))
    torque_modes = np.array(modes)
    torque_modes[J] = T
    phases.append((torque_modes, np.where(torque_modes == T, limit, np.nan_to_num(setpoints)),
                   np.zeros(world.n_joints), np.zeros(world.n_joints), 300))
    torques = [world.joint_states().torques[J]]
    for m, sp, k, d, steps in phases:
        k_raw, d_raw = cal.gains_raw(m, k, d)
        for _ in range(steps):
            watchdog.feed(m, cal.setpoints_raw(m, sp), k_raw, d_raw)
            out = watchdog.output()
            gains = cal.gains_si(out.stiffness, out.damping)
            world.set_joint_commands(out.modes, cal.setpoints_si(out.modes, out.setpoints),
                                     *gains)
            world.step(1)
            now[0] += world.time_step_s
            torques.append(world.joint_states().torques[J])
    assert torques[-1] == pytest.approx(limit)
    # No more commands: the watchdog trips, the torque ramps down to zero.
    tripped_at = None  # index in torques of the reading before the first safe-state step
    for _ in range(int(2 * cfg.device.watchdog_s / world.time_step_s) + 100):
        out = watchdog.output()
        if out.tripped and tripped_at is None:
            tripped_at = len(torques) - 1
        world.set_joint_commands(out.modes, cal.setpoints_si(out.modes, out.setpoints))
        world.step(1)
        now[0] += world.time_step_s
        torques.append(world.joint_states().torques[J])
    assert tripped_at is not None and world.joint_modes()[J] == T
    changes = np.abs(np.diff(torques))
    assert changes.max() <= step + EPS_NM
    after_trip = np.array(torques[tripped_at:])
    assert after_trip[0] == pytest.approx(limit)
    zero_at = int(np.flatnonzero(after_trip == 0.0)[0])  # physics steps after the trip
    assert zero_at == math.ceil(limit / step)  # 50 steps = 50 ms with the shipped values
    assert np.all(after_trip[zero_at:] == 0.0)


def test_a_bad_slew_limit_is_refused_by_name() -> None:
    for rate in (0.0, -1.0, math.nan):
        with pytest.raises(WorldConfigError, match='torque_rate_limit_nm_per_s'):
            WorldOptions(torque_rate_limit_nm_per_s=rate)
    assert WorldOptions(torque_rate_limit_nm_per_s=math.inf).torque_rate_limit_nm_per_s \
        == math.inf
