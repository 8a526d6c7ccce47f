"""DAM state machine: every transition, against a synthetic plant (see spcm_plant.py).

The plant is a 1-DOF-per-joint stand-in written for these tests, not a simulator recording.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from spcm_plant import SyntheticHand, run

from dam_common.config import load_config
from dam_spcm_controller.commands import JointMode
from dam_spcm_controller.errors import InputError, StateError
from dam_spcm_controller.sequence import DamSequence, Phase, SequenceParams

CFG = load_config()
K_THETA = 0.5
DP = math.radians(65.0)


#: The synthetic plant is massless with viscous friction b = 0.02 N*m*s/rad; a controller
#: damping above b makes that idealised plant alternate from step to step (a real joint has
#: inertia, the simulator's drive inertia). These tests check the sequence logic, not the gains.
PLANT_DAMPING = 0.005


@pytest.fixture
def params() -> SequenceParams:
    """The impedance law computed by the controller (``impedance_on_device`` false): TORQUE
    commands. The device-side impedance has its own tests below (``dev_params``)."""
    return SequenceParams.from_config(CFG, damping=PLANT_DAMPING, impedance_on_device=False)


@pytest.fixture
def dev_params() -> SequenceParams:
    """The default: compliant joints in IMPEDANCE, the law runs on the device (the plant)."""
    return SequenceParams.from_config(CFG, damping=PLANT_DAMPING)


def _new(params, **hand_kw):
    seq = DamSequence(params)
    hand = SyntheticHand(params.layout, **hand_kw)
    return seq, hand


def _run_to(seq, hand, phase, t0=0.0, t_end=15.0):
    return run(seq, hand, t0, t_end, until=lambda s: s.phase is phase or s.phase.terminal)


def _started(params, **hand_kw):
    seq, hand = _new(params, **hand_kw)
    run(seq, hand, 0.0, 0.05)
    seq.start(K_THETA, DP)
    return seq, hand


def _phases(log):
    out = []
    for rec in log:
        if not out or out[-1] != rec[1]:
            out.append(rec[1])
    return out


# ---------------------------------------------------------------------------------------------
# Nominal sequence


def test_full_sequence_visits_every_phase_in_order(params):
    seq, hand = _started(params)
    t, log = run(seq, hand, 0.051, 15.0, until=lambda s: s.phase.terminal)
    assert _phases(log) == [Phase.APPROACH, Phase.ROLLING_UP, Phase.ENVELOPE, Phase.DONE]
    assert seq.failure_reason is None
    assert seq.progress == 1.0
    progress = []
    seq2, hand2 = _started(params)
    run(seq2, hand2, 0.051, 15.0, until=lambda s: s.phase.terminal,
        on_step=lambda t, s, h: progress.append(s.progress))
    assert np.all(np.diff(progress) >= 0.0)


def test_idle_holds_measured_posture(params):
    seq = DamSequence(params)
    q = np.radians(np.tile([3.0, -2.0, 40.0], 3))
    cmd = seq.step(0.0, q, np.zeros(9), np.zeros(9))
    assert np.all(cmd.modes == JointMode.HOLD)
    assert np.array_equal(cmd.setpoints, q)
    # the hold posture is latched: later measurements do not move the setpoint
    cmd2 = seq.step(0.01, q + 0.1, np.zeros(9), np.zeros(9))
    assert np.array_equal(cmd2.setpoints, q)


def test_approach_latches_theta_0_at_contact(params):
    contact_deg = [18.0, 22.0, 25.0]
    seq, hand = _started(params, theta_c0_deg=contact_deg)
    _run_to(seq, hand, Phase.ROLLING_UP, 0.051)
    assert seq.phase is Phase.ROLLING_UP
    assert seq.contact.all()
    # the latched posture is where each finger met its object spring (within the small
    # penetration that the threshold torque needs: threshold / k_contact)
    pen = math.degrees(params.contact_torque_threshold / 5.0)
    assert np.all(np.degrees(seq.theta_0) >= np.array(contact_deg) - 1e-9)
    assert np.all(np.degrees(seq.theta_0) <= np.array(contact_deg) + pen + 0.05)
    assert seq.progress == pytest.approx(0.2)


def test_approach_closes_equilibrium_at_approach_speed(params):
    seq, hand = _started(params)
    # the plant starts pre-shaped, so closing starts at once; torque ramp-in lasts 0.2 s
    records = []
    run(seq, hand, 0.05, 1.0, on_step=lambda t, s, h: records.append((t, h.q[0])))
    t_a, q_a = records[400]
    t_b, q_b = records[900]
    speed = (q_b - q_a) / (t_b - t_a)
    assert speed == pytest.approx(params.approach_speed, rel=0.05)


def test_approach_preshapes_locked_and_position_joints(params):
    seq, hand = _new(params, start_deg=(0.0, 5.0, 0.0))
    run(seq, hand, 0.0, 0.01)
    seq.start(K_THETA, DP)
    cmd = seq.step(0.02, hand.q, hand.qd, hand.effort)
    # first APPROACH command: no jump away from the measurement
    assert np.allclose(cmd.setpoints[1::3], hand.q[1::3])
    assert np.allclose(cmd.setpoints[2::3], hand.q[2::3])
    assert np.all(cmd.setpoints[0::3] == 0.0)  # torque ramps in from zero
    _run_to(seq, hand, Phase.ROLLING_UP, 0.021)
    assert np.allclose(np.degrees(hand.q[1::3]), 0.0, atol=0.1)
    assert np.allclose(np.degrees(hand.q[2::3]), 15.0, atol=0.1)


def test_rolling_up_follows_trajectory_and_impedance(params):
    seq, hand = _started(params)
    t, _ = _run_to(seq, hand, Phase.ROLLING_UP, 0.051)
    t_roll = t
    theta_0 = seq.theta_0
    velocities = []
    _, log = run(seq, hand, t + 0.001, t + 3.5,
                 on_step=lambda t, s, h: velocities.append(h.qd.copy()))
    checked = 0
    for (t_k, phase, cmd, q, _), qd in zip(log, velocities, strict=True):
        if phase is not Phase.ROLLING_UP:
            continue
        tau = np.clip(K_THETA * np.array([1.0, 0.5, 0.5]) * (theta_0 - q[0::3])
                      - params.damping * qd[0::3], -params.torque_limit, params.torque_limit)
        assert np.allclose(cmd.setpoints[0::3], tau)
        tau_n = min(max((t_k - t_roll) / params.trajectory_duration, 0.0), 1.0)
        s_n = 10 * tau_n**3 - 15 * tau_n**4 + 6 * tau_n**5
        assert np.allclose(cmd.setpoints[2::3], math.radians(15.0) + DP * s_n)
        assert np.all(cmd.modes[0::3] == JointMode.TORQUE)
        assert np.all(cmd.modes[2::3] == JointMode.POSITION)
        assert np.all(cmd.modes[1::3] == JointMode.HOLD)
        assert np.allclose(cmd.setpoints[1::3], 0.0)
        checked += 1
    assert checked > 2500
    # SPCM: the compliant joints were pushed outward, tau_s = -K delta_theta_s > 0
    assert np.all(seq.delta_theta_s < 0.0)
    assert np.allclose(seq.tau_s, -seq.k_theta_i * (hand.q[0::3] - theta_0))


def test_envelope_applies_constant_torque_after_ramp(params):
    seq, hand = _started(params)
    t, _ = _run_to(seq, hand, Phase.ENVELOPE, 0.051)
    assert seq.phase is Phase.ENVELOPE
    t_end, log = run(seq, hand, t + 0.001, t + 0.4)
    first = log[0][2].setpoints
    last = seq.step(t_end + 0.001, hand.q, hand.qd, hand.effort)
    modes, sets = last.modes, last.setpoints
    assert seq.phase is Phase.ENVELOPE
    assert np.all(modes[0::3] == JointMode.TORQUE)
    # the position joints stay servoed at the end of their trajectory (no torque on them)
    assert np.all(modes[2::3] == JointMode.POSITION)
    goal = params.layout.initial_position_angle + seq.delta_theta_p
    assert np.allclose(sets[2::3], goal)
    # finger i gets envelope_torque * ratio_i / max(ratio) (balanced: finger 1 opposes 2 and 3),
    # minus the damping term
    ratios = params.layout.stiffness_ratios
    expected = params.envelope_torque * ratios / ratios.max() - params.damping * hand.qd[0::3]
    assert np.allclose(sets[0::3], expected, atol=1e-9)
    assert sets[0] == pytest.approx(2.0 * sets[3], rel=0.05, abs=1e-4)
    # bumpless: the first envelope command is close to the last rolling-up torque, not a jump
    assert np.all(np.abs(first[0::3] - params.envelope_torque) > 0.0)


def test_done_keeps_the_envelope_torque(params):
    seq, hand = _started(params)
    t, _ = _run_to(seq, hand, Phase.DONE, 0.051)
    assert seq.phase is Phase.DONE
    t_end, log = run(seq, hand, t + 0.001, t + 1.0)
    cmd = seq.step(t_end + 0.001, hand.q, hand.qd, hand.effort)
    ratios = params.layout.stiffness_ratios
    expected = params.envelope_torque * ratios / ratios.max() - params.damping * hand.qd[0::3]
    assert np.allclose(cmd.setpoints[0::3], expected, atol=1e-9)
    assert log[-1][1] is Phase.DONE


# ---------------------------------------------------------------------------------------------
# Failures


def test_approach_without_object_fails_at_joint_limit(params):
    seq, hand = _started(params)
    hand.object_present[:] = False
    _run_to(seq, hand, Phase.ROLLING_UP, 0.051, 15.0)
    assert seq.phase is Phase.FAILED
    assert 'finger1' in seq.failure_reason and 'compliant joint limit' in seq.failure_reason


def test_phase_timeout_fails(params):
    short = SequenceParams.from_config(CFG, phase_timeout=4.0, damping=PLANT_DAMPING,
                                       impedance_on_device=False)
    # a very far object: the equilibrium will not reach it before the timeout
    seq, hand = _started(short, theta_c0_deg=55.0)
    t, _ = _run_to(seq, hand, Phase.ROLLING_UP, 0.051, 15.0)
    assert seq.phase is Phase.FAILED
    assert 'phase approach exceeded phase_timeout 4 s' in seq.failure_reason
    assert t == pytest.approx(0.051 + 4.0, abs=2e-3)


def test_lost_contact_during_rolling_up_fails(params):
    seq, hand = _started(params)
    t, _ = _run_to(seq, hand, Phase.ROLLING_UP, 0.051)

    def drop(t_now, s, h):
        if t_now > t + 1.5:
            h.object_present[1] = False  # finger2 loses the object

    run(seq, hand, t + 0.001, t + 3.0, on_step=drop, until=lambda s: s.phase.terminal)
    assert seq.phase is Phase.FAILED
    assert 'lost contact on finger2' in seq.failure_reason


def test_measured_joint_beyond_limit_fails(params):
    seq, hand = _started(params)
    t, _ = _run_to(seq, hand, Phase.ROLLING_UP, 0.051)
    q = hand.q.copy()
    q[5] = math.radians(96.0)  # finger2 position joint beyond 95 deg
    seq.step(t + 0.001, q, hand.qd, hand.effort)
    assert seq.phase is Phase.FAILED
    assert 'finger2_position_joint at 96 deg' in seq.failure_reason


def test_envelope_without_object_relaxes_to_the_contact_posture(params):
    """ENVELOPE holds the SPCM impedance: with the object gone the compliant joints return to
    theta_0 with no load (the classifier then reports a failure); nothing runs away."""
    seq, hand = _started(params)
    t, _ = _run_to(seq, hand, Phase.ENVELOPE, 0.051)
    hand.object_present[:] = False
    t_end, _ = run(seq, hand, t + 0.001, t + 5.0, until=lambda s: s.phase.terminal)
    assert seq.phase is Phase.DONE
    assert np.allclose(hand.q[0::3], seq.theta_0, atol=math.radians(0.5))
    cmd = seq.step(t_end + 0.001, hand.q, hand.qd, hand.effort)
    assert np.all(np.abs(cmd.setpoints[0::3]) < params.contact_torque_threshold)


def test_external_fail(params):
    seq, hand = _started(params)
    run(seq, hand, 0.051, 0.5)
    assert seq.fail('joint states silent for 0.1 s')
    assert seq.phase is Phase.FAILED
    assert seq.failure_reason == 'joint states silent for 0.1 s'
    assert not DamSequence(params).fail('x')  # nothing to fail in IDLE


# ---------------------------------------------------------------------------------------------
# Cancel and relaxation


@pytest.mark.parametrize('phase', [Phase.APPROACH, Phase.ROLLING_UP, Phase.ENVELOPE])
def test_cancel_from_each_active_phase_relaxes(params, phase):
    seq, hand = _started(params)
    t, _ = _run_to(seq, hand, phase, 0.051)
    assert seq.phase is phase
    _, log = run(seq, hand, t + 0.001, t + 0.1)  # a little into the phase
    t_cancel, _, last_cmd, _, _ = log[-1]
    before = last_cmd.setpoints
    torque_joints = last_cmd.modes == JointMode.TORQUE
    assert torque_joints.any()
    progress = seq.progress
    assert seq.cancel()
    assert seq.phase is Phase.ABORTED
    assert seq.failure_reason is None
    t1 = t_cancel
    cmd = seq.step(t1, hand.q, hand.qd, hand.effort)
    # no POSITION joints left; they hold their last setpoint
    assert not np.any(cmd.modes == JointMode.POSITION)
    assert np.allclose(cmd.setpoints[~torque_joints], before[~torque_joints])
    # torque ramps linearly to zero
    mid = seq.step(t1 + params.torque_ramp_time / 2, hand.q, hand.qd, hand.effort)
    assert np.allclose(mid.setpoints[torque_joints], before[torque_joints] / 2)
    assert not seq.relaxed
    end = seq.step(t1 + params.torque_ramp_time, hand.q, hand.qd, hand.effort)
    assert np.allclose(end.setpoints[torque_joints], 0.0)
    assert seq.relaxed
    assert seq.progress == progress


@pytest.mark.parametrize('phase', [Phase.IDLE, Phase.DONE, Phase.FAILED])
def test_cancel_without_active_grasp_is_a_no_op(params, phase):
    seq, hand = _new(params)
    run(seq, hand, 0.0, 0.01)
    if phase is Phase.DONE:
        seq.start(K_THETA, DP)
        _run_to(seq, hand, Phase.DONE, 0.011)
    elif phase is Phase.FAILED:
        seq.start(K_THETA, DP)
        run(seq, hand, 0.011, 0.02)
        seq.fail('test')
    assert seq.phase is phase
    assert not seq.cancel()
    assert seq.phase is phase


def test_cancel_before_first_step_holds_measured(params):
    seq, hand = _new(params)
    seq.start(K_THETA, DP)
    assert seq.cancel()
    assert seq.phase is Phase.ABORTED
    cmd = seq.step(0.0, hand.q, hand.qd, hand.effort)
    assert np.all(cmd.modes == JointMode.HOLD)
    assert np.array_equal(cmd.setpoints, hand.q)


# ---------------------------------------------------------------------------------------------
# start / reset / input validation


def test_start_validates_arguments(params):
    seq = DamSequence(params)
    for bad in (0.0, -1.0, math.nan, math.inf):
        with pytest.raises(InputError, match='k_theta'):
            seq.start(bad, DP)
    with pytest.raises(InputError, match='delta_theta_p'):
        seq.start(K_THETA, 0.0)
    with pytest.raises(InputError, match=r'delta_theta_p \d\S* rad \(\d\S* deg\) exceeds '
                                         r'delta_theta_p_max \d\S* rad \(\d\S* deg\)$'):
        seq.start(K_THETA, DP + 0.01)
    assert seq.phase is Phase.IDLE


def test_start_while_active_is_refused(params):
    seq, hand = _started(params)
    with pytest.raises(StateError, match='in progress'):
        seq.start(K_THETA, DP)
    run(seq, hand, 0.051, 0.1)
    with pytest.raises(StateError, match='approach'):
        seq.start(K_THETA, DP)
    with pytest.raises(StateError):
        seq.reset()


def test_restart_after_terminal_and_reset(params):
    seq, hand = _started(params)
    run(seq, hand, 0.051, 0.2)
    seq.cancel()
    seq.start(1.0, math.radians(30.0))  # a new run directly from ABORTED
    assert seq.k_theta == 1.0
    assert np.allclose(seq.k_theta_i, [1.0, 0.5, 0.5])
    run(seq, hand, 0.201, 0.3)
    assert seq.phase is Phase.APPROACH
    seq.fail('x')
    seq.reset()
    assert seq.phase is Phase.IDLE and seq.failure_reason is None
    cmd = seq.step(0.4, hand.q, hand.qd, hand.effort)
    assert np.all(cmd.modes == JointMode.HOLD) and np.array_equal(cmd.setpoints, hand.q)


def test_step_validates_inputs_and_keeps_state(params):
    seq, hand = _started(params)
    run(seq, hand, 0.051, 0.2)
    bad = hand.q.copy()
    bad[4] = math.nan
    with pytest.raises(InputError, match=r'positions\[4\] must be finite'):
        seq.step(0.3, bad, hand.qd, hand.effort)
    with pytest.raises(InputError, match='velocities must have 9 values'):
        seq.step(0.3, hand.q, hand.qd[:8], hand.effort)
    with pytest.raises(InputError, match='t must not decrease'):
        seq.step(0.1, hand.q, hand.qd, hand.effort)
    with pytest.raises(InputError, match=r'efforts\[0\] must be finite'):
        seq.step(0.3, hand.q, hand.qd, np.full(9, math.inf))
    assert seq.phase is Phase.APPROACH
    seq.step(0.3, hand.q, hand.qd, hand.effort)  # still usable


def test_deterministic(params):
    results = []
    for _ in range(2):
        seq, hand = _started(params)
        _, log = run(seq, hand, 0.051, 15.0, until=lambda s: s.phase.terminal)
        results.append(np.array([rec[2].setpoints for rec in log]))
    assert np.array_equal(results[0], results[1])


def test_params_validation():
    with pytest.raises(InputError, match='phase_timeout'):
        SequenceParams.from_config(CFG, phase_timeout=2.0)
    with pytest.raises(InputError, match='envelope_torque'):
        SequenceParams.from_config(CFG, envelope_torque=1.0)
    with pytest.raises(InputError, match='settle_time'):
        SequenceParams.from_config(CFG, settle_time=-1.0)


def test_time_gap_longer_than_phase_timeout_fails_rolling_up(params):
    seq, hand = _started(params)
    t, _ = _run_to(seq, hand, Phase.ROLLING_UP, 0.051)
    seq.step(t + params.phase_timeout + 0.01, hand.q, hand.qd, hand.effort)
    assert seq.phase is Phase.FAILED
    assert 'phase rolling_up exceeded phase_timeout' in seq.failure_reason


def test_envelope_that_never_settles_times_out(params):
    seq, hand = _started(params)
    t, _ = _run_to(seq, hand, Phase.ENVELOPE, 0.051)
    t_env = t
    moving = np.full(9, 2.0 * params.settle_speed)  # the fingers never come to rest
    while seq.phase is Phase.ENVELOPE and t < t_env + 20.0:
        t = round(t + 0.01, 9)
        seq.step(t, hand.q, moving, hand.effort)
    assert seq.phase is Phase.FAILED
    assert 'phase envelope exceeded phase_timeout' in seq.failure_reason
    assert t == pytest.approx(t_env + params.phase_timeout, abs=0.011)


def test_envelope_settles_after_settle_time(params):
    seq, hand = _started(params)
    t, _ = _run_to(seq, hand, Phase.ENVELOPE, 0.051)
    t_env = t
    still = np.zeros(9)
    while seq.phase is Phase.ENVELOPE:
        t = round(t + 0.001, 9)
        seq.step(t, hand.q, still, hand.effort)
    # the torque ramp must finish before the settle time starts counting
    assert t == pytest.approx(t_env + params.torque_ramp_time + params.settle_time, abs=1.5e-3)
    assert seq.phase is Phase.DONE


def test_failure_relaxes_like_abort(params):
    seq, hand = _started(params)
    t, _ = _run_to(seq, hand, Phase.ROLLING_UP, 0.051)
    _, log = run(seq, hand, t + 0.001, t + 1.0)
    t_fail, _, last_cmd, _, _ = log[-1]
    torque_joints = last_cmd.modes == JointMode.TORQUE
    q = hand.q.copy()
    q[3] = math.radians(61.0)  # finger2 compliant joint beyond its 60 deg limit
    cmd = seq.step(t_fail + 0.001, q, hand.qd, hand.effort)
    assert seq.phase is Phase.FAILED
    assert 'finger2_compliant_joint at 61 deg reached its joint limit' in seq.failure_reason
    assert not np.any(cmd.modes == JointMode.POSITION)
    # the position joints hold their last trajectory setpoint
    assert np.allclose(cmd.setpoints[2::3], last_cmd.setpoints[2::3])
    end = seq.step(t_fail + 0.001 + params.torque_ramp_time, q, hand.qd, hand.effort)
    assert np.all(end.setpoints[torque_joints] == 0.0)
    assert seq.relaxed


# ---------------------------------------------------------------------------------------------
# Phase right after start() (the action feedback showed IDLE for one status tick)


@pytest.mark.parametrize('on_device', [False, True])
def test_phase_is_approach_as_soon_as_the_grasp_is_started(on_device):
    p = SequenceParams.from_config(CFG, damping=PLANT_DAMPING, impedance_on_device=on_device)
    seq, hand = _new(p)
    run(seq, hand, 0.0, 0.05)
    assert seq.phase is Phase.IDLE
    seq.start(K_THETA, DP)
    assert seq.phase is Phase.APPROACH  # before the first step after start()
    assert seq.phase.active
    cmd = seq.step(0.051, hand.q, hand.qd, hand.effort)
    assert seq.phase is Phase.APPROACH
    assert not np.any(cmd.modes[0::3] == JointMode.HOLD)  # the approach has begun
    # a cancel before the first step still aborts
    seq2, hand2 = _new(p)
    run(seq2, hand2, 0.0, 0.05)
    seq2.start(K_THETA, DP)
    assert seq2.cancel() and seq2.phase is Phase.ABORTED


# ---------------------------------------------------------------------------------------------
# Impedance on the device (the default)


def test_device_mode_visits_every_phase_and_sends_only_gains_and_equilibria(dev_params):
    assert dev_params.impedance_on_device  # the configured default
    seq, hand = _started(dev_params)
    _, log = run(seq, hand, 0.051, 15.0, until=lambda s: s.phase.terminal)
    assert _phases(log) == [Phase.APPROACH, Phase.ROLLING_UP, Phase.ENVELOPE, Phase.DONE]
    k_i = K_THETA * np.array([1.0, 0.5, 0.5])  # stiffness ratios of config/dam.yaml
    rolling = 0
    for _, phase, cmd, _, _ in log:
        if phase.active:
            assert np.all(cmd.modes[0::3] == JointMode.IMPEDANCE), phase
            assert np.allclose(cmd.stiffness[0::3], k_i)
            assert np.allclose(cmd.damping[0::3], dev_params.damping)
            # gains only on the compliant joints; never a torque command
            assert np.all(cmd.stiffness[1::3] == 0.0) and np.all(cmd.stiffness[2::3] == 0.0)
            assert not np.any(cmd.modes == JointMode.TORQUE)
        if phase is Phase.ROLLING_UP:
            assert np.allclose(cmd.setpoints[0::3], seq.theta_0)  # the equilibrium theta_0
            rolling += 1
    assert rolling > 2500
    # SPCM happened: the object pushed the compliant joints outward
    assert seq.failure_reason is None and seq.progress == 1.0


def test_device_mode_approach_moves_the_equilibrium_and_latches_theta_0(dev_params):
    contact_deg = [18.0, 22.0, 25.0]
    seq, hand = _new(dev_params, theta_c0_deg=contact_deg)
    run(seq, hand, 0.0, 0.05)
    seq.start(K_THETA, DP)
    first = seq.step(0.051, hand.q, hand.qd, hand.effort)
    # no jump: the equilibrium starts at the measured angle
    assert np.allclose(first.setpoints[0::3], hand.q[0::3])
    _, log = run(seq, hand, 0.052, 0.6)
    eq = [(rec[0], rec[2].setpoints[0]) for rec in log]
    (t_a, e_a), (t_b, e_b) = eq[100], eq[400]
    assert (e_b - e_a) / (t_b - t_a) == pytest.approx(dev_params.approach_speed, rel=1e-6)
    _run_to(seq, hand, Phase.ROLLING_UP, 0.601)
    assert seq.phase is Phase.ROLLING_UP
    pen = math.degrees(dev_params.contact_torque_threshold / 5.0)
    assert np.all(np.degrees(seq.theta_0) >= np.array(contact_deg) - 1e-9)
    assert np.all(np.degrees(seq.theta_0) <= np.array(contact_deg) + pen + 0.05)


def test_device_mode_envelope_keeps_the_impedance_and_done_keeps_it(dev_params):
    seq, hand = _started(dev_params)
    t, _ = _run_to(seq, hand, Phase.ENVELOPE, 0.051)
    assert seq.phase is Phase.ENVELOPE
    t, _ = _run_to(seq, hand, Phase.DONE, t + 0.001)
    assert seq.phase is Phase.DONE
    cmd = seq.step(t + 0.5, hand.q, hand.qd, hand.effort)
    assert np.all(cmd.modes[0::3] == JointMode.IMPEDANCE)
    assert np.allclose(cmd.setpoints[0::3], seq.theta_0)
    assert np.all(cmd.modes[2::3] == JointMode.POSITION)
    assert np.allclose(cmd.setpoints[2::3], dev_params.layout.initial_position_angle + DP)


def test_device_mode_constant_torque_envelope_ramps_to_the_paper_torque(dev_params):
    from dataclasses import replace

    p = replace(dev_params, envelope_constant_torque=True)
    seq, hand = _started(p)
    t, _ = _run_to(seq, hand, Phase.ENVELOPE, 0.051)
    assert seq.phase is Phase.ENVELOPE
    # the first envelope command starts at the static impedance torque of that moment
    start = seq.step(t, hand.q, hand.qd, hand.effort)
    k_i = K_THETA * np.array([1.0, 0.5, 0.5])
    assert np.all(start.modes[0::3] == JointMode.TORQUE)
    assert np.allclose(start.setpoints[0::3], np.maximum(k_i * (seq.theta_0 - hand.q[0::3]), 0),
                       atol=1e-3)
    t_end, _ = run(seq, hand, t + 0.001, t + p.torque_ramp_time + 0.05)
    cmd = seq.step(t_end + 0.001, hand.q, hand.qd, hand.effort)
    ratios = p.layout.stiffness_ratios
    assert np.allclose(cmd.setpoints[0::3], p.envelope_torque * ratios / ratios.max())
    assert np.all(cmd.stiffness == 0.0)


def test_device_mode_envelope_without_object_returns_to_theta_0(dev_params):
    seq, hand = _started(dev_params)
    t, _ = _run_to(seq, hand, Phase.ENVELOPE, 0.051)
    hand.object_present[:] = False
    run(seq, hand, t + 0.001, t + 5.0, until=lambda s: s.phase.terminal)
    assert seq.phase is Phase.DONE
    assert np.allclose(hand.q[0::3], seq.theta_0, atol=math.radians(0.5))
    assert np.all(np.abs(hand.effort[0::3]) < dev_params.contact_torque_threshold)


@pytest.mark.parametrize('phase', [Phase.APPROACH, Phase.ROLLING_UP, Phase.ENVELOPE])
def test_device_mode_cancel_turns_impedance_into_a_torque_ramp_to_zero(dev_params, phase):
    seq, hand = _started(dev_params)
    t, _ = _run_to(seq, hand, phase, 0.051)
    _, log = run(seq, hand, t + 0.001, t + 0.1)
    t_cancel, _, last_cmd, _, _ = log[-1]
    assert np.all(last_cmd.modes[0::3] == JointMode.IMPEDANCE)
    theta = seq._last_theta_c  # the angle of the last step
    static = np.clip(last_cmd.stiffness[0::3] * (last_cmd.setpoints[0::3] - theta),
                     -dev_params.torque_limit, dev_params.torque_limit)
    assert seq.cancel() and seq.phase is Phase.ABORTED
    cmd = seq.step(t_cancel, hand.q, hand.qd, hand.effort)
    assert np.all(cmd.modes[0::3] == JointMode.TORQUE)
    assert np.all(cmd.stiffness == 0.0) and np.all(cmd.damping == 0.0)
    assert np.allclose(cmd.setpoints[0::3], static)
    mid = seq.step(t_cancel + dev_params.torque_ramp_time / 2, hand.q, hand.qd, hand.effort)
    assert np.allclose(mid.setpoints[0::3], static / 2)
    end = seq.step(t_cancel + dev_params.torque_ramp_time, hand.q, hand.qd, hand.effort)
    assert np.all(end.setpoints[0::3] == 0.0) and seq.relaxed


def test_device_mode_equilibrium_never_leaves_the_joint_limits(dev_params):
    """Closing without an object: the equilibrium is clipped to the limits (the driver rejects
    an equilibrium outside them) until the sequence fails at the limit."""
    seq, hand = _started(dev_params)
    hand.object_present[:] = False
    _, log = run(seq, hand, 0.051, 15.0, until=lambda s: s.phase.terminal)
    assert seq.phase is Phase.FAILED and 'compliant joint limit' in seq.failure_reason
    lay = dev_params.layout
    for _, _, cmd, _, _ in log:
        imp = cmd.modes == JointMode.IMPEDANCE
        assert np.all(cmd.setpoints[imp] <= lay.upper[imp])
        assert np.all(cmd.setpoints[imp] >= lay.lower[imp])


def test_controller_mode_constant_torque_envelope_ramps_to_the_paper_torque(params):
    """envelope_constant_torque means the same with the law in the controller: the envelope
    torque itself, not capped by the impedance hold torque (here below it)."""
    from dataclasses import replace

    p = replace(params, envelope_constant_torque=True, envelope_torque=0.4)
    seq, hand = _started(p)
    t, _ = _run_to(seq, hand, Phase.ENVELOPE, 0.051)
    t_end, _ = run(seq, hand, t + 0.001, t + p.torque_ramp_time + 0.05)
    cmd = seq.step(t_end + 0.001, hand.q, hand.qd, hand.effort)
    ratios = p.layout.stiffness_ratios
    assert seq.phase is Phase.ENVELOPE
    assert np.all(cmd.modes[0::3] == JointMode.TORQUE)
    assert np.allclose(cmd.setpoints[0::3], p.envelope_torque * ratios / ratios.max())
