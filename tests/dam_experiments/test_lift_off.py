"""``lifted`` means that the object left the table during the grasp (a lift-off); being off
the table at the end is a separate fact, ``off_table_at_end``: the lockstep trial, the sweep's
table and the tools that read it.

The trials are checked against PyBullet's own contact points, read here after every step
call of the trial's world (a subclass that only records them), and the rule applied by this
test's own code: a sample touches when a contact point of the object and the table is closer
than 0.1 mm; lift-off at the start of the first stretch of 50 ms with no touching sample
(lifted); off the table at the end when no sample of the last 0.1 s touches. Stand-in trials:
the 18 mm hexagonal bar that hops off a vertex and falls back, one that leaves the table, one
that leaves it with a rise under ``classification.lift_height_m`` (5 mm), the cylinder that
leaves the table and tips out of the plane until one end rests on it, and a trial cut short
before any contact.
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
#: Columns a table of format 1 lacks.
NEW_COLUMNS = ('lift_off_time_s', 'off_table_at_end', 'rolling_up_end_s', 'estimated_rise_mm')


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


def independent_lift_off(log: list[tuple[float, float, float]]) -> tuple[float, float, bool]:
    """(lift-off time [s] or NaN, end of that stretch off the table [s] or NaN, off the table
    over the last 0.1 s) from the recorded contact distances."""
    t = np.array([row[0] for row in log])
    clear = np.array([row[1] > TOUCH_M for row in log])
    lift_off = stretch_end = math.nan
    for i in np.flatnonzero(clear):
        if i > 0 and clear[i - 1]:
            continue  # not the start of a clear stretch
        j = i
        while j + 1 < len(t) and clear[j + 1]:
            j += 1
        if t[j] - t[i] >= 0.05 - 1e-9:
            lift_off, stretch_end = float(t[i]), float(t[j])
            break
    window = t >= t[-1] - 0.1 - 1e-9
    at_end = bool(np.all(clear[window]) and t[-1] - t[0] >= 0.1
                  and not np.isnan(lift_off) and lift_off <= t[-1] - 0.1 + 1e-9)
    return lift_off, stretch_end, at_end


def _grasp(config: Any, k_theta: float, dp_deg: float, alpha_deg: float
           ) -> tuple[ExperimentResult, ContactLog, float, Any]:
    """One lockstep trial in a :class:`ContactLog` world (8 s limit): the result, the world's
    log, the object-table gap at the end [m] and the contact points at the end."""
    world = ContactLog(config)
    try:
        result = run_experiment(config, k_theta, math.radians(dp_deg), world=world,
                                friction_angle=math.radians(alpha_deg), max_time=8.0)
        gap = world.gap_m()
        pose = world.object_pose()
        points = world.client.getContactPoints(world.object_id, world.table_id)
        rotation = np.array(world.client.getMatrixFromQuaternion(pose.quaternion)).reshape(3, 3)
    finally:
        world.close()
    return result, world, gap, (pose.position, rotation, points)


@pytest.fixture(scope='module')
def hex_config() -> Any:
    return load_config(CONFIG).with_object('hex_bar')


@pytest.fixture(scope='module')
def hopped(hex_config: Any) -> Any:
    """alpha 5 deg, k_theta 7, delta_theta_p 5 deg: the bar turns on a vertex, hops off the
    table for a quarter second and falls back."""
    return _grasp(hex_config, 7.0, 5.0, 5.0)


@pytest.fixture(scope='module')
def left(hex_config: Any) -> Any:
    """alpha 10 deg, k_theta 5, delta_theta_p 10 deg: the bar leaves the table."""
    return _grasp(hex_config, 5.0, 10.0, 10.0)


@pytest.fixture(scope='module')
def tipped() -> Any:
    """The cylinder at alpha 5 deg, k_theta 15, delta_theta_p 15 deg: it leaves the table and
    tips out of the plane until one end rests on it."""
    return _grasp(load_config(CONFIG).with_object('cylinder'), 15.0, 15.0, 5.0)


def test_a_bar_that_hops_off_the_table_and_falls_back_is_lifted_not_off_at_the_end(
        hopped: Any) -> None:
    result, world, gap, _ = hopped
    lift_off, stretch_end, at_end = independent_lift_off(world.log)
    assert result.phase is Phase.DONE
    # off the table for a quarter second in the middle of the grasp: a lift-off
    assert result.lifted and result.lift_off_time == pytest.approx(lift_off, abs=1e-9)
    assert 0.2 < stretch_end - lift_off < 0.5
    assert result.phase_times['ROLLING_UP'] < lift_off < result.sim_time - 1.0
    # back on the table at the end, carried by it: not off the table at the end
    assert not at_end and not result.off_table_at_end
    assert gap <= TOUCH_M and world.log[-1][2] > 0.05  # normal force [N] at the end
    # it rose as a hexagon turning on a vertex does, under the lift height
    assert 0.001 < result.lift_final < 0.005 and result.lift_max < 0.005


def test_a_bar_that_leaves_the_table_is_lifted_and_off_it_at_the_end(left: Any) -> None:
    result, world, gap, _ = left
    lift_off, _, at_end = independent_lift_off(world.log)
    assert result.lifted and at_end and result.off_table_at_end
    assert result.lift_off_time == pytest.approx(lift_off, abs=1e-9)
    assert 0.5 < result.lift_off_time < result.sim_time - 0.1
    assert gap > 0.001 and world.log[-1][2] == 0.0  # clear of the table, no table force
    # the lift-off falls in the grasp: after the approach, before the end
    assert result.phase_times['ROLLING_UP'] < result.lift_off_time
    assert result.estimated_rise == result.estimated_rise  # classified: a number


def test_a_cylinder_that_lifts_off_and_ends_on_one_end_is_lifted_not_off_at_the_end(
        tipped: Any) -> None:
    """The contact points at the end, read here, lie on the rim of one end face (half the
    length along the axis, one radius from it) and the axis is tilted out of the table's
    plane: a 3-D motion after the lift-off that the planar analysis does not speak of."""
    result, world, gap, (position, rotation, points) = tipped
    lift_off, stretch_end, at_end = independent_lift_off(world.log)
    assert result.lifted and result.lift_off_time == pytest.approx(lift_off, abs=1e-9)
    assert stretch_end - lift_off > 0.1 and lift_off > result.phase_times['ROLLING_UP']
    assert not at_end and not result.off_table_at_end
    assert gap <= TOUCH_M and points
    # the axis now: the body's rotation applied to the resting axis (world y at the reset)
    with HandWorld(load_config(CONFIG).with_object('cylinder')) as fresh:
        resting = np.array(fresh.client.getMatrixFromQuaternion(
            fresh.object_pose().quaternion)).reshape(3, 3)
    axis = rotation @ resting.T @ np.array([0.0, 1.0, 0.0])
    assert abs(axis[2]) > math.sin(math.radians(5.0))  # tilted out of the plane
    for p in points:
        d = np.asarray(p[5]) - np.asarray(position)
        along = float(d @ axis)
        assert abs(along) == pytest.approx(0.03, abs=1e-3)  # half of the 60 mm length
        assert np.linalg.norm(d - along * axis) == pytest.approx(0.010, abs=1e-3)  # radius
    assert len({np.sign(float((np.asarray(p[5]) - position) @ axis)) for p in points}) == 1
    # it rose more than the lift height, resting on one end
    assert result.lift_final > 0.005


def test_a_bar_off_the_table_with_a_rise_under_the_lift_height_is_lifted_in_the_table(
        hex_config: Any, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """alpha 5 deg, k_theta 10, delta_theta_p 5 deg through the sweep's trial and table: the
    bar leaves the table but rises less than 5 mm; lifted all the same, and off the table at
    the end. The row is read back with the csv module."""
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
    lift_off, _, at_end = independent_lift_off(world.log)
    with TrialTable(tmp_path / 'sweep', sweep, config) as table:
        table.append(row)
        table.finalize()
    with (tmp_path / 'sweep' / TABLE_FILE).open(encoding='utf-8', newline='') as handle:
        reader = csv.DictReader(handle)
        [read] = list(reader)
        header = reader.fieldnames
    assert header == table_columns(config)
    assert header.index('lifted') < header.index('lift_off_time_s') < header.index(
        'off_table_at_end') < header.index('rolling_up_end_s') < header.index('rise_final_mm')
    assert header.index('rise_rolling_end_mm') < header.index('estimated_rise_mm')
    assert not math.isnan(lift_off) and read['lifted'] == '1'
    assert at_end and read['off_table_at_end'] == '1'
    assert float(read['rise_final_mm']) < 5.0 < 1e3 * hex_config.classification.lift_height_m \
        + 1e-9
    assert float(read['lift_off_time_s']) == pytest.approx(lift_off, abs=5e-4)
    assert read['phase'] == 'DONE' and math.isfinite(float(read['estimated_rise_mm']))
    rolling_end = float(read['rolling_up_end_s'])
    assert float(read['lift_off_time_s']) < rolling_end < float(read['sim_time_s'])
    data = read_sweep(tmp_path / 'sweep')
    assert data.table_format == 3 and data.lifted_note is None
    assert data.trials[0].lifted and data.trials[0].off_table_at_end is True
    assert data.trials[0].lift_off_time_s == float(read['lift_off_time_s'])
    cells = (tmp_path / 'sweep' / 'cells.csv').read_text(encoding='utf-8').splitlines()
    cell = dict(zip(cells[0].split(','), cells[1].split(','), strict=True))
    assert (cell['trials'], cell['lifted'], cell['off_table_at_end']) == ('1', '1', '1')


def test_a_grasp_not_classified_has_no_estimate_and_no_lift_off(tmp_path: Path) -> None:
    """A trial cut at 0.6 s (still approaching): estimated_rise_mm and lift_off_time_s are
    empty, lifted and off_table_at_end are 0."""
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
    assert read['off_table_at_end'] == '0'
    assert read['estimated_rise_mm'] == '' and read['lift_off_time_s'] == ''
    assert read['rolling_up_end_s'] == 'nan'
    cells = (tmp_path / 'sweep' / 'cells.csv').read_text(encoding='utf-8').splitlines()
    cell = dict(zip(cells[0].split(','), cells[1].split(','), strict=True))
    assert len(cells) == 2 and (cell['trials'], cell['lifted'], cell['off_table_at_end']) == (
        '1', '0', '0')


# ------------------------------------------------------------------------------------------
# Tables written here: the report's classes by lift-off, and tables of formats 1 and 2


def _small_sweep(directory: Path, config: Any, rows: dict[float, dict[str, str]]) -> Path:
    """A sweep of alpha 5 deg, delta_theta_p 10 deg and the k_theta of ``rows``, each row
    the values of that trial over a neutral default."""
    sweep = SweepSpec(friction_angles_deg=(5.0,), k_theta=tuple(rows),
                      delta_theta_p_deg=(10.0,))
    with TrialTable(directory, sweep, config) as table:
        for spec in sweep.trials():
            row = dict.fromkeys(table_columns(config), '0')
            row.update(input_columns(spec), phase='DONE', reason='x', object_mass_kg='0.04',
                       lift_off_time_s='', off_table_at_end='0', rolling_up_end_s='4.5',
                       estimated_rise_mm='0.0')
            row.update(rows[spec.k_theta])
            table.append(row)
        table.finalize()
    return directory


ROWS = {
    # rolled on a vertex: rose 1.35 mm on the table; the controller says lifted
    1.0: {'outcome': 'SUCCESS', 'lifted': '0', 'rise_final_mm': '1.35', 'rise_max_mm': '1.35',
          'estimated_rise_mm': '6.0'},
    # left the table at 2.6 s and fell back (or an end came to rest on it)
    2.0: {'outcome': 'FAILURE', 'lifted': '1', 'lift_off_time_s': '2.6',
          'rise_final_mm': '0.5', 'rise_max_mm': '6.0'},
    # never rose
    3.0: {'outcome': 'FAILURE', 'lifted': '0', 'rise_final_mm': '0.1', 'rise_max_mm': '0.2'},
    # off the table with 4 mm to the end: lifted, classed FAILURE
    4.0: {'outcome': 'FAILURE', 'lifted': '1', 'lift_off_time_s': '2.5',
          'off_table_at_end': '1', 'rise_final_mm': '4.0', 'rise_max_mm': '4.0',
          'estimated_rise_mm': '0.2'},
    # lifted only after ROLLING_UP ended, held off the table
    8.0: {'outcome': 'SUCCESS', 'lifted': '1', 'lift_off_time_s': '4.75',
          'off_table_at_end': '1', 'rise_final_mm': '8.0', 'rise_max_mm': '8.0',
          'estimated_rise_mm': '8.0'},
}


def test_the_report_classes_trials_by_lift_off(tmp_path: Path) -> None:
    config = load_config(CONFIG)
    d = _small_sweep(tmp_path / 'sweep', config, ROWS)
    report = compute_report(read_sweep(d), config, n_points=5)
    from dam_experiments.sweep_report_rows import checks, read_rows, rise_class

    rows = {t.k_theta: t for t in read_rows(read_sweep(d))}
    h = report.limits.lift_height_mm
    assert {k: rise_class(t, h) for k, t in rows.items()} == {
        1.0: 'rose on the table',
        2.0: 'lifted, then fell back or an end came to rest on the table',
        3.0: 'never rose', 4.0: 'lifted and held off the table',
        8.0: 'lifted and held off the table'}
    assert checks(rows[2.0], math.nan, (), True, report.limits) == ['not held']
    assert checks(rows[4.0], math.nan, (), True, report.limits) == []
    assert checks(rows[8.0], math.nan, (), True, report.limits) == ['lifted after rolling-up']
    assert checks(rows[1.0], math.nan, (), False, report.limits) == []
    # the cell lifts by lift-off: p_lift 1 for the trial that fell back
    assert {c.k_theta: c.lifts for c in report.cells} == {
        1.0: False, 2.0: True, 3.0: False, 4.0: True, 8.0: True}
    out = tmp_path / 'results.md'
    assert report_main([str(d), '-o', str(out), '--config', str(CONFIG),
                        '--n-delta-theta-p', '5']) == 0
    text = out.read_text(encoding='utf-8')
    section = text.split('## 5.', 1)[1]
    assert 'The 3 trials where they differ' in section
    odd = [line for line in section.splitlines() if line.startswith('| 5 | ')
           and ('SUCCESS' in line or 'FAILURE' in line)]
    assert len(odd) == 3
    assert '| 1 | 10 | 0 | SUCCESS | no | - | no | 1.35 | 6 | rose on the table |' in odd[0]
    assert ('| 2 | 10 | 0 | FAILURE | yes | 2.6 | no | 0.5 | 0 | lifted, then fell back or '
            'an end came to rest on the table |') in odd[1]
    assert ('| 4 | 10 | 0 | FAILURE | yes | 2.5 | yes | 4 | 0.2 | lifted and held off the '
            'table |') in odd[2]
    definitions = text.split('## Definitions', 1)[1].split('\n', 3)[2]
    assert 'left the table during the grasp' in definitions
    assert '`off_table_at_end`' in definitions


def _rewrite(directory: Path, table_format: int, change: Any) -> None:
    """Make a sweep directory what a sweep of ``table_format`` wrote: ``change(rows)`` gives
    the rows and their columns."""
    with (directory / TABLE_FILE).open(encoding='utf-8', newline='') as handle:
        rows = list(csv.DictReader(handle))
    rows, columns = change(rows)
    with (directory / TABLE_FILE).open('w', encoding='utf-8', newline='') as handle:
        writer = csv.DictWriter(handle, columns, extrasaction='ignore', lineterminator='\n')
        writer.writeheader()
        writer.writerows(rows)
    params = json.loads((directory / PARAMS_FILE).read_text(encoding='utf-8'))
    params['format'] = table_format
    params['columns'] = columns
    (directory / PARAMS_FILE).write_text(json.dumps(params), encoding='utf-8')


def _to_format_1(rows: list[dict[str, str]]) -> tuple[list[dict[str, str]], list[str]]:
    """No lift-off columns."""
    return rows, [c for c in rows[0] if c not in NEW_COLUMNS]


def _to_format_2(rows: list[dict[str, str]]) -> tuple[list[dict[str, str]], list[str]]:
    """No column off_table_at_end; lifted meant off the table at the end."""
    for row in rows:
        row['lifted'] = row['off_table_at_end']
    return rows, [c for c in rows[0] if c != 'off_table_at_end']



def _plot_and_report(d: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
                     note: str) -> tuple[str, str]:
    """sweep_plot's standard output and sweep_report's document for ``d``, each tool having
    printed the table's note as its one line on standard error."""
    assert plot_main([str(d), '-o', str(tmp_path / 'fig.png'), '--config', str(CONFIG),
                      '--n-delta-theta-p', '5']) == 0
    captured = capsys.readouterr()
    assert captured.err == f'sweep_plot: note: {note}\n'
    out = tmp_path / 'results.md'
    assert report_main([str(d), '-o', str(out), '--config', str(CONFIG),
                        '--n-delta-theta-p', '5']) == 0
    assert capsys.readouterr().err == f'sweep_report: note: {note}\n'
    return captured.out, out.read_text(encoding='utf-8')

