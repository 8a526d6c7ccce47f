"""What ``plan_lift`` prints of an answer (module plan_lift_client): the bound between the
position nodes only when the plan had more than one position."""

from __future__ import annotations

import math

from dam_analysis.plan_lift_client import format_response
from dam_interfaces.srv import PlanLift


def _found(position_error_bound: float) -> PlanLift.Response:
    response = PlanLift.Response(
        ok=True, found=True, k_theta=10.06, delta_theta_p=math.radians(7.5),
        worst_case_margin=0.01, position_error_bound=position_error_bound,
        best_k_theta=math.nan, best_delta_theta_p=math.nan, best_worst_case_margin=math.nan,
        csm_k_theta=math.nan, csm_delta_theta_p=math.nan, csm_margin=math.nan,
        method='position: the configured position only', message='verdict', object='cylinder')
    return response


def test_one_position_says_nothing_about_between_positions() -> None:
    """No tolerance: one position, the bound is 0 and there is nothing between positions (it
    printed 'at most 0 N less between positions')."""
    lines = format_response(_found(0.0)).splitlines()
    assert lines[1] == ('guaranteed (eq. 18)       : k_theta 10.06 N*m/rad at delta_theta_p '
                        '7.5 deg, worst-case margin +0.01 N')


def test_several_positions_give_the_bound_between_them() -> None:
    lines = format_response(_found(0.002)).splitlines()
    assert lines[1] == ('guaranteed (eq. 18)       : k_theta 10.06 N*m/rad at delta_theta_p '
                        '7.5 deg, worst-case margin +0.01 N (at most 0.002 N less between '
                        'positions)')
