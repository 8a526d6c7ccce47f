"""The scale study (modules scale_study and scale_map): lift boundaries over cylinder size,
against a closed form on an independently solved SPCM, and the command."""

from __future__ import annotations

import csv
import math
import subprocess
from pathlib import Path

import numpy as np
import pytest

from dam_analysis.errors import InputError
from dam_analysis.scale_map import main, parse_radius_range
from dam_analysis.scale_study import scale_study, scaled_config, working_ranges
from spcm_reference import PlanarFinger, follow_branch

REPO_ROOT = Path(__file__).resolve().parents[2]


def test_the_scaled_cylinder_rests_on_the_table_with_its_density(config) -> None:
    big = scaled_config(config, 0.015)
    assert big.object.radius_m == 0.015
    assert big.object.position_m[2] == 0.015  # axis at height R: resting on the table
    np.testing.assert_array_equal(big.object.position_m[:2], config.object.position_m[:2])
    assert big.object.mass_kg == pytest.approx(config.object.mass_kg * 1.5 ** 2)
    assert scaled_config(config, 0.015, constant_mass=True).object.mass_kg == \
        config.object.mass_kg
    assert config.object.radius_m == 0.010  # the configuration itself is unchanged
    for bad in (0.0, -0.01, math.nan, math.inf):
        with pytest.raises(InputError, match='radius: expected a positive number'):
            scaled_config(config, bad)


def _frictionless_boundary(config, delta_theta_p: float) -> tuple[float, float]:
    """alpha = 0: every contact force lies along the inward normal, so each finger's force is
    f_n = tau_s / (J^T n_in) and the margin sum f_n (-n_z) - m_B g is linear in k_theta:
    k* = m_B g / sum_i r_i (-delta_theta_si) (-n_z) / (J^T n_in). The SPCM states come from
    the independent solver of spcm_reference (fingertip contact, normal (cos psi, sin psi));
    J^T n_in is the torque of a unit inward force about the compliant joint (a plane point p
    moves with (-p_z, p_u) per radian of the whole finger); NaN where the slope is not
    positive (no stiffness lifts). Also returns the stiffness at which the largest |tau_s|
    reaches the torque limit. [N m/rad] The reference models the fingertip only: the radii
    tested have their first contact there."""
    ratios = np.asarray(config.hand.stiffness_ratios, dtype=float)
    limit = min(config.controller.torque_limit_nm, config.device.torque_limit_nm)
    slope, per_k = 0.0, []
    for i in range(config.hand.n_fingers):
        finger = PlanarFinger.from_config(config, i)
        branch = follow_branch(finger)
        assert finger.on_fingertip(branch.states[0][0], finger.theta_p0)
        step = int(round(delta_theta_p / math.radians(0.25)))
        assert branch.delta_theta_p[step] == pytest.approx(delta_theta_p)
        theta_s, psi = branch.states[step]
        assert finger.on_fingertip(theta_s, finger.theta_p0 + delta_theta_p)
        d_s = theta_s - branch.states[0][0]
        n = np.array([math.cos(psi), math.sin(psi)])
        p = np.asarray(finger.centre) + finger.object_radius * n
        lever = float(-n @ np.array([-p[1], p[0]]))  # J^T n_in
        r = ratios[i] / ratios[0]
        slope += r * (-d_s) * (-n[1]) / lever
        per_k.append(r * abs(d_s))
    k_star = config.object_weight_n / slope if slope > 0.0 else math.nan
    return k_star, limit / max(per_k)


@pytest.mark.parametrize('radius_mm', [8.0, 9.0, 12.0])
def test_frictionless_boundaries_equal_the_closed_form(config, radius_mm: float) -> None:
    dps = np.radians([10.0, 20.0])
    study = scale_study(config, [radius_mm * 1e-3], dps, 0.0)
    # 8 mm lifts at neither displacement, 9 mm at 10 deg only, 12 mm at both
    assert np.isfinite(study.k_sufficient[0]).tolist() == {
        8.0: [False, False], 9.0: [True, False], 12.0: [True, True]}[radius_mm]
    scaled = scaled_config(config, radius_mm * 1e-3)
    for d, dp in enumerate(dps):
        k_star, k_torque = _frictionless_boundary(scaled, float(dp))
        assert study.k_sufficient[0, d] == pytest.approx(k_star, rel=1e-6, nan_ok=True)
        # both boundaries converge at alpha = 0
        assert study.k_csm[0, d] == pytest.approx(k_star, rel=1e-6, nan_ok=True)
        assert study.k_torque[0, d] == pytest.approx(k_torque, rel=1e-6)


