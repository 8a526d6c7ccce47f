"""``lifted`` means that the object left the table: the lockstep trial, the sweep's table and
the tools that read it.

The trials are checked against PyBullet's own contact points, read here after every step
call of the trial's world (a subclass that only records them), and the rule applied by this
test's own code: a sample touches when a contact point of the object and the table is closer
than 0.1 mm; lift-off at the start of the first stretch of 50 ms with no touching sample;
lifted when no sample of the last 0.1 s touches. Four stand-in trials of the 18 mm hexagonal
bar: one that rolls on a vertex (its centroid rises 1.35 mm while it touches), one that leaves
the table, one that leaves it with a rise under ``classification.lift_height_m`` (5 mm) and
one cut short before any contact.
"""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import dam_sim_bridge.world as world_module
from dam_common.config import load_config
from dam_experiments.experiment import ExperimentResult, run_experiment
from dam_experiments.sweep import SweepSpec, input_columns, run_trial, table_columns
from dam_experiments.sweep_plot import main as plot_main
from dam_experiments.sweep_report import compute_report
from dam_experiments.sweep_report_cli import main as report_main
from dam_experiments.sweep_results import read_sweep
from dam_experiments.sweep_table import PARAMS_FILE, TABLE_FILE, TrialTable
from dam_sim_bridge.world import HandWorld
from dam_spcm_controller.sequence import Phase

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG = REPO_ROOT / 'config' / 'dam.yaml'
TOUCH_M = 1e-4  # the documented touch distance, written out here
NEW_COLUMNS = ('lift_off_time_s', 'rolling_up_end_s', 'estimated_rise_mm')


class ContactLog(HandWorld):
    """A world that records, after every step call, the simulated time, the smallest
    object-table contact distance (inf: no contact point) and the table's normal force."""

    def __init__(self, config: Any) -> None:
        self.log: list[tuple[float, float, float]] = []
        super().__init__(config)

    def step(self, n: int = 1) -> None:
        super().step(n)
        points = self.client.getContactPoints(self.object_id, self.table_id)
        self.log.append((self.sim_time, min((p[8] for p in points), default=math.inf),
                         sum(p[9] for p in points)))

    def gap_m(self) -> float:
        """Distance between the object and the table now (closest points within 1 cm)."""
        points = self.client.getClosestPoints(self.object_id, self.table_id, 0.01)
        return min((p[8] for p in points), default=math.inf)


def independent_lift_off(log: list[tuple[float, float, float]]) -> tuple[bool, float]:
    """(lifted at the end, lift-off time [s] or NaN) from the recorded contact distances."""
    t = np.array([row[0] for row in log])
    clear = np.array([row[1] > TOUCH_M for row in log])
    lift_off = math.nan
    for i in np.flatnonzero(clear):
        if i > 0 and clear[i - 1]:
            continue  # not the start of a clear stretch
        j = i
        while j + 1 < len(t) and clear[j + 1]:
            j += 1
        if t[j] - t[i] >= 0.05 - 1e-9:
            lift_off = float(t[i])
            break
    window = t >= t[-1] - 0.1 - 1e-9
    lifted = bool(np.all(clear[window]) and t[-1] - t[0] >= 0.1
                  and not np.isnan(lift_off) and lift_off <= t[-1] - 0.1 + 1e-9)
    return lifted, lift_off


@pytest.fixture(scope='module')
def hex_config() -> Any:
    return load_config(CONFIG).with_object('hex_bar')


@pytest.fixture(scope='module')
def rolled(hex_config: Any) -> tuple[ExperimentResult, ContactLog, float]:
    """alpha 5 deg, k_theta 7, delta_theta_p 5 deg: the bar turns on a vertex."""
    world = ContactLog(hex_config)
    try:
        result = run_experiment(hex_config, 7.0, math.radians(5.0), world=world,
                                friction_angle=math.radians(5.0), max_time=8.0)
        gap = world.gap_m()
    finally:
        world.close()
    return result, world, gap


