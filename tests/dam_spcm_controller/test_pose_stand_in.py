"""The object's pose from the joints against the stand-in's ground truth, lockstep.

A handful of grasps of the library's objects in the PyBullet stand-in
(:func:`dam_experiments.experiment.run_experiment`, every cycle recorded): the classifier's
estimate from the recorded joint history is checked against the object's true pose (the
centroid's rise, the section's turn about its axis) and the true table contact
(``HandWorld.object_table_contacts()`` at the end). A few seconds per grasp.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_common.config import load_config
from dam_experiments.experiment import run_experiment
from dam_sim_bridge.column_body import resting_quaternion
from dam_sim_bridge.world import HandWorld
from dam_spcm_controller.classification import (
    ClassifierSettings,
    HandGeometry,
    classify_from_joints,
)
from dam_spcm_controller.commands import HandLayout
from dam_spcm_controller.pose_tracking import JointHistory

#: Turn of the section tolerated against the stand-in's [deg].
TURN_TOLERANCE_DEG = 5.0


def _rotation(q) -> np.ndarray:
    x, y, z, w = q
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _true_turn(config, quaternion) -> float:
    """The section's turn from its resting pose, from u (axis x z) towards z [rad]."""
    turn = _rotation(quaternion) @ _rotation(resting_quaternion(config.object)).T
    e_u = np.asarray(config.object.section_x)
    moved = turn @ e_u
    return math.atan2(float(moved[2]), float(moved @ e_u))


@pytest.mark.parametrize('name, alpha_deg, k_theta, dp_deg, left', [
    ('hex_bar', 5.0, 7.0, 5.0, False),  # rolls about +25 deg on the table, rises 1.35 mm
    ('hex_bar', 10.0, 10.0, 10.0, True),
    ('square_bar', 10.0, 5.0, 15.0, True),
    ('cylinder', 30.0, 10.0, 10.0, True),
])
def test_estimate_against_the_stand_in(name, alpha_deg, k_theta, dp_deg, left):
    config = load_config().with_object(name)
    with HandWorld(config) as world:
        result = run_experiment(config, k_theta, math.radians(dp_deg),
                                friction_angle=math.radians(alpha_deg), world=world,
                                record=True, record_every=1)
        assert result.phase.name == 'DONE', result.failure_reason
        pose = world.object_pose()
        rise = float(pose.position[2]) - float(config.object.position_m[2])
        touching = world.object_table_contacts()
    sig = result.signals
    history = JointHistory.from_arrays(sig['t'][:-1], sig['positions'][:-1],
                                       sig['efforts'][:-1])
    layout = HandLayout.from_hand_config(config.hand)
    c = classify_from_joints(HandGeometry.from_config(config), layout.lower, layout.upper,
                             sig['positions'][-1], sig['efforts'][-1],
                             ClassifierSettings.from_config(config), layout.joint_names,
                             history=history)
    # the lockstep trial classified the same grasp from the sequence's own history
    assert c.outcome is result.outcome
    assert c.lift_m == pytest.approx(rise, abs=1e-3), c.reason
    assert c.lifted is left and (touching == 0) is left, (c.reason, touching)
    if config.object.section.symmetry_period == 0.0:  # a cylinder
        assert c.orientation == 0.0
    else:
        period = config.object.section.symmetry_period
        error = (c.orientation - _true_turn(config, pose.quaternion) + period / 2) % period \
            - period / 2
        assert abs(math.degrees(error)) < TURN_TOLERANCE_DEG, c.reason
    assert c.reason.startswith('object left the table' if left else 'object on the table')
