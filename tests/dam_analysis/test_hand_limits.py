"""The hand's torque limit and the CSM's domain of validity in lift answers (module
hand_limits, through LiftAnalyzer.check_lift)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from dam_analysis.analysis import LiftAnalyzer
from dam_analysis.hand_limits import HandLimits, limit_notes

DP = math.radians(10.0)


def test_the_limit_is_the_smaller_of_controller_and_device(config) -> None:
    limits = HandLimits.from_config(config)
    assert limits.torque_limit == min(config.controller.torque_limit_nm,
                                      config.device.torque_limit_nm)
    assert limits.torque_limit_source == 'controller.torque_limit_nm'  # 0.6 < 1.0 shipped
    weak_device = dataclasses.replace(
        config, device=dataclasses.replace(config.device, torque_limit_nm=0.25))
    limits = HandLimits.from_config(weak_device)
    assert (limits.torque_limit, limits.torque_limit_source) == (0.25, 'device.torque_limit_nm')
    assert limits.csm_max_penetration == config.contact.csm_max_penetration_m


def test_the_torque_verdict_changes_where_finger_1_reaches_the_limit(analyzer, config) -> None:
    """Under SPCM delta_theta_s does not depend on k_theta (the object is held fixed), so
    finger 1's |tau_s| = k_theta |delta_theta_s1| reaches the limit at a stiffness known in
    closed form; just below it the hand gives the torque, just above it does not."""
    limit = min(config.controller.torque_limit_nm, config.device.torque_limit_nm)
    [d_s1, *_] = [fc.delta_theta_s for fc in analyzer.spcm(DP)]
    k_star = limit / abs(d_s1)
    below = analyzer.check_lift(k_star * (1 - 1e-6), DP)
    above = analyzer.check_lift(k_star * (1 + 1e-6), DP)
    assert below.torque_limit == above.torque_limit == limit
    assert below.within_torque_limit and not above.within_torque_limit
    assert abs(above.compliant_torque[0]) > limit >= abs(below.compliant_torque[0])


def test_the_issue_s_pair_is_guaranteed_by_eq_18_but_not_for_this_hand(analyzer) -> None:
    """k_theta 63 N*m/rad at 10 deg: eq. (18) holds with about 3 N*m on finger 1."""
    result = analyzer.check_lift(63.0, DP)
    assert result.lift_guaranteed and not result.within_torque_limit
    assert abs(result.compliant_torque[0]) > 2.5
    notes = limit_notes(analyzer.limits, result.compliant_torque, result.lift_guaranteed,
                        result.csm_penetration, result.csm_lift)
    [torque] = [n for n in notes if n.startswith('torque:')]
    assert 'guaranteed by eq. 18 but not for this hand' in torque
    assert f'finger 1 needs |tau_s| = {abs(result.compliant_torque[0]):.4g} N*m' in torque
    assert '0.6 N*m it gives (controller.torque_limit_nm)' in torque


def test_csm_penetration_is_the_normal_force_over_the_normal_stiffness(analyzer,
                                                                       config) -> None:
    """f_n / k_n, with f_n taken from the CSM force vectors and the contact normals (the
    lazily built world arrays, another code path than the scalar one)."""
    k_n = float(config.contact.contact_stiffness_n_per_m[0])
    for k_theta, dp in ((10.0, DP), (3.0, math.radians(30.0)), (0.5, math.radians(5.0))):
        result = analyzer.check_lift(k_theta, dp)
        f_n = -np.einsum('ij,ij->i', result.csm_forces, result.normals)  # pushes inward
        np.testing.assert_allclose(result.csm_penetration, f_n / k_n, rtol=1e-9, atol=1e-15)


def test_the_csm_domain_ends_at_the_configured_penetration(analyzer, config) -> None:
    bound = config.contact.csm_max_penetration_m
    soft, stiff = analyzer.check_lift(1.0, DP), analyzer.check_lift(60.0, DP)
    assert np.nanmax(soft.csm_penetration) <= bound and soft.csm_in_domain
    assert np.nanmax(stiff.csm_penetration) > bound and not stiff.csm_in_domain
    notes = limit_notes(analyzer.limits, stiff.compliant_torque, stiff.lift_guaranteed,
                        stiff.csm_penetration, stiff.csm_lift)
    [csm] = [n for n in notes if n.startswith('CSM outside')]
    worst = int(np.nanargmax(stiff.csm_penetration)) + 1
    assert f'finger {worst} {stiff.csm_penetration[worst - 1] * 1e3:.3g} mm' in csm
    assert f'above {bound * 1e3:g} mm' in csm


def test_a_tighter_configured_bound_moves_the_domain(config) -> None:
    """The bound is the configuration's: the same pair leaves the domain under a tighter one."""
    result = LiftAnalyzer(config).check_lift(10.0, DP)
    pen = float(np.nanmax(result.csm_penetration))
    assert result.csm_in_domain
    tight = dataclasses.replace(config, contact=dataclasses.replace(
        config.contact, csm_max_penetration_m=pen / 2))
    assert not LiftAnalyzer(tight).check_lift(10.0, DP).csm_in_domain


def test_beyond_the_branch_no_torque_is_needed_and_the_csm_has_no_answer(analyzer) -> None:
    result = analyzer.check_lift(7.0, math.radians(65.0))
    assert result.beyond_branch.all()
    assert result.within_torque_limit  # no contact, no torque
    assert not result.csm_in_domain and np.isnan(result.csm_penetration).all()
    assert limit_notes(analyzer.limits, result.compliant_torque, result.lift_guaranteed,
                       result.csm_penetration, result.csm_lift) == []


@pytest.mark.parametrize('torque', [[0.1, -0.2, 0.3], [math.nan, 0.1, 0.1]])
def test_an_answer_inside_both_gets_no_note(analyzer, torque: list[float]) -> None:
    assert limit_notes(analyzer.limits, torque, True, [1e-6, 2e-6, -1e-6], True) == []
    assert analyzer.limits.within_torque_limit(torque)