@pytest.fixture(scope='module')
def left(hex_config: Any) -> tuple[ExperimentResult, ContactLog, float]:
    """alpha 10 deg, k_theta 5, delta_theta_p 10 deg: the bar leaves the table."""
    world = ContactLog(hex_config)
    try:
        result = run_experiment(hex_config, 5.0, math.radians(10.0), world=world,
                                friction_angle=math.radians(10.0), max_time=8.0)
        gap = world.gap_m()
    finally:
        world.close()
    return result, world, gap


def test_a_bar_that_rolls_on_the_table_is_not_lifted(rolled: Any) -> None:
    result, world, gap = rolled
    lifted, lift_off = independent_lift_off(world.log)
    assert result.phase is Phase.DONE
    assert not lifted and not result.lifted
    # it rose as a hexagon turning on a vertex does while it touches, and the table carries it
    assert 0.001 < result.lift_final < 0.005 and result.lift_max < 0.005
    assert gap <= TOUCH_M and world.log[-1][2] > 0.05  # normal force [N] at the end
    if math.isnan(lift_off):
        assert math.isnan(result.lift_off_time)
    else:  # it may hop off the vertex on the way and fall back: that lift-off is recorded
        assert result.lift_off_time == pytest.approx(lift_off, abs=1e-9)


def test_a_bar_that_leaves_the_table_is_lifted(left: Any) -> None:
    result, world, gap = left
    lifted, lift_off = independent_lift_off(world.log)
    assert lifted and result.lifted
    assert result.lift_off_time == pytest.approx(lift_off, abs=1e-9)
    assert 0.5 < result.lift_off_time < result.sim_time - 0.1
    assert gap > 0.001 and world.log[-1][2] == 0.0  # clear of the table, no table force
    # the lift-off falls in the grasp: after the approach, before the end
    assert result.phase_times['ROLLING_UP'] < result.lift_off_time
    assert result.estimated_rise == result.estimated_rise  # classified: a number


