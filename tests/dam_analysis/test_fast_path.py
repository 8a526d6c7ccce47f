"""The scalar fast path of ``LiftAnalyzer.check_lift`` against independent references.

References: the SPCM solved with the numpy-era functions ``newton_theta_s`` / ``distal_gap`` /
``posture_problem`` / ``contact_state``; the worst case with the vectorised
``worst_case_vertical_force`` (itself tested against an LP in test_lift) and the literal 3-D
span vectors and Jacobians of eqs. 7-11; the CSM with the vectorised ``csm_evaluate`` of the
map functions.
"""

from __future__ import annotations

import dataclasses
import math
import pickle

import numpy as np
import pytest
from scipy.optimize import brentq

from dam_analysis.analysis import LiftResult, check_delta_theta_p, check_k_theta
from dam_analysis.errors import InputError, NoSolutionError
from dam_analysis.lift import (
    compliant_jacobian,
    span_vectors,
    worst_case_cone,
    worst_case_vertical_force,
)
from dam_analysis.model import distal_gap
from dam_analysis.regions import csm_evaluate, finger_table
from dam_analysis.spcm import (
    SpcmPath,
    contact_state,
    newton_theta_s,
    plane_contact,
    posture_problem,
)

THETA_TOL = 1e-10  # [rad]; the Newton tolerance |gap| < 1e-13 m allows ~1e-11 rad


def _reference_theta_s(model, path, dp: float) -> float | None:
    """theta_s by damped Newton from the linearly interpolated branch (None: no solution);
    between the last valid grid node and the branch end by Brent's method on the gap."""
    if dp > path.valid_until:
        return None
    last = path.last_node
    if dp > path.delta_theta_p[last]:
        return _reference_tail_theta_s(model, path, dp)
    grid, nodes, step = path.delta_theta_p, path.theta_s, path.step
    j = min(int(dp / step), len(grid) - 2)
    frac = (dp - grid[j]) / step
    guess = float(nodes[j] + frac * (nodes[j + 1] - nodes[j])) if frac > 0.0 else float(nodes[j])
    if not math.isfinite(guess):
        guess = float(nodes[j])
    theta_p = model.theta_p0 + dp
    sol = newton_theta_s(path.geometry, model.theta_l0, theta_p, guess)
    if sol is None or abs(sol - guess) > 10.0 * step:
        return None
    sol = path.theta_s0 if dp == 0.0 else min(sol, path.theta_s0)
    if posture_problem(path.geometry, sol, model.theta_l0, theta_p, path.theta_s0,
                       model.limits_s, model.limits_p) is not None:
        return None
    return sol


def _reference_tail_theta_s(model, path, dp: float) -> float | None:
    theta_p = model.theta_p0 + dp

    def gap(theta_s: float) -> float:
        return distal_gap(path.geometry, theta_s, model.theta_l0, theta_p)[0]

    lo, hi = float(path.theta_s[path.last_node]), path.end.theta_s
    if gap(lo) * gap(hi) > 0.0:  # at the fold itself the root is double
        sol = hi if abs(gap(hi)) < 1e-13 else None
    else:
        sol = brentq(gap, lo, hi, xtol=1e-16, rtol=1e-15)
    if sol is None or posture_problem(path.geometry, sol, model.theta_l0, theta_p,
                                      path.theta_s0, model.limits_s, model.limits_p):
        return None
    return sol


