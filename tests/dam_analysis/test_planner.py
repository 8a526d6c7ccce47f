"""The robust planner (module planner): its reductions of the ranges, and its answers checked
by brute force over samples of the ranges."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from dam_analysis.analysis import LiftAnalyzer
from dam_analysis.errors import InputError
from dam_analysis.planner import (
    DEFAULT_MIN_MARGIN_N,
    DP_STEP_RAD,
    LiftPlanner,
    check_ranges,
    plan_verdict,
    position_nodes,
    ranges_from_request,
)

DEG = math.radians(1.0)


@pytest.fixture(scope='module')
def planner(config, analyzer) -> LiftPlanner:
    return LiftPlanner(config, analyzer)


def _ranges(config, planner, alpha=(3.0, 6.0), mass=(0.03, 0.05), tol=1e-3, k_max=None,
            dp=(0.0, 60.0), margin=DEFAULT_MIN_MARGIN_N):
    return check_ranges(config, (alpha[0] * DEG, alpha[1] * DEG), mass, tol,
                        planner.device_k_max if k_max is None else k_max,
                        (dp[0] * DEG, dp[1] * DEG), margin)


def _worst_margin(analyzer: LiftAnalyzer, k: float, dp: float, alpha: float, mass: float,
                  g: float) -> float:
    """Eq. 18's worst-case margin for another mass: the forces do not depend on it."""
    r = analyzer.check_lift(k, dp, alpha)
    return r.worst_case_margin + analyzer.model.object_weight - mass * g


def test_a_larger_friction_angle_never_raises_the_worst_case(analyzer) -> None:
    """The reduction of the friction range to its upper end: a larger cone contains the
    smaller one, so the minimum over it is no higher."""
    alphas = np.radians(np.linspace(0.0, 40.0, 41))
    for k, dp in ((10.0, 10 * DEG), (3.0, 25 * DEG), (0.5, 40 * DEG), (60.0, 5 * DEG)):
        margins = [analyzer.check_lift(k, dp, float(a)).worst_case_margin for a in alphas]
        assert all(b <= a + 1e-12 for a, b in zip(margins, margins[1:], strict=False)), margins


def test_no_csm_pair_where_the_csm_lifts_with_none(config) -> None:
    """The hexagonal pencil: its fingertips meet the upper faces and push it down, so the CSM
    lifts it with no pair; the plan names none and says why, rather than a pair whose margin
    is negative."""
    pencil = LiftPlanner(config.with_object('hex_pencil'))
    plan = pencil.plan(_ranges(config, pencil, tol=0.0))
    assert not plan.found
    assert math.isnan(plan.csm_k_theta) and math.isnan(plan.csm_margin)
    assert 'predicts a lift for no pair under the cap' in plan_verdict(plan)


def test_the_position_grid() -> None:
    np.testing.assert_allclose(position_nodes(0.0), [0.0])
    np.testing.assert_allclose(position_nodes(1e-3), [-1e-3, -5e-4, 0.0, 5e-4, 1e-3])
    nodes = position_nodes(0.7e-3)
    assert nodes.size == 5 and nodes[0] == -0.7e-3 and np.max(np.diff(nodes)) <= 0.5e-3


def test_without_ranges_the_pair_is_the_smallest_stiffness_over_the_displacements(
        config, planner, analyzer) -> None:
    """One friction angle, one mass, no tolerance: k = (m g + min_margin) / A at the best
    displacement, where A is the worst case at k_theta = 1 plus the weight; brute force over
    the displacement grid finds no smaller stiffness."""
    ranges = _ranges(config, planner, alpha=(5.0, 5.0), mass=(0.04, 0.04), tol=0.0)
    plan = planner.plan(ranges)
    assert plan.found and plan.position_error_bound == 0.0
    g, alpha = config.task.gravity_m_per_s2, 5 * DEG
    margin = _worst_margin(analyzer, plan.k_theta, plan.delta_theta_p, alpha, 0.04, g)
    assert margin == pytest.approx(DEFAULT_MIN_MARGIN_N, abs=1e-9)
    assert plan.worst_case_margin == pytest.approx(margin, abs=1e-9)
    smallest = math.inf
    for dp in np.arange(1, round(60 / 0.25) + 1) * DP_STEP_RAD:
        unit = analyzer.check_lift(1.0, float(dp), alpha)
        slope = unit.worst_case_margin + analyzer.model.object_weight
        if math.isfinite(slope) and slope > 0.0 and unit.within_torque_limit:
            k = (0.04 * g + DEFAULT_MIN_MARGIN_N) / slope
            if analyzer.check_lift(k, float(dp), alpha).within_torque_limit:
                smallest = min(smallest, k)
    assert plan.k_theta == pytest.approx(smallest, rel=1e-9)
    assert analyzer.check_lift(plan.k_theta, plan.delta_theta_p, alpha).within_torque_limit


