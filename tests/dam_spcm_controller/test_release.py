"""ReleaseMotion: unload the compliant joints, open the position joints, end in HOLD."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_common.config import load_config
from dam_spcm_controller.commands import JointCommand, JointMode
from dam_spcm_controller.errors import InputError
from dam_spcm_controller.release import ReleaseMotion, ReleaseStage
from dam_spcm_controller.sequence import SequenceParams

DT = 0.002  # [s], the driver's 500 Hz


@pytest.fixture(scope='module')
def params() -> SequenceParams:
    return SequenceParams.from_config(load_config())


def _held_grasp(params: SequenceParams) -> tuple[JointCommand, np.ndarray]:
    """An ENVELOPE-like hold: compliant joints in IMPEDANCE 0.05 rad beyond the measured angle
    (k 10, 5, 5), position joints at 40 deg, locked joints held."""
    lay = params.layout
    pos = np.zeros(lay.n_joints)
    pos[lay.compliant] = [0.3, 0.25, 0.25]
    pos[lay.position] = math.radians(40.0)
    modes = np.full(lay.n_joints, JointMode.HOLD, dtype=np.int8)
    modes[lay.compliant] = JointMode.IMPEDANCE
    modes[lay.position] = JointMode.POSITION
    setpoints = pos.copy()
    setpoints[lay.compliant] = pos[lay.compliant] + 0.05
    stiffness = np.zeros(lay.n_joints)
    stiffness[lay.compliant] = [10.0, 5.0, 5.0]
    return JointCommand(modes, setpoints, stiffness, np.zeros(lay.n_joints)), pos


def _run(motion: ReleaseMotion, pos: np.ndarray, t0: float = 0.0, limit_s: float = 20.0
         ) -> list[tuple[float, JointCommand]]:
    out = []
    t = t0
    while not motion.done:
        assert t - t0 < limit_s, 'the release did not end'
        out.append((t, motion.step(t, pos)))
        t += DT
    return out


def test_unload_ramps_the_static_impedance_torque_linearly_to_zero(params) -> None:
    held, pos = _held_grasp(params)
    lay = params.layout
    motion = ReleaseMotion(params, held, 0.0, pos)
    steps = _run(motion, pos)
    first = steps[0][1]
    assert np.all(first.modes[lay.compliant] == JointMode.TORQUE)
    # the torque the device applied statically: k (theta_0 - theta), independently here
    np.testing.assert_allclose(first.setpoints[lay.compliant], [0.5, 0.25, 0.25], rtol=1e-12)
    unload = [(t, c) for t, c in steps if np.all(c.modes[lay.compliant] == JointMode.TORQUE)]
    ramp = params.torque_ramp_time
    for t, c in unload:
        expected = np.array([0.5, 0.25, 0.25]) * max(0.0, 1.0 - t / ramp)
        np.testing.assert_allclose(c.setpoints[lay.compliant], expected, atol=1e-12)
        assert np.all(c.modes[lay.position] == JointMode.HOLD)  # held while unloading
    assert np.all(unload[-1][1].setpoints[lay.compliant] == 0.0)  # one command at exactly 0
    assert unload[-1][0] == pytest.approx(ramp, abs=DT)


def test_open_moves_the_position_joints_back_within_the_approach_speed(params) -> None:
    held, pos = _held_grasp(params)
    lay = params.layout
    motion = ReleaseMotion(params, held, 5.0, pos)
    steps = _run(motion, pos, t0=5.0)
    opening = [(t, c) for t, c in steps if np.all(c.modes[lay.position] == JointMode.POSITION)]
    assert opening
    angles = np.array([c.setpoints[lay.position] for _, c in opening])
    speed = np.abs(np.diff(angles, axis=0)) / DT
    assert speed.max() <= params.approach_speed * (1.0 + 1e-3)
    assert speed.max() >= 0.9 * params.approach_speed  # and not needlessly slow
    np.testing.assert_allclose(angles[-1], params.layout.initial_position_angle, atol=1e-9)
    for _, c in opening:  # compliant joints held where they are, no torque
        assert np.all(c.modes[lay.compliant] == JointMode.HOLD)
    assert motion.stage is ReleaseStage.OPEN_HELD
    last = motion.step(steps[-1][0] + DT, pos)
    assert np.all(last.modes == JointMode.HOLD)


def test_without_a_held_command_only_the_opening_runs(params) -> None:
    lay = params.layout
    pos = np.zeros(lay.n_joints)
    pos[lay.position] = math.radians(30.0)
    motion = ReleaseMotion(params, None, 0.0, pos)
    steps = _run(motion, pos)
    assert not any(np.any(c.modes == JointMode.TORQUE) for _, c in steps)
    opening = [c for _, c in steps if np.all(c.modes[lay.position] == JointMode.POSITION)]
    assert opening[-1].setpoints[lay.position] == pytest.approx(
        [params.layout.initial_position_angle] * lay.n_fingers)
    # the end holds what is measured (HOLD ignores the setpoint on the device)
    assert np.all(steps[-1][1].modes == JointMode.HOLD)


def test_bad_input_is_refused(params) -> None:
    pos = np.zeros(params.layout.n_joints)
    with pytest.raises(InputError, match='positions'):
        ReleaseMotion(params, None, 0.0, pos[:-1])
    with pytest.raises(InputError, match='t'):
        ReleaseMotion(params, None, math.nan, pos)
    motion = ReleaseMotion(params, None, 0.0, pos)
    bad = pos.copy()
    bad[0] = math.inf
    with pytest.raises(InputError, match='positions'):
        motion.step(0.1, bad)
