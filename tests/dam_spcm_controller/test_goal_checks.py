"""What a /dam_grasp goal must satisfy before the hand moves (pure, no ROS)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from dam_spcm_controller.errors import InputError
from dam_spcm_controller.goal_checks import check_goal, guarantee_refusal

RATIOS = np.array([1.0, 0.5, 0.5])
DEFAULTS = dict(stiffness_ratios=RATIOS, default_k_theta=5.0,
                default_delta_theta_p=math.radians(10.0),
                delta_theta_p_max=math.radians(65.0), max_device_stiffness=50.0)


def test_empty_fields_take_the_configured_pair() -> None:
    assert check_goal([], [], **DEFAULTS) == (5.0, pytest.approx(math.radians(10.0)))


def test_per_finger_values_that_follow_the_ratios_give_finger_1s() -> None:
    k, dp = check_goal([8.0, 4.0, 4.0], [0.2] * 3, **DEFAULTS)
    assert (k, dp) == (8.0, 0.2)


@pytest.mark.parametrize(('k_theta', 'delta_theta_p', 'words'), [
    ([8.0, 8.0, 8.0], [0.2], 'does not follow the configured stiffness ratios'),
    ([8.0], [0.2, 0.1, 0.2], 'the controller moves every position joint by the same'),
    ([8.0], [0.0], 'delta_theta_p must be positive, got 0 rad (0 deg)'),
    ([80.0], [0.2], 'device.max_stiffness_nm_per_rad = 50 N*m/rad'),
    ([8.0], [math.radians(80.0)], 'exceeds delta_theta_p_max'),
    ([math.nan], [0.2], 'k_theta'),
])
def test_a_goal_that_cannot_run_says_why(k_theta: list[float], delta_theta_p: list[float],
                                         words: str) -> None:
    with pytest.raises(InputError) as info:
        check_goal(k_theta, delta_theta_p, **DEFAULTS)
    assert words in str(info.value)


def test_without_the_device_law_its_stiffness_limit_does_not_apply() -> None:
    assert check_goal([80.0], [0.2], **dict(DEFAULTS, max_device_stiffness=None))[0] == 80.0


@dataclass
class Answer:
    ok: bool = True
    message: str = 'the verdict'
    lift_guaranteed: bool = True
    worst_case_margin: float = 0.25
    within_torque_limit: bool = True
    torque_limit: float = 0.5


@pytest.mark.parametrize(('answer', 'words'), [
    (None, 'did not answer in time'),
    (Answer(ok=False, message='bad pair'), 'rejected the pair: bad pair'),
    (Answer(lift_guaranteed=False, worst_case_margin=-0.125),
     'k_theta 5 N*m/rad, delta_theta_p 10 deg is outside the sufficient-lift region '
     '(worst-case margin -0.125 N): the verdict'),
    (Answer(within_torque_limit=False),
     'only with more compliant torque than the hand gives (0.5 N*m)'),
])
def test_the_guarantee_refuses_with_the_reason(answer: Answer | None, words: str) -> None:
    reason = guarantee_refusal(answer, 5.0, math.radians(10.0))
    assert reason is not None and reason.startswith('require_lift_guarantee is set')
    assert words in reason


def test_a_guaranteed_pair_within_the_torque_may_run() -> None:
    assert guarantee_refusal(Answer(), 5.0, math.radians(10.0)) is None
