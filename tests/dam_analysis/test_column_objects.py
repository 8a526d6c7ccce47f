"""The lift analysis of non-circular columns, checked by independent computations.

Everything the checks compare against is rebuilt here from the YAML entries alone: the
cross-section (its own parametric boundary: the face lines of a regular polygon, the vertex
list of a convex polygon centred by its own quadrature, ``(a cos s, b sin s)`` for an ellipse),
the planar forward kinematics of the fingers, the closest pair of a capsule link and the
section (exact segment-segment distances for polygons, a dense sampling refined by a root
search for curves), the SPCM branch (own root tracking in ``theta_s``), and the worst case of
eq. (18) as a linear program over the friction cone written by its faces.

The hex pencil's branch ends at about 18 deg, so the larger checks use the square bar, the
elliptic column, a 20 mm hexagon and an asymmetric pentagon added to the library here.
"""

from __future__ import annotations

import copy
import math
from functools import cache
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.optimize import brentq, linprog

from dam_analysis.analysis import LiftAnalyzer
from dam_common.config import config_from_dict

CONFIG_FILE = Path(__file__).resolve().parents[2] / 'config' / 'dam.yaml'
RAW = yaml.safe_load(CONFIG_FILE.read_text())

#: Objects added to the library for these tests.
EXTRA = {
    'big_hex': {'shape': 'regular_polygon', 'sides': 6, 'across_flats_m': 0.02,
                'length_m': 0.06, 'mass_kg': 0.04},
    'pentagon': {'shape': 'convex_polygon', 'length_m': 0.06, 'mass_kg': 0.04,
                 'vertices_m': [[-0.010, 0.0], [0.010, 0.0], [0.012, 0.010], [0.002, 0.021],
                                [-0.011, 0.012]]},
    'near_circle': {'shape': 'ellipse', 'semi_axes_m': [0.010, 0.010 * (1.0 - 1e-9)],
                    'length_m': 0.06, 'mass_kg': 0.04},
}
for _n in (32, 64, 128, 256):
    EXTRA[f'ngon{_n}'] = {'shape': 'regular_polygon', 'sides': _n, 'across_flats_m': 0.02,
                          'length_m': 0.06, 'mass_kg': 0.04}

#: Coarser SPCM grid for the polygon-to-circle study (the SPCM states themselves are exact).
COARSE_STEP = math.radians(0.2)


def raw_entry(name: str) -> dict:
    return EXTRA[name] if name in EXTRA else RAW['object']['library'][name]


@cache
def config_of(name: str):
    data = copy.deepcopy(RAW)
    data['object']['library'].update(copy.deepcopy(EXTRA))
    return config_from_dict(data).with_object(name)


@cache
def analyzer_of(name: str, coarse: bool = False) -> LiftAnalyzer:
    if coarse:
        return LiftAnalyzer(config_of(name), path_step=COARSE_STEP)
    return LiftAnalyzer(config_of(name))


# --------------------------------------------------------------------------------------------
# The section, rebuilt from its YAML entry


def _segment_points(a: np.ndarray, b: np.ndarray, pts: np.ndarray) -> tuple[np.ndarray,
                                                                             np.ndarray]:
    """Distances (m,) of the points pts (m, 2) to the segment [a, b], and the parameters."""
    e = b - a
    ee = float(e @ e)
    t = np.clip((pts - a) @ e / ee, 0.0, 1.0) if ee > 0.0 else np.zeros(len(pts))
    foot = a + t[:, None] * e
    return np.hypot(*(pts - foot).T), t


def _cross(u: np.ndarray, v: np.ndarray) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


