"""Outcome classification (paper Fig. 7) on synthetic final postures.

The fixtures are built here from independent planar geometry (point-to-segment distances,
two-link inverse kinematics, root finding); they are not simulator recordings.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from dam_common.config import load_config
from dam_spcm_controller.classification import (
    ClassifierSettings,
    HandGeometry,
    Outcome,
    classify_from_joints,
    classify_with_object_height,
    estimate_object,
    finger_points,
)
from dam_spcm_controller.commands import HandLayout
from dam_spcm_controller.errors import InputError

CFG = load_config()
GEO = HandGeometry.from_config(CFG)
LAY = HandLayout.from_hand_config(CFG.hand)
L1, L2, L3 = 0.040, 0.025, 0.025
BASE_U, BASE_Z = 0.029, 0.095  # finger 1; fingers 2 and 3 mirror it in the u-z plane
R, R_LINK = 0.010, 0.005
RHO = R + R_LINK
ENVELOPE_EFFORTS = np.tile([0.15, 0.0, 0.15], 3)


def _finger1_points(tc: float, tl: float, tp: float) -> list[np.ndarray]:
    """Finger 1 closes towards -u; angles from the downward vertical, radians."""
    pts = [np.array([BASE_U, BASE_Z])]
    phi = 0.0
    for angle, length in ((tc, L1), (tl, L2), (tp, L3)):
        phi += angle
        pts.append(pts[-1] + length * np.array([-math.sin(phi), -math.cos(phi)]))
    return pts


def _dist_point_segment(p, a, b) -> float:
    ab = b - a
    t = min(max(float(np.dot(p - a, ab) / np.dot(ab, ab)), 0.0), 1.0)
    return float(np.linalg.norm(p - (a + t * ab)))


def _finger1_distance(c, angles) -> float:
    pts = _finger1_points(*angles)
    return min(_dist_point_segment(c, pts[k], pts[k + 1]) for k in range(3))


def _symmetric(angles_rad) -> np.ndarray:
    return np.tile(np.asarray(angles_rad, dtype=float), 3)


def _enveloped_fixture():
    """Compliant 5 deg, position 80 deg; the object rests on the distal links."""
    angles = (math.radians(5.0), 0.0, math.radians(80.0))
    tip_z = _finger1_points(*angles)[-1][1]
    z = brentq(lambda z: _finger1_distance(np.array([0.0, z]), angles) - RHO,
               tip_z + 1e-4, 0.09)
    return _symmetric(angles), np.array([0.0, z])


def _pinch_fixture(h: float = 0.020):
    """Fingertips touch the object at its equator, centre at height h (two-link IK)."""
    x = BASE_U - RHO  # inward distance of the tip centre from the base
    y = BASE_Z - h  # downward distance
    a, b = L1 + L2, L3
    d2 = x * x + y * y
    tp = math.acos((d2 - a * a - b * b) / (2 * a * b))
    tc = math.atan2(x, y) - math.atan2(b * math.sin(tp), a + b * math.cos(tp))
    return _symmetric((tc, 0.0, tp)), np.array([0.0, h])


def _table_contact_fixture():
    """The approach posture: position joints at 15 deg, distal links touch the object
    lying on the table."""
    c = np.array([0.0, R])
    tp = math.radians(15.0)
    tc = brentq(lambda tc: _finger1_distance(c, (tc, 0.0, tp)) - RHO, 0.0, math.radians(15.0))
    return _symmetric((tc, 0.0, tp)), c


def test_geometry_from_config():
    assert np.allclose(GEO.base_uz, [[0.029, 0.095], [-0.029, 0.095], [-0.029, 0.095]])
    assert np.array_equal(GEO.inward_sign, [-1.0, 1.0, 1.0])
    assert GEO.contact_distance == pytest.approx(RHO)
    assert GEO.object_z0 == pytest.approx(0.010)


def test_finger_points_closed_form():
    straight = finger_points(GEO, np.zeros(9))
    assert np.allclose(straight[0, 3], [0.029, 0.095 - 0.09])
    curled = finger_points(GEO, _symmetric((math.pi / 2, 0.0, 0.0)))
    assert np.allclose(curled[0, 3], [0.029 - 0.09, 0.095])  # finger 1 points to -u
    assert np.allclose(curled[1, 3], [-0.029 + 0.09, 0.095])  # finger 2 points to +u
    q = _symmetric((0.3, -0.1, 1.2))
    pts = finger_points(GEO, q)
    for k, p in enumerate(_finger1_points(0.3, -0.1, 1.2)):
        assert np.allclose(pts[0, k], p)


def test_enveloped_object_is_found_and_classified_success():
    q, centre = _enveloped_fixture()
    est = estimate_object(GEO, q)
    assert np.allclose(est.centre, centre, atol=1e-5)
    assert est.max_residual < 1e-5
    res = classify_from_joints(GEO, LAY.lower, LAY.upper, q, ENVELOPE_EFFORTS)
    assert res.outcome is Outcome.SUCCESS, res.reason
    assert res.contact and res.load_held and res.lifted and res.enveloped
    assert res.lift_m == pytest.approx(centre[1] - R, abs=1e-5)


def test_fingertip_pinch_is_lifted_but_dam_failed():
    q, centre = _pinch_fixture()
    res = classify_from_joints(GEO, LAY.lower, LAY.upper, q, ENVELOPE_EFFORTS)
    assert np.allclose(res.estimate.centre, centre, atol=1e-4)
    assert res.outcome is Outcome.LIFTED_DAM_FAILED, res.reason
    assert res.lifted and not res.enveloped
    assert 'not caged' in res.reason


def test_object_still_on_table_is_failure():
    q, centre = _table_contact_fixture()
    res = classify_from_joints(GEO, LAY.lower, LAY.upper, q, ENVELOPE_EFFORTS)
    assert np.allclose(res.estimate.centre, centre, atol=1e-4)
    assert res.contact and not res.lifted
    assert res.outcome is Outcome.FAILURE
    assert res.reason.startswith('object on the table: rise ')


def test_fingers_closed_on_nothing_is_failure():
    # compliant joints at their 60 deg limit: the fingers closed on empty space
    q = _symmetric((math.radians(60.0), 0.0, math.radians(95.0)))
    res = classify_from_joints(GEO, LAY.lower, LAY.upper, q, ENVELOPE_EFFORTS,
                               joint_names=LAY.joint_names)
    assert res.outcome is Outcome.FAILURE
    assert not res.load_held
    assert 'finger1_compliant_joint at 60 deg is at its limit' in res.reason


def test_no_load_on_the_compliant_joints_is_failure():
    q, _ = _enveloped_fixture()
    efforts = ENVELOPE_EFFORTS.copy()
    efforts[3] = 0.001  # finger2 compliant torque shows no load
    res = classify_from_joints(GEO, LAY.lower, LAY.upper, q, efforts,
                               joint_names=LAY.joint_names)
    assert res.outcome is Outcome.FAILURE
    assert res.contact and not res.lifted and not res.load_held
    assert 'finger2_compliant_joint torque 0.001' in res.reason


def test_posture_inconsistent_with_the_object_is_failure():
    # straight fingers 58 mm apart cannot touch a 20 mm cylinder (rho = 15 mm) on both sides
    res = classify_from_joints(GEO, LAY.lower, LAY.upper, _symmetric((0.0, 0.0, 0.05)),
                               ENVELOPE_EFFORTS)
    assert not res.contact
    assert res.outcome is Outcome.FAILURE


def test_object_on_the_outer_side_of_the_links_is_not_accepted():
    # mirror the enveloped fixture's object below the distal links: that centre is on the
    # outer side, so it must not be the estimate
    q, centre = _enveloped_fixture()
    est = estimate_object(GEO, q)
    tip_z = _finger1_points(math.radians(5.0), 0.0, math.radians(80.0))[-1][1]
    assert est.centre[1] > tip_z
    assert np.allclose(est.centre, centre, atol=1e-5)


def test_ground_truth_height_helper():
    q, _ = _enveloped_fixture()
    res = classify_from_joints(GEO, LAY.lower, LAY.upper, q, ENVELOPE_EFFORTS)
    assert classify_with_object_height(res, 0.040, 0.010) is Outcome.SUCCESS
    assert classify_with_object_height(res, 0.012, 0.010) is Outcome.FAILURE
    q, _ = _pinch_fixture()
    pinch = classify_from_joints(GEO, LAY.lower, LAY.upper, q, ENVELOPE_EFFORTS)
    assert classify_with_object_height(pinch, 0.02, 0.010) is Outcome.LIFTED_DAM_FAILED
    with pytest.raises(InputError, match='object_z'):
        classify_with_object_height(res, math.nan, 0.01)


def test_settings_and_inputs_are_validated():
    with pytest.raises(InputError, match='lift_height'):
        ClassifierSettings(lift_height=0.0)
    with pytest.raises(InputError, match=r'positions\[2\] must be finite'):
        classify_from_joints(GEO, LAY.lower, LAY.upper,
                             np.array([0, 0, math.nan, 0, 0, 0, 0, 0, 0.0]), np.zeros(9))
    with pytest.raises(InputError, match='efforts must have 9 values'):
        classify_from_joints(GEO, LAY.lower, LAY.upper, np.zeros(9), np.zeros(3))
    with pytest.raises(InputError, match='both sides'):
        HandGeometry(GEO.link_lengths, 0.005, GEO.base_uz, np.ones(3), 0.01, 0.01)


def test_settings_from_config_use_the_contact_threshold():
    s = ClassifierSettings.from_config(CFG, lift_height=0.01)
    # scaled to the least stiff finger's share (fingers 2 and 3: ratio 0.5 of finger 1)
    ratios = CFG.hand.stiffness_ratios
    expected = CFG.controller.contact_torque_threshold_nm * ratios.min() / ratios.max()
    assert s.load_torque_threshold == pytest.approx(expected)
    assert s.load_torque_threshold == pytest.approx(
        0.5 * CFG.controller.contact_torque_threshold_nm)
    assert s.lift_height == 0.01
