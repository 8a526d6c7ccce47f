"""Planar kinematics, capsule geometry and the first contact (module model)."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
import yaml

from dam_analysis.errors import NoSolutionError
from dam_analysis.model import (
    build_hand_model,
    closest_point_on_segment,
    distal_gap,
    joint_positions,
    link_clearances,
    table_clearance,
)
from dam_common.config import config_from_dict
from dam_common.errors import ConfigError


def test_forward_kinematics_closed_form(config):
    model = build_hand_model(config)
    g = model.fingers[0]
    l1, l2, l3 = g.link_lengths
    ts, tl, tp = 0.3, -0.1, 0.7
    joints = joint_positions(g, ts, tl, tp)
    tip = np.array([l1 * math.sin(ts) + l2 * math.sin(ts + tl) + l3 * math.sin(ts + tl + tp),
                    -l1 * math.cos(ts) - l2 * math.cos(ts + tl) - l3 * math.cos(ts + tl + tp)])
    np.testing.assert_allclose(joints[3], tip, atol=1e-15)
    # all zero: the finger hangs straight down
    np.testing.assert_allclose(joint_positions(g, 0.0, 0.0, 0.0)[3], [0.0, -sum(g.link_lengths)])


def test_positive_angle_is_right_handed_about_joint_axis(config):
    """A small positive compliant angle moves the tip as omega x r with omega = joint_axis."""
    model = build_hand_model(config)
    for g in model.fingers:
        eps = 1e-7
        tip0 = g.to_world(joint_positions(g, 0.0, 0.0, 0.0)[3])
        tip1 = g.to_world(joint_positions(g, eps, 0.0, 0.0)[3])
        expected = np.cross(g.joint_axis, tip0 - g.base_position)
        np.testing.assert_allclose((tip1 - tip0) / eps, expected, atol=1e-8)
        # and it flexes inward
        assert (tip1 - tip0) @ g.inward_direction > 0.0


def test_distal_gap_derivative_matches_finite_difference(config):
    model = build_hand_model(config)
    g = model.fingers[1]
    for ts in (0.02, 0.08, 0.15):
        gap, deriv = distal_gap(g, ts, 0.0, 0.5)
        eps = 1e-7
        fd = (distal_gap(g, ts + eps, 0.0, 0.5)[0] - distal_gap(g, ts - eps, 0.0, 0.5)[0]) / (
            2 * eps)
        assert deriv == pytest.approx(fd, rel=1e-5, abs=1e-9)
        # the gap is the brute-force segment distance minus R + r
        joints = joint_positions(g, ts, 0.0, 0.5)
        pts = joints[2] + np.linspace(0, 1, 20001)[:, None] * (joints[3] - joints[2])
        brute = np.min(np.linalg.norm(pts - g.object_center, axis=1))
        assert gap == pytest.approx(brute - g.object_radius - g.link_radius, abs=1e-8)


def test_closest_point_on_segment_clamps():
    a, b = np.array([0.0, 0.0]), np.array([1.0, 0.0])
    p, t = closest_point_on_segment(a, b, np.array([2.0, 1.0]))
    np.testing.assert_allclose(p, [1.0, 0.0])
    assert t == 1.0
    p, t = closest_point_on_segment(a, b, np.array([0.25, -3.0]))
    np.testing.assert_allclose(p, [0.25, 0.0])


def test_first_contact_default(config):
    model = build_hand_model(config)
    for i, g in enumerate(model.fingers):
        joints = joint_positions(g, model.theta_s0[i], model.theta_l0, model.theta_p0)
        gaps = link_clearances(g, joints)
        assert gaps[2] == pytest.approx(0.0, abs=1e-12)  # the distal link touches
        assert np.all(gaps[:2] > 0.0)  # the proximal links do not
        assert table_clearance(g, joints) > 0.0
        # slightly less closed: no contact yet (it is the FIRST contact from theta_s = 0)
        assert distal_gap(g, model.theta_s0[i] - 1e-6, model.theta_l0, model.theta_p0)[0] > 0
    # first contact below the cylinder's equator: the finger can push the object up
    assert np.all(model.theta_s0 > 0.0)


def _raw(config_path):
    with open(config_path, encoding='utf-8') as fh:
        return yaml.safe_load(fh)


def test_first_contact_failures():
    from pathlib import Path
    raw = _raw(Path(__file__).resolve().parents[2] / 'config' / 'dam.yaml')
    far = copy.deepcopy(raw)
    for f in far['hand']['fingers']:
        f['base_position_m'][0] = math.copysign(0.2, f['base_position_m'][0])
    with pytest.raises(NoSolutionError, match='does not reach'):
        build_hand_model(config_from_dict(far))
    low = copy.deepcopy(raw)
    for f in low['hand']['fingers']:
        f['base_position_m'][2] = 0.090
    with pytest.raises(NoSolutionError, match='table'):
        build_hand_model(config_from_dict(low))
    inside = copy.deepcopy(raw)  # the object moved under finger 1
    inside['object']['position_m'] = [0.022, 0.0]
    with pytest.raises(NoSolutionError, match='overlaps'):
        build_hand_model(config_from_dict(inside))
    # Finger bases closer together than the object is wide: the loader refuses it first.
    narrow = copy.deepcopy(raw)
    for f in narrow['hand']['fingers']:
        f['base_position_m'][0] = math.copysign(0.005, f['base_position_m'][0])
    with pytest.raises(ConfigError, match='fingers would stand inside it'):
        config_from_dict(narrow)
