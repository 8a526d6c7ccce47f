"""Sufficient lift condition, eqs. (5)-(18) (module lift), against independent LPs."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import linprog
from scipy.spatial.transform import Rotation

from dam_analysis.lift import (
    compliant_jacobian,
    enumerate_worst_case,
    grasp_matrix_t,
    h_matrix,
    null_space_basis,
    span_vectors,
    worst_case_vertical_force,
)

AXIS = np.array([0.0, -1.0, 0.0])


def _random_finger(rng):
    """Random planar contact: joint position, contact point and object normal (x-z plane)."""
    base = np.array([rng.uniform(-0.1, 0.1), 0.0, rng.uniform(0.0, 0.15)])
    point = np.array([rng.uniform(-0.05, 0.05), 0.0, rng.uniform(0.0, 0.05)])
    ang = rng.uniform(0, 2 * math.pi)
    normal = np.array([math.cos(ang), 0.0, math.sin(ang)])
    return base, point, normal


def _lp_reference(jacobians, span, tau):
    """min c_z^T sum f_ci s.t. J_i^T f_ci = tau_i, f_ci in the polyhedral cone.

    The cone is written by its FACES (H-representation: m_k^T f >= 0 with m_k = v^k x v^k+1),
    not by its span vectors, so the LP is independent of the parametrisation under test.
    """
    n = len(span)
    c = np.zeros(3 * n)
    a_eq = np.zeros((n, 3 * n))
    a_ub = []
    for i, v in enumerate(span):
        c[3 * i + 2] = 1.0
        a_eq[i, 3 * i:3 * i + 3] = jacobians[i]
        n_faces = v.shape[1]
        centre = v.sum(axis=1)
        for k in range(n_faces):
            m = np.cross(v[:, k], v[:, (k + 1) % n_faces])
            if m @ centre < 0:
                m = -m
            row = np.zeros(3 * n)
            row[3 * i:3 * i + 3] = -m
            a_ub.append(row)
    res = linprog(c, A_ub=np.array(a_ub), b_ub=np.zeros(len(a_ub)), A_eq=a_eq, b_eq=tau,
                  bounds=[(None, None)] * (3 * n), method='highs')
    return res


def _case(rng, n, n_faces, alpha=None):
    alpha = rng.uniform(0.0, math.radians(60)) if alpha is None else alpha
    jac, span, h, c = [], [], [], []
    for _ in range(n):
        base, point, normal = _random_finger(rng)
        j = compliant_jacobian(AXIS, point, base)
        v = span_vectors(normal, AXIS, alpha, n_faces)
        jac.append(j)
        span.append(v)
        h.append(j @ v)
        c.append(v[2])
    return np.array(jac), span, np.array(h), np.array(c), alpha


def test_fast_worst_case_equals_lp_on_random_cases():
    rng = np.random.default_rng(12345)
    seen = {'bounded': 0, 'unbounded': 0, 'infeasible': 0}
    for trial in range(300):
        n = int(rng.integers(1, 4))
        n_faces = int(rng.choice([4, 6, 8, 12]))
        jac, span, h, c, _ = _case(rng, n, n_faces)
        tau = rng.normal(0.0, 0.2, n)
        if trial % 10 == 0:
            tau[0] = 0.0
        worst = worst_case_vertical_force(h, c, tau)
        res = _lp_reference(jac, span, tau)
        statuses = set(worst.status)
        if 'infeasible' in statuses:
            assert res.status == 2, (trial, res.message)
            seen['infeasible'] += 1
        elif 'unbounded' in statuses:
            assert res.status == 3, (trial, res.message)
            assert worst.total == -math.inf
            seen['unbounded'] += 1
        else:
            assert res.status == 0, (trial, res.message)
            assert worst.total == pytest.approx(res.fun, rel=1e-7, abs=1e-9)
            seen['bounded'] += 1
    # the randomised cases really exercise all three outcomes
    assert min(seen.values()) >= 10, seen


def test_literal_enumeration_eqs_14_17_equals_lp_when_bounded():
    rng = np.random.default_rng(7)
    checked = 0
    while checked < 25:
        n = int(rng.integers(1, 4))
        n_faces = 6 if n == 3 else 8
        jac, span, h, c, _ = _case(rng, n, n_faces)
        tau = np.abs(rng.normal(0.0, 0.2, n))
        res = _lp_reference(jac, span, tau)
        if res.status != 0:
            continue
        best, count = enumerate_worst_case(jac, span, tau)
        assert count > 0
        assert best == pytest.approx(res.fun, rel=1e-7, abs=1e-9)
        worst = worst_case_vertical_force(h, c, tau)
        assert worst.total == pytest.approx(best, rel=1e-7, abs=1e-9)
        checked += 1


def test_enumeration_misses_unbounded_case_the_fast_path_detects():
    """Cone containing the joint-to-contact line: eqs. 14-17 give a finite number, LP -inf."""
    base = np.array([0.0, 0.0, 0.1])
    point = np.array([0.0, 0.0, 0.0])  # straight below the joint
    normal = np.array([0.2, 0.0, 1.0]) / math.hypot(0.2, 1.0)  # n_in almost along the link
    alpha = math.radians(30)
    jac = np.array([compliant_jacobian(AXIS, point, base)])
    v = span_vectors(normal, AXIS, alpha, 8)
    tau = np.array([0.1])
    res = _lp_reference(jac, [v], tau)
    assert res.status == 3  # unbounded
    worst = worst_case_vertical_force(np.array([jac[0] @ v]), v[2][None, :], tau)
    assert worst.status[0] == 'unbounded' and worst.total == -math.inf
    best, count = enumerate_worst_case(jac, [v], tau)
    assert count > 0 and math.isfinite(best)


def test_span_vectors_geometry():
    normal = np.array([0.6, 0.0, -0.8])
    for n_faces in (4, 8, 10):
        for alpha in (0.0, math.radians(5), math.radians(30)):
            v = span_vectors(normal, AXIS, alpha, n_faces)
            assert v.shape == (3, n_faces)
            np.testing.assert_allclose(np.linalg.norm(v, axis=0), 1.0)
            # every edge makes the friction angle with the inward normal
            np.testing.assert_allclose(v.T @ -normal, math.cos(alpha), atol=1e-12)
            if alpha == 0.0:
                continue
            # two edges lie in the finger plane (no y component), at +-alpha
            in_plane = np.abs(v[1]) < 1e-12
            assert in_plane.sum() == 2
            t = np.cross(AXIS, normal)
            angles = sorted(math.atan2(e @ t, e @ -normal) for e in v.T[in_plane])
            np.testing.assert_allclose(angles, [-alpha, alpha], atol=1e-12)


def test_jacobian_by_virtual_work():
    """tau = J^T f equals the work rate of f when the joint turns (finite difference)."""
    rng = np.random.default_rng(3)
    for _ in range(20):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        joint = rng.normal(size=3)
        point = rng.normal(size=3)
        f = rng.normal(size=3)
        eps = 1e-7
        moved = Rotation.from_rotvec(eps * axis).apply(point - joint) + joint
        assert compliant_jacobian(axis, point, joint) @ f == pytest.approx(
            (moved - point) @ f / eps, rel=1e-5, abs=1e-9)


def test_grasp_matrix_eq_5():
    points = np.array([[0.01, 0.0, 0.005], [-0.01, 0.01, 0.002]])
    centre = np.array([0.0, 0.0, 0.01])
    f = np.array([1.0, 2.0, 3.0, -1.0, 0.5, 2.0])
    w = grasp_matrix_t(points, centre) @ f
    np.testing.assert_allclose(w[:3], f[:3] + f[3:])
    moment = np.cross(points[0] - centre, f[:3]) + np.cross(points[1] - centre, f[3:])
    np.testing.assert_allclose(w[3:], moment)


def test_h_and_null_space():
    rng = np.random.default_rng(11)
    jac, span, _, _, _ = _case(rng, 3, 8)
    h = h_matrix(jac, span)
    assert h.shape == (3, 24)
    null = null_space_basis(h)
    assert null.shape == (24, 21)
    np.testing.assert_allclose(h @ null, 0.0, atol=1e-12)
    assert np.linalg.matrix_rank(null) == 21
    # eq. 10: lambda = H^# tau + N Phi reproduces tau for any Phi
    tau = rng.normal(size=3)
    lam = np.linalg.pinv(h) @ tau + null @ rng.normal(size=21)
    np.testing.assert_allclose(h @ lam, tau, atol=1e-12)
