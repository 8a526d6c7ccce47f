"""/check_lift's guarantee against the stand-in (lockstep trials, PyBullet ground truth).

* cells of the cylinder that eq. 18 guarantees at 5 deg lift off in the stand-in;
* the hexagonal bar at alpha 5 deg, k_theta 7 N*m/rad, delta_theta_p 5 deg, where eq. 18 holds
  at rest: the stand-in's bar ends turned on the table (its turn read from PyBullet's
  orientation of the body, its rise from the body's height), the rolling check refuses the
  guarantee, and the pose the bar ended in is one where the analysis finds it can rest.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_analysis.analysis import LiftAnalyzer
from dam_analysis.rolling import pose_margin
from dam_common.config import load_config
from dam_experiments.experiment import run_experiment
from dam_sim_bridge.world import HandWorld
from dam_sim_bridge.world_options import WorldOptions

CONFIG = load_config()
ALPHA = math.radians(5.0)


def _rotation(q: np.ndarray) -> np.ndarray:
    x, y, z, w = (float(v) for v in q)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


@pytest.mark.parametrize('k_theta,dp_deg', [(15.0, 5.0), (10.0, 10.0)])
def test_cylinder_cells_eq_18_guarantees_lift_off_in_the_stand_in(k_theta: float,
                                                                 dp_deg: float) -> None:
    verdict = LiftAnalyzer(CONFIG).check_lift([k_theta], [math.radians(dp_deg)], ALPHA)
    assert verdict.lift_guaranteed and not verdict.rolling_checked
    result = run_experiment(CONFIG, k_theta, math.radians(dp_deg), friction_angle=ALPHA,
                            max_time=8.0)
    assert result.lifted, result.row()


def test_the_bar_that_turns_on_the_table_is_refused_with_the_pose_it_ends_in() -> None:
    config = CONFIG.with_object('hex_bar')
    dp = math.radians(5.0)
    verdict = LiftAnalyzer(config).check_lift([7.0], [dp], ALPHA)
    assert verdict.worst_case_margin > 0.0  # eq. 18 at rest would guarantee it
    assert not verdict.lift_guaranteed and verdict.rolling_checked
    world = HandWorld(config, WorldOptions.from_config(config))
    try:
        world.reset()
        rest = world.object_pose()
        result = run_experiment(config, 7.0, dp, friction_angle=ALPHA, world=world,
                                max_time=8.0)
        end = world.object_pose()
    finally:
        world.close()
    assert not result.off_table_at_end  # it ends on the table
    relative = _rotation(end.quaternion) @ _rotation(rest.quaternion).T
    x_axis = config.object.section_x
    z_axis = np.array([0.0, 0.0, 1.0])
    turned_x = relative @ x_axis
    turn = math.atan2(float(turned_x @ z_axis), float(turned_x @ x_axis))  # x towards z
    rise = float(end.position[2] - rest.position[2])
    assert abs(math.degrees(turn)) > 15.0  # it turned on the table
    # the pose the bar ended in is one where the analysis finds it can rest (the grid's
    # nearest pose), and the pose the answer names is as high on a vertex
    analyzer = LiftAnalyzer(config)
    rc = analyzer.rolling
    j = min(range(len(rc.poses)), key=lambda i: abs(rc.poses[i].turn - turn))
    assert abs(math.degrees(rc.poses[j].turn - turn)) <= 1.0
    k = [7.0 * r / analyzer.model.stiffness_ratios[0] for r in analyzer.model.stiffness_ratios]
    margin = pose_margin(rc.pose_states([dp] * 3, j), k, ALPHA, analyzer.rolling_cos_phi,
                         analyzer.model.object_weight, rc._pivots[j], rc._signs,
                         rc._gravity_arm[j], not rc.poses[j].resting)
    assert margin <= 0.0
    assert 20.0 <= abs(math.degrees(verdict.rolling_turn)) <= 30.0
    section = config.object.section
    # the rise of a turned section resting on its lowest point, for the stand-in's turn
    lowest = min(float(np.sin(turn) * v[0] + np.cos(turn) * v[1]) for v in section.vertices)
    assert rise == pytest.approx(-lowest - section.rest_height, abs=0.3e-3)