def test_the_guarantee_holds_on_samples_of_every_range(config, planner) -> None:
    """The issue's example ranges (alpha 3-6 deg, mass 30-50 g, position +-1 mm): the answer,
    checked at 4 friction angles x 3 masses x 11 positions (0.2 mm apart, so most fall
    between the planner's 0.5 mm nodes), keeps its margin everywhere and its torque within
    the hand."""
    ranges = _ranges(config, planner)
    plan = planner.plan(ranges)
    assert plan.found, plan.reason
    g = config.task.gravity_m_per_s2
    worst = math.inf
    for offset in np.linspace(-1e-3, 1e-3, 11):
        analyzer = planner.analyzer_at(float(offset))
        assert isinstance(analyzer, LiftAnalyzer)
        for alpha in np.radians([3.0, 4.0, 5.0, 6.0]):
            for mass in (0.03, 0.04, 0.05):
                worst = min(worst, _worst_margin(analyzer, plan.k_theta, plan.delta_theta_p,
                                                 float(alpha), mass, g))
            assert analyzer.check_lift(plan.k_theta, plan.delta_theta_p,
                                       float(alpha)).within_torque_limit
    assert worst >= ranges.min_margin - 1e-9, worst
    # the node minimum less the stated bound is what the planner promised
    assert plan.worst_case_margin - plan.position_error_bound >= ranges.min_margin - 1e-9
    assert worst >= plan.worst_case_margin - plan.position_error_bound - 1e-9
    assert 'alpha_max = 6 deg' in plan.method and '5 positions' in plan.method


def test_a_cap_below_the_needed_stiffness_gives_the_best_available(config, planner) -> None:
    ranges = _ranges(config, planner, k_max=3.0)
    plan = planner.plan(ranges)
    assert not plan.found and math.isnan(plan.k_theta)
    assert 'is above the cap there' in plan.reason
    # the displacement named is the one whose need is nearest its cap: with a uniform cap of
    # 3 N*m/rad, the one that needs the least (a user saw 'inf at 61.75 deg, cap nan')
    needed = float(plan.reason.split('needs, ')[1].split(' N*m/rad')[0])
    free = planner.plan(_ranges(config, planner))
    assert needed == pytest.approx(free.k_theta, rel=1e-3)
    assert 'cap there, 3 N*m/rad' in plan.reason
    assert plan.best_k_theta <= 3.0 and math.isfinite(plan.best_worst_case_margin)
    assert plan.best_worst_case_margin < ranges.min_margin  # else it would be guaranteed
    text = plan_verdict(plan)
    assert text.startswith('no pair is guaranteed over the ranges: ') and 'best available' in text


def test_at_thirty_degrees_nothing_is_guaranteed(config, planner) -> None:
    """The paper: no sufficient region at alpha = 30 deg; the CSM still has a pair."""
    plan = planner.plan(_ranges(config, planner, alpha=(20.0, 30.0)))
    assert not plan.found and 'holds for no stiffness there' in plan.reason
    assert math.isfinite(plan.csm_margin) and plan.csm_margin > 0.0


def test_the_csm_pair_is_the_largest_smallest_margin(config, planner) -> None:
    """Its margin is the minimum of the CSM margins over the sampled friction angles (at the
    one position node and mass of this request), and its stiffness keeps to the device's cap.
    (That no other displacement beats it is not checked here.)"""
    ranges = _ranges(config, planner, tol=0.0, alpha=(3.0, 6.0), mass=(0.04, 0.04))
    plan = planner.plan(ranges)
    analyzer = planner.analyzer_at(0.0)
    g = config.task.gravity_m_per_s2

    def smallest(k: float, dp: float) -> float:
        values = [analyzer.check_lift(k, dp, float(a)).csm_margin
                  + analyzer.model.object_weight - 0.04 * g
                  for a in np.radians(np.linspace(3.0, 6.0, 5))]
        return min(values)

    assert plan.csm_margin == pytest.approx(smallest(plan.csm_k_theta, plan.csm_delta_theta_p))
    assert plan.csm_k_theta <= planner.device_k_max + 1e-9


