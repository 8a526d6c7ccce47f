"""The object's pose from the joint history (pose_tracking, section_contact) on synthetic grasps.

The fixtures are built here independently of the code under test: finger postures touching a
section placed at a known pose by root finding on a brute-force distance (the section's
boundary sampled densely), and compliant-joint torques from the balance of forces and moments
solved here in closed form.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.optimize import brentq

from dam_common.config import load_config
from dam_spcm_controller.errors import InputError
from dam_spcm_controller.object_estimate import FitInterrupted, HandGeometry, finger_points
from dam_spcm_controller.pose_tracking import JointHistory, TrackerSettings, track_pose
from dam_spcm_controller.section_contact import LinkAxes, SectionPolygon, chain_contacts

CFG = load_config().with_object('hex_bar')
# rigid contacts: the fixtures place the fingers exactly on the surface
GEO = dataclasses.replace(HandGeometry.from_config(CFG), contact_stiffness=math.inf)
SECTION = CFG.object.section
W = GEO.object_mass * GEO.gravity


def _boundary(pose: np.ndarray, per_edge: int = 400) -> np.ndarray:
    """Dense samples of the section's boundary at ``pose`` (u, z, psi)."""
    v = np.asarray(SECTION.vertices, dtype=float)
    t = np.linspace(0.0, 1.0, per_edge, endpoint=False)[:, None]
    pts = np.concatenate([v[i] + t * (v[(i + 1) % len(v)] - v[i]) for i in range(len(v))])
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return pose[:2] + pts @ np.array([[c, s], [-s, c]])


