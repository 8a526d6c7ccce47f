"""Input validation and the LiftAnalyzer facade (module analysis)."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from dam_analysis.analysis import check_delta_theta_p, check_friction_angle, check_k_theta
from dam_analysis.errors import InputError, NoSolutionError

RATIOS = np.array([1.0, 0.5, 0.5])
DP_MAX = math.radians(65.0)


def test_check_k_theta():
    np.testing.assert_allclose(check_k_theta(0.8, RATIOS), [0.8, 0.4, 0.4])
    np.testing.assert_allclose(check_k_theta([0.8], RATIOS), [0.8, 0.4, 0.4])
    np.testing.assert_allclose(check_k_theta([1, 2, 3], RATIOS), [1.0, 2.0, 3.0])
    assert check_k_theta([1, 2, 3], RATIOS).dtype == np.float64
    for bad, pattern in (([], 'k_theta: empty'), ([1.0, 2.0], 'k_theta: expected 1 or 3'),
                         (0.0, 'k_theta: stiffness must be positive'),
                         ([1.0, -2.0, 1.0], r'k_theta: .*-2\.0'),
                         (math.nan, 'k_theta: non-finite value nan'),
                         ([1.0, math.inf, 1.0], 'k_theta: non-finite value inf'),
                         ('abc', 'k_theta: not a number'), ([[1.0]], 'k_theta: expected a')):
        with pytest.raises(InputError, match=pattern):
            check_k_theta(bad, RATIOS)


def test_check_delta_theta_p():
    np.testing.assert_allclose(check_delta_theta_p(0.3, 3, DP_MAX), [0.3, 0.3, 0.3])
    np.testing.assert_allclose(check_delta_theta_p([0.0, 0.1, DP_MAX], 3, DP_MAX),
                               [0.0, 0.1, DP_MAX])
    for bad, pattern in (([], 'delta_theta_p: empty'), ([0.1, 0.2], 'expected 1 or 3'),
                         (-0.01, r'delta_theta_p: must be >= 0, got \[-0\.01'),
                         (DP_MAX + 0.01,
                          r'delta_theta_p: \[1\.144, 1\.144, 1\.144\] rad \(\[65\.57, 65\.57, '
                          r'65\.57\] deg\) exceeds delta_theta_p_max 1\.134 rad \(65 deg\)$'),
                         (math.nan, 'delta_theta_p: non-finite')):
        with pytest.raises(InputError, match=pattern):
            check_delta_theta_p(bad, 3, DP_MAX)


def test_check_friction_angle():
    assert check_friction_angle(-1.0, 0.1) == 0.1
    assert check_friction_angle(0.0, 0.1) == 0.0
    assert check_friction_angle(0.5, 0.1) == 0.5
    for bad, pattern in ((math.pi / 2, 'friction_angle: .* below 90 deg'),
                         (2.0, r'friction_angle: 2 rad \(114\.6 deg\) must be below 90 deg$'),
                         (math.inf, 'friction_angle: non-finite'),
                         ([0.1, 0.2], 'friction_angle: expected one value')):
        with pytest.raises(InputError, match=pattern):
            check_friction_angle(bad, 0.1)


def test_check_lift_conventions(analyzer):
    dp = math.radians(20.0)
    a = analyzer.check_lift(1.0, dp, -1.0)
    b = analyzer.check_lift([1.0, 0.5, 0.5], [dp, dp, dp], analyzer.model.friction_angle)
    assert a.friction_angle == analyzer.model.friction_angle
    assert a.worst_case_margin == b.worst_case_margin and a.csm_margin == b.csm_margin
    np.testing.assert_allclose(a.k_theta, [1.0, 0.5, 0.5])
    # tau_s = -K_theta delta_theta_s, positive along the SPCM
    np.testing.assert_allclose(a.compliant_torque, -a.k_theta * a.delta_theta_s)
    assert np.all(a.compliant_torque > 0.0)
    assert a.delta_theta_s.shape == (3,) and a.csm_forces.shape == (3, 3)
    with pytest.raises(InputError, match='k_theta'):
        analyzer.check_lift(-1.0, dp)


def test_check_lift_result_equals_independent_recomputation(analyzer):
    """Margins recomputed from the reported contacts with the literal eqs. 14-17."""
    from dam_analysis.lift import compliant_jacobian, enumerate_worst_case, span_vectors
    dp, alpha = math.radians(15.0), math.radians(4.0)
    r = analyzer.check_lift([3.0, 1.0, 2.0], dp, alpha)
    jac = np.array([compliant_jacobian(g.joint_axis, r.contact_points[i], g.base_position)
                    for i, g in enumerate(analyzer.model.fingers)])
    span = [span_vectors(r.normals[i], g.joint_axis, alpha, 8)
            for i, g in enumerate(analyzer.model.fingers)]
    best, _ = enumerate_worst_case(jac, span, r.compliant_torque)
    assert r.sufficient_status == ('bounded',) * 3
    assert r.worst_case_margin == pytest.approx(best - analyzer.model.object_weight, rel=1e-9)
    assert r.csm_margin == pytest.approx(r.csm_forces[:, 2].sum()
                                         - analyzer.model.object_weight, rel=1e-12)


def test_beyond_the_spcm_branch_is_no_lift_not_an_error(analyzer):
    """DP_MAX is a well-formed request beyond the end of the branch (61.7 deg on the default
    hand): "no lift", NaN margins and per-finger values, and a message with the end and why."""
    path = analyzer.table.paths[0]
    assert path.valid_until < DP_MAX
    r = analyzer.check_lift(1.0, DP_MAX)
    assert r.lift_guaranteed is False and r.csm_lift is False
    assert math.isnan(r.worst_case_margin) and math.isnan(r.csm_margin)
    assert r.beyond_branch.tolist() == [True, True, True]
    assert r.sufficient_status == ('no_spcm',) * 3
    assert np.all(np.isnan(r.delta_theta_s)) and np.all(np.isnan(r.compliant_torque))
    assert np.all(np.isnan(r.contact_points)) and np.all(np.isnan(r.csm_forces))
    end_deg = f'{math.degrees(path.valid_until):.5f} deg'
    assert r.branch_message.startswith('no lift: finger 1: no SPCM solution at delta_theta_p '
                                       '= 65.00000 deg')
    assert end_deg in r.branch_message and 'fold' in r.branch_message
    # the SPCM states themselves still do not exist there
    with pytest.raises(NoSolutionError, match=f'delta_theta_p = 65.00000 deg.*{end_deg}'):
        analyzer.spcm(DP_MAX)


def test_one_finger_beyond_its_branch_keeps_the_others(analyzer):
    dp = [math.radians(20.0), math.radians(30.0), DP_MAX]
    r = analyzer.check_lift([2.0, 1.0, 1.0], dp)
    assert r.beyond_branch.tolist() == [False, False, True]
    assert math.isnan(r.worst_case_margin) and not r.lift_guaranteed and not r.csm_lift
    within = analyzer.spcm([dp[0], dp[1], dp[1]])
    np.testing.assert_allclose(r.delta_theta_s[:2], [within[0].delta_theta_s,
                                                     within[1].delta_theta_s], atol=1e-12)
    np.testing.assert_allclose(r.compliant_torque[:2], -np.array([2.0, 1.0])
                               * r.delta_theta_s[:2])
    assert math.isnan(r.delta_theta_s[2])
    assert r.sufficient_status[2] == 'no_spcm' and r.sufficient_status[0] != 'no_spcm'
    assert 'finger 3' in r.branch_message


def test_check_lift_speed(analyzer):
    dp = math.radians(30.0)
    for _ in range(50):
        analyzer.check_lift(0.5, dp)
    times = []
    for i in range(400):
        t0 = time.perf_counter()
        analyzer.check_lift(0.5 + 1e-3 * i, dp)
        times.append(time.perf_counter() - t0)
    # target well under 0.2 ms; the bound leaves room for a loaded test machine
    assert np.median(times) < 0.5e-3, np.median(times)
