"""Clean start: hold the measured state, ramp torque from zero; ramp out on release."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_spcm_controller.activation import (
    LinearRamp,
    hold_measured,
    ramp_torque_in,
    ramp_torque_out,
)
from dam_spcm_controller.commands import JointMode
from dam_spcm_controller.errors import InputError


def test_hold_measured_equals_measurement_and_is_a_copy():
    q = np.array([0.1, -0.2, 0.3])
    cmd = hold_measured(q)
    assert np.all(cmd.modes == JointMode.HOLD)
    assert np.array_equal(cmd.setpoints, q)
    q[0] = 5.0
    assert cmd.setpoints[0] == 0.1


def test_hold_measured_rejects_nan():
    with pytest.raises(InputError, match=r'positions\[1\]'):
        hold_measured(np.array([0.0, math.nan]))


def test_torque_ramps_in_linearly_from_zero():
    tau = np.array([0.4, -0.2])
    assert np.array_equal(ramp_torque_in(1.0, 1.0, 0.5, tau), [0.0, 0.0])
    assert np.allclose(ramp_torque_in(1.25, 1.0, 0.5, tau), [0.2, -0.1])
    assert np.allclose(ramp_torque_in(1.5, 1.0, 0.5, tau), tau)
    assert np.allclose(ramp_torque_in(9.0, 1.0, 0.5, tau), tau)
    assert np.array_equal(ramp_torque_in(0.0, 1.0, 0.5, tau), [0.0, 0.0])  # before activation


def test_torque_ramps_out_to_zero():
    tau = np.array([0.3])
    assert np.allclose(ramp_torque_out(2.0, 2.0, 0.2, tau), [0.3])
    assert np.allclose(ramp_torque_out(2.05, 2.0, 0.2, tau), [0.225])
    assert np.allclose(ramp_torque_out(2.2, 2.0, 0.2, tau), [0.0])


def test_linear_ramp_values_and_zero_duration():
    ramp = LinearRamp(t_start=1.0, duration=2.0, start_value=-1.0, end_value=3.0)
    assert ramp.value(0.0) == -1.0
    assert ramp.value(2.0) == pytest.approx(1.0)
    assert ramp.value(3.0) == 3.0 and ramp.done(3.0) and not ramp.done(2.9)
    step = LinearRamp(t_start=1.0, duration=0.0)
    assert step.value(1.0) == 1.0 and step.value(0.5) == 1.0


def test_linear_ramp_rejects_bad_values():
    with pytest.raises(InputError, match='duration'):
        LinearRamp(t_start=0.0, duration=-1.0)
    with pytest.raises(InputError, match='t_start'):
        LinearRamp(t_start=math.inf, duration=1.0)
