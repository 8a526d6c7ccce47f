"""The lift_map tool (Fig. 5(b)): PNG and CSV output, checked against bisection on check_lift."""

from __future__ import annotations

import csv
import math
import re
import subprocess
import sys

import numpy as np
import pytest

from dam_analysis import lift_map
from ros_testing import installed_executable

PNG_MAGIC = b'\x89PNG\r\n\x1a\n'
ALPHAS_DEG = (1.0, 5.0, 30.0)
N_DP = 27  # 2.5 deg steps on [0, 65] deg


def _read_csv(path):
    with open(path, newline='') as stream:
        rows = list(csv.reader(stream))
    assert rows[0] == ['alpha_deg', 'delta_theta_p_deg', 'k_theta_sufficient', 'k_theta_csm',
                       'k_theta_torque_limit']
    return np.array([[float(cell) if cell else math.nan for cell in row] for row in rows[1:]])


def _assert_png(path):
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC
    assert len(data) > 10_000  # axes, two curves per angle, hatching and a legend


@pytest.fixture(scope='module')
def installed_run(tmp_path_factory):
    """One run of the installed executable (what ``ros2 run dam_analysis lift_map`` runs)."""
    out = tmp_path_factory.mktemp('lift_map') / 'map.png'
    exe = installed_executable('dam_analysis', 'lift_map')
    assert exe.is_file(), f'{exe} missing: build the workspace with scripts/setup.sh'
    proc = subprocess.run(
        [str(exe), '--friction-angles', *[f'{a:g}deg' for a in ALPHAS_DEG],
         '--n-delta-theta-p', str(N_DP), '--out', str(out)],
        capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    return out, proc


def _smallest_lifting_k(analyzer, dp_rad, alpha_rad, field, k_hi):
    """Bisection (in log k) for the smallest finger-1 stiffness with ``field`` True.

    NaN if even ``k_hi`` does not lift (beyond the end of the SPCM branch nothing lifts).
    ``k_hi`` must stay moderate for the CSM: at very large stiffness (~1e4 N m/rad) the cap
    ``mu f_n / k_t`` exceeds the accumulated slip, the contact sticks and the CSM stops lifting.
    """
    def lifts(k):
        return bool(getattr(analyzer.check_lift(k, dp_rad, alpha_rad), field))

    if not lifts(k_hi):  # also beyond the end of the SPCM branch: no lift there
        return math.nan
    lo, hi = 1e-4, k_hi
    assert not lifts(lo)
    for _ in range(60):
        mid = math.sqrt(lo * hi)
        if lifts(mid):
            hi = mid
        else:
            lo = mid
    return hi


def test_installed_executable_writes_png_csv_and_progress(installed_run):
    out, proc = installed_run
    _assert_png(out)
    table = _read_csv(out.with_suffix('.csv'))
    assert table.shape == (len(ALPHAS_DEG) * N_DP, 5)
    for alpha in ALPHAS_DEG:
        rows = table[table[:, 0] == alpha]
        np.testing.assert_allclose(rows[:, 1], np.linspace(0.0, 65.0, N_DP), atol=1e-9)
        assert f'alpha = {alpha:g} deg' in proc.stderr  # progress per friction angle


def test_csv_boundaries_agree_with_bisection_on_check_lift(installed_run, analyzer):
    table = _read_csv(installed_run[0].with_suffix('.csv'))
    rng = np.random.default_rng(3)
    checked_finite = 0
    for alpha in ALPHAS_DEG:
        rows = table[table[:, 0] == alpha]
        picks = rng.choice(len(rows), size=7, replace=False)
        for alpha_deg, dp_deg, k_suff, k_csm, _ in rows[picks]:
            dp, a = math.radians(dp_deg), math.radians(alpha_deg)
            for field, value in (('lift_guaranteed', k_suff), ('csm_lift', k_csm)):
                k_hi = 100.0 if math.isnan(value) else max(100.0, 2.0 * value)
                ref = _smallest_lifting_k(analyzer, dp, a, field, k_hi)
                where = (alpha_deg, dp_deg, field)
                if math.isnan(ref):
                    assert math.isnan(value), where
                else:
                    assert value == pytest.approx(ref, rel=1e-6), where
                    checked_finite += 1
    assert checked_finite >= 10  # the sample really compares finite boundaries


def test_alpha_30_sufficient_region_empty_csm_not(installed_run, analyzer):
    table = _read_csv(installed_run[0].with_suffix('.csv'))
    rows = table[table[:, 0] == 30.0]
    assert np.all(np.isnan(rows[:, 2]))
    assert np.sum(np.isfinite(rows[:, 3])) >= N_DP // 2
    # beyond the end of the SPCM branch (61.72 deg) nothing lifts, at any friction angle
    end_deg = math.degrees(min(path.valid_until for path in analyzer.table.paths))
    beyond = table[table[:, 1] > end_deg]
    assert beyond.size and np.all(np.isnan(beyond[:, 2:]))


def test_the_torque_ceiling_is_where_check_lift_says_the_limit_is_exceeded(installed_run,
                                                                          analyzer):
    """The map hatched the sufficient region up to 18 N*m/rad at 10 deg where check_lift said
    the torque limit is exceeded from 15: the ceiling is where check_lift's own verdict flips,
    the same for every friction angle."""
    table = _read_csv(installed_run[0].with_suffix('.csv'))
    checked = 0
    for alpha_deg, dp_deg, _ks, _kc, k_torque in table[::5]:
        if dp_deg == 0.0 or not math.isfinite(k_torque):
            continue
        dp, a = math.radians(dp_deg), math.radians(alpha_deg)
        assert analyzer.check_lift(0.99 * k_torque, dp, a).within_torque_limit, dp_deg
        assert not analyzer.check_lift(1.01 * k_torque, dp, a).within_torque_limit, dp_deg
        same = table[(table[:, 1] == dp_deg)][:, 4]
        assert np.all(same == k_torque)  # one ceiling for every friction angle
        checked += 1
    assert checked >= 8
    at_10 = table[(table[:, 0] == 5.0) & (np.abs(table[:, 1] - 10.0) < 1.3)]
    assert np.all((at_10[:, 4] > 12.0) & (at_10[:, 4] < 18.0)), at_10[:, [1, 4]]


def _drawn(argv, tmp_path, monkeypatch):
    """The axes ``lift_map`` draws for ``argv`` (kept open instead of closed)."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    kept = []
    monkeypatch.setattr(plt, 'close', lambda fig: kept.append(fig))
    assert lift_map.main([*argv, '--n-delta-theta-p', '60', '--out',
                          str(tmp_path / 'm.png')]) == 0
    [figure] = kept
    return figure.axes[0]


def test_what_the_hand_cannot_drive_is_shaded_and_not_hatched(tmp_path, monkeypatch):
    ax = _drawn(['--friction-angles', '5deg', '--k-max', '40'], tmp_path, monkeypatch)
    lines = {line.get_label(): line for line in ax.get_lines()}
    [ceiling_label] = [label for label in lines if label.startswith('torque ceiling')]
    ceiling = lines[ceiling_label]
    dp, k_torque = (np.asarray(v, dtype=float) for v in ceiling.get_data())
    hatched = [c for c in ax.collections if c.get_hatch()]
    assert hatched
    for collection in hatched:
        for path in collection.get_paths():
            x, y = path.vertices[:, 0], path.vertices[:, 1]
            top = np.interp(x, dp, np.where(np.isfinite(k_torque), k_torque, 40.0))
            assert np.all(y <= np.minimum(top, 40.0) + 1e-6), 'hatched above the ceiling'
    shaded = [c for c in ax.collections if not c.get_hatch()]
    assert shaded, 'nothing shaded above the ceiling'


def test_a_boundary_that_stops_inside_the_plot_is_marked_and_said_why(tmp_path, monkeypatch):
    ax = _drawn(['--object', 'square_bar', '--friction-angles', '5deg'], tmp_path, monkeypatch)
    notes = [t.get_text() for t in ax.texts]
    assert any(n.startswith('CSM ends at') for n in notes), notes
    marks = [line for line in ax.get_lines() if line.get_marker() == 'x']
    assert len(marks) == len(notes)


def test_an_empty_map_has_no_legend_entry_for_a_line_not_drawn(tmp_path, monkeypatch):
    ax = _drawn(['--object', 'hex_pencil', '--friction-angles', '5deg'], tmp_path, monkeypatch)
    for line in ax.get_lines():
        label = line.get_label()
        if label.startswith('_') or line.get_linestyle() == 'None':
            continue
        y = np.asarray(line.get_ydata(), dtype=float)
        assert y.size and np.any(np.isfinite(y)), f'legend entry {label!r} has no line'
    labels = [line.get_label() for line in ax.get_lines()]
    assert 'alpha = 5 deg: sufficient region empty' in labels, labels
    # the ceiling lies above the whole plot here: said, not listed as a line
    assert any(label.startswith('torque ceiling') and 'above the plot (from' in label
               for label in labels), labels


def test_main_in_process_with_explicit_csv_and_range(tmp_path, analyzer):
    png, table_path = tmp_path / 'five.png', tmp_path / 'table.csv'
    code = lift_map.main(['--friction-angles', '5deg', '--n-delta-theta-p', '5',
                          '--delta-theta-p-max', '20deg', '--k-max', '12', '--out', str(png),
                          '--csv', str(table_path)])
    assert code == 0
    _assert_png(png)
    table = _read_csv(table_path)
    np.testing.assert_allclose(table[:, 1], [0.0, 5.0, 10.0, 15.0, 20.0])
    # the tabulated values of docs/analysis.md, section 7 (alpha = 5 deg, dp = 5, 10, 15)
    np.testing.assert_allclose(table[1:4, 2], [7.40, 6.35, 34.7], rtol=5e-3)
    np.testing.assert_allclose(table[1:4, 3], [2.69, 1.59, 1.35], rtol=5e-3)
    assert math.isnan(table[0, 2]) and math.isnan(table[0, 3])  # no displacement, no torque


@pytest.mark.parametrize(('argv', 'needle'), [
    (['--friction-angles', '95deg'], '95'),
    (['--friction-angles', '90deg'], '90'),
    (['--friction-angles', '-1deg'], '-1'),
    ([], '--friction-angles'),
    (['--friction-angles', '5deg', '--n-delta-theta-p', '1'], '1'),
    (['--friction-angles', '5deg', '--delta-theta-p-max', '80deg'], '80'),
    (['--friction-angles', '5deg', '--k-max', '0'], '--k-max'),
    (['--friction-angles', '5'], 'did you mean 5deg?'),
    (['--friction-angles', '5deg', '--delta-theta-p-max', '20'], 'did you mean 20deg?'),
])
def test_bad_arguments_exit_2_naming_the_value(argv, needle, tmp_path, capsys):
    with pytest.raises(SystemExit) as info:
        lift_map.main([*argv, '--out', str(tmp_path / 'x.png')])
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert needle in err.split('error:', 1)[1]
    assert not (tmp_path / 'x.png').exists()


def test_bad_angle_via_installed_executable_exits_2():
    proc = subprocess.run([str(installed_executable('dam_analysis', 'lift_map')),
                           '--friction-angles', '1deg', '91.5deg'],
                          capture_output=True, text=True, timeout=30)
    assert proc.returncode == 2
    assert '91.5 deg' in proc.stderr


def test_module_runs_without_ros_imports():
    code = ('import sys, dam_analysis.lift_map; '
            'assert "rclpy" not in sys.modules, "lift_map imports rclpy"')
    subprocess.run([sys.executable, '-c', code], check=True, timeout=30,
                   env={'PYTHONPATH': ':'.join(p for p in sys.path if p)})


def test_a_friction_angle_that_takes_long_reports_on_stderr_while_it_runs(
        analyzer, capfd, monkeypatch) -> None:
    """Besides the line per friction angle, a line every DAM_PROGRESS_S seconds while one
    runs (5 by default; here 0.001, so that one angle of 27 displacements is slow enough)."""
    monkeypatch.setenv('DAM_PROGRESS_S', '0.001')
    lift_map.compute_boundaries(analyzer, [5.0], np.radians(np.linspace(0.0, 65.0, N_DP)))
    captured = capfd.readouterr()
    assert captured.out == ''
    lines = captured.err.splitlines()
    assert lines[-1].startswith('lift_map: alpha = 5 deg (1/1) done in ')
    assert lines[:-1], captured.err
    assert all(re.fullmatch(r'lift_map: alpha = 5 deg \(1/1\), \d+ s', ln)
               for ln in lines[:-1]), lines