def test_at_the_configured_radius_the_study_is_the_lift_map(config, analyzer) -> None:
    dps = np.radians([5.0, 10.0, 25.0, 64.0])  # 64 deg: beyond the end of the branch
    alpha = math.radians(5.0)
    study = scale_study(config, [config.object.radius_m], dps, alpha)
    bounds = analyzer.boundaries(alpha, dps)
    np.testing.assert_array_equal(study.k_sufficient[0], bounds.sufficient)
    np.testing.assert_array_equal(study.k_csm[0], bounds.csm)
    assert math.isnan(study.k_torque[0, 3]) and study.no_contact == ('',)
    # the torque ceiling is where check_lift's torque verdict turns
    k_tau = float(study.k_torque[0, 1])
    assert analyzer.check_lift(k_tau * 0.999, dps[1]).within_torque_limit
    assert not analyzer.check_lift(k_tau * 1.001, dps[1]).within_torque_limit


def test_sizes_without_a_first_contact_are_named_not_drawn(config) -> None:
    study = scale_study(config, [0.002, 0.010, 0.024], np.radians([10.0]), math.radians(5.0))
    assert 'does not reach the object' in study.no_contact[0]
    assert 'already overlaps the object' in study.no_contact[2]
    assert study.no_contact[1] == ''
    for j in (0, 2):
        assert np.isnan([study.k_sufficient[j, 0], study.k_csm[j, 0],
                         study.k_torque[j, 0]]).all()
    assert working_ranges(study) == [[(0.010, 0.010)]]
    works = study.works()
    assert works[1, 0] == (study.k_sufficient[1, 0] < study.k_torque[1, 0])


def test_bad_input_is_refused_with_the_value(config) -> None:
    with pytest.raises(InputError, match='delta_theta_p: 70 deg is outside'):
        scale_study(config, [0.01], np.radians([70.0]), 0.1)
    with pytest.raises(InputError, match='friction_angle'):
        scale_study(config, [0.01], [0.1], math.pi / 2)


def test_radius_ranges() -> None:
    np.testing.assert_allclose(parse_radius_range('3mm:20mm:18'), np.arange(3, 21) * 1e-3)
    np.testing.assert_allclose(parse_radius_range('7mm:7mm:1'), [7e-3])
    np.testing.assert_allclose(parse_radius_range('0.003:0.02:18'), np.arange(3, 21) * 1e-3)
    import argparse
    for bad, words in (('3mm:20mm', 'START:STOP:COUNT'), ('a:2mm:3', 'is not a length'),
                       ('3mm:20mm:x', 'not a whole number'), ('0:20mm:3', 'must be above 0'),
                       ('0.003:nan:3', 'not a finite length'), ('20mm:3mm:3', 'below START'),
                       ('3mm:4mm:0', 'must be in'), ('3mm:4mm:1', 'START == STOP'),
                       ('3mm:nan:3', 'has no unit while the other end has one'),
                       ('3:20:18', 'did you mean 3mm?')):
        with pytest.raises(argparse.ArgumentTypeError, match=words):
            parse_radius_range(bad)