@pytest.mark.parametrize(('kwargs', 'words'), [
    ({'alpha': (6.0, 3.0)}, 'friction_angle: empty range'),
    ({'alpha': (5.0, 90.0)}, '[0.08727, 1.571] rad ([5, 90] deg) is outside [0, pi/2) rad'),
    ({'alpha': (math.nan, 5.0)}, 'friction_angle_min: non-finite value nan'),
    ({'mass': (0.05, 0.03)}, 'mass: empty range, max 0.03 kg (30 g) is below min 0.05 kg (50 g)'),
    ({'mass': (0.0, 0.03)}, 'mass_min: 0 kg (0 g) must be positive'),
    ({'tol': -1e-3}, 'position_tolerance: -0.001 m (-1 mm) is outside'),
    ({'tol': 0.02}, 'position_tolerance: 0.02 m (20 mm) is outside [0, 0.005] m ([0, 5] mm)'),
    ({'k_max': 0.0}, 'k_theta_max: 0 N*m/rad must be positive'),
    ({'k_max': math.inf}, 'k_theta_max: non-finite value inf'),
    ({'dp': (10.0, 80.0)}, 'delta_theta_p: [0.1745, 1.396] rad ([10, 80] deg) is outside'),
    ({'margin': -0.5}, 'min_margin: -0.5 N must not be negative'),
])
def test_bad_ranges_are_refused_with_the_field_and_value(config, planner, kwargs, words) -> None:
    with pytest.raises(InputError) as info:
        _ranges(config, planner, **kwargs)
    assert words in str(info.value)


def test_fields_left_out_are_the_configuration(config, planner) -> None:
    ranges, taken = ranges_from_request(planner, -1.0, -1.0, -1.0, -1.0, 0.0, -1.0, -1.0,
                                        -1.0, -1.0)
    alpha, mass = config.contact.friction_angle_rad, config.object.mass_kg
    assert ranges.friction_angle == (alpha, alpha) and ranges.mass == (mass, mass)
    assert ranges.k_theta_max == planner.device_k_max and ranges.position_tolerance == 0.0
    assert ranges.delta_theta_p == (0.0, config.task.delta_theta_p_max_rad)
    assert ranges.min_margin == DEFAULT_MIN_MARGIN_N
    assert taken == ['friction_angle = 5 deg', 'mass = 0.04 kg', 'k_theta_max = 100 N*m/rad',
                     'min_margin = 0.01 N']
    # only the lower end given: the range is that one value
    ranges, taken = ranges_from_request(planner, 0.1, -1.0, 0.05, -1.0, 0.0, 5.0, 0.1, 0.5,
                                        0.0)
    assert ranges.friction_angle == (0.1, 0.1) and ranges.mass == (0.05, 0.05)
    assert taken == []
    with pytest.raises(InputError, match='friction_angle_min: non-finite value nan'):
        ranges_from_request(planner, math.nan, -1.0, -1.0, -1.0, 0.0, -1.0, -1.0, -1.0, -1.0)


def test_a_position_without_first_contact_is_named(config) -> None:
    """Moving the object far enough that a finger cannot reach it is an answer, not a crash."""
    far = dataclasses.replace(config, object=dataclasses.replace(
        config.object, position_m=np.array([0.0045, 0.0, 0.010])))
    planner = LiftPlanner(far)
    plan = planner.plan(check_ranges(far, (0.08, 0.08), (0.04, 0.04), 5e-3, 50.0,
                                     (0.0, 1.0), 0.01))
    assert not plan.found and 'make no first contact' in plan.reason


def test_a_stop_request_ends_the_plan_between_two_position_nodes(config) -> None:
    """A node that is stopping must not finish seconds of analyses first."""
    from dam_analysis.errors import Interrupted

    planner = LiftPlanner(config)
    asked = []

    def stop() -> bool:
        asked.append(len(planner._analyzers))
        return len(asked) > 2  # two nodes built, then the signal

    ranges = _ranges(config, planner, tol=2e-3)
    with pytest.raises(Interrupted, match='planning interrupted'):
        planner.plan(ranges, stop=stop)
    assert asked == [0, 1, 2] and len(planner._analyzers) == 2
    assert planner.plan(ranges).found  # the next request plans as usual


def test_the_verdict_names_a_bound_between_positions_only_when_there_are_several(
        config, planner) -> None:
    """With no position tolerance there is one node and nothing between nodes: the verdict
    said '0 N less at most between the position nodes' (the review of the last change)."""
    plan = planner.plan(_ranges(config, planner, tol=0.0))
    assert plan.found and plan.offsets.size == 1
    text = plan_verdict(plan)
    assert 'position' not in text and 'between' not in text
    assert text.startswith('guaranteed over the ranges: k_theta ')
    several = dataclasses.replace(plan, offsets=np.linspace(-1e-3, 1e-3, 5),
                                  position_error_bound=0.002)
    assert '(worst-case margin 0.01 N, 0.002 N less at most between the position nodes)' in (
        plan_verdict(several))
