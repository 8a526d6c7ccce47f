"""The checks of a /hand/command's fields, without ROS (dam_hand_driver.command_check)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_common.device_protocol import JointMode
from dam_hand_driver.command_check import (
    WIRE_MODES,
    CommandItem,
    CommandRejected,
    check_joint_commands,
)
from dam_hand_driver.errors import HandDriverError

INDEX = {'thumb': 0, 'index': 1}
LO = np.array([-0.5, 0.0])
HI = np.array([1.0, 1.5])
TORQUE_LIMIT, MAX_K, MAX_D = 0.4, 20.0, 0.5


def _check(names, modes, setpoints, stiffness=(), damping=()) -> list[CommandItem]:
    return check_joint_commands(list(names), list(modes), list(setpoints), list(stiffness),
                                list(damping), INDEX, TORQUE_LIMIT, LO, HI, MAX_K, MAX_D)


def test_the_message_mode_numbers_name_the_wire_modes() -> None:
    from dam_interfaces.msg import HandCommand  # the numbers the message defines

    assert WIRE_MODES == {HandCommand.MODE_TORQUE: JointMode.TORQUE,
                          HandCommand.MODE_POSITION: JointMode.POSITION,
                          HandCommand.MODE_HOLD: JointMode.HOLD,
                          HandCommand.MODE_IMPEDANCE: JointMode.IMPEDANCE}


def test_accepted_commands_keep_the_order_of_the_message_in_si_units() -> None:
    out = _check(['index', 'thumb'], [2, 0], [0.7, -0.4])
    assert out == [CommandItem(1, JointMode.HOLD, 0.7, 0.0, 0.0),
                   CommandItem(0, JointMode.TORQUE, -0.4, 0.0, 0.0)]
    # numpy numbers are taken as the Python numbers they hold
    out = _check(['thumb'], [np.int8(1)], [np.float32(0.25)])
    assert out == [(0, JointMode.POSITION, 0.25, 0.0, 0.0)]
    assert type(out[0].setpoint) is float


def test_gains_are_read_for_impedance_joints_only() -> None:
    out = _check(['thumb', 'index'], [0, 3], [0.1, 1.5], [math.nan, MAX_K], [-1.0, 0.0])
    assert out == [(0, JointMode.TORQUE, 0.1, 0.0, 0.0),
                   (1, JointMode.IMPEDANCE, 1.5, MAX_K, 0.0)]


def test_limits_are_inclusive_and_the_next_value_beyond_is_refused() -> None:
    assert _check(['thumb'], [0], [TORQUE_LIMIT])[0].setpoint == TORQUE_LIMIT
    with pytest.raises(CommandRejected, match=r'torque -0\.4000000000000001 N\*m is beyond '
                                              r'the limit \+-0\.4 N\*m'):
        _check(['thumb'], [0], [-math.nextafter(TORQUE_LIMIT, 1.0)])
    assert _check(['thumb'], [1], [-0.5])[0].setpoint == -0.5
    with pytest.raises(CommandRejected, match=r"'index': angle 1\.6 rad is outside the joint "
                                              r'limits \[0\.0, 1\.5\] rad'):
        _check(['index'], [1], [1.6])
    with pytest.raises(CommandRejected, match=r"'thumb': impedance equilibrium theta_0 -0\.6"):
        _check(['thumb'], [3], [-0.6], [1.0], [0.1])
    with pytest.raises(CommandRejected, match=r'damping 0\.51 N\*m\*s/rad is outside '
                                              r'\[0, 0\.5\] N\*m\*s/rad'):
        _check(['thumb'], [3], [0.0], [1.0], [0.51])
    with pytest.raises(CommandRejected, match=r'stiffness 20\.5 N\*m/rad is outside '
                                              r'\(0, 20\.0\] N\*m/rad'):
        _check(['thumb'], [3], [0.0], [20.5], [0.1])


@pytest.mark.parametrize(('names', 'modes', 'setpoints', 'stiffness', 'damping', 'reason'), [
    (['thumb'], [0, 0], [0.1], [], [], 'name, mode and setpoint differ in length: 1, 2, 1'),
    (['thumb'], [0], [0.1], [], [0.1, 0.1],
     'damping has 2 entries for 1 names (expected none or one per name)'),
    (['pinky'], [0], [0.1], [], [], "unknown joint name 'pinky' (known: ['index', 'thumb'])"),
    (['thumb', 'thumb'], [0, 2], [0.1, 0.0], [], [], "joint 'thumb' appears more than once"),
    (['thumb'], [4], [0.1], [], [], "joint 'thumb': mode 4 is not MODE_TORQUE (0), "
                                    'MODE_POSITION (1), MODE_HOLD (2) or MODE_IMPEDANCE (3)'),
    (['index'], [2], [math.inf], [], [], "joint 'index': setpoint inf is not finite"),
    (['index'], [3], [0.5], [], [], "joint 'index': MODE_IMPEDANCE needs stiffness and "
                                    'damping (got 0 and 0 entries)'),
    (['index'], [3], [0.5], [0.0], [0.1], "joint 'index': stiffness 0.0 N*m/rad is outside "
                                          '(0, 20.0] N*m/rad'),
])
def test_a_bad_command_is_refused_whole_naming_field_and_value(
        names, modes, setpoints, stiffness, damping, reason) -> None:
    with pytest.raises(CommandRejected) as caught:
        _check(names, modes, setpoints, stiffness, damping)
    assert str(caught.value) == reason
    assert isinstance(caught.value, HandDriverError) and isinstance(caught.value, ValueError)
