"""SPCM kinematics, eqs. (1)-(4) (module spcm)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from dam_analysis.errors import NoSolutionError
from dam_analysis.model import build_hand_model, joint_positions
from dam_analysis.spcm import build_paths, posture_problem, solve_spcm


@pytest.fixture(scope='module')
def model(config):
    return build_hand_model(config)


@pytest.fixture(scope='module')
def paths(model):
    return build_paths(model)


@pytest.mark.parametrize('dp_deg', [0.0, 3.3, 17.0, 31.4, 45.0, 58.0])
def test_contact_conditions_eqs_2_to_4(model, paths, dp_deg):
    """Contact point on both surfaces (eq. 2), one point (eq. 3), opposite normals (eq. 4)."""
    dp = math.radians(dp_deg)
    for i, fc in enumerate(solve_spcm(paths, np.full(3, dp))):
        g = model.fingers[i]
        # on the cylinder: distance from the axis (a line along y) equals R
        rel = fc.contact_point - model.object_center
        assert math.hypot(rel[0], rel[2]) == pytest.approx(g.object_radius, abs=1e-12)
        # on the distal capsule: distance to the distal segment equals r (brute force)
        joints = g.to_world(joint_positions(g, fc.theta_s, model.theta_l0, fc.theta_p))
        seg = joints[2] + np.linspace(0, 1, 40001)[:, None] * (joints[3] - joints[2])
        assert np.min(np.linalg.norm(seg - fc.contact_point, axis=1)) == pytest.approx(
            g.link_radius, abs=2e-8)
        # normals: n_CB is the radial direction, n_CF = -n_CB, unit length
        radial = np.array([rel[0], 0.0, rel[2]]) / g.object_radius
        np.testing.assert_allclose(fc.normal_object, radial, atol=1e-12)
        np.testing.assert_allclose(fc.normal_finger, -fc.normal_object)
        assert fc.theta_p == pytest.approx(model.theta_p0 + dp)
        assert fc.delta_theta_s == pytest.approx(fc.theta_s - model.theta_s0[i])


def test_zero_displacement_is_first_contact(paths):
    for fc in solve_spcm(paths, np.zeros(3)):
        assert fc.delta_theta_s == 0.0


def test_compliant_joint_yields(paths):
    """Flexing the position joint into a fixed object pushes the compliant joint back."""
    dps = np.radians(np.linspace(0.5, 55.0, 30))
    ds = np.array([paths[0].solve(float(d)).delta_theta_s for d in dps])
    assert np.all(ds < 0.0)


def test_rate_matches_finite_difference(paths):
    for d in (5.0, 25.0, 50.0):
        dp = math.radians(d)
        eps = 1e-6
        fd = (paths[1].solve(dp + eps).theta_s - paths[1].solve(dp - eps).theta_s) / (2 * eps)
        assert paths[1].solve(dp).dtheta_s_dtheta_p == pytest.approx(fd, rel=1e-5, abs=1e-7)


def test_request_between_grid_nodes_is_exact(model, paths):
    """Off-grid requests are solved exactly, not interpolated."""
    dp = paths[0].delta_theta_p[100] + 0.37 * paths[0].step
    fc = paths[0].solve(float(dp))
    rel = fc.contact_point - model.object_center
    assert math.hypot(rel[0], rel[2]) == pytest.approx(model.fingers[0].object_radius,
                                                       abs=1e-13)


def test_end_of_branch_raises(paths):
    """Beyond the fold (the distal link rolls over the object) there is no SPCM solution."""
    path = paths[0]
    assert path.failure is not None or path.valid_until == pytest.approx(
        path.model.delta_theta_p_max)
    if path.failure is not None:
        with pytest.raises(NoSolutionError, match='finger 1'):
            path.solve(path.valid_until + math.radians(1.0))


def test_posture_problems_detected(model):
    """Every invalid posture is named: table, proximal link in the object, limits, pulling."""
    g = model.fingers[0]
    ts0 = float(model.theta_s0[0])
    lim_s, lim_p = model.limits_s, model.limits_p
    tl, tp0 = model.theta_l0, model.theta_p0
    assert posture_problem(g, ts0, tl, tp0, ts0, lim_s, lim_p) is None
    # hanging straight down with the base lowered by 5 mm: tip capsule below the table
    low = dataclasses.replace(g, base_height=g.base_height - 0.005)
    assert 'table' in posture_problem(low, 0.0, 0.0, 0.0, 1.0, lim_s, lim_p)
    # compliant joint opened past the rest angle: the finger would pull on the object
    assert 'contact lost' in posture_problem(g, ts0 + 0.01, tl, tp0, ts0, lim_s, lim_p)
    assert 'compliant joint limit' in posture_problem(g, lim_s[0] - 0.01, tl, tp0, ts0, lim_s,
                                                      lim_p)
    assert 'position joint limit' in posture_problem(g, ts0, tl, lim_p[1] + 0.01, ts0, lim_s,
                                                     lim_p)
    # object moved onto link 1: a proximal link penetrates it
    inside = dataclasses.replace(g, object_center=np.array([0.0, -0.02]))
    assert 'proximal' in posture_problem(inside, 0.0, 0.0, 0.0, 1.0, lim_s, lim_p)


def test_slip_rate_of_the_material_point_by_finite_difference(analyzer):
    """The CSM slip rate is the tangential velocity of the finger's material point at the
    contact: follow that point (fixed in the distal link) through a small SPCM step."""
    model = analyzer.model
    g = model.fingers[0]
    path = analyzer.table.paths[0]
    grid = analyzer.table.grid[0]
    for j in (40, 300, 700, 1100):
        dp = float(path.delta_theta_p[j])
        fc = path.solve(dp)
        phi3 = fc.theta_s + model.theta_l0 + fc.theta_p
        axis_dir = np.array([math.sin(phi3), -math.cos(phi3)])
        perp_dir = np.array([math.cos(phi3), math.sin(phi3)])
        rel = np.array([(fc.contact_point - g.base_position) @ g.inward_direction,
                        fc.contact_point[2] - g.base_position[2]]) - fc.joints[2]
        local = np.array([rel @ axis_dir, rel @ perp_dir])
        eps = 1e-6
        fc2 = path.solve(dp + eps)
        phi3b = fc2.theta_s + model.theta_l0 + fc2.theta_p
        moved = (fc2.joints[2] + local[0] * np.array([math.sin(phi3b), -math.cos(phi3b)])
                 + local[1] * np.array([math.cos(phi3b), math.sin(phi3b)]))
        velocity = g.direction_to_world((moved - fc.joints[2] - rel) / eps)
        tangent = np.cross(g.joint_axis, fc.normal_object)
        assert grid.slip_rate[j] == pytest.approx(velocity @ tangent, rel=1e-4, abs=1e-9)
        # and the material point does not penetrate: no normal velocity (rolling contact)
        assert abs(velocity @ fc.normal_object) < 1e-5
