"""Joint layout from the configuration and the command container."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_common.config import load_config
from dam_spcm_controller.commands import HandLayout, JointCommand, JointMode, zero_torque_command
from dam_spcm_controller.errors import InputError


def test_layout_from_config_matches_joint_names_and_limits():
    cfg = load_config()
    lay = HandLayout.from_hand_config(cfg.hand)
    assert lay.joint_names == cfg.hand.joint_names
    assert lay.n_fingers == 3 and lay.n_joints == 9
    names = np.array(lay.joint_names)
    assert all(n.endswith('_compliant_joint') for n in names[lay.compliant])
    assert all(n.endswith('_locked_joint') for n in names[lay.locked])
    assert all(n.endswith('_position_joint') for n in names[lay.position])
    assert np.allclose(np.degrees(lay.upper[lay.position]), 95.0)
    assert np.allclose(np.degrees(lay.lower[lay.compliant]), -45.0)
    assert lay.initial_position_angle == pytest.approx(math.radians(15.0))
    assert np.allclose(lay.stiffness_ratios, [1.0, 0.5, 0.5])
    assert lay.finger_name(2) == 'finger3'


def test_layout_rejects_bad_input():
    names = tuple(f'f_{r}_joint' for r in ('compliant', 'locked', 'position'))
    with pytest.raises(InputError, match='three joints per finger'):
        HandLayout(names[:2], np.ones(1), np.zeros(2), np.ones(2), 0.0, 0.0)
    with pytest.raises(InputError, match='f_locked_joint are empty'):
        HandLayout(names, np.ones(1), np.zeros(3), np.array([1.0, 0.0, 1.0]), 0.0, 0.0)
    with pytest.raises(InputError, match=r'stiffness_ratios\[0\] must be positive'):
        HandLayout(names, np.zeros(1), np.zeros(3), np.ones(3), 0.0, 0.0)


def test_joint_command_mode_lookup():
    cmd = JointCommand(np.array([0, 1, 2], dtype=np.int8), np.zeros(3))
    assert cmd.mode(0) is JointMode.HOLD
    assert cmd.mode(1) is JointMode.POSITION
    assert cmd.mode(2) is JointMode.TORQUE


def test_index_of_reorders_message_arrays():
    lay = HandLayout.from_hand_config(load_config().hand)
    shuffled = list(reversed(lay.joint_names)) + ['wrist_joint']
    values = np.arange(len(shuffled), dtype=float)
    reordered = values[lay.index_of(shuffled)]
    for k, name in enumerate(lay.joint_names):
        assert reordered[k] == values[shuffled.index(name)]
    with pytest.raises(InputError, match="missing: \\['finger3_position_joint'\\]"):
        lay.index_of(lay.joint_names[:-1])
    with pytest.raises(InputError, match="'finger1_locked_joint' appears twice"):
        lay.index_of(list(lay.joint_names) + ['finger1_locked_joint'])


def test_the_zero_torque_command_lets_the_compliant_joints_go_and_holds_the_rest() -> None:
    last = JointCommand(
        np.array([JointMode.IMPEDANCE, JointMode.HOLD, JointMode.POSITION,
                  JointMode.TORQUE, JointMode.HOLD, JointMode.POSITION], dtype=np.int8),
        np.array([0.3, 0.0, 0.7, 0.05, 0.01, 0.6]),
        stiffness=np.array([5.0, 0, 0, 0, 0, 0]), damping=np.array([0.01, 0, 0, 0, 0, 0]))
    zero = zero_torque_command(last, np.array([0.2, 0.0, 0.65, 0.1, 0.0, 0.55]))
    assert zero.modes.tolist() == [JointMode.TORQUE, JointMode.HOLD, JointMode.HOLD,
                                   JointMode.TORQUE, JointMode.HOLD, JointMode.HOLD]
    # zero torque on the compliant joints; the position joints where they were sent
    assert zero.setpoints.tolist() == [0.0, 0.0, 0.7, 0.0, 0.01, 0.6]
    assert not zero.has_impedance
    assert last.modes[0] == JointMode.IMPEDANCE  # the last command is left as it was


def test_with_no_command_sent_the_zero_torque_command_holds_the_measured_angles() -> None:
    measured = np.array([0.1, -0.02, 0.3])
    zero = zero_torque_command(None, measured)
    assert (zero.modes == JointMode.HOLD).all()
    assert zero.setpoints.tolist() == measured.tolist()
