"""Contact stiffness model (module csm): spring-slider, torque balance, the paper's ordering."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_analysis.csm import CsmPath, csm_forces_grid, csm_forces_sequential


def _synthetic(slip, tau_hat=1.0, h_n=1.0, h_t=0.0, cz_n=0.0, cz_t=1.0):
    m = len(slip)
    full = np.ones(m)
    return CsmPath(delta_theta_p=np.arange(m, dtype=float), tau_hat=tau_hat * full,
                   h_n=h_n * full, h_t=h_t * full, cz_n=cz_n * full, cz_t=cz_t * full,
                   slip=np.asarray(slip, dtype=float))


def test_spring_slider_by_hand():
    """Stick, slide, unload elastically, slide back: hand-computed play-operator values."""
    mu = 0.15
    path = _synthetic([0.0, 1e-6, 2e-6, 1e-6, -3e-6])
    f_n, f_t, sep = csm_forces_sequential(path, np.array([1.0]), math.atan(mu), 1e5)
    np.testing.assert_allclose(f_n[0], 1.0)
    np.testing.assert_allclose(f_t[0], [0.0, 0.1, 0.15, 0.05, -0.15], atol=1e-12)
    assert not sep.any()


def test_torque_balance_with_tangential_force():
    """tau = h_n f_n + h_t f_t at every node, stick or slide."""
    rng = np.random.default_rng(5)
    m = 60
    path = CsmPath(delta_theta_p=np.arange(m, dtype=float),
                   tau_hat=np.linspace(0.0, 0.2, m), h_n=rng.uniform(0.05, 0.09, m),
                   h_t=rng.uniform(-0.03, 0.03, m), cz_n=rng.uniform(0.0, 0.3, m),
                   cz_t=rng.uniform(-1.0, 1.0, m), slip=np.cumsum(rng.normal(0, 2e-6, m)))
    k = np.array([0.1, 1.0, 10.0])
    mu = math.tan(math.radians(10))
    f_n, f_t, _ = csm_forces_sequential(path, k, math.atan(mu), 1e5)
    np.testing.assert_allclose(path.h_n * f_n + path.h_t * f_t, k[:, None] * path.tau_hat,
                               atol=1e-12)
    assert np.all(np.abs(f_t) <= mu * f_n * (1 + 1e-9) + 1e-15)


@pytest.mark.parametrize('alpha_deg', [1.0, 5.0, 30.0])
def test_closed_form_equals_sequential_on_default_path(analyzer, alpha_deg):
    k_t = float(analyzer.model.contact_stiffness[1])
    for i in range(analyzer.n_fingers):
        path = analyzer.table.csm_path(i)
        valid = np.isfinite(path.tau_hat)
        path = CsmPath(*[np.asarray(getattr(path, f))[valid] for f in
                         ('delta_theta_p', 'tau_hat', 'h_n', 'h_t', 'cz_n', 'cz_t', 'slip')])
        assert path.monotone
        k = np.array([1e-3, 0.05, 0.5, 5.0, 50.0])
        a = csm_forces_grid(path, k, math.radians(alpha_deg), k_t)
        b = csm_forces_sequential(path, k, math.radians(alpha_deg), k_t)
        for x, y in zip(a, b, strict=True):
            np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-12)


def test_closed_form_equals_sequential_with_stick_phases():
    """Tiny, varying slip and a soft tangential spring: long stick phases, caps that shrink."""
    rng = np.random.default_rng(8)
    m = 200
    path = CsmPath(delta_theta_p=np.arange(m, dtype=float),
                   tau_hat=np.abs(np.sin(np.linspace(0, 6, m))) * 0.1,
                   h_n=rng.uniform(0.05, 0.09, m), h_t=rng.uniform(-0.03, 0.03, m),
                   cz_n=rng.uniform(0.0, 0.3, m), cz_t=rng.uniform(-1.0, 1.0, m),
                   slip=-np.cumsum(rng.uniform(0.0, 1e-6, m)))
    k = np.geomspace(0.01, 100.0, 9)
    for alpha in (0.01, 0.1, 0.5):
        a = csm_forces_grid(path, k, alpha, 1e3)
        b = csm_forces_sequential(path, k, alpha, 1e3)
        for x, y in zip(a, b, strict=True):
            np.testing.assert_allclose(x, y, rtol=1e-9, atol=1e-12)


def test_csm_force_is_admissible_and_balances_the_torque(analyzer):
    """check_lift's CSM force: inside the cone, tau_s = J^T f_c, friction along the slip."""
    rng = np.random.default_rng(21)
    model = analyzer.model
    for _ in range(40):
        dp = rng.uniform(0.01, math.radians(60))
        k = rng.uniform(0.05, 20.0)
        alpha = rng.uniform(0.0, math.radians(40))
        r = analyzer.check_lift(k, dp, alpha)
        for i, g in enumerate(model.fingers):
            f = r.csm_forces[i]
            jac = np.cross(g.joint_axis, r.contact_points[i] - g.base_position)
            assert jac @ f == pytest.approx(r.compliant_torque[i], rel=1e-9, abs=1e-12)
            f_n = -f @ r.normals[i]
            f_t = np.linalg.norm(f + f_n * r.normals[i])
            assert f_n > 0.0
            assert f_t <= math.tan(alpha) * f_n * (1 + 1e-9) + 1e-12
            # sliding friction on the object points along the finger's slip (grid history)
            slip_sign = analyzer.table.csm_path(i).slip_sign
            t = np.cross(g.joint_axis, r.normals[i])
            if f_t > 1e-12:
                assert np.sign(f @ t) == slip_sign


def test_csm_is_milder_than_the_worst_case(analyzer):
    """Paper: the CSM force is one admissible force, so its lift is >= the worst case."""
    rng = np.random.default_rng(99)
    for _ in range(200):
        dp = rng.uniform(0.0, math.radians(60))
        k = rng.uniform(0.01, 30.0, 3)
        alpha = rng.uniform(0.0, math.radians(45))
        r = analyzer.check_lift(k, dp, alpha)
        assert r.csm_margin >= r.worst_case_margin - 1e-9
        if r.lift_guaranteed:
            assert r.csm_lift
