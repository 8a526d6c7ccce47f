"""The joint command state (``dam_sim_bridge.joint_commands``) on its own, without Bullet: the
joint states a mode change needs are given by hand, so the hand-over rules are checked with
exact numbers."""

from __future__ import annotations

import math
import re

import pytest

from dam_common.device_protocol import JointMode
from dam_sim_bridge.errors import CommandError
from dam_sim_bridge.joint_commands import JointCommands, toward
from dam_sim_bridge.world_options import WorldOptions

T, P, H, IMP = (int(JointMode.TORQUE), int(JointMode.POSITION), int(JointMode.HOLD),
              int(JointMode.IMPEDANCE))
NAMES = ('j0', 'j1', 'j2')
INDICES = (4, 7, 9)  # Bullet joint indices, deliberately not 0..2
OPTIONS = WorldOptions(torque_limit_nm=1.0, torque_rate_limit_nm_per_s=20.0, time_step_s=1e-3)


class _States:
    """``getJointStates`` rows (angle, velocity, reaction, motor torque), counting reads."""

    def __init__(self, rows: list[tuple[float, float, tuple, float]]) -> None:
        self.rows = rows
        self.reads = 0

    def __call__(self) -> list[tuple[float, float, tuple, float]]:
        self.reads += 1
        return self.rows


def _commands() -> JointCommands:
    return JointCommands(NAMES, INDICES, [-1.0, -1.0, -1.0], [1.0, 1.0, 1.0],
                         [0.1, 0.2, 0.3], OPTIONS)


def test_a_reset_holds_every_joint_at_its_angle() -> None:
    c = _commands()
    assert c.modes == [H, H, H]
    assert c.targets == [0.1, 0.2, 0.3]
    sent: list[tuple[list[int], list[float]]] = []
    c.send_servo_targets(lambda j, t: sent.append((j, t)), force=True)
    assert sent == [([4, 7, 9], [0.1, 0.2, 0.3])]


def test_the_servo_targets_are_sent_only_when_they_change() -> None:
    c = _commands()
    sent: list[tuple[list[int], list[float]]] = []
    c.send_servo_targets(lambda j, t: sent.append((j, t)), force=True)
    c.command([P, T, P], [5.0, 0.0, -0.25], None, None, _States([]), stepped=False)
    c.send_servo_targets(lambda j, t: sent.append((j, t)))
    c.send_servo_targets(lambda j, t: sent.append((j, t)))  # the same: not again
    # POSITION setpoints clipped to the limits; the TORQUE joint left the servo
    assert sent[1:] == [([4, 9], [1.0, -0.25])]


def test_torque_after_a_step_starts_from_the_servos_clipped_torque() -> None:
    c = _commands()
    states = _States([(0.1, 0.0, (), 3.0), (0.2, 0.0, (), -0.4), (0.3, 0.0, (), 0.5)])
    newly = c.command([T, T, H], [0.2, 0.2, math.nan], None, None, states, stepped=True)
    assert newly == [4, 7]
    assert c.applied_torque == [1.0, -0.4, 0.0]  # 3.0 clipped to the 1 N*m limit
    assert states.reads == 1
    fresh = _commands()
    assert fresh.command([T, H, H], [0.2, 0.0, 0.0], None, None, _States([]),
                         stepped=False) == [4]
    assert fresh.applied_torque == [0.0, 0.0, 0.0]  # before any step the servo gave none


def test_impedance_seats_its_equilibrium_where_the_law_gives_the_applied_torque() -> None:
    c = _commands()
    states = _States([(0.1, 2.0, (), 0.3), (0.2, 0.0, (), 0.0), (0.3, 0.0, (), 0.0)])
    c.command([IMP, H, H], [0.5, 0.0, 0.0], [10.0, 0.0, 0.0], [0.2, 0.0, 0.0], states,
              stepped=True)
    # theta + (applied + d * theta_dot) / k = 0.1 + (0.3 + 0.4) / 10
    assert c.theta_0_eff[0] == pytest.approx(0.17, abs=1e-15)
    assert c.theta_0 == [0.5, 0.0, 0.0]
    plan = c.step_plan()
    assert plan.rows == (0,) and plan.joints == [4] and plan.n_torque == 0
    assert plan.max_change == pytest.approx(0.02)
    assert plan.max_shift == (pytest.approx(0.002),)


def test_the_plan_is_kept_for_the_same_command_and_remade_for_another() -> None:
    c = _commands()
    c.command([T, H, H], [0.0, 0.0, 0.0], None, None, _States([]), stepped=False)
    plan = c.step_plan()
    c.command([T, H, H], [0.0, 0.0, 0.0], None, None, _States([]), stepped=False)
    assert c.step_plan() is plan
    c.command([T, H, H], [-0.0, 0.0, 0.0], None, None, _States([]), stepped=False)
    assert c.plan is None  # a zero's sign is a different command
    assert math.copysign(1.0, c.step_plan().target[0]) == -1.0


@pytest.mark.parametrize(('modes', 'setpoints', 'stiffness', 'damping', 'words'), [
    ([T, T], [0.0, 0.0], None, None, 'shape (3,)'),
    ([T, 7, H], [0.0, 0.0, 0.0], None, None, 'not a JointMode'),
    ([T, P, H], [0.0, math.inf, 0.0], None, None, "['j1']"),
    ([IMP, H, H], [0.0, 0.0, 0.0], None, None, 'need a stiffness'),
    ([IMP, H, H], [0.0, 0.0, 0.0], [0.0, 1.0, 1.0], [0.1, 0.1, 0.1], 'stiffness > 0'),
])
def test_a_refused_command_names_the_problem_and_changes_nothing(
        modes, setpoints, stiffness, damping, words) -> None:
    c = _commands()
    c.command([P, T, H], [0.5, 0.3, 0.0], None, None, _States([]), stepped=False)
    before = (list(c.modes), list(c.targets), list(c.torque_cmd), c.step_plan())
    with pytest.raises(CommandError, match=re.escape(words)):
        c.command(modes, setpoints, stiffness, damping, _States([]), stepped=True)
    assert (c.modes, c.targets, c.torque_cmd, c.plan) == before


def test_toward_stops_exactly_on_the_target() -> None:
    assert toward(0.0, 0.05, 0.02) == pytest.approx(0.02)
    assert toward(0.0, -0.05, 0.02) == pytest.approx(-0.02)
    assert toward(0.3, 0.31, 0.02) == 0.31
