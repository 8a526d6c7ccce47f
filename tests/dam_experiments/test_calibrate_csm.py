"""calibrate_csm's overlay: only what the grasps determine is written, and the loader takes it."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from dam_analysis.csm_outcomes import CellMargins, GraspCells
from dam_analysis.model import build_hand_model
from dam_analysis.regions import PathTable
from dam_common.config import load_config
from dam_experiments.csm_calibration_run import calibrate, overlay

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG_PATH = REPO_ROOT / 'config' / 'dam.yaml'
CONFIG = load_config(CONFIG_PATH)


def _cells(alpha_deg: float, lifted_from: np.ndarray | None = None) -> GraspCells:
    k, dp = np.meshgrid(np.geomspace(0.2, 20.0, 12), [5.0, 15.0, 30.0, 45.0], indexing='ij')
    n = k.size
    cells = GraspCells(np.full(n, math.radians(alpha_deg)), k.ravel(), np.radians(dp.ravel()),
                       np.full(n, CONFIG.object.mass_kg), np.zeros(n))
    if lifted_from is not None:
        cells = GraspCells(cells.friction_angle, cells.k_theta, cells.delta_theta_p,
                           cells.object_mass, lifted_from)
    return cells


def _write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / 'overlay.yaml'
    path.write_text(text, encoding='utf-8')
    return path


def test_a_determined_friction_angle_is_written_and_an_undetermined_k_t_is_not(
        tmp_path: Path) -> None:
    """Grasps recorded at 15 deg whose outcomes are the CSM's end verdict at 20 deg and the
    configured k_t (1e5 N/m, where the contacts slide and k_t cancels): alpha comes out near
    20 deg and /check_lift agrees with more grasps with it, so it is written; k_t stays."""
    base = _cells(15.0)
    margins = CellMargins(PathTable(build_hand_model(CONFIG)), base.k_theta,
                          base.delta_theta_p, base.object_mass, CONFIG.task.gravity_m_per_s2)
    truth = margins.margins(math.radians(20.0), 1e5, 'end') > 0.0
    assert 0 < truth.sum() < truth.size  # both outcomes present
    result = calibrate(_cells(15.0, truth.astype(float)), CONFIG, verdict='end', folds=0)
    text = overlay(result, CONFIG, 'test cells', CONFIG.object.name)
    data = yaml.safe_load(text)
    assert result.fit.log10_tangential_stiffness.status != 'determined'
    assert 'object' not in data and 'contact_stiffness_n_per_m' not in data['contact']
    alpha = result.fit.friction_angle[0]
    assert alpha.status == 'determined'
    assert alpha.contains(math.radians(20.0)) and not alpha.contains(math.radians(15.0))
    # the end verdict at the recorded 15 deg misses grasps the fitted angle gets right
    assert result.end_agreement_overlay > result.end_agreement_configured
    assert result.end_agreement_overlay == int(np.sum(
        (margins.margins(alpha.estimate, 1e5, 'end') > 0.0) == truth))
    assert data['contact']['friction_angle_deg'] == pytest.approx(math.degrees(alpha.estimate),
                                                                  rel=1e-5)
    merged = load_config(CONFIG_PATH, [_write(tmp_path, text)])
    assert merged.contact.friction_angle_rad == pytest.approx(alpha.estimate, rel=1e-5)
    np.testing.assert_array_equal(merged.contact.contact_stiffness_n_per_m,
                                  CONFIG.contact.contact_stiffness_n_per_m)
    assert '# k_t is not determined' in text
    # the searched range is said per angle (it is recorded +- 20 deg, clipped: 15 deg gives
    # [0.25, 35] deg, 5 deg [0.25, 25], 30 deg [10, 50])
    from dam_experiments.calibrate_csm import report_lines

    [line] = [x for x in report_lines(result) if x.startswith('friction angle recorded')]
    assert line.startswith('friction angle recorded 15 deg: searched in [0.25, 35] deg '
                           '(recorded +- 20 deg within [0.25, 80] deg), fitted '), line
    assert report_lines(result)[0].startswith(f'{result.fit.cells} grasps, ')


def test_values_that_do_not_help_check_lift_are_not_written(tmp_path: Path) -> None:
    """Outcomes exactly as the end verdict at the recorded angle says: no fitted value can
    make /check_lift agree with more grasps, so the overlay holds none."""
    base = _cells(20.0)
    margins = CellMargins(PathTable(build_hand_model(CONFIG)), base.k_theta,
                          base.delta_theta_p, base.object_mass, CONFIG.task.gravity_m_per_s2)
    truth = margins.margins(math.radians(20.0), CONFIG.contact.tangential_stiffness_n_per_m,
                            'end') > 0.0
    result = calibrate(_cells(20.0, truth.astype(float)), CONFIG, verdict='end', folds=0)
    assert result.end_agreement_configured == truth.size
    assert not result.overlay_helps
    text = overlay(result, CONFIG, 'test cells', CONFIG.object.name)
    assert yaml.safe_load(text) == {}
    assert 'no better, so none is written' in text


def test_grasps_that_never_lift_write_nothing(tmp_path: Path) -> None:
    cells = _cells(10.0)  # every outcome 0: only a bound on alpha, nothing determined
    result = calibrate(cells, CONFIG, folds=0)
    text = overlay(result, CONFIG, 'test cells', CONFIG.object.name)
    assert result.fit.friction_angle[0].status != 'determined'
    assert yaml.safe_load(text) == {}
    merged = load_config(CONFIG_PATH, [_write(tmp_path, text)])
    assert merged.contact.friction_angle_rad == CONFIG.contact.friction_angle_rad
    np.testing.assert_array_equal(merged.contact.contact_stiffness_n_per_m,
                                  CONFIG.contact.contact_stiffness_n_per_m)
    assert merged.contact.series_stiffness_n_per_m == CONFIG.contact.series_stiffness_n_per_m


def test_a_determined_k_t_is_written_for_the_grasped_object(tmp_path: Path) -> None:
    """Outcomes of the end verdict with a soft tangential spring (30 N/m, where sticking
    matters) at the recorded angle: k_t is determined and goes to the grasped object's
    csm_tangential_stiffness_n_per_m, which the loader takes and the analysis then uses; the
    contact section and the other objects keep theirs."""
    base = _cells(30.0)
    margins = CellMargins(PathTable(build_hand_model(CONFIG)), base.k_theta,
                          base.delta_theta_p, base.object_mass, CONFIG.task.gravity_m_per_s2)
    truth = margins.margins(math.radians(30.0), 30.0, 'end') > 0.0
    assert 0 < truth.sum() < truth.size
    result = calibrate(_cells(30.0, truth.astype(float)), CONFIG, verdict='end', folds=0,
                       fit_friction_angle=False)
    kt = result.fit.log10_tangential_stiffness
    assert kt.status == 'determined' and kt.contains(math.log10(30.0))
    assert result.overlay_helps
    text = overlay(result, CONFIG, 'test cells', CONFIG.object.name)
    data = yaml.safe_load(text)
    written = data['object']['library'][CONFIG.object.name]['csm_tangential_stiffness_n_per_m']
    assert written == pytest.approx(result.overlay_tangential_stiffness, rel=1e-5)
    merged = load_config(CONFIG_PATH, [_write(tmp_path, text)])
    assert merged.object.csm_tangential_stiffness_n_per_m == written
    np.testing.assert_array_equal(merged.contact.contact_stiffness_n_per_m,
                                  CONFIG.contact.contact_stiffness_n_per_m)
    assert merged.objects['hex_bar'].csm_tangential_stiffness_n_per_m is None
    assert build_hand_model(merged).tangential_stiffness == written