def test_the_command_writes_the_table_the_picture_and_the_summary(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / 'scale.png'
    assert main(['--radius-range', '2mm:14mm:4', '--delta-theta-p', '10deg', '20deg',
                 '--friction-angle', '5deg', '--out', str(out),
                 '--config', str(REPO_ROOT / 'config' / 'dam.yaml')]) == 0
    printed = capsys.readouterr().out
    assert out.stat().st_size > 20_000
    with open(out.with_suffix('.csv'), encoding='utf-8') as stream:
        rows = list(csv.DictReader(stream))
    assert [(r['radius_mm'], r['delta_theta_p_deg']) for r in rows] == [
        (r, d) for r in ('2', '6', '10', '14') for d in ('10', '20')]  # no float noise
    assert rows[0]['k_theta_sufficient'] == '' and 'does not reach' in rows[0]['no_first_contact']
    assert float(rows[4]['mass_kg']) == pytest.approx(0.04)  # 10 mm: the configured object
    assert 'delta_theta_p 10 deg: within 0.6 N*m, guaranteed (sufficient condition) at' in printed
    assert 'no first contact at radius 2 mm: the distal link does not reach' in printed


def test_angles_take_units_and_a_missing_directory_is_refused_before_the_work(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    config = str(REPO_ROOT / 'config' / 'dam.yaml')
    out = tmp_path / 'a.png'
    assert main(['--radius-range', '10mm:10mm:1', '--delta-theta-p', '0.17453292519943295',
                 '--friction-angle', '5deg', '--out', str(out), '--config', config]) == 0
    with open(out.with_suffix('.csv'), encoding='utf-8') as stream:
        [row] = list(csv.DictReader(stream))
    assert row['delta_theta_p_deg'] == '10' and row['k_theta_sufficient'] != ''
    capsys.readouterr()
    with pytest.raises(SystemExit) as exit_info:
        main(['--radius-range', '3mm:20mm:18', '--delta-theta-p', '10deg',
              '--out', str(tmp_path / 'nowhere' / 'b.png'), '--config', config])
    assert exit_info.value.code == 2
    err = capsys.readouterr().err
    assert 'does not exist' in err and 'radius 3 mm' not in err  # refused before any radius


@pytest.mark.parametrize(('args', 'words'), [
    (['--radius-range', '3mm:1mm:2', '--delta-theta-p', '10deg'], 'below START'),
    (['--radius-range', '3mm:5mm:2', '--delta-theta-p', '80deg'], 'delta_theta_p: 80 deg'),
    (['--radius-range', '3mm:5mm:2'], 'the following arguments are required: --delta-theta-p'),
    (['--radius-range', '3mm:5mm:2', '--delta-theta-p', '10'], 'did you mean 10deg?'),
])
def test_bad_arguments_exit_2_with_one_line(args: list[str], words: str,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(args)
    assert exit_info.value.code == 2
    assert words in capsys.readouterr().err


def test_installed_command() -> None:
    exe = REPO_ROOT / 'ros2_ws' / 'install' / 'dam_analysis' / 'lib' / 'dam_analysis' / \
        'scale_map'
    assert exe.is_file(), 'build the workspace (scripts/setup.sh)'
    done = subprocess.run([str(exe), '--help'], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and '--radius-range' in done.stdout, done.stderr


def test_another_column_is_scaled_uniformly_by_its_half_height(config) -> None:
    """The hexagonal pencil scaled to a half height of 9 mm is the library's hexagonal bar
    (18 mm across flats); with the bar's mass both give the same boundaries."""
    import dataclasses

    from dam_analysis.analysis import LiftAnalyzer

    pencil = config.with_object('hex_pencil')
    bar = config.with_object('hex_bar')
    scaled = scaled_config(pencil, 0.009)
    section = scaled.object.section
    np.testing.assert_allclose(section.vertices, bar.object.section.vertices, atol=1e-15)
    assert scaled.object.position_m[2] == pytest.approx(0.009)  # resting on a face
    assert scaled.object.mass_kg == pytest.approx(pencil.object.mass_kg * (9.0 / 3.5) ** 2)
    same_mass = dataclasses.replace(scaled, object=dataclasses.replace(
        scaled.object, mass_kg=bar.object.mass_kg))
    dps = np.radians([5.0, 10.0])
    ours = LiftAnalyzer(same_mass).boundaries(math.radians(5.0), dps)
    theirs = LiftAnalyzer(bar).boundaries(math.radians(5.0), dps)
    np.testing.assert_allclose(ours.sufficient, theirs.sufficient, rtol=1e-9)
    np.testing.assert_allclose(ours.csm, theirs.csm, rtol=1e-9)


def test_the_command_scales_a_named_object(tmp_path: Path,
                                           capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / 'pencil.png'
    assert main(['--object', 'hex_pencil', '--radius-range', '3mm:9mm:3', '--delta-theta-p',
                 '10deg', '--out', str(out)]) == 0
    printed = capsys.readouterr().out
    with open(out.with_suffix('.csv'), encoding='utf-8') as stream:
        rows = list(csv.DictReader(stream))
    assert [float(r['half_height_mm']) for r in rows] == [3.0, 6.0, 9.0]
    # eq. 18 holds at rest at 9 mm (the hex_bar's size), but the bar can rest turned on the
    # table there (dam_analysis.rolling): no half height is guaranteed; the CSM lifts at 9 mm
    assert 'guaranteed (sufficient condition) at no half height' in printed, printed
    assert 'CSM lift at 9 mm' in printed, printed
    assert main(['--object', 'pencil', '--radius-range', '3mm:9mm:3', '--delta-theta-p',
                 '10deg', '--out', str(out)]) == 2
    assert "'pencil' is not in the object library" in capsys.readouterr().err


def test_a_curve_with_no_value_has_no_legend_line(tmp_path: Path, monkeypatch) -> None:
    """A map where nothing lifts (the configured 3.5 mm hexagonal pencil) listed legend
    entries for lines that were not drawn; each now says the curve has no value instead."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    kept = []
    monkeypatch.setattr(plt, 'close', lambda fig: kept.append(fig))
    assert main(['--object', 'hex_pencil', '--radius-range', '3mm:3.5mm:2', '--delta-theta-p',
                 '10deg', '--out', str(tmp_path / 'p.png')]) == 0
    [figure] = kept
    lines = figure.axes[0].get_lines()
    for line in lines:
        if line.get_label().startswith('_') or line.get_linestyle() == 'None':
            continue
        y = np.asarray(line.get_ydata(), dtype=float)
        assert y.size and np.any(np.isfinite(y)), f'{line.get_label()!r} has no line'
    assert any('none in this range' in line.get_label() for line in lines)
