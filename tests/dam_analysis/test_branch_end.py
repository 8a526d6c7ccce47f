"""The exact end of the SPCM branch (module branch_end) against an independent solution of the
closure eqs. 2-4 (tests/spcm_reference.py: fsolve continuation, fold where det J = 0)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from dam_analysis.spcm import SpcmPath
from spcm_reference import (
    PlanarFinger,
    ReferenceBranch,
    follow_branch,
    theta_s_near_fold,
)

K_THETA = [7.0]


@pytest.fixture(scope='module')
def references(config) -> list[ReferenceBranch]:
    return [follow_branch(PlanarFinger.from_config(config, i))
            for i in range(config.hand.n_fingers)]


def _plane_normal(analyzer, result, i: int) -> np.ndarray:
    g = analyzer.model.fingers[i]
    return np.array([result.normals[i] @ g.inward_direction, result.normals[i][2]])


def test_reference_applies_and_starts_at_the_first_contact(analyzer, references):
    """The fingertip formulation of the reference holds along the whole branch."""
    for i, ref in enumerate(references):
        finger = ref.finger
        assert ref.states[0][0] == pytest.approx(analyzer.model.theta_s0[i], abs=1e-12)
        for dp, (theta_s, _) in zip(ref.delta_theta_p, ref.states, strict=True):
            assert finger.on_fingertip(theta_s, finger.theta_p0 + dp)
        assert finger.on_fingertip(ref.fold_state[0],
                                   finger.theta_p0 + ref.fold_delta_theta_p)
        assert math.degrees(ref.fold_delta_theta_p) == pytest.approx(61.718, abs=1e-3)


def test_branch_end_is_the_fold_of_the_independent_closure(analyzer, references):
    """The end is not quantised to the 0.05 deg grid: it is the fold to far below 1e-4 deg."""
    for path, ref in zip(analyzer.table.paths, references, strict=True):
        assert path.end.kind == 'fold'
        assert math.degrees(path.valid_until) == pytest.approx(
            math.degrees(ref.fold_delta_theta_p), abs=1e-8)
        assert path.end.theta_s == pytest.approx(ref.fold_state[0], abs=1e-8)
        assert path.valid_until - path.delta_theta_p[path.last_node] > math.radians(0.01)
        assert 'fold' in path.end.reason and 'loses contact' in path.end.reason


@pytest.mark.parametrize('below_deg', [1e-3, 1e-6, 0.01])
def test_just_below_the_end_is_answered_on_the_branch(analyzer, references, below_deg):
    end = references[0].fold_delta_theta_p
    dp = end - math.radians(below_deg)
    r = analyzer.check_lift(K_THETA, dp)
    assert not r.beyond_branch.any() and r.branch_message == ''
    assert math.isfinite(r.csm_margin)
    for i, ref in enumerate(references):
        theta_s, psi = theta_s_near_fold(ref, dp)
        assert r.delta_theta_s[i] == pytest.approx(theta_s - analyzer.model.theta_s0[i],
                                                   abs=1e-9)
        np.testing.assert_allclose(_plane_normal(analyzer, r, i),
                                   [math.cos(psi), math.sin(psi)], atol=1e-8)


def test_the_issue_example_61_70001_deg_has_a_solution(analyzer, references):
    dp = math.radians(61.70001)
    r = analyzer.check_lift(K_THETA, dp)
    assert not r.beyond_branch.any()
    theta_s, _ = theta_s_near_fold(references[0], dp)
    assert r.delta_theta_s[0] == pytest.approx(theta_s - analyzer.model.theta_s0[0], abs=1e-9)


@pytest.mark.parametrize('dp_deg', ['end + 1e-3', 65.0])
def test_beyond_the_end_is_no_lift_naming_the_end_and_the_reason(analyzer, references,
                                                                  dp_deg):
    end = references[0].fold_delta_theta_p
    dp = end + math.radians(1e-3) if dp_deg == 'end + 1e-3' else math.radians(dp_deg)
    r = analyzer.check_lift(K_THETA, dp)
    assert r.lift_guaranteed is False and r.csm_lift is False
    assert math.isnan(r.worst_case_margin) and math.isnan(r.csm_margin)
    assert r.beyond_branch.all()
    assert np.all(np.isnan(r.delta_theta_s)) and np.all(np.isnan(r.compliant_torque))
    assert f'delta_theta_p = {math.degrees(dp):.5f} deg' in r.branch_message
    assert f'branch ends at {math.degrees(end):.5f} deg' in r.branch_message
    assert 'fold' in r.branch_message


def test_slip_up_to_the_end_is_the_rolling_fingertip_slip(analyzer, references):
    """On the fingertip sphere the material point's slip along t is (R + r) d psi - r d phi_3
    (the tip centre moves on a circle of radius R + r, the link turns by d phi_3)."""
    model = analyzer.model
    reach = model.fingers[0].object_radius + model.fingers[0].link_radius
    radius = model.fingers[0].link_radius
    for i, ref in enumerate(references):
        finger = ref.finger
        path = analyzer.table.paths[i]

        def rolled(state_a, dp_a, state_b, dp_b, finger=finger):
            phi3_a = state_a[0] + finger.theta_l + finger.theta_p0 + dp_a
            phi3_b = state_b[0] + finger.theta_l + finger.theta_p0 + dp_b
            d_psi = math.remainder(state_b[1] - state_a[1], 2.0 * math.pi)
            return reach * d_psi - radius * (phi3_b - phi3_a)

        # the grid (trapezoidal rule) from the first contact to 20 deg
        j = int(round(math.radians(20.0) / path.step))
        k = int(np.argmin(np.abs(ref.delta_theta_p - path.delta_theta_p[j])))
        assert ref.delta_theta_p[k] == pytest.approx(path.delta_theta_p[j], abs=1e-12)
        expected = rolled(ref.states[0], 0.0, ref.states[k], ref.delta_theta_p[k])
        assert analyzer.table.slip[i][j] == pytest.approx(expected, rel=1e-5)
        # the tail (quadrature on the exact states) from the last node to the end
        dp_a = float(path.delta_theta_p[path.last_node])
        state_a = theta_s_near_fold(ref, dp_a)
        for dp in (dp_a + 0.3 * (ref.fold_delta_theta_p - dp_a),
                   ref.fold_delta_theta_p - 1e-9, ref.fold_delta_theta_p):
            state = (ref.fold_state if dp == ref.fold_delta_theta_p
                     else theta_s_near_fold(ref, dp))
            increment = analyzer.table.tail_slip(i, dp) - analyzer.table.slip[i][
                path.last_node]
            assert increment == pytest.approx(rolled(state_a, dp_a, state, dp), abs=1e-10)


def test_a_joint_limit_ends_the_branch_exactly(analyzer, references):
    """A compliant-joint limit crossed by the branch: the end is where the reference theta_s
    reaches it; a position-joint limit: where theta_p does."""
    model = analyzer.model
    ref = references[0]
    limit = math.radians(-3.0)
    path = SpcmPath(dataclasses.replace(model, limits_s=(limit, model.limits_s[1])), 0)
    # reference: the first grid interval where theta_s passes the limit, then Brent's method
    k = int(np.argmax(ref.states[:, 0] < limit))
    finger = ref.finger

    def theta_s_minus_limit(dp: float) -> float:
        lo, hi = ref.states[k - 1][0], ref.states[k][0]
        return brentq(finger.tip_distance, lo + 1e-3, hi - 1e-3,
                      args=(finger.theta_p0 + dp,), xtol=1e-16) - limit

    expected = brentq(theta_s_minus_limit, ref.delta_theta_p[k - 1], ref.delta_theta_p[k],
                      xtol=1e-15)
    assert path.end.kind == 'posture' and 'compliant joint limit' in path.end.reason
    assert math.degrees(path.valid_until) == pytest.approx(math.degrees(expected), abs=1e-7)
    assert 'compliant joint limit' in path.beyond_message(path.valid_until + 1e-9)

    limit_p = math.radians(40.0123)
    path = SpcmPath(dataclasses.replace(model, limits_p=(model.limits_p[0], limit_p)), 0)
    assert path.end.kind == 'posture' and 'position joint limit' in path.end.reason
    assert path.valid_until == pytest.approx(limit_p - model.theta_p0, abs=1e-11)
    path.solve(path.valid_until)  # the end itself is a valid state


@pytest.mark.parametrize(('f', 'a', 'b'), [
    (lambda x: math.cos(x) - x, 0.0, 1.0),
    (lambda x: x ** 3 - 2.0 * x - 5.0, 2.0, 3.0),
    (lambda x: math.exp(x) - 10.0, 0.0, 5.0),
    (lambda x: math.atan(1e3 * (x - 0.123456)), -1.0, 1.0),  # steep: bisection steps
    (lambda x: (x - 0.3) ** 5, 0.0, 1.0),  # flat: interpolation creeps
])
def test_brent_root_finds_what_scipy_brentq_finds(f, a: float, b: float) -> None:
    """The branch end's root finder (no scipy at a node's start-up) against scipy's."""
    from dam_analysis.branch_end import brent_root

    got = brent_root(f, a, b, xtol=1e-15, rtol=1e-15, maxiter=200)
    expected = brentq(f, a, b, xtol=1e-15, rtol=1e-15, maxiter=200)
    assert got == pytest.approx(expected, abs=1e-15 + 1e-15 * abs(expected))
    assert brent_root(f, b, a, xtol=1e-15, rtol=1e-15, maxiter=200) == \
        pytest.approx(expected, abs=1e-15 + 1e-15 * abs(expected))


def test_brent_root_refuses_a_range_without_a_sign_change() -> None:
    from dam_analysis.branch_end import brent_root

    with pytest.raises(ValueError, match='have the same sign'):
        brent_root(lambda x: x * x + 1.0, -1.0, 1.0, xtol=1e-15, rtol=1e-15, maxiter=200)
    with pytest.raises(RuntimeError, match='within 3 steps'):
        brent_root(lambda x: (x - 0.3) ** 5, 0.0, 1.0, xtol=1e-15, rtol=1e-15, maxiter=3)
