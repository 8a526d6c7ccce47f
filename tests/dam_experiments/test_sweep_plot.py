"""``sweep_plot``: a sweep directory drawn as the paper's Fig. 7, checked on the Figure.

The sweep directories are written without simulations: the sweep's own ``TrialTable`` writes
``sweep.json`` and ``trials.csv`` (the columns of ``table_columns``), with rows made here with
chosen outcomes. The boundaries are checked against ``compute_boundaries`` called here.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dam_analysis.analysis import LiftAnalyzer
from dam_analysis.lift_map import compute_boundaries
from dam_common.config import load_config
from dam_experiments.errors import SweepPlotError
from dam_experiments.sweep import SweepSpec, input_columns, table_columns
from dam_experiments.sweep_plot import (
    CLASS_LABELS,
    CSM_LABEL,
    DISAGREE_LABEL,
    P_LIFT_LABEL,
    SUFFICIENT_LABEL,
    check_output,
    main,
    plot_sweep,
)
from dam_experiments.sweep_results import OUTCOMES, k_axis_is_log, read_sweep
from dam_experiments.sweep_table import PARAMS_FILE, TABLE_FILE, TrialTable
from ros_testing import installed_executable

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG = REPO_ROOT / 'config' / 'dam.yaml'
PNG_MAGIC = b'\x89PNG\r\n\x1a\n'
N_POINTS = 21  # boundary samples: enough to compare, cheap to compute

#: (outcome, lifted) by trial number of the marker sweep: every class, two disagreements.
CLASSES = [('FAILURE', 0), ('FAILURE', 0), ('LIFTED_DAM_FAILED', 1), ('SUCCESS', 1),
           ('SUCCESS', 1), ('FAILURE', 1), ('LIFTED_DAM_FAILED', 1), ('SUCCESS', 0)]
#: Lifted by trial number of the repeat sweep (3 cells x 3 repeats): p_lift 0, 1/3, 1.
REPEAT_LIFTS = [0, 0, 0, 1, 0, 0, 1, 1, 1]


@pytest.fixture(scope='module')
def config() -> Any:
    return load_config(CONFIG)


@pytest.fixture(scope='module')
def analyzer(config: Any) -> LiftAnalyzer:
    return LiftAnalyzer(config)


def write_sweep(directory: Path, config: Any, sweep: SweepSpec, k_given: list[str] | None,
                outcome: Callable[[int], tuple[str, int]], n_rows: int | None = None) -> Path:
    """A sweep directory as ``sweep`` leaves it (its ``TrialTable`` writes the files), with
    the outcome of trial ``i`` from ``outcome(i)`` and the first ``n_rows`` trials (all when
    None); a lifted trial classed SUCCESS ends off the table, the other lifted ones on it."""
    info = {'axes_as_given': {'k_theta': k_given}} if k_given is not None else {}
    table = TrialTable(directory, sweep, config, info)
    columns = table_columns(config)
    with table:
        for spec in sweep.trials()[:n_rows]:
            name, lifted = outcome(spec.index)
            row = dict.fromkeys(columns, '0')
            row.update(input_columns(spec))
            row.update(outcome=name, lifted=str(lifted), phase='DONE', reason='',
                       rise_final_mm='12.0' if lifted else '0.0',
                       lift_off_time_s='2.5' if lifted else '',
                       off_table_at_end=str(int(lifted and name == 'SUCCESS')))
            table.append(row)
        table.finalize()
    return directory


@pytest.fixture(scope='module')
def marker_sweep(tmp_path_factory: pytest.TempPathFactory, config: Any) -> Path:
    """alpha 5 and 30 deg x k_theta 0.5:20:4:log x delta_theta_p 10, 30 deg: 16 trials."""
    sweep = SweepSpec(friction_angles_deg=(5.0, 30.0), k_theta=tuple(np.geomspace(0.5, 20, 4)),
                      delta_theta_p_deg=(10.0, 30.0))
    return write_sweep(tmp_path_factory.mktemp('markers'), config, sweep, ['0.5:20:4:log'],
                       lambda i: CLASSES[i % len(CLASSES)])


@pytest.fixture(scope='module')
def repeat_sweep(tmp_path_factory: pytest.TempPathFactory, config: Any) -> Path:
    """alpha 5 deg x k_theta 1:10:3 x delta_theta_p 20 deg, 3 repeats: 9 trials."""
    sweep = SweepSpec(friction_angles_deg=(5.0,), k_theta=(1.0, 5.5, 10.0),
                      delta_theta_p_deg=(20.0,), repeats=3)
    return write_sweep(tmp_path_factory.mktemp('repeats'), config, sweep, ['1:10:3'],
                       lambda i: ('SUCCESS' if REPEAT_LIFTS[i] else 'FAILURE',
                                  REPEAT_LIFTS[i]))


def _panels(fig: Any) -> list[Any]:
    return [ax for ax in fig.axes if str(ax.get_gid()).startswith('alpha=')]


def _by_gid(ax: Any, gid: str) -> Any:
    found = [c for c in [*ax.collections, *ax.lines, *ax.texts] if c.get_gid() == gid]
    assert len(found) <= 1, gid
    return found[0] if found else None


def _points(collection: Any) -> set[tuple[float, float]]:
    return {(round(float(x), 9), round(float(y), 9)) for x, y in collection.get_offsets()}


def _expected_boundaries(analyzer: LiftAnalyzer, alphas: list[float], dp_max_deg: float
                         ) -> tuple[np.ndarray, list[Any]]:
    """The documented grid (0 to min(1.1 x the sweep's largest delta_theta_p, the configured
    maximum)) and ``compute_boundaries`` on it."""
    right = min(1.1 * dp_max_deg, math.degrees(analyzer.model.delta_theta_p_max))
    grid = np.linspace(0.0, right, N_POINTS)
    return grid, compute_boundaries(analyzer, alphas, np.radians(grid), progress=False)


def _as_drawn(values: np.ndarray) -> np.ndarray:
    return np.where(np.isfinite(values), values, np.nan)


def test_markers_per_trial_and_the_boundaries(marker_sweep: Path, config: Any,
                                              analyzer: LiftAnalyzer, tmp_path: Path) -> None:
    out = tmp_path / 'fig7.png'
    result = plot_sweep(marker_sweep, out, config=config, analyzer=analyzer,
                        n_points=N_POINTS)
    fig = result.figure
    panels = _panels(fig)
    assert len(panels) == 2 and len(fig.axes) == 2  # one per friction angle, no colour bar
    assert [ax.get_gid() for ax in panels] == ['alpha=5', 'alpha=30']
    rows = list(csv.DictReader((marker_sweep / TABLE_FILE).open(encoding='utf-8')))
    grid, expected = _expected_boundaries(analyzer, [5.0, 30.0], 30.0)
    for ax, alpha, b in zip(panels, ('5', '30'), expected, strict=True):
        mine = [r for r in rows if r['friction_angle_deg'] == alpha]
        for outcome in OUTCOMES:
            chosen = [r for r in mine if r['outcome'] == outcome]
            drawn = _by_gid(ax, f'outcome:{outcome}')
            assert len(drawn.get_offsets()) == len(chosen) > 0
            assert _points(drawn) == {(round(float(r['delta_theta_p_deg']), 9),
                                       round(float(r['k_theta_nm_per_rad']), 9))
                                      for r in chosen}
        odd = [r for r in mine if (r['outcome'] != 'FAILURE') != (r['lifted'] == '1')]
        assert len(_by_gid(ax, 'disagree').get_offsets()) == len(odd) == 2
        sufficient, csm = _by_gid(ax, 'sufficient'), _by_gid(ax, 'csm')
        assert sufficient.get_linestyle() == '-' and csm.get_linestyle() == '--'
        for line, values in ((sufficient, b.sufficient), (csm, b.csm)):
            np.testing.assert_allclose(line.get_xdata(), grid, rtol=1e-12, atol=1e-12)
            np.testing.assert_allclose(line.get_ydata(), _as_drawn(values), rtol=1e-12,
                                       equal_nan=True)
        # the paper: at 30 deg eq. 18 has no solution, the CSM still lifts
        no_solution = not np.any(np.isfinite(b.sufficient))
        assert (_by_gid(ax, 'no_sufficient') is not None) == no_solution
        assert ax.get_yscale() == 'log'
        assert ax.get_ylim() == pytest.approx((0.5 / 1.6, 20.0 * 1.6))
        assert ax.get_xlim() == pytest.approx((0.0, 33.0))
        assert '[deg]' in ax.get_xlabel() and '[N*m/rad]' in ax.get_ylabel()
        assert alpha in ax.get_title()
    assert not np.any(np.isfinite(expected[1].sufficient))
    assert np.any(np.isfinite(expected[1].csm)) and np.any(np.isfinite(expected[0].sufficient))
    labels = [t.get_text() for t in panels[1].get_legend().get_texts()]
    assert labels == [f'{CLASS_LABELS[o]} ({o})' for o in OUTCOMES] + [
        DISAGREE_LABEL, SUFFICIENT_LABEL, CSM_LABEL]
    assert out.read_bytes()[:8] == PNG_MAGIC and out.stat().st_size > 20_000
    assert result.config_matches and result.log_k
    summary = '\n'.join(result.summary)
    assert '16 of 16 trials, 1 per cell, k_theta axis log' in summary
    # trials 0-7 at 5 deg, 8-15 at 30 deg, classes by trial number (CLASSES)
    for alpha in ('5', '30'):
        assert (f'alpha {alpha} deg: 8 trials, lifted (left the table) 5 (62 %), off the '
                f'table at the end 2, success 3 (1 of them never left the table), lifted but '
                f'DAM failed 2, failure 3 (1 of them did leave the table); ') in summary
    assert 'sufficient condition: no k_theta is guaranteed' in result.summary[2]
    assert '4 trials where the ground truth' in summary


def test_repeats_give_a_lift_probability_per_cell(repeat_sweep: Path, config: Any,
                                                  analyzer: LiftAnalyzer) -> None:
    result = plot_sweep(repeat_sweep, None, config=config, analyzer=analyzer,
                        n_points=N_POINTS)
    fig = result.figure
    [panel] = _panels(fig)
    assert len(fig.axes) == 2  # the panel and its colour bar
    cells = _by_gid(panel, 'p_lift')
    assert _points(cells) == {(20.0, 1.0), (20.0, 5.5), (20.0, 10.0)}
    assert sorted(zip(cells.get_offsets()[:, 1], cells.get_array(), strict=True)) == [
        (1.0, 0.0), (5.5, pytest.approx(1 / 3)), (10.0, 1.0)]
    assert cells.colorbar is not None and cells.colorbar.ax.get_ylabel() == P_LIFT_LABEL
    assert cells.get_clim() == (0.0, 1.0)
    for outcome in OUTCOMES:
        assert _by_gid(panel, f'outcome:{outcome}') is None
    assert panel.get_yscale() == 'linear' and panel.get_ylim() == pytest.approx((0.0, 11.0))
    labels = [t.get_text() for t in panel.get_legend().get_texts()]
    assert labels == [SUFFICIENT_LABEL, CSM_LABEL]
    assert ('alpha 5 deg: 9 trials, lifted (left the table) 4 (44 %), off the table at the '
            'end 4, success 4') in result.summary[1]
    assert '9 of 9 trials, 3 per cell, k_theta axis linear' in result.summary[0]


def test_a_boundary_outside_the_plotted_range_is_named(tmp_path: Path, config: Any,
                                                       analyzer: LiftAnalyzer) -> None:
    """k_theta up to 2 N*m/rad at alpha 5 deg: eq. 18 needs more (its lowest k* is about
    6 N*m/rad), so its line is off the axis and the panel says so, with its lowest value."""
    sweep = SweepSpec(friction_angles_deg=(5.0,), k_theta=(0.5, 2.0),
                      delta_theta_p_deg=(10.0, 25.0))
    d = write_sweep(tmp_path / 'low', config, sweep, None, lambda i: ('FAILURE', 0))
    result = plot_sweep(d, None, config=config, analyzer=analyzer, n_points=N_POINTS,
                        k_scale='log')
    [ax] = _panels(result.figure)
    [boundary] = _expected_boundaries(analyzer, [5.0], 25.0)[1]
    sufficient = np.asarray(boundary.sufficient, dtype=float)
    lowest = float(sufficient[np.isfinite(sufficient)].min())
    assert 5.0 < lowest < 7.0 and lowest > ax.get_ylim()[1]
    assert _by_gid(ax, 'outside').get_text() == (
        f'eq. 18 boundary above the plotted range (lowest k_theta* {lowest:.3g} N*m/rad)')


def test_a_last_row_with_all_its_fields_but_no_newline_is_still_being_written(
        tmp_path: Path, config: Any, analyzer: LiftAnalyzer) -> None:
    """The table's writer ends every row with a newline: a last row without one is cut short,
    even when the cut fell inside its last field (all columns present)."""
    sweep = SweepSpec(friction_angles_deg=(5.0,), k_theta=(1.0, 10.0),
                      delta_theta_p_deg=(20.0,))
    d = write_sweep(tmp_path / 'cut', config, sweep, None, lambda i: ('SUCCESS', 1))
    table = d / TABLE_FILE
    text = table.read_text(encoding='utf-8')
    assert text.endswith('\n')
    table.write_text(text[:-3], encoding='utf-8')  # inside the last row's last field
    result = plot_sweep(d, None, config=config, analyzer=analyzer, n_points=N_POINTS,
                        k_scale='log')
    assert result.data.skipped == 1 and len(result.data.trials) == 1


def test_a_sweep_still_running_and_another_configuration(tmp_path: Path, config: Any,
                                                        analyzer: LiftAnalyzer) -> None:
    sweep = SweepSpec(friction_angles_deg=(5.0, 30.0), k_theta=(1.0, 10.0),
                      delta_theta_p_deg=(20.0,))
    d = write_sweep(tmp_path / 'running', config, sweep, None,
                    lambda i: ('SUCCESS', 1), n_rows=2)
    with (d / TABLE_FILE).open('a', encoding='utf-8') as handle:
        handle.write('2,30,1,20,0,')  # the row being written
    heavier = dataclasses.replace(config, object=dataclasses.replace(config.object,
                                                                     mass_kg=0.05))
    result = plot_sweep(d, None, config=heavier, analyzer=analyzer, n_points=N_POINTS,
                        k_scale='log')
    assert result.data.skipped == 1 and len(_panels(result.figure)) == 1
    assert '2 of 4 trials' in result.summary[0] and 'left out' in result.summary[0]
    assert not result.config_matches
    assert 'other than the sweep' in result.figure.get_suptitle()
    assert _panels(result.figure)[0].get_yscale() == 'log'


@pytest.mark.parametrize(('tokens', 'values', 'log'), [
    (['0.05:20:24:log'], [], True), (['1', '2:8:3:LOG'], [], True), (['1:10:4'], [], False),
    (['0.5', '10'], [], False), (None, [0.5, 1.0, 2.0, 4.0], True),
    (None, [1.0, 2.0, 3.0], False), (None, [0.5, 10.0], False)])
def test_the_k_theta_axis_is_log_when_the_sweep_said_so(tokens: list[str] | None,
                                                        values: list[float], log: bool) -> None:
    params: dict[str, Any] = {'sweep': {'k_theta': values}}
    if tokens is not None:
        params['axes_as_given'] = {'k_theta': tokens}
    assert k_axis_is_log(params) is log


def _edit_row(column: str, value: str) -> Callable[[Path], None]:
    def edit(d: Path) -> None:
        text = (d / TABLE_FILE).read_text(encoding='utf-8').splitlines()
        header = text[0].split(',')
        cells = text[1].split(',')
        cells[header.index(column)] = value
        text[1] = ','.join(cells)
        (d / TABLE_FILE).write_text('\n'.join(text) + '\n', encoding='utf-8')
    return edit


@pytest.mark.parametrize(('edit', 'message'), [
    (lambda d: (d / TABLE_FILE).unlink(), 'trials.csv: no such file'),
    (lambda d: (d / PARAMS_FILE).unlink(), 'sweep.json: no such file'),
    (lambda d: (d / PARAMS_FILE).write_text('{', encoding='utf-8'), 'sweep.json: cannot read'),
    (lambda d: (d / TABLE_FILE).write_text('', encoding='utf-8'), 'trials.csv is empty'),
    (lambda d: (d / TABLE_FILE).write_text(
        (d / TABLE_FILE).read_text(encoding='utf-8').splitlines()[0] + '\n', encoding='utf-8'),
     'holds no trials'),
    (lambda d: (d / TABLE_FILE).write_text('trial,outcome\n0,SUCCESS\n', encoding='utf-8'),
     "no column 'friction_angle_deg'"),
    (_edit_row('outcome', 'LIFTED'), "outcome 'LIFTED' is not one of"),
    (_edit_row('lifted', 'yes'), "lifted 'yes' is not 0 or 1"),
    (_edit_row('k_theta_nm_per_rad', '-1'), "k_theta_nm_per_rad '-1' is not a number"),
    (_edit_row('friction_angle_deg', 'abc'), "friction_angle_deg 'abc' is not a number"),
])
def test_bad_sweep_directories_are_named(tmp_path: Path, config: Any,
                                         edit: Callable[[Path], None], message: str) -> None:
    sweep = SweepSpec(friction_angles_deg=(5.0,), k_theta=(1.0,), delta_theta_p_deg=(20.0,))
    d = write_sweep(tmp_path / 'sweep', config, sweep, ['1'], lambda i: ('SUCCESS', 1))
    read_sweep(d)
    edit(d)
    with pytest.raises(SweepPlotError) as info:
        read_sweep(d)
    assert message in str(info.value)


def test_outputs_that_cannot_be_written(tmp_path: Path) -> None:
    (tmp_path / 'file').write_text('x', encoding='utf-8')
    for path, message in ((tmp_path / 'fig7.xyz', "unknown picture format 'xyz'"),
                          (tmp_path, 'is a directory'),
                          (tmp_path / 'missing' / 'fig7.png', 'does not exist'),
                          (tmp_path / 'file' / 'fig7.png', 'is not a directory')):
        with pytest.raises(SweepPlotError) as info:
            check_output(Path(path))
        assert message in str(info.value)
    check_output(tmp_path / 'fig7.pdf')


def test_main_in_process(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(['--help'])
    assert info.value.code == 0
    text = capsys.readouterr().out
    assert all(o in text for o in ('DIR', '--output', '--config', '--k-scale'))
    assert main([str(tmp_path / 'nowhere'), '--ros-args', '-r', 'a:=b']) == 2
    err = capsys.readouterr().err
    assert err == f'sweep_plot: {tmp_path / "nowhere"}: no such directory\n'
    with pytest.raises(SystemExit) as info:
        main([str(tmp_path), '--n-delta-theta-p', '1'])
    assert info.value.code == 2
    assert "--n-delta-theta-p: 1 must be at least 2" in capsys.readouterr().err


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    exe = installed_executable('dam_experiments', 'sweep_plot')
    assert exe.is_file(), f'{exe} missing: build the workspace with scripts/setup.sh'
    return subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=120)


def test_installed_executable(marker_sweep: Path, tmp_path: Path) -> None:
    out = tmp_path / 'fig7.png'
    proc = _run(str(marker_sweep), '-o', str(out), '--config', str(CONFIG),
                '--n-delta-theta-p', '5')
    assert proc.returncode == 0, proc.stderr
    assert out.read_bytes()[:8] == PNG_MAGIC
    assert 'alpha 5 deg: 8 trials, lifted (left the table) 5' in proc.stdout
    assert 'alpha 30 deg: 8 trials, lifted (left the table) 5' in proc.stdout
    assert f'wrote {out}' in proc.stdout and proc.stderr == ''


def test_installed_executable_on_bad_input(marker_sweep: Path, tmp_path: Path) -> None:
    (tmp_path / 'empty').mkdir()
    (tmp_path / 'header').mkdir()
    header = (marker_sweep / TABLE_FILE).read_text(encoding='utf-8').splitlines()[0]
    (tmp_path / 'header' / TABLE_FILE).write_text(header + '\n', encoding='utf-8')
    (tmp_path / 'header' / PARAMS_FILE).write_bytes((marker_sweep / PARAMS_FILE).read_bytes())
    cases = [
        ([str(tmp_path / 'nowhere')], 'no such directory'),
        ([str(tmp_path / 'empty')], 'trials.csv: no such file'),
        ([str(tmp_path / 'header')], 'holds no trials'),
        ([str(marker_sweep), '-o', str(tmp_path / 'no' / 'fig7.png')], 'does not exist'),
    ]
    for args, message in cases:
        proc = _run(*args)
        assert proc.returncode == 2, (args, proc.stderr)
        lines = proc.stderr.splitlines()
        assert len(lines) == 1 and lines[0].startswith('sweep_plot: '), proc.stderr
        assert message in lines[0]