class PolygonSection:
    """A convex polygon by its counter-clockwise vertices about its centroid (section frame)."""

    def __init__(self, vertices: np.ndarray) -> None:
        v = np.asarray(vertices, dtype=float)
        area = sum(_cross(v[k], v[(k + 1) % len(v)]) for k in range(len(v))) / 2
        if area < 0:
            v = v[::-1]
        self.v = v - _centroid(v)
        self.samples = np.concatenate([
            self.v[k] + np.linspace(0, 1, 2000, endpoint=False)[:, None]
            * (self.v[(k + 1) % len(v)] - self.v[k]) for k in range(len(v))])

    def inside(self, p: np.ndarray) -> bool:
        m = len(self.v)
        return all(_cross(self.v[(k + 1) % m] - self.v[k], p - self.v[k]) > 0 for k in range(m))

    def boundary_distance(self, p: np.ndarray) -> float:
        nxt = np.roll(self.v, -1, axis=0)
        return min(float(_segment_points(self.v[k], nxt[k], p[None])[0][0])
                   for k in range(len(self.v)))

    def segment_pair(self, a: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """Exact closest pair: (distance, section point, segment point); 0 when crossing."""
        best = (math.inf, None, None)
        m = len(self.v)
        for k in range(m):
            p, q = self.v[k], self.v[(k + 1) % m]
            # two segments that cross are at distance 0
            d1, d2 = _cross(q - p, a - p), _cross(q - p, b - p)
            d3, d4 = _cross(b - a, p - a), _cross(b - a, q - a)
            if d1 * d2 < 0 and d3 * d4 < 0:
                t = d1 / (d1 - d2)
                x = a + t * (b - a)
                return 0.0, x, x
            # otherwise the closest pair has an end point of one of them
            for point, s0, s1, on_section in ((a, p, q, False), (b, p, q, False),
                                              (p, a, b, True), (q, a, b, True)):
                d, t = _segment_points(s0, s1, point[None])
                foot = s0 + t[0] * (s1 - s0)
                if d[0] < best[0]:
                    best = ((float(d[0]), point, foot) if on_section
                            else (float(d[0]), foot, point))
        return best


def _centroid(v: np.ndarray) -> np.ndarray:
    """Area centroid by a fan of triangles from the first vertex."""
    total, moment = 0.0, np.zeros(2)
    for k in range(1, len(v) - 1):
        area = _cross(v[k] - v[0], v[k + 1] - v[0]) / 2
        total += area
        moment += area * (v[0] + v[k] + v[k + 1]) / 3
    return moment / total


class CurveSection:
    """The ellipse ``(a cos s, b sin s)`` (a circle for a = b), centred on its centroid."""

    def __init__(self, a: float, b: float) -> None:
        self.a, self.b = a, b
        self.s = np.linspace(0, 2 * math.pi, 20000, endpoint=False)
        self.samples = np.column_stack([a * np.cos(self.s), b * np.sin(self.s)])
        self._cs = self.s[::10]
        self._coarse = self.samples[::10]
        self._ds = self._cs[1] - self._cs[0]

    def inside(self, p: np.ndarray) -> bool:
        return (p[0] / self.a) ** 2 + (p[1] / self.b) ** 2 < 1.0

    def boundary_distance(self, p: np.ndarray) -> float:
        return self.segment_pair(p, p)[0]

    def segment_pair(self, a: np.ndarray, b: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        """Closest pair: the best coarse sample refined by Brent's method on the derivative
        of the squared distance to the segment along the boundary parameter."""
        d, _ = _segment_points(a, b, self._coarse)
        i = int(np.argmin(d))
        e = b - a
        ee = float(e @ e)

        def foot(p: np.ndarray) -> np.ndarray:
            if ee == 0.0:
                return a
            return a + min(1.0, max(0.0, float((p - a) @ e) / ee)) * e

        def slope(s: float) -> float:
            p = np.array([self.a * math.cos(s), self.b * math.sin(s)])
            dp = np.array([-self.a * math.sin(s), self.b * math.cos(s)])
            return float((p - foot(p)) @ dp)

        s_best = float(self._cs[i])
        lo, hi = s_best - self._ds, s_best + self._ds
        if slope(lo) < 0 < slope(hi):
            s_best = brentq(slope, lo, hi, xtol=1e-15, rtol=1e-15)
        p = np.array([self.a * math.cos(s_best), self.b * math.sin(s_best)])
        f = foot(p)
        return float(np.hypot(*(p - f))), p, f


def section_of(name: str):
    entry = raw_entry(name)
    shape = entry['shape']
    if shape == 'circle':
        return CurveSection(entry['radius_m'], entry['radius_m'])
    if shape == 'ellipse':
        return CurveSection(*entry['semi_axes_m'])
    if shape == 'regular_polygon':
        n, r = entry['sides'], entry['across_flats_m'] / 2
        # face k: outward normal at -90 deg + k 360/n (face 0 on the table), distance r
        normals = [np.array([math.cos(-math.pi / 2 + 2 * math.pi * k / n),
                             math.sin(-math.pi / 2 + 2 * math.pi * k / n)]) for k in range(n)]
        verts = [np.linalg.solve(np.array([normals[k], normals[(k + 1) % n]]), [r, r])
                 for k in range(n)]
        return PolygonSection(np.array(verts))
    return PolygonSection(np.array(entry['vertices_m'], dtype=float))


# --------------------------------------------------------------------------------------------
# The hand in the world x-z plane (every finger plane is one; the column axis is world y)


class Finger:
    """One finger and the object in world (x, z) coordinates, from the YAML alone."""

    def __init__(self, name: str, index: int) -> None:
        hand = RAW['hand']
        f = hand['fingers'][index]
        yaw = math.radians(f['base_yaw_deg'])
        assert abs(math.sin(yaw)) < 1e-12  # the finger plane is a world x-z plane
        self.sign = math.cos(yaw)  # world x per unit of the inward coordinate u
        self.base = np.array([f['base_position_m'][0], f['base_position_m'][2]])
        self.base_y = f['base_position_m'][1]
        self.axis = np.array([math.sin(yaw), -math.cos(yaw), 0.0])
        self.lengths = hand['link_lengths_m']
        self.r = hand['link_radius_m']
        self.theta_l = math.radians(hand['initial_locked_angle_deg'])
        self.theta_p0 = math.radians(hand['initial_position_angle_deg'])
        self.section = section_of(name)
        rest = -float(self.section.samples[:, 1].min())  # resting on the table z = 0
        self.centre = np.array([RAW['object']['position_m'][0], rest])

    def joints_uz(self, theta_s: float, theta_p: float) -> np.ndarray:
        """(4, 2) plane coordinates (u inward, z up) relative to the base: a link at the
        cumulative angle phi points along (sin phi, -cos phi)."""
        out = [np.zeros(2)]
        phi = 0.0
        for length, joint in zip(self.lengths, (theta_s, self.theta_l, theta_p), strict=True):
            phi += joint
            out.append(out[-1] + length * np.array([math.sin(phi), -math.cos(phi)]))
        return np.array(out)

    def to_world(self, uz: np.ndarray) -> np.ndarray:
        uz = np.atleast_2d(uz)
        return np.column_stack([self.base[0] + self.sign * uz[:, 0], self.base[1] + uz[:, 1]])

    def link_pair(self, joints_xz: np.ndarray, k: int):
        """(distance, section point, segment point) of link k, world (x, z)."""
        d, q, s = self.section.segment_pair(joints_xz[k] - self.centre,
                                            joints_xz[k + 1] - self.centre)
        return d, q + self.centre, s + self.centre

    def gap(self, theta_s: float, theta_p: float, link: int = 2) -> float:
        joints = self.to_world(self.joints_uz(theta_s, theta_p))
        return self.link_pair(joints, link)[0] - self.r


def own_first_contact(finger: Finger) -> float:
    """Close the compliant joint from 0 until the distal capsule touches."""
    step = math.radians(0.25)
    theta = 0.0
    while finger.gap(theta + step, finger.theta_p0) > 0.0:
        theta += step
        for link in (0, 1):  # no proximal link touches first
            assert finger.gap(theta, finger.theta_p0, link) > 0.0
    return brentq(finger.gap, theta, theta + step, args=(finger.theta_p0,), xtol=1e-15)


def own_branch(finger: Finger, dps_deg: list[float]) -> dict[float, float]:
    """theta_s on the SPCM branch, followed from the first contact in 0.5 deg steps by the
    root of the gap nearest to the previous one."""
    theta = own_first_contact(finger)
    out = {0.0: theta}
    grid = np.arange(0.5, max(dps_deg) + 1e-9, 0.5)
    grid = np.unique(np.concatenate([grid, dps_deg]))
    for dp in grid:
        theta_p = finger.theta_p0 + math.radians(dp)
        g0 = finger.gap(theta, theta_p)
        width = 1e-3
        while True:
            lo, hi = theta - width, theta + width
            g_lo, g_hi = finger.gap(lo, theta_p), finger.gap(hi, theta_p)
            if g_lo * g0 <= 0.0:
                theta = brentq(finger.gap, lo, theta, args=(theta_p,), xtol=1e-15)
                break
            if g_hi * g0 <= 0.0:
                theta = brentq(finger.gap, theta, hi, args=(theta_p,), xtol=1e-15)
                break
            width *= 2
            assert width < 0.5, f'lost the branch at {dp} deg'
        out[float(dp)] = theta
    return out


@cache
def own_branches(name: str, dps: tuple[float, ...]) -> tuple[dict[float, float], ...]:
    # fingers 2 and 3 share one x-z geometry (they differ only in y): follow 1 and 2
    b1, b2 = (own_branch(Finger(name, i), list(dps)) for i in (0, 1))
    return b1, b2, b2


# --------------------------------------------------------------------------------------------
# (a) SPCM contact geometry

SPCM_CASES = {
    'square_bar': (5.0, 15.0, 30.0, 45.0),
    'elliptic_column': (5.0, 15.0, 30.0, 45.0),
    'big_hex': (2.0, 5.0, 15.0, 30.0, 45.0, 55.0),
    'pentagon': (5.0, 15.0, 30.0, 45.0),
    'hex_pencil': (5.0, 10.0, 15.0),
}


def _unique_foot(section, a: np.ndarray, b: np.ndarray, best: float) -> bool:
    d, _ = _segment_points(a, b, section.samples)
    near = section.samples[d <= best + 1e-8]
    return near.size > 0 and float(np.ptp(near, axis=0).max()) < 1e-4


@pytest.mark.parametrize('name', list(SPCM_CASES))
def test_spcm_branch_and_contact_geometry(name):
    analyzer = analyzer_of(name)
    config = analyzer.config
    dps = SPCM_CASES[name]
    branches = own_branches(name, dps)
    fingers = [Finger(name, i) for i in range(3)]
    # the configuration places the column as the YAML says, resting on the table
    np.testing.assert_allclose(config.object.position_m,
                               [fingers[0].centre[0], RAW['object']['position_m'][1],
                                fingers[0].centre[1]], atol=1e-15)
    for i in range(3):
        assert analyzer.model.theta_s0[i] == pytest.approx(branches[i][0.0], abs=1e-10)
    for dp_deg in (0.0, *dps):
        contacts = analyzer.spcm(math.radians(dp_deg))
        for i, (fc, finger) in enumerate(zip(contacts, fingers, strict=True)):
            where = f'{name} finger {i + 1} at {dp_deg} deg'
            # the branch: own root tracking from the own first contact
            assert fc.theta_s == pytest.approx(branches[i][dp_deg], abs=1e-9), where
            assert fc.delta_theta_s == pytest.approx(branches[i][dp_deg] - branches[i][0.0],
                                                     abs=1e-9), where
            assert fc.theta_p == pytest.approx(finger.theta_p0 + math.radians(dp_deg))
            assert fc.delta_theta_s <= 0.0 or dp_deg == 0.0
            # own forward kinematics from the returned angles
            uz = finger.joints_uz(fc.theta_s, fc.theta_p)
            np.testing.assert_allclose(fc.joints, uz, atol=1e-15, err_msg=where)
            joints = finger.to_world(uz)
            # contact: the distal capsule touches the section
            dist, q_ref, s_ref = finger.link_pair(joints, 2)
            assert dist - finger.r == pytest.approx(0.0, abs=2e-10), where
            cp = np.array([fc.contact_point[0], fc.contact_point[2]])
            assert fc.contact_point[1] == pytest.approx(finger.base_y, abs=1e-15)
            # the returned point is on the boundary, at r from the distal segment: a
            # closest point (whether or not the closest pair is unique)
            rel = cp - finger.centre
            assert finger.section.boundary_distance(rel) < 1e-10, where
            assert not finger.section.inside(rel * (1 + 1e-7)), where
            assert finger.section.inside(rel * (1 - 1e-7)), where
            d_seg, t_seg = _segment_points(joints[2], joints[3], cp[None])
            assert d_seg[0] == pytest.approx(finger.r, abs=2e-10), where
            # the object's outward normal points at the distal segment (eq. 4)
            n = np.array([fc.normal_object[0], fc.normal_object[2]])
            assert fc.normal_object[1] == pytest.approx(0.0, abs=1e-15)
            assert np.hypot(*n) == pytest.approx(1.0, abs=1e-12)
            seg_point = joints[2] + t_seg[0] * (joints[3] - joints[2])
            np.testing.assert_allclose(n, (seg_point - cp) / finger.r, atol=1e-7, err_msg=where)
            np.testing.assert_allclose(fc.normal_finger, -fc.normal_object)
            assert fc.on_fingertip == (t_seg[0] > 1.0 - 1e-9), where
            if _unique_foot(finger.section, joints[2] - finger.centre,
                            joints[3] - finger.centre, dist):
                np.testing.assert_allclose(cp, q_ref, atol=1e-8, err_msg=where)
                np.testing.assert_allclose(n, (s_ref - q_ref) / dist, atol=1e-6,
                                           err_msg=where)
            # no other link penetrates the object, nothing goes through the table
            for link in (0, 1):
                assert finger.link_pair(joints, link)[0] >= finger.r - 1e-9, (where, link)
            assert float(joints[:, 1].min()) - finger.r >= 0.0, where


def test_the_pentagon_is_mirrored_for_the_opposing_finger():
    """An asymmetric section: finger 1 (facing -x) sees it mirrored, fingers 2 and 3 do not;
    the branches differ and each matches its own independent branch (test above)."""
    analyzer = analyzer_of('pentagon')
    assert analyzer.model.theta_s0[0] - analyzer.model.theta_s0[1] < -1e-3
    contacts = analyzer.spcm(math.radians(45.0))
    assert contacts[1].delta_theta_s == pytest.approx(contacts[2].delta_theta_s, abs=1e-15)
    assert abs(contacts[0].delta_theta_s - contacts[1].delta_theta_s) > 1e-2
    assert contacts[0].contact_point[0] > 0.0 > contacts[1].contact_point[0]


# --------------------------------------------------------------------------------------------
# (b) the sufficient condition, eq. (18), as a linear program on the friction cone's faces


def _cone_edges(normal_object: np.ndarray, axis: np.ndarray, alpha: float, faces: int
                ) -> np.ndarray:
    """(faces, 3) edges of the L-faced cone of eq. (7) about n_in = -n_CB: two edges in the
    finger plane at +-alpha, the others turned about n_in by 2 pi / L."""
    n_in = -normal_object / np.linalg.norm(normal_object)
    b = axis / np.linalg.norm(axis)
    t = np.cross(b, n_in)
    t /= np.linalg.norm(t)
    phi = 2 * math.pi * np.arange(faces) / faces
    return (math.cos(alpha) * n_in[None]
            + math.sin(alpha) * (np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * b))


def lp_worst_case(points, normals, bases, axes, tau, alpha, faces):
    """min sum_i f_iz subject to J_i . f_i = tau_i and f_i in the friction cone, with
    J_i = a_i x (p_Ci - p_si) (the moment of f_i about the compliant joint axis).

    The cone is written by its faces (m_k . f >= 0, m_k = e_k x e_k+1 turned inwards); a
    frictionless contact (alpha = 0) is the ray f = lambda n_in, lambda >= 0.
    Returns (status, value): 'optimal' | 'unbounded' | 'infeasible'.
    """
    n = len(points)
    jac = [np.cross(a, p - s) for a, p, s in zip(axes, points, bases, strict=True)]
    if alpha == 0.0:
        n_in = [-np.asarray(nv) for nv in normals]
        c = np.array([v[2] for v in n_in])
        a_eq = np.diag([float(j @ v) for j, v in zip(jac, n_in, strict=True)])
        res = linprog(c, A_eq=a_eq, b_eq=tau, bounds=[(0, None)] * n, method='highs')
    else:
        c = np.tile([0.0, 0.0, 1.0], n)
        a_eq = np.zeros((n, 3 * n))
        rows = []
        for i in range(n):
            a_eq[i, 3 * i:3 * i + 3] = jac[i]
            edges = _cone_edges(np.asarray(normals[i]), axes[i], alpha, faces)
            centre = edges.sum(axis=0)
            for k in range(faces):
                m = np.cross(edges[k], edges[(k + 1) % faces])
                if m @ centre < 0:
                    m = -m
                row = np.zeros(3 * n)
                row[3 * i:3 * i + 3] = -m
                rows.append(row)
        res = linprog(c, A_ub=np.array(rows), b_ub=np.zeros(len(rows)), A_eq=a_eq, b_eq=tau,
                      bounds=[(None, None)] * (3 * n), method='highs')
    status = {0: 'optimal', 2: 'infeasible', 3: 'unbounded'}[res.status]
    return status, (float(res.fun) if res.status == 0 else None)


LP_CASES = {
    'square_bar': (5.0, 15.0, 30.0, 45.0, 55.0),
    'elliptic_column': (5.0, 15.0, 30.0, 45.0),
    'big_hex': (5.0, 15.0, 30.0, 45.0, 55.0),
    'pentagon': (5.0, 20.0, 40.0),
    'hex_pencil': (5.0, 15.0),
}


@pytest.mark.parametrize('name', list(LP_CASES))
def test_sufficient_condition_against_a_per_point_lp(name):
    analyzer = analyzer_of(name)
    hand = RAW['hand']
    ratios = np.array([f['stiffness_ratio'] for f in hand['fingers']])
    weight = raw_entry(name)['mass_kg'] * RAW['task']['gravity_m_per_s2']
    faces = RAW['contact']['cone_faces']
    fingers = [Finger(name, i) for i in range(3)]
    bases = [np.array(f['base_position_m'], dtype=float) for f in hand['fingers']]
    axes = [f.axis for f in fingers]
    outcomes = {'guaranteed': 0, 'not': 0, 'unbounded': 0}
    for dp_deg in LP_CASES[name]:
        dp = math.radians(dp_deg)
        contacts = analyzer.spcm(dp)
        points = [fc.contact_point for fc in contacts]
        normals = [fc.normal_object for fc in contacts]
        # pressing into the object turns the compliant joint inward (positive torque)
        for fc, a, s in zip(contacts, axes, bases, strict=True):
            assert float(np.cross(a, fc.contact_point - s) @ -fc.normal_object) > 0.0
        for alpha_deg in (0.0, 5.0, 15.0, 30.0):
            alpha = math.radians(alpha_deg)
            for k_theta in (1.0, 10.0, 40.0):
                where = f'{name} dp {dp_deg} alpha {alpha_deg} k {k_theta}'
                result = analyzer.check_lift(k_theta, dp, alpha)
                k_i = k_theta * ratios / ratios[0]
                tau = k_i * -np.array([fc.delta_theta_s for fc in contacts])
                assert np.all(tau > 0.0)
                np.testing.assert_allclose(result.k_theta, k_i, rtol=1e-15)
                np.testing.assert_allclose(result.compliant_torque, tau, rtol=1e-12, atol=1e-15)
                np.testing.assert_allclose(result.contact_points, points, atol=1e-15)
                np.testing.assert_allclose(result.normals, normals, atol=1e-15)
                status, value = lp_worst_case(points, normals, bases, axes, tau, alpha, faces)
                if status == 'unbounded':
                    assert result.worst_case_margin == -math.inf, where
                    assert 'unbounded' in result.sufficient_status, where
                    assert not result.lift_guaranteed, where
                    outcomes['unbounded'] += 1
                    continue
                assert status == 'optimal', where
                assert result.sufficient_status == ('bounded',) * 3, where
                margin = value - weight
                assert result.worst_case_margin == pytest.approx(margin, rel=1e-7,
                                                                 abs=1e-9), where
                guaranteed = margin > 0.0
                # eq. 18 at rest; a section that can roll is then checked in its turned poses
                assert (result.lift_guaranteed or result.rolling_checked) == guaranteed, where
                assert guaranteed or not result.lift_guaranteed, where
                outcomes['guaranteed' if guaranteed else 'not'] += 1
    if name == 'big_hex':
        assert outcomes['guaranteed'] > 5 and outcomes['not'] > 5, outcomes


def test_lp_cases_cover_every_outcome():
    """The parametrised LP cases include unbounded worst cases (large friction angle)."""
    seen = []
    for name in ('square_bar', 'hex_pencil'):
        analyzer = analyzer_of(name)
        dp = math.radians(LP_CASES[name][-1])
        seen.append(analyzer.check_lift(10.0, dp, math.radians(30.0)).worst_case_margin)
    assert -math.inf in seen


# --------------------------------------------------------------------------------------------
# (c) regular N-gons of inradius R converge to the disc of radius R


def _circle_g_s(finger: Finger, fc) -> float:
    """d gap / d theta_s of the disc at a contact: rotating the finger about its compliant
    joint moves the closest segment point s (plane coordinates) with velocity (-s_z, s_u);
    the gap changes at the normal component."""
    n_xz = np.array([fc.normal_object[0], fc.normal_object[2]])
    s_xz = np.array([fc.contact_point[0], fc.contact_point[2]]) + finger.r * n_xz
    rel = s_xz - finger.base
    s_u, s_z = finger.sign * rel[0], rel[1]
    n_u, n_z = finger.sign * n_xz[0], n_xz[1]
    return n_u * -s_z + n_z * s_u


CONVERGENCE_DPS = (2.0, 5.0, 8.0, 12.0, 25.0, 40.0, 55.0)


def _lift_slope(k_star: np.ndarray) -> np.ndarray:
    """1 / k_theta* [rad/(N m)], 0 where no stiffness lifts (NaN boundary). Near the end of a
    region k* grows without bound, so its relative error is no measure of convergence; the
    slope of the margin in k_theta (eq. 18 is linear in k_theta) stays well conditioned."""
    return np.where(np.isnan(k_star), 0.0, 1.0 / k_star)


def test_regular_polygons_converge_to_the_cylinder():
    """Regular N-gons lying on a face with the cylinder's radius as inradius (same mass and
    length): the SPCM converges like the shape, R (1 / cos(pi / N) - 1); the contact normal,
    frozen along each face, like pi / N, and with it the lift boundaries."""
    dps = np.radians(CONVERGENCE_DPS)
    boundary_dps = np.radians(np.arange(1.0, 59.0, 2.0))
    alpha = math.radians(RAW['contact']['friction_angle_deg'])
    cylinder = analyzer_of('cylinder', coarse=True)
    finger = Finger('cylinder', 0)
    circle = [cylinder.spcm(d) for d in dps]
    g_s0 = _circle_g_s(finger, cylinder.spcm(0.0)[0])
    g_s = np.array([_circle_g_s(finger, c[0]) for c in circle])
    bound_c = cylinder.boundaries(alpha, boundary_dps)
    radius = RAW['object']['library']['cylinder']['radius_m']
    errors = {'spcm': [], 'normal': [], 'sufficient': [], 'csm': []}
    for n_sides in (32, 64, 128, 256):
        analyzer = analyzer_of(f'ngon{n_sides}', coarse=True)
        d_r = radius * (1 / math.cos(math.pi / n_sides) - 1)  # circumradius - inradius
        spcm_err, normal_err = 0.0, 0.0
        for j, d in enumerate(dps):
            poly = analyzer.spcm(d)
            for fc_p, fc_c in zip(poly, circle[j], strict=True):
                err = abs(fc_p.delta_theta_s - fc_c.delta_theta_s)
                # the N-gon lies between the discs of radius R and R + d_r, so its gap is
                # within d_r of the disc's: each root moves by at most d_r / |g_s|
                assert err <= 1.25 * d_r * (1 / abs(g_s[j]) + 1 / abs(g_s0)), (n_sides, j)
                spcm_err = max(spcm_err, err)
                # the normal turns by at most half an exterior angle against the direction
                # from the centre to the tip, which moves with the posture
                cos = float(fc_p.normal_object @ fc_c.normal_object)
                angle = math.acos(min(1.0, cos))
                tip_p = finger.joints_uz(fc_p.theta_s, fc_p.theta_p)[3]
                tip_c = finger.joints_uz(fc_c.theta_s, fc_c.theta_p)[3]
                moved = float(np.hypot(*(tip_p - tip_c))) / (radius + finger.r)
                assert angle <= math.pi / n_sides + 2 * moved + 1e-9, (n_sides, j, angle)
                normal_err = max(normal_err, angle)
        bound_p = analyzer.boundaries(alpha, boundary_dps)
        for key in ('sufficient', 'csm'):
            diff = _lift_slope(getattr(bound_p, key)) - _lift_slope(getattr(bound_c, key))
            errors[key].append(float(np.max(np.abs(diff))))
        errors['spcm'].append(spcm_err)
        errors['normal'].append(normal_err)
    for key, values in errors.items():
        assert all(b < a for a, b in zip(values, values[1:], strict=False)), (key, values)
    for key in ('normal', 'sufficient', 'csm'):  # first order in 1 / N
        assert errors[key][-1] < 0.7 * errors[key][-2], (key, errors[key])
    assert errors['spcm'][-1] < 2e-5  # rad
    assert errors['normal'][-1] < math.pi / 256 + 1e-4
    for key in ('sufficient', 'csm'):
        peak = float(np.max(_lift_slope(getattr(bound_c, key))))
        assert errors[key][-1] < 0.2 * peak, (key, errors[key], peak)


# --------------------------------------------------------------------------------------------
# (d) the generic (non-circle) path against the circle's closed forms


def test_nearly_circular_ellipse_matches_the_cylinder():
    """Semi-axes 10 mm and 10 mm (1 - 1e-9): the generic segment-distance path must give the
    cylinder's answers (closed forms) to within the 1e-11 m shape difference."""
    cylinder, ellipse = analyzer_of('cylinder'), analyzer_of('near_circle')
    np.testing.assert_allclose(ellipse.model.theta_s0, cylinder.model.theta_s0, atol=1e-9)
    for p_e, p_c in zip(ellipse.table.paths, cylinder.table.paths, strict=True):
        assert p_e.valid_until == pytest.approx(p_c.valid_until, abs=1e-7)
        assert p_e.end.kind == p_c.end.kind
    dps = np.radians([0.0, 3.0, 10.0, 25.0, 40.0, 55.0, 61.0])
    for d in dps:
        for f_e, f_c in zip(ellipse.spcm(d), cylinder.spcm(d), strict=True):
            assert f_e.delta_theta_s == pytest.approx(f_c.delta_theta_s, abs=1e-8)
            np.testing.assert_allclose(f_e.contact_point, f_c.contact_point, atol=1e-9)
            np.testing.assert_allclose(f_e.normal_object, f_c.normal_object, atol=1e-7)
            assert f_e.on_fingertip == f_c.on_fingertip
            assert f_e.dtheta_s_dtheta_p == pytest.approx(f_c.dtheta_s_dtheta_p, rel=1e-6)
        for alpha_deg in (0.0, 5.0, 20.0):
            for k_theta in (2.0, 10.0, 40.0):
                r_e = ellipse.check_lift(k_theta, d, math.radians(alpha_deg))
                r_c = cylinder.check_lift(k_theta, d, math.radians(alpha_deg))
                where = (math.degrees(d), alpha_deg, k_theta)
                assert r_e.lift_guaranteed == r_c.lift_guaranteed, where
                assert r_e.csm_lift == r_c.csm_lift, where
                assert r_e.sufficient_status == r_c.sufficient_status, where
                for a, b in ((r_e.worst_case_margin, r_c.worst_case_margin),
                             (r_e.csm_margin, r_c.csm_margin)):
                    if math.isfinite(b):
                        assert a == pytest.approx(b, rel=1e-6, abs=1e-8), where
                    else:
                        assert a == b or (math.isnan(a) and math.isnan(b)), where
                np.testing.assert_allclose(r_e.csm_forces, r_c.csm_forces, rtol=1e-5,
                                           atol=1e-8)
    b_e = ellipse.boundaries(math.radians(5.0), dps[1:])
    b_c = cylinder.boundaries(math.radians(5.0), dps[1:])
    np.testing.assert_allclose(b_e.sufficient, b_c.sufficient, rtol=1e-6)
    np.testing.assert_allclose(b_e.csm, b_c.csm, rtol=1e-6)