def test_a_table_of_format_2_is_read_with_a_note(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Its lifted meant off the table at the end: read as off_table_at_end, and lifted from
    the lift-off times; the tools say so in one line, and the trials and the report's classes
    are those of the same table in format 3."""
    config = load_config(CONFIG)
    d = _small_sweep(tmp_path / 'sweep', config, ROWS)
    new = read_sweep(d)
    _rewrite(d, 2, _to_format_2)
    with (d / TABLE_FILE).open(encoding='utf-8', newline='') as handle:
        assert [r['lifted'] for r in csv.DictReader(handle)] == ['0', '0', '0', '1', '1']
    data = read_sweep(d)
    assert data.table_format == 2 and data.lift_off_recorded
    assert data.trials == new.trials
    assert [t.lifted for t in data.trials] == [False, True, False, True, True]
    assert [t.off_table_at_end for t in data.trials] == [False, False, False, True, True]
    note = data.lifted_note
    assert note is not None and "'off_table_at_end'" in note and 'format 3' in note
    from dam_experiments.sweep_report_rows import read_rows, rise_class

    h = 1e3 * config.classification.lift_height_m
    assert [rise_class(t, h) for t in read_rows(data)] == [rise_class(t, h)
                                                           for t in read_rows(new)]
    plotted, text = _plot_and_report(d, tmp_path, capsys, note)
    assert 'lifted (left the table) 3 (60 %), off the table at the end 2,' in plotted
    assert '**A table of format 2: its `lifted` meant off the table' in text
    from dam_experiments.calibrate_csm import cells_from_sweep, cells_of_sweep

    _cells, _config, _label, notes = cells_from_sweep(d, config, None)
    assert note in notes
    assert cells_of_sweep(data, config)[0].lifted.tolist() == [0.0, 1.0, 0.0, 1.0, 1.0]


def test_a_table_of_format_1_is_read_with_a_note(tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    """Its lifted is the old 5 mm rule: the tools read it, each with one line saying so, and
    the report classes its trials by the old rule."""
    config = load_config(CONFIG)
    old = {1.0: {'outcome': 'SUCCESS', 'lifted': '0', 'rise_final_mm': '1.0',
                 'rise_max_mm': '6.0'},
           2.0: {'outcome': 'FAILURE', 'lifted': '0', 'rise_final_mm': '1.5',
                 'rise_max_mm': '2.0'},
           4.0: {'outcome': 'SUCCESS', 'lifted': '1', 'lift_off_time_s': '2.0',
                 'rise_final_mm': '8.0', 'rise_max_mm': '8.0'}}
    d = _small_sweep(tmp_path / 'sweep', config, old)
    _rewrite(d, 1, _to_format_1)
    data = read_sweep(d)
    assert data.table_format == 1 and not data.lift_off_recorded
    assert [t.lifted for t in data.trials] == [0, 0, 1]
    assert all(math.isnan(t.lift_off_time_s) for t in data.trials)
    assert all(t.off_table_at_end is None for t in data.trials)
    note = data.lifted_note
    assert note is not None and 'old rule' in note and "'lift_off_time_s'" in note
    plotted, text = _plot_and_report(d, tmp_path, capsys, note)
    assert 'lifted (format 1: the old rise rule) 1 (33 %), success' in plotted
    assert '**A table of format 1: its `lifted` is the old rule**' in text
    assert '| SUCCESS | no | - | - | 1 | - | rose then fell back |' in text
    from dam_experiments.calibrate_csm import cells_from_sweep

    _cells, _config, _label, notes = cells_from_sweep(d, config, None)
    assert note in notes


@pytest.mark.parametrize(('change', 'message'), [
    ({'lifted': '0', 'lift_off_time_s': '2.0'}, "lift_off_time_s '2.0' with lifted '0'"),
    ({'lifted': '1', 'lift_off_time_s': ''}, 'lifted 1 without a lift_off_time_s'),
    ({'off_table_at_end': '1'}, 'off_table_at_end 1 with lifted 0'),
    ({'off_table_at_end': 'yes'}, "off_table_at_end 'yes' is not 0 or 1"),
])
def test_a_row_whose_lift_columns_contradict_is_refused_by_name(
        tmp_path: Path, change: dict[str, str], message: str) -> None:
    from dam_experiments.errors import SweepPlotError

    d = _small_sweep(tmp_path / 'sweep', load_config(CONFIG), {1.0: {'outcome': 'FAILURE'}})
    _rewrite(d, 3, lambda rows: ([{**rows[0], **change}], list(rows[0])))
    with pytest.raises(SweepPlotError, match=r'line 2 \(trial \'0\'\): ' + message):
        read_sweep(d)


def test_a_fall_that_began_before_the_goal_is_no_lift_off_of_the_grasp() -> None:
    """The object dropped from 20 mm at the reset falls for about 64 ms; the goal comes 40 ms
    after the reset, while it falls. Counted from the reset, the fall is a lift-off (off the
    table for 50 ms); the rule begins again at the goal, and what is left of the fall (about
    24 ms) is none: the grasp, too soft to lift (k_theta 0.5), is not lifted."""
    config = load_config(CONFIG)
    start = np.asarray(config.object.position_m, dtype=float).copy()
    start[2] += 0.02
    world = ContactLog(config)
    try:
        result = run_experiment(config, 0.5, math.radians(10.0), world=world,
                                object_position=start, hold_before=0.04, max_time=8.0)
    finally:
        world.close()
    # the log holds the samples after every step call: the hold, then every device cycle
    goal = world.log[0][0]
    assert goal == pytest.approx(0.04, abs=1e-9) and world.log[0][1] > TOUCH_M  # in the air
    landed = next(t for t, gap, _ in world.log if gap <= TOUCH_M)
    assert 0.05 + 1e-9 <= landed < goal + 0.05  # a lift-off from the reset, not from the goal
    assert math.isnan(independent_lift_off(world.log)[0])  # from the goal on: none
    assert not result.lifted and math.isnan(result.lift_off_time)
    assert not result.off_table_at_end and result.lift_max < 0.002