def test_a_bar_off_the_table_with_a_rise_under_the_lift_height_is_lifted_in_the_table(
        hex_config: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """alpha 5 deg, k_theta 10, delta_theta_p 5 deg through the sweep's trial and table: the
    bar leaves the table but rises less than 5 mm; lifted all the same. The row is read back
    with the csv module."""
    worlds: list[ContactLog] = []

    def make(config: Any, options: Any = None) -> ContactLog:
        worlds.append(ContactLog(config))
        return worlds[-1]

    sweep = SweepSpec(objects=('hex_bar',), friction_angles_deg=(5.0,), k_theta=(10.0,),
                      delta_theta_p_deg=(5.0,), max_time_s=8.0)
    config = load_config(CONFIG)
    monkeypatch.setattr(world_module, 'HandWorld', make)
    [spec] = sweep.trials()
    row = run_trial(spec, sweep, config).row
    monkeypatch.undo()
    [world] = worlds
    lifted, lift_off = independent_lift_off(world.log)
    with TrialTable(tmp_path / 'sweep', sweep, config) as table:
        table.append(row)
        table.finalize()
    with (tmp_path / 'sweep' / TABLE_FILE).open(encoding='utf-8', newline='') as handle:
        reader = csv.DictReader(handle)
        [read] = list(reader)
        header = reader.fieldnames
    assert header == table_columns(config)
    assert header.index('lifted') < header.index('lift_off_time_s') < header.index(
        'rolling_up_end_s') < header.index('rise_final_mm')
    assert header.index('rise_rolling_end_mm') < header.index('estimated_rise_mm')
    assert lifted and read['lifted'] == '1'
    assert float(read['rise_final_mm']) < 5.0 < 1e3 * hex_config.classification.lift_height_m \
        + 1e-9
    assert float(read['lift_off_time_s']) == pytest.approx(lift_off, abs=5e-4)
    assert read['phase'] == 'DONE' and math.isfinite(float(read['estimated_rise_mm']))
    rolling_end = float(read['rolling_up_end_s'])
    assert float(read['lift_off_time_s']) < rolling_end < float(read['sim_time_s'])
    data = read_sweep(tmp_path / 'sweep')
    assert data.lift_off_recorded and data.lifted_note is None
    assert data.trials[0].lifted and data.trials[0].lift_off_time_s == float(
        read['lift_off_time_s'])


def test_a_grasp_not_classified_has_no_estimate_and_no_lift_off(tmp_path: Path) -> None:
    """A trial cut at 0.6 s (still approaching): estimated_rise_mm and lift_off_time_s are
    empty, lifted is 0."""
    sweep = SweepSpec(friction_angles_deg=(5.0,), k_theta=(2.0,), delta_theta_p_deg=(10.0,),
                      max_time_s=0.6)
    config = load_config(CONFIG)
    [spec] = sweep.trials()
    row = run_trial(spec, sweep, config).row
    with TrialTable(tmp_path / 'sweep', sweep, config) as table:
        table.append(row)
        table.finalize()
    with (tmp_path / 'sweep' / TABLE_FILE).open(encoding='utf-8', newline='') as handle:
        [read] = list(csv.DictReader(handle))
    assert read['phase'] == 'APPROACH' and read['lifted'] == '0'
    assert read['estimated_rise_mm'] == '' and read['lift_off_time_s'] == ''
    assert read['rolling_up_end_s'] == 'nan'
    cells = (tmp_path / 'sweep' / 'cells.csv').read_text(encoding='utf-8').splitlines()
    assert len(cells) == 2 and ',0,0,' in cells[1]  # one trial, none lifted


# ------------------------------------------------------------------------------------------
# Tables written here: the report's classes by lift-off, and a table of format 1


def _small_sweep(directory: Path, config: Any, rows: dict[float, dict[str, str]]) -> Path:
    """A sweep of alpha 5 deg, delta_theta_p 10 deg and the k_theta of ``rows``, each row
    the values of that trial over a neutral default."""
    sweep = SweepSpec(friction_angles_deg=(5.0,), k_theta=tuple(rows),
                      delta_theta_p_deg=(10.0,))
    with TrialTable(directory, sweep, config) as table:
        for spec in sweep.trials():
            row = dict.fromkeys(table_columns(config), '0')
            row.update(input_columns(spec), phase='DONE', reason='x', object_mass_kg='0.04',
                       lift_off_time_s='', rolling_up_end_s='4.5', estimated_rise_mm='0.0')
            row.update(rows[spec.k_theta])
            table.append(row)
        table.finalize()
    return directory


ROWS = {
    # rolled on a vertex: rose 1.35 mm on the table; the controller says lifted
    1.0: {'outcome': 'SUCCESS', 'lifted': '0', 'rise_final_mm': '1.35', 'rise_max_mm': '1.35',
          'estimated_rise_mm': '6.0'},
    # left the table at 2.6 s and fell back
    2.0: {'outcome': 'FAILURE', 'lifted': '0', 'lift_off_time_s': '2.6',
          'rise_final_mm': '0.5', 'rise_max_mm': '6.0'},
    # off the table with 4 mm: lifted, classed FAILURE
    4.0: {'outcome': 'FAILURE', 'lifted': '1', 'lift_off_time_s': '2.5',
          'rise_final_mm': '4.0', 'rise_max_mm': '4.0', 'estimated_rise_mm': '0.2'},
    # lifted only after ROLLING_UP ended
    8.0: {'outcome': 'SUCCESS', 'lifted': '1', 'lift_off_time_s': '4.75',
          'rise_final_mm': '8.0', 'rise_max_mm': '8.0', 'estimated_rise_mm': '8.0'},
}


def test_the_report_classes_trials_by_lift_off(tmp_path: Path) -> None:
    config = load_config(CONFIG)
    d = _small_sweep(tmp_path / 'sweep', config, ROWS)
    report = compute_report(read_sweep(d), config, n_points=5)
    from dam_experiments.sweep_report_rows import checks, read_rows, rise_class

    rows = {t.k_theta: t for t in read_rows(read_sweep(d))}
    h = report.limits.lift_height_mm
    assert {k: rise_class(t, h) for k, t in rows.items()} == {
        1.0: 'rose on the table', 2.0: 'left the table, then fell back', 4.0: 'lifted',
        8.0: 'lifted after the rolling-up phase'}
    assert 'fell back' in checks(rows[2.0], math.nan, (), False, report.limits)
    assert 'fell back' not in checks(rows[1.0], math.nan, (), False, report.limits)
    assert checks(rows[8.0], math.nan, (), True, report.limits) == ['lifted after rolling-up']
    out = tmp_path / 'results.md'
    assert report_main([str(d), '-o', str(out), '--config', str(CONFIG),
                        '--n-delta-theta-p', '5']) == 0
    text = out.read_text(encoding='utf-8')
    section = text.split('## 5.', 1)[1]
    assert 'The 2 trial(s) where they differ' in section
    odd = [line for line in section.splitlines() if line.startswith('| 5 | ')
           and ('SUCCESS' in line or 'FAILURE' in line)]
    assert len(odd) == 2
    assert '| 1 | 10 | 0 | SUCCESS | no | - | 1.35 | 6 | rose on the table |' in odd[0]
    assert '| 4 | 10 | 0 | FAILURE | yes | 2.5 | 4 | 0.2 | lifted |' in odd[1]
    assert 'left the table' in text.split('## Definitions', 1)[1].split('\n', 3)[2]


def _to_format_1(directory: Path) -> None:
    """Make a sweep directory what a sweep of format 1 wrote: no lift-off columns."""
    with (directory / TABLE_FILE).open(encoding='utf-8', newline='') as handle:
        rows = list(csv.DictReader(handle))
    columns = [c for c in rows[0] if c not in NEW_COLUMNS]
    with (directory / TABLE_FILE).open('w', encoding='utf-8', newline='') as handle:
        writer = csv.DictWriter(handle, columns, extrasaction='ignore', lineterminator='\n')
        writer.writeheader()
        writer.writerows(rows)
    params = json.loads((directory / PARAMS_FILE).read_text(encoding='utf-8'))
    params['format'] = 1
    params['columns'] = columns
    (directory / PARAMS_FILE).write_text(json.dumps(params), encoding='utf-8')


def test_a_table_of_format_1_is_read_with_a_note(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Its lifted is the old 5 mm rule: the tools read it, each with one line saying so, and
    the report classes its trials by the old rule."""
    config = load_config(CONFIG)
    old = {1.0: {'outcome': 'SUCCESS', 'lifted': '0', 'rise_final_mm': '1.0',
                 'rise_max_mm': '6.0'},
           2.0: {'outcome': 'FAILURE', 'lifted': '0', 'rise_final_mm': '1.5',
                 'rise_max_mm': '2.0'},
           4.0: {'outcome': 'SUCCESS', 'lifted': '1', 'rise_final_mm': '8.0',
                 'rise_max_mm': '8.0'}}
    d = _small_sweep(tmp_path / 'sweep', config, old)
    _to_format_1(d)
    data = read_sweep(d)
    assert not data.lift_off_recorded and [t.lifted for t in data.trials] == [0, 0, 1]
    assert all(math.isnan(t.lift_off_time_s) for t in data.trials)
    note = data.lifted_note
    assert note is not None and 'old rule' in note and "'lift_off_time_s'" in note
    assert plot_main([str(d), '-o', str(tmp_path / 'fig.png'), '--config', str(CONFIG),
                      '--n-delta-theta-p', '5']) == 0
    captured = capsys.readouterr()
    assert captured.err == f'sweep_plot: note: {note}\n'
    assert 'lifted (format 1: the old rise rule) 1' in captured.out
    out = tmp_path / 'results.md'
    assert report_main([str(d), '-o', str(out), '--config', str(CONFIG),
                        '--n-delta-theta-p', '5']) == 0
    assert capsys.readouterr().err == f'sweep_report: note: {note}\n'
    text = out.read_text(encoding='utf-8')
    assert '**A table of format 1: its `lifted` is the old rule**' in text
    assert '| SUCCESS | no | - | 1 | - | rose then fell back |' in text
    from dam_experiments.calibrate_csm import cells_from_sweep

    _cells, _config, _label, notes = cells_from_sweep(d, config, None)
    assert note in notes
