"""Impedance law of the compliant joints against its closed form."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_spcm_controller.errors import InputError
from dam_spcm_controller.impedance import (
    ImpedanceGains,
    delta_theta_s,
    finger_stiffness,
    impedance_torque,
    tau_s_static,
)

RATIOS = np.array([1.0, 0.5, 0.5])


def test_finger_stiffness_follows_paper_ratios():
    k = finger_stiffness(0.8, RATIOS)
    # paper section 3.3: k_theta1 = k_theta, k_theta2 = k_theta3 = k_theta / 2
    assert k[0] == pytest.approx(0.8)
    assert k[1] == pytest.approx(0.4)
    assert k[2] == pytest.approx(0.4)


def test_torque_matches_closed_form_per_finger():
    gains = ImpedanceGains.from_ratios(0.5, RATIOS, damping=0.01, torque_limit=10.0)
    theta_0 = np.radians([20.0, 25.0, 30.0])
    theta = np.radians([10.0, 27.0, 30.0])
    theta_dot = np.array([0.1, -0.2, 0.3])
    tau = impedance_torque(gains, theta_0, theta, theta_dot)
    for i, k in enumerate([0.5, 0.25, 0.25]):
        expected = k * (theta_0[i] - theta[i]) - 0.01 * theta_dot[i]
        assert tau[i] == pytest.approx(expected, rel=1e-12, abs=1e-15)


def test_static_torque_is_minus_k_delta_theta_s():
    k = np.array([0.5, 0.25, 0.25])
    theta_0 = np.array([0.3, 0.3, 0.3])
    theta = np.array([0.1, 0.35, 0.3])
    assert np.allclose(delta_theta_s(theta, theta_0), [-0.2, 0.05, 0.0])
    assert np.allclose(tau_s_static(k, theta, theta_0), [0.1, -0.0125, 0.0])
    gains = ImpedanceGains(k, damping=0.2, torque_limit=1.0)
    # at rest the impedance law equals the paper's tau_s = -K_theta delta_theta_s
    assert np.allclose(impedance_torque(gains, theta_0, theta, np.zeros(3)),
                       tau_s_static(k, theta, theta_0))


def test_torque_is_zero_at_contact_posture():
    gains = ImpedanceGains.from_ratios(2.0, RATIOS, damping=0.05, torque_limit=1.0)
    theta_0 = np.radians([18.0, 22.0, 22.0])
    assert np.all(impedance_torque(gains, theta_0, theta_0, np.zeros(3)) == 0.0)


def test_torque_saturates_symmetrically():
    gains = ImpedanceGains.from_ratios(10.0, RATIOS, damping=0.0, torque_limit=0.6)
    tau = impedance_torque(gains, np.zeros(3), np.array([1.0, -1.0, 0.02]), np.zeros(3))
    assert tau[0] == pytest.approx(-0.6)
    assert tau[1] == pytest.approx(0.6)
    assert tau[2] == pytest.approx(-5.0 * 0.02)  # inside the limit: untouched


def test_damping_opposes_velocity():
    gains = ImpedanceGains.from_ratios(1.0, RATIOS, damping=0.1, torque_limit=1.0)
    tau = impedance_torque(gains, np.zeros(3), np.zeros(3), np.array([1.0, -2.0, 0.0]))
    assert np.allclose(tau, [-0.1, 0.2, 0.0])


@pytest.mark.parametrize('k_theta', [0.0, -0.5, math.nan, math.inf])
def test_bad_stiffness_is_rejected(k_theta):
    with pytest.raises(InputError, match='k_theta'):
        finger_stiffness(k_theta, RATIOS)


def test_bad_gains_are_rejected_with_the_value():
    with pytest.raises(InputError, match=r'damping.*-0\.1'):
        ImpedanceGains(np.ones(3), damping=-0.1, torque_limit=1.0)
    with pytest.raises(InputError, match='torque_limit'):
        ImpedanceGains(np.ones(3), damping=0.0, torque_limit=0.0)
    with pytest.raises(InputError, match=r'k_theta_i\[1\]'):
        ImpedanceGains(np.array([1.0, 0.0, 1.0]), damping=0.0, torque_limit=1.0)
    with pytest.raises(InputError, match=r'stiffness_ratios\[2\]'):
        finger_stiffness(1.0, np.array([1.0, 0.5, -0.5]))


def test_bad_measurements_are_rejected():
    gains = ImpedanceGains.from_ratios(1.0, RATIOS, damping=0.0, torque_limit=1.0)
    with pytest.raises(InputError, match='theta must have 3 values'):
        impedance_torque(gains, np.zeros(3), np.zeros(2), np.zeros(3))
    with pytest.raises(InputError, match=r'theta_dot\[1\] must be finite'):
        impedance_torque(gains, np.zeros(3), np.zeros(3), np.array([0.0, math.nan, 0.0]))
