"""The CSM's verdict on many grasps (csm_outcomes) and its calibration (csm_calibration)."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.special import ndtr

from dam_analysis.analysis import LiftAnalyzer
from dam_analysis.csm_calibration import draw_outcomes, fit_outcomes, margin_cube
from dam_analysis.csm_outcomes import CellMargins, GraspCells
from dam_analysis.errors import InputError
from dam_analysis.model import build_hand_model
from dam_analysis.regions import PathTable
from dam_common.config import config_from_dict, load_config, merge_overlay, series_stiffness

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG_PATH = REPO_ROOT / 'config' / 'dam.yaml'
CONFIG = load_config(CONFIG_PATH)
G = CONFIG.task.gravity_m_per_s2


def _config_with(contact: dict) -> object:
    import yaml

    data = yaml.safe_load(CONFIG_PATH.read_text(encoding='utf-8'))
    return config_from_dict(merge_overlay(data, {'contact': contact}))


@pytest.fixture(scope='module')
def table() -> PathTable:
    return PathTable(build_hand_model(CONFIG))


def _cells(k: list[float], dp_deg: list[float], alpha_deg: float, mass: float = 0.04
           ) -> GraspCells:
    kk, dd = np.meshgrid(k, dp_deg, indexing='ij')
    n = kk.size
    return GraspCells(np.full(n, math.radians(alpha_deg)), kk.ravel(), np.radians(dd.ravel()),
                      np.full(n, mass), np.zeros(n))


def test_an_infinite_series_stiffness_leaves_the_csm_exactly_as_it_was() -> None:
    plain = LiftAnalyzer(CONFIG)
    inf = LiftAnalyzer(_config_with({'series_stiffness_n_per_m': math.inf}))
    for k, dp, a in [(10.0, 0.17, 0.087), (2.0, 0.5, 0.52), (0.5, 0.3, 0.2)]:
        assert inf.check_lift(k, dp, a).csm_margin == plain.check_lift(k, dp, a).csm_margin


def test_a_series_stiffness_acts_as_the_springs_in_series() -> None:
    # k_t = 1e5 in series with 50 N/m is the contact k_t = 1 / (1/1e5 + 1/50) alone
    k_eff = 1.0 / (1.0 / 1e5 + 1.0 / 50.0)
    assert series_stiffness(1e5, 50.0) == pytest.approx(k_eff, rel=1e-15)
    series = LiftAnalyzer(_config_with({'series_stiffness_n_per_m': 50.0}))
    direct = LiftAnalyzer(_config_with({'contact_stiffness_n_per_m': [1e5, k_eff, 1e5]}))
    changed = 0
    for k, dp, a in [(10.0, 0.17, 0.087), (2.0, 0.5, 0.52), (0.5, 0.3, 0.2), (3.0, 0.1, 0.5)]:
        m_series = series.check_lift(k, dp, a).csm_margin
        assert m_series == pytest.approx(direct.check_lift(k, dp, a).csm_margin, abs=1e-12)
        changed += m_series != pytest.approx(LiftAnalyzer(CONFIG).check_lift(k, dp, a)
                                             .csm_margin, abs=1e-6)
    assert changed  # a soft finger does change the CSM


def test_a_bad_series_stiffness_is_refused_with_its_value() -> None:
    from dam_common.errors import ConfigError

    for bad in (0.0, -3.0, 'stiff'):
        with pytest.raises(ConfigError, match='series_stiffness_n_per_m'):
            _config_with({'series_stiffness_n_per_m': bad})


def test_the_end_verdict_is_check_lifts_margin(table: PathTable) -> None:
    analyzer = LiftAnalyzer(CONFIG)
    cells = _cells([0.3, 1.0, 4.0, 12.0], [5.0, 17.0, 40.0], 30.0, mass=0.05)
    margins = CellMargins(table, cells.k_theta, cells.delta_theta_p, cells.object_mass, G)
    got = margins.margins(cells.friction_angle[0], CONFIG.contact.tangential_stiffness_n_per_m,
                          'end')
    extra_weight = (0.05 - CONFIG.object.mass_kg) * G
    for k, dp, m in zip(cells.k_theta, cells.delta_theta_p, got, strict=True):
        want = analyzer.check_lift(k, dp, cells.friction_angle[0]).csm_margin - extra_weight
        if math.isnan(want):
            assert m == -math.inf
        else:
            assert m == pytest.approx(want, abs=1e-9)


def test_the_path_verdict_is_the_largest_margin_on_the_way(table: PathTable) -> None:
    analyzer = LiftAnalyzer(CONFIG)
    cells = _cells([0.6, 2.0, 8.0], [20.0, 45.0], 5.0)
    margins = CellMargins(table, cells.k_theta, cells.delta_theta_p, cells.object_mass, G)
    k_t = CONFIG.contact.tangential_stiffness_n_per_m
    path = margins.margins(cells.friction_angle[0], k_t, 'path')
    end = margins.margins(cells.friction_angle[0], k_t, 'end')
    assert np.all(path >= end)
    for k, dp, m in zip(cells.k_theta, cells.delta_theta_p, path, strict=True):
        # brute force through check_lift on the verdict's own 0.5 deg steps, and the end
        steps = list(np.radians(np.arange(0.5, math.degrees(dp), 0.5))) + [dp]
        values = [analyzer.check_lift(k, d, cells.friction_angle[0]).csm_margin
                  for d in steps]
        best = max((v for v in values if not math.isnan(v)), default=-math.inf)
        assert m == pytest.approx(best, abs=1e-9)


def test_cells_refuse_malformed_input() -> None:
    with pytest.raises(InputError, match='lifted'):
        GraspCells(np.zeros(2), np.ones(2), np.ones(2), np.ones(2), np.array([0.0, 0.5]))
    with pytest.raises(InputError, match='shape'):
        GraspCells(np.zeros(2), np.ones(3), np.ones(2), np.ones(2), np.zeros(2))
    with pytest.raises(InputError, match='at least one'):
        GraspCells(*(np.zeros(0) for _ in range(5)))


@pytest.fixture(scope='module')
def synthetic_case(table: PathTable) -> tuple[GraspCells, object, np.ndarray]:
    """180 cells (90 pairs twice) at one recorded friction angle; the true margins."""
    one = _cells(list(np.geomspace(0.2, 20.0, 15)), [5.0, 10.0, 20.0, 30.0, 40.0, 55.0], 20.0)
    cells = GraspCells(*(np.tile(getattr(one, f), 2) for f in (
        'friction_angle', 'k_theta', 'delta_theta_p', 'object_mass', 'lifted')))
    margins = CellMargins(table, cells.k_theta, cells.delta_theta_p, cells.object_mass, G)
    cube = margin_cube(cells, margins, alpha_half_width=math.radians(6.0),
                       alpha_step=math.radians(0.25), log_kt_range=(1.0, 5.0),
                       log_kt_step=0.5)
    truth = margins.margins(math.radians(20.0), 1e3, 'path')
    return cells, cube, truth


def test_the_fit_recovers_a_known_friction_angle_and_its_intervals_cover(
        synthetic_case: tuple[GraspCells, object, np.ndarray]) -> None:
    """Outcomes drawn from the CSM itself (alpha 20 deg, k_t 1e3 N/m, sigma 0.2 N): the 90 %
    intervals hold the true values in at least 85 of 100 draws."""
    cells, cube, truth = synthetic_case
    rng = np.random.default_rng(7)
    sigma, lapse = 0.2, 0.02
    cover_alpha = cover_sigma = cover_kt = 0
    estimates = []
    for _ in range(100):
        lifted = draw_outcomes(truth, sigma, lapse, rng)
        fit = fit_outcomes(cube, lifted, lapse=lapse, level=0.9)
        interval = fit.friction_angle[0]
        cover_alpha += interval.contains(math.radians(20.0))
        cover_sigma += fit.sigma.contains(sigma)
        cover_kt += fit.log10_tangential_stiffness.contains(3.0)
        estimates.append(math.degrees(interval.estimate))
    assert cover_alpha >= 85, cover_alpha
    assert cover_sigma >= 85, cover_sigma
    assert cover_kt >= 85, cover_kt
    assert abs(np.median(estimates) - 20.0) < 1.0


def test_a_parameter_the_data_cannot_see_is_not_determined(
        synthetic_case: tuple[GraspCells, object, np.ndarray]) -> None:
    """From ~1e4 N/m up every contact of these pairs slides at the cone's edge: k_t changes no
    margin, and outcomes made at 1e5 N/m must not give it a value."""
    cells, cube, truth = synthetic_case
    t_4, t_5 = (int(np.argmin(np.abs(cube.log_kt - v))) for v in (4.0, 5.0))
    assert np.allclose(cube.margin[0][:, t_4], cube.margin[0][:, t_5], atol=1e-3)
    a_20 = int(np.argmin(np.abs(cube.alpha[0] - math.radians(20.0))))
    lifted = (cube.margin[0][a_20, t_5] > 0.0).astype(float)
    fit = fit_outcomes(cube, lifted)
    kt = fit.log10_tangential_stiffness
    assert kt.status in ('not determined', 'bounded below')
    assert math.isinf(kt.high)
    # a configuration then keeps its own value when the data allow it
    assert fit.tangential_stiffness(1e5) == 1e5


def test_the_likelihood_is_the_probit_of_the_margin(
        synthetic_case: tuple[GraspCells, object, np.ndarray]) -> None:
    """The fit's maximum log-likelihood, recomputed by hand at its estimates."""
    cells, cube, truth = synthetic_case
    lifted = draw_outcomes(truth, 0.2, 0.02, np.random.default_rng(3))
    fit = fit_outcomes(cube, lifted, lapse=0.02)
    a = int(np.argmin(np.abs(cube.alpha[0] - fit.friction_angle[0].estimate)))
    t = int(np.argmin(np.abs(cube.log_kt - fit.log10_tangential_stiffness.estimate)))
    p = 0.02 + 0.96 * ndtr(cube.margin[0][a, t] / fit.sigma.estimate)
    by_hand = float(np.sum(np.where(lifted > 0.5, np.log(p), np.log1p(-p))))
    assert by_hand == pytest.approx(fit.log_likelihood, rel=1e-9)