def _segment_distance(points: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ab = b - a
    t = np.clip((points - a) @ ab / (ab @ ab), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=1)


def _chain(finger: int, q: tuple[float, float, float]) -> list[np.ndarray]:
    """Joint and tip points of one finger, written out (downward vertical is angle 0)."""
    s = GEO.inward_sign[finger]
    pts = [GEO.base_uz[finger].copy()]
    phi = 0.0
    for angle, length in zip(q, GEO.link_lengths, strict=True):
        phi += angle
        pts.append(pts[-1] + length * np.array([s * math.sin(phi), -math.cos(phi)]))
    return pts


def _gap(finger: int, q, boundary: np.ndarray) -> tuple[float, np.ndarray]:
    """Brute-force distance of the finger's capsules from the section, and the touch point."""
    chain = _chain(finger, q)
    best, point = math.inf, None
    for k in range(3):
        d = _segment_distance(boundary, chain[k], chain[k + 1])
        j = int(np.argmin(d))
        if d[j] < best:
            best, point = float(d[j]), boundary[j]
    return best - GEO.link_radius, point


def _touching(pose: np.ndarray, position_angle: float) -> tuple[np.ndarray, np.ndarray]:
    """Joint angles (9,) of fingers that touch the section at ``pose``, with the locked
    joints at 0 and the position joints at ``position_angle``; and the contact points (3, 2)."""
    boundary = _boundary(pose)
    q, points = [], []
    for i in range(GEO.n_fingers):
        def gap(tc, i=i):
            return _gap(i, (tc, 0.0, position_angle), boundary)[0]
        # open: far from the object; closing until it enters the object
        lo = -0.7
        hi = lo
        while gap(hi) > 0.0:
            hi += 0.01
        tc = brentq(gap, hi - 0.01, hi, xtol=1e-12)
        q += [tc, 0.0, position_angle]
        points.append(_gap(i, (tc, 0.0, position_angle), boundary)[1])
    return np.array(q), np.array(points)


def _link_gravity(finger: int, q) -> float:
    """Counter-clockwise moment of the finger's own link weights about its compliant joint."""
    chain = _chain(finger, q)
    moment = 0.0
    for k, m in enumerate(GEO.link_masses):
        mid = 0.5 * (chain[k] + chain[k + 1]) - chain[0]
        moment += mid[0] * (-m * GEO.gravity)
    return moment


def _torques(pose, q, points, hanging: bool, squeeze: float = 0.6,
             press: float = 0.3) -> np.ndarray:
    """Compliant-joint torques (9,) of contact forces that squeeze the object and, when
    ``hanging``, carry its weight with no moment about its centroid; else press it down onto
    the table with ``press`` [N] each."""
    pa, pb = points[0], 0.5 * (points[1] + points[2])
    d = pb - pa
    fa = squeeze * d / np.linalg.norm(d)
    if hanging:  # fa + fb = (0, W), (pa - c) x fa + (pb - c) x fb = 0
        k = -(pb[0] - pose[0]) * W / (d @ d)
        fa = fa + k * np.array([d[1], -d[0]])  # (pa - pb) x this = k |d|^2
        fb = np.array([0.0, W]) - fa
    else:
        fb = -fa + np.array([0.0, -press])
        fa = fa + np.array([0.0, -press])
    tau = np.zeros(9)
    for i, (p, f) in enumerate(((pa, fa), (pb, 0.5 * fb), (pb, 0.5 * fb))):
        qi = q[3 * i:3 * i + 3]
        r = p - GEO.base_uz[i]
        moment = r[0] * f[1] - r[1] * f[0]
        tau[3 * i] = GEO.inward_sign[i] * (moment - _link_gravity(i, qi))
    return tau


def _history(poses, angles, hanging) -> JointHistory:
    h = JointHistory(9)
    for k, (pose, angle, hang) in enumerate(zip(poses, angles, hanging, strict=True)):
        q, points = _touching(pose, angle)
        h.append(0.01 * k, q, _torques(pose, q, points, hang))
    return h


REST = np.array([GEO.object_u0, GEO.object_z0, 0.0])


def test_section_distances_against_brute_force():
    poly = SectionPolygon.from_section(SECTION)
    rng = np.random.default_rng(3)
    for _ in range(20):
        pose = REST + np.array([rng.uniform(-2e-3, 2e-3), rng.uniform(0.0, 6e-3),
                                rng.uniform(-0.6, 0.6)])
        q = np.tile([rng.uniform(-0.2, 0.3), 0.0, rng.uniform(0.2, 1.2)], 3)
        pts = finger_points(GEO, q)
        con = chain_contacts(poly, LinkAxes.from_points(pts), pose[None, :2], pose[2:3])
        boundary = _boundary(pose, per_edge=2000)
        for i in range(3):
            brute = _gap(i, tuple(q[3 * i:3 * i + 3]), boundary)[0] + GEO.link_radius
            if brute > 1e-4:  # outside: exact
                assert con.distance[0, i] == pytest.approx(brute, abs=2e-6)


def test_face_along_a_link_is_a_stretch():
    # a square face lying along a vertical link axis: the contact is the overlap
    poly = SectionPolygon.from_vertices(np.array([[-0.01, -0.01], [0.01, -0.01], [0.01, 0.01],
                                                  [-0.01, 0.01]]))
    pts = np.array([[[0.03, 0.04], [0.015, 0.02], [0.015, -0.02], [0.03, -0.04]]])
    con = chain_contacts(poly, LinkAxes.from_points(pts), np.zeros((1, 2)), np.zeros(1))
    assert con.distance[0, 0] == pytest.approx(0.005)
    assert con.link[0, 0] == 1
    ends = np.sort(con.region[0, 0, :, 1])
    assert ends == pytest.approx([-0.01, 0.01])  # the whole face
    tilted = chain_contacts(poly, LinkAxes.from_points(pts), np.zeros((1, 2)),
                            np.array([0.05]))
    assert np.allclose(tilted.region[0, 0, 0], tilted.region[0, 0, 1])  # one corner


def test_hanging_object_is_followed_off_the_table():
    # (turning on, a face would come to lie along a link and hold the object there)
    target = REST + np.array([0.2e-3, 4e-3, math.radians(3.0)])
    steps = 24
    poses = [REST + (target - REST) * k / steps for k in range(steps + 1)]
    angles = np.linspace(math.radians(15.0), math.radians(22.0), steps + 1)
    tracked = track_pose(GEO, _history(poses, angles, [k > 0 for k in range(steps + 1)]))
    assert not tracked.on_table
    assert tracked.centre == pytest.approx(target[:2], abs=5e-5)
    assert math.degrees(tracked.orientation) == pytest.approx(3.0, abs=0.5)
    lowest = _boundary(target)[:, 1].min()
    assert tracked.clearance == pytest.approx(lowest - GEO.table_z, abs=5e-5)
    assert np.abs(tracked.residuals).max() < 2e-5


def test_object_rolled_on_the_table_stays_on_it():
    # pushed by finger 1 (from +u) it tips about its -u bottom vertex, away from the finger;
    # the fingers press it down onto the table
    v = np.asarray(SECTION.vertices)
    pivot = REST[:2] + v[np.argmin(v[:, 1] + 1e-9 * v[:, 0])]
    steps = 20
    poses = []
    for k in range(steps + 1):
        psi = math.radians(20.0) * k / steps
        c, s = math.cos(psi), math.sin(psi)
        centre = pivot + np.array([[c, -s], [s, c]]) @ (REST[:2] - pivot)
        poses.append(np.array([centre[0], centre[1], psi]))
    tracked = track_pose(GEO, _history(poses, np.full(steps + 1, math.radians(15.0)),
                                       [False] * (steps + 1)))
    assert tracked.on_table and tracked.clearance == 0.0
    assert tracked.centre == pytest.approx(poses[-1][:2], abs=5e-5)
    assert math.degrees(tracked.orientation) == pytest.approx(20.0, abs=0.5)


def test_history_buffer_and_inputs():
    h = JointHistory(9, capacity=2)
    for k in range(5):
        h.append(0.1 * k, np.full(9, k), np.full(9, -k))
    assert len(h) == 5 and h.positions.shape == (5, 9)
    assert h.positions[4, 0] == 4.0 and h.efforts[3, 8] == -3.0 and h.times[2] == 0.2
    with pytest.raises(ValueError):
        h.positions[0, 0] = 1.0  # a read-only view
    h.clear()
    assert len(h) == 0
    with pytest.raises(InputError, match='times must not decrease'):
        JointHistory.from_arrays([0.0, -1.0], np.zeros((2, 9)), np.zeros((2, 9)))
    with pytest.raises(InputError, match='must match'):
        JointHistory.from_arrays([0.0], np.zeros((2, 9)), np.zeros((2, 9)))
    with pytest.raises(InputError, match='no sample'):
        track_pose(GEO, JointHistory(9))
    with pytest.raises(InputError, match='history has 6 joints'):
        track_pose(GEO, JointHistory(6))
    with pytest.raises(InputError, match='non-circular'):
        track_pose(HandGeometry.from_config(load_config().with_object('cylinder')), h)
    with pytest.raises(InputError, match='grid_step'):
        TrackerSettings(grid_step=0.0)
    with pytest.raises(InputError, match='bisections'):
        TrackerSettings(bisections=0)
    h.append(0.0, np.zeros(9), np.zeros(9))
    with pytest.raises(FitInterrupted):
        track_pose(GEO, h, stop=lambda: True)
