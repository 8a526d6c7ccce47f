"""Minimum-jerk trajectory: boundary conditions by finite differences, monotonicity."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_spcm_controller.errors import InputError
from dam_spcm_controller.trajectory import MinimumJerkTrajectory, minimum_jerk_profile

START = math.radians(15.0)
DELTA = math.radians(65.0)
T = 3.0


def _traj(n: int = 3) -> MinimumJerkTrajectory:
    return MinimumJerkTrajectory(np.full(n, START), np.full(n, DELTA), T)


def test_paper_experiment_goes_from_15_to_80_deg():
    traj = _traj()
    assert np.allclose(np.degrees(traj.position(0.0)), 15.0)
    assert np.allclose(np.degrees(traj.position(T)), 80.0)
    assert np.allclose(np.degrees(traj.theta_goal), 80.0)
    # half way in time is half way in angle (the quintic is point-symmetric)
    assert np.allclose(np.degrees(traj.position(T / 2)), 47.5)


def test_boundary_velocity_and_acceleration_vanish_by_finite_differences():
    traj = _traj(1)
    h = 1e-4
    for t_end in (0.0, T):
        # one-sided differences inside [0, T]; clamping makes outside points constant
        sgn = 1.0 if t_end == 0.0 else -1.0
        p0 = traj.position(t_end)[0]
        p1 = traj.position(t_end + sgn * h)[0]
        p2 = traj.position(t_end + 2 * sgn * h)[0]
        vel = (p1 - p0) / h
        acc = (p2 - 2 * p1 + p0) / h**2
        assert abs(vel) < 1e-6
        assert abs(acc) < 1e-2  # a quintic: acc ~ 60 DELTA h / T^3 ~ 2e-4 here
        # the analytic derivatives agree
        _, v, a = traj.evaluate(t_end)
        assert v[0] == 0.0 and a[0] == 0.0


def test_analytic_derivatives_match_finite_differences_inside():
    traj = _traj(1)
    h = 1e-5
    for t in np.linspace(0.1, T - 0.1, 17):
        p_minus, p0, p_plus = (traj.position(t - h)[0], traj.position(t)[0],
                               traj.position(t + h)[0])
        _, v, a = traj.evaluate(t)
        assert v[0] == pytest.approx((p_plus - p_minus) / (2 * h), rel=1e-6)
        assert a[0] == pytest.approx((p_plus - 2 * p0 + p_minus) / h**2, rel=1e-3, abs=1e-4)


def test_peak_velocity_is_15_over_8_of_the_mean():
    traj = _traj(1)
    _, v, _ = traj.evaluate(T / 2)
    assert v[0] == pytest.approx(1.875 * DELTA / T)


def test_monotonic_and_clamped():
    traj = _traj(1)
    ts = np.linspace(-1.0, T + 1.0, 2001)
    p = np.array([traj.position(t)[0] for t in ts])
    assert np.all(np.diff(p) >= 0.0)
    assert p[0] == pytest.approx(START)
    assert p[-1] == pytest.approx(START + DELTA)
    assert p.min() >= START - 1e-15 and p.max() <= START + DELTA + 1e-15


def test_negative_displacement_is_monotonic_decreasing():
    traj = MinimumJerkTrajectory(np.array([1.0]), np.array([-0.5]), 2.0)
    p = np.array([traj.position(t)[0] for t in np.linspace(0, 2, 101)])
    assert np.all(np.diff(p) <= 0.0)
    assert p[-1] == pytest.approx(0.5)


def test_profile_closed_form():
    for tau in (0.0, 0.25, 0.5, 0.9, 1.0):
        s, ds, dds = minimum_jerk_profile(tau)
        assert s == pytest.approx(10 * tau**3 - 15 * tau**4 + 6 * tau**5)
        assert ds == pytest.approx(30 * tau**2 - 60 * tau**3 + 30 * tau**4)
        assert dds == pytest.approx(60 * tau - 180 * tau**2 + 120 * tau**3, abs=1e-12)


def test_phase_is_clamped_time_fraction():
    traj = _traj()
    assert traj.phase(-1.0) == 0.0
    assert traj.phase(1.5) == pytest.approx(0.5)
    assert traj.phase(10.0) == 1.0


def test_bad_arguments_are_rejected():
    with pytest.raises(InputError, match='duration'):
        MinimumJerkTrajectory(np.zeros(3), np.ones(3), 0.0)
    with pytest.raises(InputError, match='delta_theta_p must have 3 values'):
        MinimumJerkTrajectory(np.zeros(3), np.ones(2), 1.0)
    with pytest.raises(InputError, match=r'theta_start\[0\] must be finite'):
        MinimumJerkTrajectory(np.array([math.nan]), np.ones(1), 1.0)
