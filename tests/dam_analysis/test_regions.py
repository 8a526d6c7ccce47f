"""Lift regions and maps (module regions), and the paper's findings on the default hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

DP_MAX = math.radians(65.0)


@pytest.fixture(scope='module')
def dps():
    return np.radians(np.arange(0.5, 65.01, 0.5))


@pytest.fixture(scope='module')
def bounds(analyzer, dps):
    return {a: analyzer.boundaries(math.radians(a), dps) for a in (0.01, 0.1, 1.0, 5.0, 30.0)}


def test_sufficient_margin_is_linear_in_k(analyzer):
    dp = math.radians(12.0)
    m = [analyzer.check_lift(k, dp, math.radians(3)).worst_case_margin for k in (1.0, 2.0, 5.0)]
    assert m[2] - m[0] == pytest.approx(4.0 * (m[1] - m[0]), rel=1e-9)
    # and at k -> 0 the margin tends to -m_B g
    assert m[0] - (m[1] - m[0]) == pytest.approx(-analyzer.model.object_weight, rel=1e-9)


@pytest.mark.parametrize('alpha_deg', [1.0, 5.0])
def test_boundaries_are_where_the_margins_change_sign(analyzer, bounds, dps, alpha_deg):
    b = bounds[alpha_deg]
    alpha = math.radians(alpha_deg)
    checked = 0
    for j in range(0, dps.size, 7):
        for k_star, field in ((b.sufficient[j], 'worst_case_margin'), (b.csm[j], 'csm_margin')):
            if not math.isfinite(k_star):
                continue
            below = getattr(analyzer.check_lift(k_star * (1 - 1e-6), dps[j], alpha), field)
            above = getattr(analyzer.check_lift(k_star * (1 + 1e-6), dps[j], alpha), field)
            assert below < 0.0 < above, (alpha_deg, math.degrees(dps[j]), field)
            checked += 1
    assert checked >= 4


def test_map_equals_check_lift(analyzer):
    """The vectorised map equals one check_lift per point (its speed: bench/bench_lift_map)."""
    alphas = np.radians([1.0, 5.0, 30.0])
    dps = np.linspace(0.0, DP_MAX, 200)
    ks = np.geomspace(0.01, 50.0, 200)
    lm = analyzer.lift_map(alphas, dps, ks)
    assert lm.sufficient_margin.shape == (3, 200, 200)
    rng = np.random.default_rng(4)
    compared = beyond = 0
    for _ in range(60):
        a, d, k = rng.integers(0, 3), rng.integers(0, 200), rng.integers(0, 200)
        r = analyzer.check_lift(ks[k], dps[d], alphas[a])
        if r.beyond_branch.any():  # beyond the SPCM branch: no lift, the map says NaN
            assert math.isnan(lm.csm_margin[a, d, k]) and math.isnan(r.csm_margin)
            assert math.isnan(lm.sufficient_margin[a, d, k])
            assert math.isnan(r.worst_case_margin)
            assert not lm.sufficient_lift[a, d, k] and not lm.csm_lift[a, d, k]
            assert not r.lift_guaranteed and not r.csm_lift
            beyond += 1
            continue
        assert lm.sufficient_margin[a, d, k] == pytest.approx(r.worst_case_margin, rel=1e-9,
                                                              abs=1e-12)
        assert lm.csm_margin[a, d, k] == pytest.approx(r.csm_margin, rel=1e-9, abs=1e-12)
        assert lm.sufficient_lift[a, d, k] == r.lift_guaranteed
        assert lm.csm_lift[a, d, k] == r.csm_lift
        compared += 1
    assert compared > 30 and beyond > 0


# ---- the paper's findings (section 3.3, Fig. 5(b), Fig. 7) on the default configuration ----


def test_finding_csm_boundary_below_sufficient(bounds):
    """'the thin line is always lower than that of the sufficient condition'."""
    for b in bounds.values():
        both = np.isfinite(b.sufficient)
        assert np.all(np.isfinite(b.csm[both]))  # where sufficient lifts, the CSM lifts
        assert np.all(b.csm[both] <= b.sufficient[both] * (1 + 1e-9))


def test_finding_boundaries_converge_as_alpha_to_zero(bounds):
    """'both thick and thin lines converge to a single one as alpha -> 0'.

    At every displacement where both boundaries exist for alpha = 1 deg, the relative gap
    shrinks linearly with alpha and is below 5 % at alpha = 0.01 deg. It is NOT below 5 % at
    alpha = 1 deg on this hand (15 % at best): the contact normal is nearly horizontal
    (|n_z| <= 1/3 for any capsule touching a cylinder that lies on the table), so a 1 deg tilt
    of the force changes the small vertical resultant by several percent, and near the end of
    the sufficient region (k* -> infinity) any alpha > 0 gives a large relative gap
    (docs/analysis.md).
    """
    common = np.isfinite(bounds[1.0].sufficient) & np.isfinite(bounds[1.0].csm)
    assert common.sum() >= 10
    gaps = {}
    for a in (0.01, 0.1, 1.0):
        b = bounds[a]
        assert np.all(np.isfinite(b.sufficient[common]) & np.isfinite(b.csm[common]))
        gaps[a] = (b.sufficient[common] - b.csm[common]) / b.sufficient[common]
    assert gaps[0.01].max() < 0.05
    assert np.all(gaps[0.01] < gaps[0.1]) and np.all(gaps[0.1] < gaps[1.0])
    # first order in alpha: ten times smaller alpha, about ten times smaller gap
    np.testing.assert_allclose(gaps[0.1] / gaps[0.01], 10.0, rtol=0.1)
    assert gaps[1.0].min() > 0.05  # documented: the default hand cannot show 5 % at 1 deg


def test_finding_alpha_30_sufficient_empty_csm_not(analyzer, bounds, dps):
    """alpha = 30 deg: no sufficient solution over [0, 65] deg, the CSM region is large."""
    b = bounds[30.0]
    assert np.all(np.isnan(b.sufficient))
    assert np.isfinite(b.csm).sum() >= 20
    # the mechanism: the worst case is unbounded (an internal force pulls the object down)
    alpha = math.radians(30.0)
    seen = set()
    for dp in dps[::6]:
        r = analyzer.check_lift(1e3, dp, alpha)
        assert not r.lift_guaranteed
        if r.beyond_branch.any():  # no SPCM state: no lift, nothing to explain
            continue
        # either an internal force of any size pulls down (unbounded), or the worst admissible
        # force already pulls down (the lower cone edge points below the horizontal), so a
        # stiffer joint only makes it worse
        unbounded = 'unbounded' in r.sufficient_status
        assert unbounded or r.worst_case_margin + analyzer.model.object_weight < 0.0
        seen.add(unbounded)
    assert seen == {True, False}


def test_finding_alpha_5_small_sufficient_region(bounds):
    """alpha = 5 deg: a small sufficient region exists; the CSM region is larger."""
    b = bounds[5.0]
    suff = np.isfinite(b.sufficient)
    csm = np.isfinite(b.csm)
    assert suff.any()
    assert csm.sum() > suff.sum()
    assert np.nanmin(b.sufficient) > 2.0 * np.nanmin(b.csm)


def test_step_by_step_fallback_equals_closed_form(analyzer):
    """The fallback used for reversing slip agrees with the closed form on the default path."""
    from dam_analysis.regions import _csm_sequential_each, csm_evaluate, end_tables
    dps = np.radians([0.0, 3.0, 12.5, 27.0, 44.0])
    ends = end_tables(analyzer.table, dps)
    k = np.array([0.02, 0.3, 4.0])
    for i, end in enumerate(ends):
        a = csm_evaluate(analyzer.table, i, end, k, math.radians(7.0))
        b = _csm_sequential_each(analyzer.table, i, end, k, math.radians(7.0),
                                 float(analyzer.model.contact_stiffness[1]))
        np.testing.assert_allclose(a.f_n, b.f_n, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(a.f_t, b.f_t, rtol=1e-9, atol=1e-12)


def test_csm_boundary_with_soft_contact_uses_exact_margin():
    """With a soft tangential spring contacts still stick at the sliding estimate; the
    boundary must still be where the exact CSM margin changes sign."""
    import copy
    from pathlib import Path

    import yaml

    from dam_analysis.analysis import LiftAnalyzer
    from dam_common.config import config_from_dict
    with open(Path(__file__).resolve().parents[2] / 'config' / 'dam.yaml',
              encoding='utf-8') as fh:
        raw = yaml.safe_load(fh)
    raw = copy.deepcopy(raw)
    raw['contact']['contact_stiffness_n_per_m'] = [30.0, 30.0, 30.0]
    soft = LiftAnalyzer(config_from_dict(raw), path_step=math.radians(0.25))
    alpha = math.radians(10.0)
    dps = np.radians([4.0, 8.0, 16.0, 24.0])
    b = soft.boundaries(alpha, dps)
    stuck = 0
    for j, dp in enumerate(dps):
        k_star = b.csm[j]
        if not math.isfinite(k_star):
            continue
        lo = soft.check_lift(k_star * (1 - 1e-6), dp, alpha).csm_margin
        hi = soft.check_lift(k_star * (1 + 1e-6), dp, alpha).csm_margin
        assert lo < 0.0 < hi
        f = soft.check_lift(k_star, dp, alpha)
        f_n = -np.einsum('ij,ij->i', f.csm_forces, f.normals)
        f_t = np.linalg.norm(f.csm_forces + f_n[:, None] * f.normals, axis=1)
        stuck += int(np.any(f_t < math.tan(alpha) * f_n * (1 - 1e-6)))
    assert stuck >= 1  # the bisection branch was really needed
