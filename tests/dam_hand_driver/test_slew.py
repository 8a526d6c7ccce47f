"""The driver's per-frame slew of TORQUE setpoints and IMPEDANCE equilibria (no ROS)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_common.config import load_config
from dam_common.device_protocol import JointMode
from dam_hand_driver.errors import ParameterError
from dam_hand_driver.slew import CommandSlew, slew_torque
from dam_sim_bridge.world import HandWorld
from dam_sim_bridge.world_options import WorldOptions

T, P, H = int(JointMode.TORQUE), int(JointMode.POSITION), int(JointMode.HOLD)
IMP = int(JointMode.IMPEDANCE)
RATE, PERIOD, LIMIT = 20.0, 0.002, 1.0
STEP = RATE * PERIOD  # 0.04 N*m per frame
ZEROS = np.zeros(2)


def _slew() -> CommandSlew:
    return CommandSlew(2, LIMIT, RATE, PERIOD)


def test_slew_torque_moves_by_rate_times_dt_and_clamps() -> None:
    out = slew_torque(np.zeros(2), np.array([0.5, -5.0]), 1.0, 20.0, 0.002)
    assert out == pytest.approx([0.04, -0.04])  # 20 N*m/s * 2 ms
    for _ in range(100):
        out = slew_torque(out, np.array([0.5, -5.0]), 1.0, 20.0, 0.002)
    assert out == pytest.approx([0.5, -1.0])  # reaches the target, clamped to the limit


def test_a_torque_step_starts_from_the_measured_torque_and_moves_a_step_per_frame() -> None:
    slew = _slew()
    modes = np.array([T, H])
    measured = np.array([0.1, 0.3])
    sent = [slew.step(modes, np.array([-0.5, 0.0]), ZEROS, ZEROS, ZEROS, ZEROS, measured)]
    for _ in range(40):
        sent.append(slew.step(modes, np.array([-0.5, 0.0]), ZEROS, ZEROS, ZEROS, ZEROS,
                              sent[-1] * [1.0, 0.0]))
    torques = np.array([s[0] for s in sent])
    assert torques[0] == pytest.approx(0.1 - STEP)  # from the measurement, not from zero
    assert np.abs(np.diff(torques)).max() <= STEP + 1e-12
    assert torques[-1] == pytest.approx(-0.5)
    assert all(s[1] == 0.0 for s in sent)  # the HOLD joint's setpoint goes through


def test_the_impedance_step_of_the_issue_moves_the_equilibrium_by_step_over_k() -> None:
    """theta_0 0.675 rad from the measured angle at k 10: the equilibrium sent starts where
    the law gives the measured torque and moves by 0.04 / 10 rad per frame, so the torque the
    command asks for, k theta_0 - k theta, changes by at most 0.04 N*m per frame; then it is
    theta_0 itself."""
    slew = _slew()
    k, d = 10.0, 0.2
    theta, theta_dot, tau = 0.1, 0.5, 0.02
    theta_0 = theta + 0.675
    modes = np.array([IMP, H])
    gains = (np.array([k, 0.0]), np.array([d, 0.0]))
    sent = []
    for _ in range(200):
        out = slew.step(modes, np.array([theta_0, 0.0]), *gains, np.array([theta, 0.0]),
                        np.array([theta_dot, 0.0]), np.array([tau, 0.0]))
        sent.append(out[0])
    sent = np.array(sent)
    seat = theta + (tau + d * theta_dot) / k  # k (seat - theta) - d theta_dot = tau
    assert sent[0] == pytest.approx(seat + STEP / k)
    assert k * np.abs(np.diff(sent)).max() <= STEP + 1e-12
    frames = math.ceil((theta_0 - seat) / (STEP / k))
    assert np.all(sent[frames - 1:] == theta_0)  # theta_0 exactly, once there
    assert np.all(sent[:frames - 1] < theta_0)


def test_small_equilibrium_changes_pass_unchanged() -> None:
    """A controller moving theta_0 slowly is not delayed by a frame."""
    slew = _slew()
    k = 10.0
    modes = np.array([IMP, IMP])
    gains = (np.full(2, k), np.full(2, 0.1))
    state = (np.full(2, 0.2), ZEROS, ZEROS)
    slew.step(modes, np.full(2, 0.2), *gains, *state)  # seated at rest: theta_0 = theta
    for i in range(1, 50):
        theta_0 = 0.2 + i * 0.9 * STEP / k
        assert slew.step(modes, np.full(2, theta_0), *gains, *state).tolist() == [theta_0] * 2


def test_new_gains_and_mode_changes_restart_from_the_measurement() -> None:
    slew = _slew()
    theta, tau = np.array([0.3, 0.3]), np.array([0.05, 0.05])
    imp = np.array([IMP, IMP])
    slew.step(imp, np.full(2, 0.3), np.full(2, 10.0), ZEROS, theta, ZEROS, tau)
    assert slew.step(imp, np.full(2, 0.3), np.full(2, 10.0), ZEROS, theta, ZEROS,
                     tau).tolist() == [0.3, 0.3]
    # Stiffness 10 -> 50 on joint 0: it restarts where k' (theta_0 - theta) is the measured
    # torque; joint 1 keeps its equilibrium.
    out = slew.step(imp, np.full(2, 0.3), np.array([50.0, 10.0]), ZEROS, theta, ZEROS, tau)
    assert out[0] == pytest.approx(0.3 + 0.05 / 50.0 - STEP / 50.0)
    assert out[1] == 0.3
    # IMPEDANCE -> TORQUE starts from the measured torque, as HOLD -> TORQUE does.
    out = slew.step(np.array([T, H]), np.array([0.5, 0.0]), ZEROS, ZEROS, theta, ZEROS, tau)
    assert out[0] == pytest.approx(0.05 + STEP)
    # After reset() every joint starts afresh.
    slew.step(np.array([T, T]), np.array([0.5, 0.5]), ZEROS, ZEROS, theta, ZEROS, tau)
    slew.reset()
    out = slew.step(np.array([T, T]), np.array([0.5, 0.5]), ZEROS, ZEROS, theta, ZEROS,
                    np.array([-0.2, 0.4]))
    assert out == pytest.approx([-0.2 + STEP, 0.4 + STEP])


def test_bad_parameters_are_refused_by_name() -> None:
    for kwargs, word in (({'torque_limit_nm': 0.0}, 'torque_limit_nm'),
                         ({'rate_nm_per_s': -1.0}, 'rate_nm_per_s'),
                         ({'period_s': math.nan}, 'period_s')):
        args = {'torque_limit_nm': 1.0, 'rate_nm_per_s': 20.0, 'period_s': 0.002, **kwargs}
        with pytest.raises(ParameterError, match=word):
            CommandSlew(2, **args)


def test_the_driver_slew_bounds_the_issue_step_on_a_device_that_does_not_slew() -> None:
    """The issue's IMPEDANCE command through the driver's slew, one frame of latency, to a
    world without a slew limit: the torque it applies, read at every state frame, changes by at
    most rate * period (0.04 N*m) plus 1e-3 N*m for the joint's own motion, and the joint
    settles at theta_0. Without the driver's slew the first frame jumps to the actuator
    limit."""
    cfg = load_config()
    rate, period = cfg.device.torque_rate_limit_nm_per_s, 1.0 / cfg.device.rate_hz
    j = 3  # finger 2's compliant joint, distal link curled in: it swings above the object
    for slewed in (True, False):
        with HandWorld(cfg, WorldOptions.from_config(
                cfg, torque_rate_limit_nm_per_s=math.inf)) as world:
            steps = round(period / world.time_step_s)
            n = world.n_joints
            modes = np.full(n, H)
            setpoints = np.full(n, math.nan)
            modes[j:j + 3] = P
            setpoints[j:j + 3] = [math.radians(-30.0), 0.0, math.radians(90.0)]
            world.set_joint_commands(modes, setpoints)
            world.step(1000)
            slew = CommandSlew(n, cfg.device.torque_limit_nm, rate, period)
            theta_0 = world.joint_states().positions[j] + 0.675
            modes[j], setpoints[j] = IMP, theta_0
            stiffness, damping = np.zeros(n), np.zeros(n)
            stiffness[j], damping[j] = 10.0, cfg.controller.damping_nms_per_rad
            pending = None
            efforts = []
            for _ in range(1000):
                js = world.joint_states()
                efforts.append(js.torques[j])
                sent = (slew.step(modes, setpoints, stiffness, damping, *js) if slewed
                        else setpoints)
                if pending is not None:
                    world.set_joint_commands(modes, pending, stiffness, damping)
                pending = sent
                world.step(steps)
            changes = np.abs(np.diff(efforts))
            if slewed:
                assert changes.max() <= rate * period + 1e-3
                assert world.joint_states().positions[j] == pytest.approx(theta_0, abs=0.01)
            else:
                assert changes.max() > 0.9