def _random_displacements(rng, path, count: int) -> list[float]:
    end = path.valid_until
    out = [0.0, end, end + 0.5e-12, end + 1e-9, end + math.radians(1.0),
           float(path.delta_theta_p[7]), float(path.delta_theta_p[-1])]
    out += rng.uniform(0.0, path.model.delta_theta_p_max, count).tolist()
    out += (end - rng.uniform(0.0, 20 * path.step, count // 4)).tolist()  # near the fold
    out += (rng.integers(0, 200, count // 8) * path.step).tolist()  # on (or at) grid nodes
    return out


def test_plane_state_equals_newton_reference(analyzer):
    """theta_s and the contact within 1e-10 of the reference; the same requests fail."""
    model = analyzer.model
    rng = np.random.default_rng(21)
    solved = failed = 0
    for i, path in enumerate(analyzer.table.paths):
        for dp in _random_displacements(rng, path, 400):
            ref = _reference_theta_s(model, path, dp)
            if ref is None:
                with pytest.raises(NoSolutionError, match=f'finger {i + 1}'):
                    path.plane_state(dp)
                failed += 1
                continue
            theta_s, p_u, p_z, n_u, n_z, tip = path.plane_state(dp)
            assert theta_s == pytest.approx(ref, abs=THETA_TOL), (i, dp)
            r_u, r_z, rn_u, rn_z, r_tip = plane_contact(model.fingers[i], ref, model.theta_l0,
                                                        model.theta_p0 + dp)
            np.testing.assert_allclose([p_u, p_z, n_u, n_z], [r_u, r_z, rn_u, rn_z],
                                       rtol=0.0, atol=1e-10)
            assert path.solve_theta_s(dp) == theta_s
            solved += 1
    assert solved > 1000 and failed > 20


def _reason(problem: str | None) -> str:
    if problem is None:
        return 'ok'
    for key in ('contact lost', 'compliant joint limit', 'position joint limit', 'table',
                'proximal'):
        if key in problem:
            return key
    raise AssertionError(problem)


def test_fast_posture_check_equals_posture_problem(analyzer):
    """Every posture the fast check accepts posture_problem accepts, and vice versa, on the
    default finger, one lowered towards the table and one with the object on link 1."""
    model = analyzer.model
    g = model.fingers[0]
    geometries = [g, dataclasses.replace(g, base_height=g.base_height - 0.01),
                  dataclasses.replace(g, object_center=np.array([0.0, -0.03]))]
    rng = np.random.default_rng(5)
    reasons: dict[str, int] = {}
    for geometry in geometries:
        hand = dataclasses.replace(model, fingers=(geometry, *model.fingers[1:]))
        path = SpcmPath(hand, 0, step=math.radians(5.0))
        ts0 = path.theta_s0
        for _ in range(3000):
            theta_s = rng.uniform(model.limits_s[0] - 0.1, model.limits_s[1] + 0.1)
            theta_p = rng.uniform(model.limits_p[0] - 0.1, model.limits_p[1] + 0.1)
            if rng.random() < 0.05:  # at the rest angle, up to the 1e-12 rad tolerance
                theta_s = ts0 + float(rng.choice([0.0, 1e-12, 2e-12]))
            problem = posture_problem(geometry, theta_s, model.theta_l0, theta_p, ts0,
                                      model.limits_s, model.limits_p)
            state = path._checked_contact(theta_s, theta_p)
            assert (state is None) == (problem is not None), (theta_s, theta_p, problem)
            reasons[_reason(problem)] = reasons.get(_reason(problem), 0) + 1
            if state is not None:
                assert state == plane_contact(geometry, theta_s, model.theta_l0, theta_p)
    assert min(reasons.values()) >= 20 and len(reasons) == 6, reasons


def test_worst_case_cone_equals_vectorised_version():
    """Random planar contacts (as eq. 7 gives them), zero torques and degenerate cones."""
    rng = np.random.default_rng(99)
    seen: dict[str, int] = {}
    for trial in range(4000):
        n_faces = int(rng.choice([3, 4, 6, 8, 12]))
        cos_phi = np.cos(2.0 * np.pi * np.arange(n_faces) / n_faces)
        alpha = rng.uniform(0.0, math.radians(70.0)) if trial % 9 else 0.0
        ca, sa = math.cos(alpha), math.sin(alpha)
        h_n, h_t = rng.normal(0.0, 0.05, 2)  # J^T n_in, J^T t [m]
        angle = rng.uniform(0.0, 2.0 * math.pi)
        cz_n, cz_t = math.cos(angle), math.sin(angle)  # vertical parts of n_in and t
        if trial % 50 == 0:
            h_n = h_t = 0.0
        elif trial % 50 == 1:
            h_t = 0.0
        elif trial % 5 == 2 and alpha > 0.0:  # one face's torque tiny but not zero
            x_k = float(cos_phi[rng.integers(n_faces)])
            tiny = float(rng.choice([1e-14, 1e-11, 1e-9, 1e-7])) * abs(sa * h_t)
            h_n = (tiny - sa * h_t * x_k) / ca
        tau = float(rng.normal(0.0, 0.2)) if trial % 7 else 0.0
        h = ca * h_n + sa * h_t * cos_phi  # as the numpy version of check_lift built them
        c = ca * cz_n + sa * cz_t * cos_phi
        ref = worst_case_vertical_force(h[None, :], c[None, :], np.array([tau]))
        value, status = worst_case_cone(ca * h_n, sa * h_t, ca * cz_n, sa * cz_t,
                                        cos_phi.tolist(), tau)
        assert status == ref.status[0], trial
        assert value == ref.value[0], (trial, value, ref.value[0])
        seen[status] = seen.get(status, 0) + 1
    assert min(seen.values()) >= 50 and len(seen) == 3, seen


def _reference_check_lift(analyzer, k, dp, alpha):
    """The request recomputed with the numpy functions (3-D contacts, span vectors, CSM)."""
    model = analyzer.model
    contacts = []
    for i, path in enumerate(analyzer.table.paths):
        theta_s = _reference_theta_s(model, path, dp[i])
        if theta_s is None:
            return None
        contacts.append(contact_state(model.fingers[i], theta_s, model.theta_l0,
                                      model.theta_p0 + dp[i], path.theta_s0))
    d_s = np.array([fc.delta_theta_s for fc in contacts])
    tau = -k * d_s
    h, c = [], []
    for fc, g in zip(contacts, model.fingers, strict=True):
        jac = compliant_jacobian(g.joint_axis, fc.contact_point, g.base_position)
        v = span_vectors(fc.normal_object, g.joint_axis, alpha, model.cone_faces)
        h.append(jac @ v)
        c.append(v[2])
    worst = worst_case_vertical_force(np.array(h), np.array(c), tau)
    fz, sep = 0.0, False
    for i, fc in enumerate(contacts):
        end = finger_table(model, i, [fc], np.array([dp[i]]))
        ev = csm_evaluate(analyzer.table, i, end, np.array([k[i]]), alpha)
        fz += float(ev.fz[0, 0])
        sep = sep or bool(ev.separated[0, 0])
    return {'worst': worst.total - model.object_weight, 'status': tuple(worst.status),
            'csm': math.nan if sep else fz - model.object_weight, 'delta_theta_s': d_s,
            'points': np.array([fc.contact_point for fc in contacts]),
            'normals': np.array([fc.normal_object for fc in contacts]),
            'tip': np.array([fc.on_fingertip for fc in contacts])}


def _close(a: float, b: float) -> bool:
    if math.isnan(a) or math.isnan(b):
        return math.isnan(a) and math.isnan(b)
    return a == b or math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-12)


def test_check_lift_equals_numpy_reference_on_random_requests(analyzer):
    rng = np.random.default_rng(2024)
    model = analyzer.model
    n = analyzer.n_fingers
    dp_max = model.delta_theta_p_max
    end = min(p.valid_until for p in analyzer.table.paths)
    fixed_alphas = np.radians([1.0, 5.0, 30.0]).tolist() + [-1.0]
    counts = {'ok': 0, 'no_solution': 0, 'unbounded': 0, 'csm_sep': 0, 'guaranteed': 0,
              'stick': 0}
    for trial in range(500):
        k_in = float(rng.uniform(0.02, 20.0)) if trial % 2 else rng.uniform(0.02, 20.0, n).tolist()
        if trial % 5 == 4:  # stiff enough for the CSM contact to stick (slide cap > slip)
            k_in = (np.asarray(k_in) * 10.0 ** rng.uniform(2.0, 5.0)).tolist()
        if trial % 3 == 0:  # one in six beyond the end of the SPCM branch
            dp_in = float(rng.uniform(0.0, dp_max) if trial % 2 else rng.uniform(end, dp_max))
        elif trial % 3 == 1:
            dp_in = rng.uniform(0.0, end, n).tolist()
        else:
            dp_in = float(end - rng.uniform(0.0, math.radians(0.5)))
        alpha_in = (float(rng.choice(fixed_alphas)) if trial % 4 else
                    float(rng.uniform(0.0, math.radians(45.0))))  # fresh friction angles
        k = check_k_theta(k_in, model.stiffness_ratios)
        dp = check_delta_theta_p(dp_in, n, dp_max)
        alpha = model.friction_angle if alpha_in < 0.0 else alpha_in
        ref = _reference_check_lift(analyzer, k, dp.tolist(), alpha)
        if ref is None:  # beyond the end of a branch: a "no lift" answer, not an error
            r = analyzer.check_lift(k_in, dp_in, alpha_in)
            assert not r.lift_guaranteed and not r.csm_lift, trial
            assert math.isnan(r.worst_case_margin) and math.isnan(r.csm_margin), trial
            beyond = np.array([d > p.valid_until for p, d in zip(analyzer.table.paths, dp,
                                                                    strict=True)])
            np.testing.assert_array_equal(r.beyond_branch, beyond)
            assert np.all(np.isnan(r.delta_theta_s[beyond]))
            assert np.all(np.isfinite(r.delta_theta_s[~beyond]))
            first = int(np.argmax(beyond))
            assert f'finger {first + 1}: no SPCM solution' in r.branch_message
            counts['no_solution'] += 1
            continue
        r = analyzer.check_lift(k_in, dp_in, alpha_in)
        assert not r.beyond_branch.any() and r.branch_message == '', trial
        assert r.sufficient_status == ref['status'], trial
        assert _close(r.worst_case_margin, ref['worst']), (trial, r.worst_case_margin, ref)
        assert _close(r.csm_margin, ref['csm']), (trial, r.csm_margin, ref['csm'])
        if abs(ref['worst']) > 1e-9:
            assert r.lift_guaranteed == (ref['worst'] > 0.0 and
                                         set(ref['status']) == {'bounded'})
        if not math.isnan(ref['csm']) and abs(ref['csm']) > 1e-9:
            assert r.csm_lift == (ref['csm'] > 0.0)
        np.testing.assert_allclose(r.delta_theta_s, ref['delta_theta_s'], rtol=0.0,
                                   atol=THETA_TOL)
        np.testing.assert_allclose(r.compliant_torque, -k * ref['delta_theta_s'], rtol=1e-9,
                                   atol=1e-12)
        np.testing.assert_allclose(r.contact_points, ref['points'], rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(r.normals, ref['normals'], rtol=0.0, atol=1e-10)
        np.testing.assert_array_equal(r.on_fingertip, ref['tip'])
        np.testing.assert_array_equal(r.k_theta, k)
        np.testing.assert_array_equal(r.delta_theta_p, dp)
        assert r.friction_angle == alpha
        assert r.csm_separation.any() == math.isnan(ref['csm'])
        if not r.csm_separation.any():  # the CSM forces add up to the CSM margin
            assert r.csm_forces[:, 2].sum() - model.object_weight == pytest.approx(
                r.csm_margin, rel=1e-9, abs=1e-12)
        # sticking contacts: |f_t| below the friction limit mu f_n
        f_n = -np.einsum('ij,ij->i', r.csm_forces, r.normals)
        f_t = np.linalg.norm(r.csm_forces + f_n[:, None] * r.normals, axis=1)
        counts['stick'] += bool(np.any(f_t < math.tan(alpha) * f_n * (1.0 - 1e-9)))
        counts['ok'] += 1
        counts['unbounded'] += 'unbounded' in r.sufficient_status
        counts['csm_sep'] += bool(r.csm_separation.any())
        counts['guaranteed'] += r.lift_guaranteed
    assert counts['ok'] > 300 and counts['no_solution'] > 20, counts
    assert counts['unbounded'] > 10 and counts['guaranteed'] > 10, counts
    assert counts['stick'] > 10 and counts['stick'] < counts['ok'] - 100, counts


def test_lift_result_keeps_its_fields_and_builds_contact_arrays_on_demand(analyzer):
    r = analyzer.check_lift([1.0, 0.6, 0.7], math.radians(25.0), math.radians(10.0))
    names = [f.name for f in dataclasses.fields(LiftResult)]
    assert names[:7] == ['lift_guaranteed', 'worst_case_margin', 'sufficient_status',
                         'csm_lift', 'csm_margin', 'csm_separation', 'csm_forces']
    assert 'contact_points' in names and 'normals' in names and 'on_fingertip' in names
    assert 'contact_points' not in vars(r)  # not built yet
    assert r.contact_points.shape == (3, 3) and r.normals.shape == (3, 3)
    assert r.csm_forces.shape == (3, 3) and r.csm_separation.dtype == bool
    assert r.on_fingertip.dtype == bool
    np.testing.assert_allclose(np.linalg.norm(r.normals, axis=1), 1.0, rtol=1e-14)
    # every reading gives the same array; copies, pickling and replace keep the values
    assert r.contact_points is r.contact_points
    same = dataclasses.replace(r)
    np.testing.assert_array_equal(same.csm_forces, r.csm_forces)
    back = pickle.loads(pickle.dumps(analyzer.check_lift([1.0, 0.6, 0.7], math.radians(25.0),
                                                         math.radians(10.0))))
    np.testing.assert_array_equal(back.normals, r.normals)
    assert back.worst_case_margin == r.worst_case_margin
    with pytest.raises(AttributeError, match='no_such_field'):
        _ = r.no_such_field
    # an ordinary instance (all fields given) still works
    plain = LiftResult(**{name: getattr(r, name) for name in names})
    np.testing.assert_array_equal(plain.contact_points, r.contact_points)


@pytest.mark.parametrize('k_in, dp_in, alpha_in', [
    (0.8, 0.3, 0.1), (np.float64(0.8), np.float64(0.3), np.float64(0.1)),
    (np.array([0.8]), np.array([0.3, 0.3, 0.3]), np.array(0.1)), ((0.8, 0.4, 0.4), (0.3,), 0.1),
    ([1, 2, 3], [0.3, 0.2, 0.1], -1), ([True], 0.3, 0.0), (2, 0, 0.1)])
def test_input_types_give_the_same_answer_as_validated_lists(analyzer, k_in, dp_in, alpha_in):
    k, dp, alpha = analyzer.validate(k_in, dp_in, alpha_in)
    a = analyzer.check_lift(k_in, dp_in, alpha_in)
    b = analyzer.check_lift(k.tolist(), dp.tolist(), alpha)
    assert a.worst_case_margin == b.worst_case_margin
    assert a.sufficient_status == b.sufficient_status
    assert _close(a.csm_margin, b.csm_margin)
    np.testing.assert_array_equal(a.k_theta, k)
    np.testing.assert_array_equal(a.delta_theta_p, dp)
    assert a.k_theta.dtype == np.float64 and a.delta_theta_p.dtype == np.float64


@pytest.mark.parametrize('k_in, dp_in, alpha_in', [
    ([], 0.3, 0.1), ([0.8, 0.4], 0.3, 0.1), (0.0, 0.3, 0.1), ([0.8, -0.4, 0.4], 0.3, 0.1),
    (math.nan, 0.3, 0.1), ([0.8, math.inf, 0.4], 0.3, 0.1), ('abc', 0.3, 0.1),
    ([[0.8]], 0.3, 0.1), (1e308, [1e308, 1e308, 1e308], 0.1), (0.8, -0.01, 0.1),
    (0.8, [0.1, 0.2], 0.1), (0.8, 3.0, 0.1), (0.8, math.nan, 0.1), (0.8, 0.3, math.pi / 2),
    (0.8, 0.3, [0.1, 0.2]), (0.8, 0.3, math.inf)])
def test_bad_input_raises_the_messages_of_the_check_functions(analyzer, k_in, dp_in, alpha_in):
    with pytest.raises(InputError) as expected:
        analyzer.validate(k_in, dp_in, alpha_in)
    with pytest.raises(InputError) as got:
        analyzer.check_lift(k_in, dp_in, alpha_in)
    assert str(got.value) == str(expected.value)


def test_fingers_on_one_branch_share_their_spcm_state(config):
    """The cylinder's three fingers follow one SPCM branch, so check_lift solves it once per
    angle; the answers equal those solved finger by finger, bit for bit (unequal angles
    too). A hexagonal bar's section is mirrored for finger 1: its branch is its own."""
    from dam_analysis.analysis import LiftAnalyzer

    shared = LiftAnalyzer(config).build()
    assert shared._same_branch == [0, 0, 0]
    alone = LiftAnalyzer(config).build()
    alone._same_branch = [0, 1, 2]
    rng = np.random.default_rng(3)
    for i in range(200):
        k = list(rng.uniform(0.1, 15.0, 3))
        dp = [float(rng.uniform(0.0, 1.1))] * 3 if i % 2 else list(rng.uniform(0.0, 1.1, 3))
        a, b = shared.check_lift(k, dp, 0.09), alone.check_lift(k, dp, 0.09)
        assert repr((a.worst_case_margin, a.csm_margin, a.delta_theta_s.tolist(),
                     a.csm_path_margin, a.branch_message)) == \
            repr((b.worst_case_margin, b.csm_margin, b.delta_theta_s.tolist(),
                  b.csm_path_margin, b.branch_message))
    hex_bar = LiftAnalyzer(config.with_object('hex_bar')).build()
    assert hex_bar._same_branch[0] == 0 and hex_bar._same_branch[1:] != [0, 0]