def test_csm_dependence_draws_the_configured_boundary_and_stops_cleanly(tmp_path: Path
                                                                         ) -> None:
    """The boundary it prints at k_t = 1e5 N/m is the configured CSM's (LiftAnalyzer), one
    at 10 N/m differs; SIGINT while it works: one line, status 130."""
    import signal
    import subprocess

    from ros_testing import installed_executable, stop_with_signal, wait_for_signal_handlers

    exe = str(installed_executable('dam_analysis', 'csm_dependence'))
    out = tmp_path / 'dep.png'
    done = subprocess.run([exe, '-o', str(out), '--config', str(CONFIG_PATH),
                           '--friction-angles', '30deg', '--k-t', '10', '1e5'],
                          capture_output=True, text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr
    assert out.stat().st_size > 10_000
    printed = {}
    for line in done.stdout.splitlines():
        k_t = float(line.split('k_t ')[1].split(' N/m')[0])
        printed[k_t] = [float(v) for v in line.split('= ')[1].split(' N*m/rad')[0].split(', ')]
    want = LiftAnalyzer(CONFIG).boundaries(math.radians(30.0), np.radians([10.0, 20.0])).csm
    # printed at 3 significant digits, from a 60-point curve interpolated linearly
    np.testing.assert_allclose(printed[1e5][:2], want, rtol=0.03)
    assert printed[10.0][1] > 2.0 * printed[1e5][1]
    proc = subprocess.Popen([exe, '-o', str(tmp_path / 'x.png')], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)
    wait_for_signal_handlers(proc)
    time.sleep(1.0)
    _, stderr = stop_with_signal(proc, signal.SIGINT)
    assert proc.returncode == 130
    assert 'Traceback' not in stderr and 'interrupted' in stderr
