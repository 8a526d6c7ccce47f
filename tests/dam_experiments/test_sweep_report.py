"""``sweep_report``: the results document of a sweep, its numbers checked two ways.

* A synthetic sweep (written by the sweep's own ``TrialTable``, no simulation) whose lifts,
  guarantees and CSM verdicts are placed so that every number of the report is known by
  construction; only the analysis' boundaries come from ``compute_boundaries``.
* A small real sweep (12 whole grasps with a 1 s trajectory): the test recomputes the numbers
  from ``trials.csv`` with its own code (the ``csv`` module, the definitions as the document
  states them) and compares them with the numbers parsed out of the generated Markdown.
* The command: exit status and one-line messages on bad input, the figures written beside the
  document and linked from it.
"""

from __future__ import annotations

import csv
import math
import re
import statistics
import subprocess
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from dam_analysis.analysis import LiftAnalyzer
from dam_analysis.lift_map import compute_boundaries
from dam_common.config import load_config
from dam_experiments.sweep import SweepSpec, input_columns, table_columns
from dam_experiments.sweep_cli import main as sweep_main
from dam_experiments.sweep_report import SweepReport, compute_report
from dam_experiments.sweep_report_cli import main
from dam_experiments.sweep_report_markdown import render_markdown
from dam_experiments.sweep_results import read_sweep
from dam_experiments.sweep_table import PARAMS_FILE, TABLE_FILE, TrialTable
from ros_testing import installed_executable

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG = REPO_ROOT / 'config' / 'dam.yaml'
PNG_MAGIC = b'\x89PNG\r\n\x1a\n'
N_POINTS = 21  # dense boundary samples: enough to find eq. 18's region, cheap

# ------------------------------------------------------------------------------------------
# The synthetic sweep: alpha 5, 30 deg x k_theta 0.25 ... 16 (ratio 2) x dp 10, 20, 30 deg,
# 2 repeats. Lifted repeats per cell by (alpha, dp) column, in ascending k_theta.
K_GRID = (0.25, 0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
LIFTS = {
    (5.0, 10.0): (0, 0, 0, 1, 2, 2, 2),   # boundary 1 | 2 (p_lift 0.5 lifts)
    (5.0, 20.0): (0, 0, 0, 0, 0, 2, 0),   # boundary 4 | 8, then a dip: 2 transitions
    (5.0, 30.0): (0, 0, 0, 0, 2, 2, 2),   # boundary 2 | 4, but no CSM boundary there
    (30.0, 10.0): (0,) * 7,                # no lift: censored
    (30.0, 20.0): (2,) * 7,                # lifts at the lowest k: censored
    (30.0, 30.0): (0, 2, 2, 2, 2, 2, 2),  # boundary 0.25 | 0.5
}
#: check_lift_guaranteed 1 at these cells (alpha, dp, k); the rest 0.
GUARANTEED = {(5.0, 10.0, 1.0), (5.0, 10.0, 2.0), (5.0, 10.0, 8.0), (5.0, 10.0, 16.0),
              (5.0, 20.0, 16.0), (30.0, 10.0, 0.5)}
#: csm_lift 1 for k_theta at or above this, per friction angle.
CSM_FROM = {5.0: 2.0, 30.0: 1.0}
#: Columns of particular trials (alpha, dp, k) -> column values (both repeats unless keyed
#: with the repeat as a fourth element).
SPECIAL: dict[tuple[float, ...], dict[str, str]] = {
    # false guarantees, each class of a trial that did not lift: rose without leaving the
    # table (done, or still running), never rose
    (5.0, 10.0, 1.0): {'rise_final_mm': '0.4', 'rise_max_mm': '0.6'},
    (5.0, 20.0, 16.0): {'rise_final_mm': '0.0', 'rise_max_mm': '0.2', 'phase': 'FAILED',
                        'reason': 'lost contact on finger3: compliant torque 0.003 N*m below '
                                  '0.005 N*m for 0.1 s during rolling_up'},
    (30.0, 10.0, 0.5): {'rise_final_mm': '1.5', 'rise_max_mm': '2.0', 'phase': 'ROLLING_UP',
                        'reason': 'still in phase ROLLING_UP at 4 s'},
    # evidence: a compliant joint at its limit, a heavier object, a late lift (off the table
    # only after ROLLING_UP ended at 4.5 s)
    (30.0, 10.0, 16.0): {'peak_tau_finger1_compliant_nm': '0.995'},
    (5.0, 30.0, 2.0, 0): {'object_mass_kg': '0.045'},
    (30.0, 20.0, 0.25): {'lift_off_time_s': '4.75'},
    # lifted, then back on the table at the end
    (30.0, 30.0, 0.5): {'off_table_at_end': '0', 'rise_final_mm': '3.0'},
}


@pytest.fixture(scope='module')
def config() -> Any:
    return load_config(CONFIG)


@pytest.fixture(scope='module')
def analyzer(config: Any) -> LiftAnalyzer:
    return LiftAnalyzer(config)


def synthetic_row(spec: Any, columns: list[str]) -> dict[str, str]:
    """The row of one trial of the synthetic sweep."""
    alpha, dp, k = spec.friction_angle_deg, spec.delta_theta_p_deg, spec.k_theta
    lifted = int(spec.repeat < LIFTS[(alpha, dp)][K_GRID.index(k)])
    row = dict.fromkeys(columns, '0.05')
    row.update(input_columns(spec))
    row.update(object_mass_kg='0.04', table_friction='0.5', friction_angle_sim_deg=f'{alpha:g}',
               phase='DONE', outcome='SUCCESS' if lifted else 'FAILURE', lifted=str(lifted),
               rise_final_mm='8.0' if lifted else '0.1', rise_max_mm='8.5' if lifted else '0.2',
               rise_rolling_end_mm='7.0' if lifted else '0.1',
               lift_off_time_s='2.5' if lifted else '', off_table_at_end=str(lifted),
               rolling_up_end_s='4.5',
               estimated_rise_mm='8.0' if lifted else '0.1',
               check_lift_guaranteed=str(int((alpha, dp, k) in GUARANTEED)),
               worst_case_margin_n='0.1' if (alpha, dp, k) in GUARANTEED else '-0.1',
               csm_lift=str(int(k >= CSM_FROM[alpha])), csm_margin_n='0.2',
               # the path verdict placed one k step below the end verdict's boundary
               csm_path_lift=str(int(k >= CSM_FROM[alpha] / 2)), csm_path_margin_n='0.3',
               sim_time_s='4',
               reason='lifted and enveloped' if lifted else 'object raised only 0.1 mm')
    row.update(SPECIAL.get((alpha, dp, k), {}))
    row.update(SPECIAL.get((alpha, dp, k, spec.repeat), {}))
    return row


def write_synthetic(directory: Path, config: Any, n_rows: int | None = None) -> Path:
    sweep = SweepSpec(friction_angles_deg=(5.0, 30.0), k_theta=K_GRID,
                      delta_theta_p_deg=(10.0, 20.0, 30.0), repeats=2)
    table = TrialTable(directory, sweep, config, {'axes_as_given': {'k_theta': ['0.25:16:7:log']},
                                                  'software_version': 'test 0'})
    columns = table_columns(config)
    with table:
        for spec in sweep.trials()[:n_rows]:
            table.append(synthetic_row(spec, columns))
        table.finalize()
    return directory


@pytest.fixture(scope='module')
def synthetic(tmp_path_factory: pytest.TempPathFactory, config: Any) -> Path:
    return write_synthetic(tmp_path_factory.mktemp('synthetic'), config)


@pytest.fixture(scope='module')
def synthetic_report(synthetic: Path, config: Any, analyzer: LiftAnalyzer) -> SweepReport:
    return compute_report(read_sweep(synthetic), config, analyzer, n_points=N_POINTS)


def _k_csm(analyzer: LiftAnalyzer, alpha: float, dps: list[float]) -> list[float]:
    [b] = compute_boundaries(analyzer, [alpha], np.radians(dps), progress=False)
    return [float(v) for v in b.csm]


def test_the_synthetic_numbers_are_the_placed_ones(synthetic_report: SweepReport,
                                                   analyzer: LiftAnalyzer) -> None:
    r = synthetic_report
    # the analysis' boundaries where the placement assumes them
    c5 = _k_csm(analyzer, 5.0, [10.0, 20.0, 30.0])
    c30 = _k_csm(analyzer, 30.0, [10.0, 30.0])
    assert 1.0 < c5[0] < 2.0 and 1.0 < c5[1] < 2.0 and math.isnan(c5[2])
    assert 0.5 < c30[0] < 1.0 and 0.25 < c30[1] < 0.5
    a5, a30 = r.angles
    assert r.complete and r.n_present == 84 and r.config_matches and r.log_k
    # ground truth and section 3
    assert (a5.n_cells, a5.n_lifting, a5.n_guaranteed) == (21, 8, 5)
    assert (a30.n_cells, a30.n_lifting, a30.n_guaranteed) == (21, 13, 1)
    assert (a5.n_missed, a5.missed_share) == (5, 5 / 8)
    assert (a30.n_missed, a30.missed_share) == (13, 1.0)
    assert a5.sufficient_exists and not a30.sufficient_exists
    # section 1: three false guarantee cells, their six non-lifted trials classed
    assert (a5.n_false_guarantees, a30.n_false_guarantees) == (2, 1)
    assert r.n_false_guarantee_cells == 3 and r.n_guaranteed_unlifted_trials == 1
    labels = {(f.cell.friction_angle_deg, f.cell.delta_theta_p_deg, f.cell.k_theta,
               f.trial.repeat): f.label for f in r.false_guarantees}
    assert labels == {
        (5.0, 10.0, 1.0, 0): 'rose on the table; done',
        (5.0, 10.0, 1.0, 1): 'rose on the table; done',
        (5.0, 20.0, 16.0, 0): 'never rose; controller failure in rolling_up',
        (5.0, 20.0, 16.0, 1): 'never rose; controller failure in rolling_up',
        (30.0, 10.0, 0.5, 0): 'rose on the table; still running at the time limit '
                              '(rolling_up)',
        (30.0, 10.0, 0.5, 1): 'rose on the table; still running at the time limit '
                              '(rolling_up)'}
    # section 2a: csm_lift against the ground truth
    assert (a5.n_agree, a30.n_agree) == (17, 13)
    assert a5.agreement == pytest.approx(17 / 21) and a30.agreement == pytest.approx(13 / 21)
    # and csm_path_lift, placed from k >= CSM_FROM / 2
    for a in (a5, a30):
        cells = [c for c in r.cells if c.friction_angle_deg == a.friction_angle_deg]
        placed = sum((c.k_theta >= CSM_FROM[a.friction_angle_deg] / 2) == c.lifts for c in cells)
        assert a.n_path_agree == placed and a.path_agreement == pytest.approx(placed / 21)
    # section 2b: the columns
    status5 = [(c.status, c.transitions) for c in a5.columns]
    status30 = [(c.status, c.transitions) for c in a30.columns]
    assert status5 == [('compared', 1), ('compared', 2), ('no CSM boundary', 1)]
    assert status30 == [('no lift', 0), ('lifts at the lowest k_theta', 0), ('compared', 1)]
    d1 = math.log10(math.sqrt(1.0 * 2.0) / c5[0])
    d2 = math.log10(math.sqrt(4.0 * 8.0) / c5[1])
    d3 = math.log10(math.sqrt(0.25 * 0.5) / c30[1])
    assert [c.distance_dec for c in a5.columns[:2]] == pytest.approx([d1, d2], rel=1e-9)
    assert a5.columns[2].k_sim == pytest.approx(math.sqrt(8.0))
    assert a5.median_distance_dec == pytest.approx((abs(d1) + abs(d2)) / 2, rel=1e-9)
    assert a30.median_distance_dec == pytest.approx(abs(d3), rel=1e-9)
    step = math.log10(2.0)
    assert abs(d1) <= step < abs(d2) and abs(d3) <= step  # what the placement aimed at
    assert (a5.n_within_step, a5.within_step_share) == (1, 0.5)
    assert (a30.n_within_step, a30.within_step_share) == (1, 1.0)
    assert a5.n_multi_transition == 1
    # section 4: categories and their evidence
    cats = {c.key: c for c in r.categories}
    assert cats['csm_not_sim'].counts == (4, 5) and cats['sim_not_csm'].counts == (0, 3)
    assert cats['suff_not_sim'].counts == (2, 1)
    csm_not = cats['csm_not_sim']
    assert len(csm_not.trials) == 18
    assert dict(csm_not.checks) == {'controller failure': 2, 'time limit': 0,
                                    'compliant torque limit': 2, 'servo limit': 0,
                                    'heavier object': 1, 'next to the boundary': 4}
    assert csm_not.unexplained == 18 - 9
    assert dict(csm_not.rises) == {'never rose': 18}
    # the false guarantees: none of their trials left the table
    assert dict(cats['suff_not_sim'].rises) == {'rose on the table': 4, 'never rose': 2}
    sim_not = cats['sim_not_csm']
    assert len(sim_not.trials) == 6  # (30, 20, 0.25), (30, 20, 0.5), (30, 30, 0.5)
    # all three next to the CSM boundary (k_csm in 0.25 | 0.5 at dp 20 and 30 deg); late
    # lift: (30, 20, 0.25)
    c30_20 = _k_csm(analyzer, 30.0, [20.0])[0]
    assert 0.25 < c30_20 < 0.5
    assert dict(sim_not.checks) == {'lifted after rolling-up': 2, 'not held': 2,
                                    'lighter object': 0, 'next to the boundary': 6}
    assert sim_not.unexplained == 0
    assert dict(sim_not.rises) == {
        'lifted and held off the table': 4,
        'lifted, then fell back or an end came to rest on the table': 2}


def _summary_rows(text: str) -> dict[str, list[str]]:
    """The summary table's rows by friction angle, as cell texts."""
    block = text.split('## Summary', 1)[1].split('\n## ', 1)[0]
    rows = [line.strip('|').split('|') for line in block.splitlines()
            if line.startswith('| ') and not line.startswith('| alpha')]
    return {cells[0].strip(): [c.strip() for c in cells[1:]] for cells in rows}


def _share(text: str) -> tuple[int, int, float | None]:
    found = re.fullmatch(r'(\d+) of (\d+) \((?:([\d.]+) %|n/a)\)', text)
    assert found, text
    return int(found[1]), int(found[2]), None if found[3] is None else float(found[3])


def _category_counts(text: str) -> dict[str, list[int]]:
    block = text.split('## 4.', 1)[1].split('\n### ', 1)[0]
    rows = [line.strip('|').split('|') for line in block.splitlines()
            if line.startswith('| ') and not line.startswith('| category')]
    return {r[0].strip(): [int(c) for c in r[1:]] for r in rows}


def test_the_synthetic_document_states_them(synthetic_report: SweepReport) -> None:
    text = render_markdown(synthetic_report, 'ros2 run dam_experiments sweep_report X',
                           {'fig7': 'results/fig7.png', 'boundaries': 'results/boundaries.png'})
    assert text == render_markdown(synthetic_report, 'ros2 run dam_experiments sweep_report X',
                                   {'fig7': 'results/fig7.png',
                                    'boundaries': 'results/boundaries.png'})
    assert 'Incomplete' not in text and '## Definitions' in text
    rows = _summary_rows(text)
    assert rows['5'][:4] == ['42', '21', '8', '2'] and rows['30'][:4] == ['42', '21', '13', '1']
    assert _share(rows['5'][4]) == (17, 21, 81.0) and _share(rows['30'][4]) == (13, 21, 61.9)
    assert _share(rows['5'][5])[:2] == (synthetic_report.angles[0].n_path_agree, 21)
    assert rows['5'][6] == (f'{synthetic_report.angles[0].median_distance_dec:.3f} '
                            '(2 of 3 columns; no CSM boundary in 1)')
    assert _share(rows['5'][7]) == (1, 2, 50.0) and _share(rows['30'][7]) == (1, 1, 100.0)
    assert _share(rows['5'][8]) == (5, 8, 62.5) and _share(rows['30'][8]) == (13, 13, 100.0)
    assert '**3 false guarantees**' in text
    assert text.count('never rose; controller failure in rolling_up') == 2
    assert 'The sufficient condition has no solution at this friction angle' in text
    assert text.count('has no solution at this friction angle') == 1  # alpha 30 only
    assert '1 trial of guaranteed cells that lift' in text
    assert _category_counts(text) == {
        'CSM lifts, simulation does not': [4, 5, 9],
        'simulation lifts, CSM does not': [0, 3, 3],
        'eq. 18 guarantees, simulation does not lift': [2, 1, 3]}
    assert '**unexplained: 9**' in text and '**unexplained: 0**' in text
    assert 'Bullet\'s contact is not the CSM\'s spring-slider' in text
    assert '--k-theta 0.25:16:7:log' in text and '--repeats 2' in text
    assert '](results/fig7.png)' in text and '](results/boundaries.png)' in text


def test_an_incomplete_sweep_says_so_at_the_top(tmp_path: Path, config: Any,
                                                analyzer: LiftAnalyzer) -> None:
    d = write_synthetic(tmp_path / 'part', config, n_rows=30)
    with (d / TABLE_FILE).open('a', encoding='utf-8') as handle:
        handle.write('30,5,1,20,0,')  # a row being written
    report = compute_report(read_sweep(d), config, analyzer, n_points=N_POINTS)
    assert report.n_present == 30 and not report.complete
    text = render_markdown(report, 'cmd')
    head = text.split('## The sweep', 1)[0]
    assert '**Incomplete sweep: 30 of 84 trials are present.**' in head
    assert '1 row cut short' in head
    assert [a.friction_angle_deg for a in report.angles] == [5.0]


# ------------------------------------------------------------------------------------------
# A real sweep and an independent check of the document's numbers

REAL_SWEEP = ['--friction-angles', '5deg', '30deg', '--k-theta', '0.5', '3', '10',
              '--delta-theta-p', '10deg', '25deg', '--trajectory-duration', '1', '--max-time',
              '4',
              '--config', str(CONFIG), '--workers', '1', '--quiet']


@pytest.fixture(scope='module')
def real_document(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """A real sweep of 12 whole grasps (about 20 s of CPU) and its generated document."""
    root = tmp_path_factory.mktemp('real')
    assert sweep_main([*REAL_SWEEP, '--out', str(root / 'sweep')]) == 0
    out = root / 'docs' / 'results.md'
    out.parent.mkdir()
    assert main([str(root / 'sweep'), '-o', str(out), '--config', str(CONFIG),
                 '--n-delta-theta-p', str(N_POINTS)]) == 0
    return root / 'sweep', out.read_text(encoding='utf-8')


def independent_numbers(table: Path, analyzer: LiftAnalyzer) -> dict[str, dict[str, Any]]:
    """The summary numbers per friction angle, from ``trials.csv`` by the document's
    definitions, with nothing of the report's code."""
    with table.open(encoding='utf-8', newline='') as handle:
        rows = list(csv.DictReader(handle))
    cells: dict[tuple[float, float, float], list[dict[str, str]]] = {}
    for row in rows:
        key = (float(row['friction_angle_deg']), float(row['delta_theta_p_deg']),
               float(row['k_theta_nm_per_rad']))
        cells.setdefault(key, []).append(row)
    out: dict[str, dict[str, Any]] = {}
    for alpha in sorted({k[0] for k in cells}):
        mine = {k: v for k, v in cells.items() if k[0] == alpha}
        lifts = {k: sum(r['lifted'] == '1' for r in v) / len(v) >= 0.5 for k, v in mine.items()}
        guaranteed = {k: v[0]['check_lift_guaranteed'] == '1' for k, v in mine.items()}
        csm = {k: v[0]['csm_lift'] == '1' for k, v in mine.items()}
        path = {k: v[0]['csm_path_lift'] == '1' for k, v in mine.items()}
        dps = sorted({k[1] for k in mine})
        [b] = compute_boundaries(analyzer, [alpha], np.radians(dps), progress=False)
        distances, within = [], 0
        for dp, k_csm in zip(dps, b.csm, strict=True):
            ks = sorted(k[2] for k in mine if k[1] == dp)
            lifting = [k for k in ks if lifts[(alpha, dp, k)]]
            if not lifting or lifting[0] == ks[0] or not np.isfinite(k_csm):
                continue
            k_lift = lifting[0]
            k_below = ks[ks.index(k_lift) - 1]
            d = abs(math.log10(math.sqrt(k_below * k_lift) / k_csm))
            distances.append(d)
            within += d <= math.log10(k_lift / k_below)
        n_lift = sum(lifts.values())
        out[f'{alpha:g}'] = {
            'trials': sum(len(v) for v in mine.values()), 'cells': len(mine),
            'lifting': n_lift,
            'false': sum(guaranteed[k] and not lifts[k] for k in mine),
            'agree': sum(csm[k] == lifts[k] for k in mine),
            'path_agree': sum(path[k] == lifts[k] for k in mine),
            'median': statistics.median(distances) if distances else None,
            'compared': len(distances), 'within': within,
            'missed': sum(lifts[k] and not guaranteed[k] for k in mine),
            'categories': (sum(csm[k] and not lifts[k] for k in mine),
                           sum(lifts[k] and not csm[k] for k in mine),
                           sum(guaranteed[k] and not lifts[k] for k in mine))}
    return out


def test_the_documents_numbers_agree_with_an_independent_count(
        real_document: tuple[Path, str], analyzer: LiftAnalyzer) -> None:
    sweep_dir, text = real_document
    expected = independent_numbers(sweep_dir / TABLE_FILE, analyzer)
    rows = _summary_rows(text)
    assert sorted(rows) == sorted(expected) == ['30', '5']
    for alpha, e in expected.items():
        r = rows[alpha]
        assert [int(r[0]), int(r[1]), int(r[2]), int(r[3])] == [
            e['trials'], e['cells'], e['lifting'], e['false']], alpha
        n, whole, pct = _share(r[4])
        assert (n, whole) == (e['agree'], e['cells'])
        assert pct == pytest.approx(100.0 * e['agree'] / e['cells'], abs=0.05)
        assert _share(r[5])[:2] == (e['path_agree'], e['cells'])
        median, compared, _all, _no_csm = re.fullmatch(
            r'(\S+) \((\d+) of (\d+) columns; no CSM boundary in (\d+)\)', r[6]).groups()
        assert int(compared) == e['compared']
        if e['median'] is None:
            assert median == 'n/a'
        else:
            assert float(median) == pytest.approx(e['median'], abs=5e-4)
        assert _share(r[7])[:2] == (e['within'], e['compared'])
        n, whole, pct = _share(r[8])
        assert (n, whole) == (e['missed'], e['lifting'])
        if whole:
            assert pct == pytest.approx(100.0 * n / whole, abs=0.05)
    counts = _category_counts(text)
    alphas = sorted(expected, key=float)
    for i, title in enumerate(('CSM lifts, simulation does not',
                               'simulation lifts, CSM does not',
                               'eq. 18 guarantees, simulation does not lift')):
        per_alpha = [expected[a]['categories'][i] for a in alphas]
        assert counts[title] == [*per_alpha, sum(per_alpha)], title
    # section 5, counted from trials.csv here: ground truth against the controller's class
    with open(sweep_dir / TABLE_FILE, encoding='utf-8', newline='') as stream:
        table = list(csv.DictReader(stream))
    # lifted is a lift-off: it has a lift-off time; off the table at the end only after one
    assert all((r['lifted'] == '1') == (r['lift_off_time_s'] != '') for r in table)
    assert all(r['lifted'] == '1' for r in table if r['off_table_at_end'] == '1')
    block = text.split('## 5.', 1)[1].split('\n\n', 3)[2]  # its first table
    shown = {cells[0].strip(): [int(c) for c in cells[1:]]
             for cells in (line.strip('|').split('|') for line in block.splitlines()
                           if line.startswith('| ') and not line.startswith('| alpha'))}
    for alpha in alphas:
        mine = [r for r in table if f"{float(r['friction_angle_deg']):g}" == alpha]
        said = [r['outcome'] in ('SUCCESS', 'LIFTED_DAM_FAILED') for r in mine]
        truth = [r['lifted'] == '1' for r in mine]
        pairs = list(zip(truth, said, strict=True))
        assert shown[alpha] == [len(mine), pairs.count((True, True)), pairs.count((True, False)),
                                pairs.count((False, True)), pairs.count((False, False))]
    # the check is not vacuous: the sweep has lifting and failing cells, a compared column
    assert 0 < sum(e['lifting'] for e in expected.values()) < 12
    assert sum(e['compared'] for e in expected.values()) >= 1
    assert '12 of 12' in text and 'Incomplete' not in text


def test_the_figures_are_written_beside_the_document_and_linked(
        real_document: tuple[Path, str], tmp_path: Path) -> None:
    sweep_dir, text = real_document
    docs = sweep_dir.parent / 'docs'
    links = re.findall(r'!\[[^\]]*\]\(([^)]+)\)', text)
    assert links == ['results/fig7.png', 'results/boundaries.png']
    for link in links:
        path = docs / link
        assert path.read_bytes()[:8] == PNG_MAGIC and path.stat().st_size > 20_000
    assert sorted(p.name for p in (docs / 'results').iterdir()) == ['boundaries.png',
                                                                    'fig7.png']


# ------------------------------------------------------------------------------------------
# The command on bad input


def _drop_column(name: str) -> Callable[[Path], None]:
    def edit(d: Path) -> None:
        with (d / TABLE_FILE).open(encoding='utf-8', newline='') as handle:
            rows = list(csv.DictReader(handle))
        columns = [c for c in rows[0] if c != name]
        with (d / TABLE_FILE).open('w', encoding='utf-8', newline='') as handle:
            writer = csv.DictWriter(handle, columns, extrasaction='ignore',
                                    lineterminator='\n')
            writer.writeheader()
            writer.writerows(rows)
    return edit


def _set_first(column: str, value: str) -> Callable[[Path], None]:
    def edit(d: Path) -> None:
        with (d / TABLE_FILE).open(encoding='utf-8', newline='') as handle:
            rows = list(csv.DictReader(handle))
        rows[0][column] = value
        with (d / TABLE_FILE).open('w', encoding='utf-8', newline='') as handle:
            writer = csv.DictWriter(handle, list(rows[0]), lineterminator='\n')
            writer.writeheader()
            writer.writerows(rows)
    return edit


def _repeat_first_row(d: Path) -> None:
    with (d / TABLE_FILE).open('a', encoding='utf-8') as handle:
        handle.write((d / TABLE_FILE).read_text(encoding='utf-8').splitlines()[1] + '\n')


@pytest.mark.parametrize(('edit', 'message'), [
    (_repeat_first_row, 'trial 0 is in the table twice (first on line 2)'),
    (_drop_column('rise_max_mm'), "no column 'rise_max_mm', which the report needs"),
    (_drop_column('csm_lift'), "no column 'csm_lift'"),
    (_drop_column('lifted'), "no column 'lifted'"),
    (_set_first('check_lift_guaranteed', 'yes'), "check_lift_guaranteed 'yes' is not 0 or 1"),
    (_set_first('rise_final_mm', 'high'), "rise_final_mm 'high' is not a number"),
    (_set_first('rise_final_mm', '-inf'), "rise_final_mm '-inf' is not a number"),
    (_set_first('worst_case_margin_n', 'inf'), "worst_case_margin_n 'inf' is not a number"),
    (lambda d: (d / PARAMS_FILE).unlink(), 'sweep.json: no such file'),
    (lambda d: (d / TABLE_FILE).unlink(), 'trials.csv: no such file'),
])
def test_bad_sweeps_exit_2_with_one_line(tmp_path: Path, config: Any,
                                         capsys: pytest.CaptureFixture[str],
                                         edit: Callable[[Path], None], message: str) -> None:
    sweep = SweepSpec(friction_angles_deg=(5.0,), k_theta=(1.0, 2.0), delta_theta_p_deg=(10.0,))
    d = tmp_path / 'sweep'
    table = TrialTable(d, sweep, config)
    with table:
        for spec in sweep.trials():
            row = dict.fromkeys(table_columns(config), '0')
            row.update(input_columns(spec), outcome='FAILURE', phase='DONE', reason='x',
                       lift_off_time_s='')
            table.append(row)
        table.finalize()
    edit(d)
    out = tmp_path / 'results.md'
    assert main([str(d), '-o', str(out), '--config', str(CONFIG)]) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and err.startswith('sweep_report: ') and message in err
    assert not out.exists() and not (tmp_path / 'results').exists()


def test_an_unbounded_worst_case_is_read_and_shown(tmp_path: Path, config: Any) -> None:
    """``worst_case_margin_n = -inf`` is what the sweep writes where the worst case of eq. 18
    is unbounded (alpha = 30 deg at large delta_theta_p): read, and shown as such."""
    sweep = SweepSpec(friction_angles_deg=(30.0,), k_theta=(1.0, 2.0),
                      delta_theta_p_deg=(10.0,))
    d = tmp_path / 'sweep'
    table = TrialTable(d, sweep, config)
    with table:
        for spec in sweep.trials():
            row = dict.fromkeys(table_columns(config), '0')
            row.update(input_columns(spec), outcome='FAILURE', phase='DONE', reason='x',
                       lift_off_time_s='', worst_case_margin_n='-inf', csm_lift='1',
                       csm_margin_n='-inf')
            table.append(row)
        table.finalize()
    out = tmp_path / 'results.md'
    assert main([str(d), '-o', str(out), '--config', str(CONFIG)]) == 0
    assert '-inf' in out.read_text(encoding='utf-8')


def test_bad_outputs_and_arguments(synthetic: Path, tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    (tmp_path / 'file').write_text('x', encoding='utf-8')
    (tmp_path / 'taken.md').mkdir()
    (tmp_path / 'clash').write_text('x', encoding='utf-8')
    for output, message in ((tmp_path / 'results.txt', 'must be a .md file'),
                            (tmp_path / 'missing' / 'results.md', 'does not exist'),
                            (tmp_path / 'file' / 'results.md', 'is not a directory'),
                            (tmp_path / 'taken.md', 'is a directory'),
                            (tmp_path / 'clash.md', 'exists and is not a directory')):
        assert main([str(synthetic), '-o', str(output)]) == 2, output
        err = capsys.readouterr().err
        assert len(err.splitlines()) == 1 and message in err, err
    assert main([str(tmp_path / 'nowhere'), '--ros-args', '-r', 'a:=b']) == 2
    assert capsys.readouterr().err == (f'sweep_report: {tmp_path / "nowhere"}: no such '
                                       f'directory\n')
    with pytest.raises(SystemExit) as info:
        main([str(synthetic), '--n-delta-theta-p', '1'])
    assert info.value.code == 2
    assert '--n-delta-theta-p: 1 must be at least 2' in capsys.readouterr().err


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    exe = installed_executable('dam_experiments', 'sweep_report')
    assert exe.is_file(), f'{exe} missing: build the workspace with scripts/setup.sh'
    return subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=180)


def test_installed_executable(synthetic: Path, tmp_path: Path) -> None:
    out = tmp_path / 'report.md'
    proc = _run(str(synthetic), '-o', str(out), '--config', str(CONFIG),
                '--n-delta-theta-p', '5')
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ''
    text = out.read_text(encoding='utf-8')
    assert f'sweep_report {synthetic} -o {out} --config {CONFIG} --n-delta-theta-p 5' in text
    for name in ('fig7.png', 'boundaries.png'):
        assert (tmp_path / 'report' / name).read_bytes()[:8] == PNG_MAGIC
        assert f'](report/{name})' in text
    lines = proc.stdout.splitlines()
    assert lines[0] == f'sweep_report: {synthetic}: 84 of 84 trials, 2 per cell'
    assert lines[1].startswith('  alpha 5 deg: 21 cells, 8 lifting; false guarantees 2; CSM '
                               'agreement 17 of 21 (81.0 %)')
    assert lines[2].endswith('no stiffness is guaranteed')
    assert lines[-1].startswith('sweep_report: wrote ') and str(out) in lines[-1]
    # bad input: exit 2, one line
    proc = _run(str(tmp_path / 'nowhere'))
    assert proc.returncode == 2 and proc.stderr.splitlines() == [
        f'sweep_report: {tmp_path / "nowhere"}: no such directory']


def test_a_sweep_of_two_objects_is_drawn_and_reported_one_object_at_a_time(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """sweep --objects cylinder hex_bar: the picture and the report refuse to mix them (exit 2,
    naming both and --object); with --object each shows its own object, its trials only, and
    boundaries of the analysis of that object (not of the configured default)."""
    from dam_experiments.sweep_plot import main as plot_main
    from dam_experiments.sweep_plot import plot_sweep

    cfg_path = Path(__file__).resolve().parents[2] / 'config' / 'dam.yaml'
    out = tmp_path / 'sweep'
    assert sweep_main(['--objects', 'cylinder', 'hex_bar', '--friction-angles', '5deg',
                       '--k-theta', '2', '10', '--delta-theta-p', '10deg', '--max-time', '0.6',
                       '--config', str(cfg_path), '--quiet', '--workers', '1',
                       '--out', str(out)]) == 0
    capsys.readouterr()
    assert plot_main([str(out), '-o', str(tmp_path / 'mixed.png'), '--config',
                      str(cfg_path)]) == 2
    err = capsys.readouterr().err
    assert 'a sweep of 2 objects (cylinder, hex_bar)' in err and '--object NAME' in err, err
    assert main([str(out), '-o', str(tmp_path / 'mixed.md'), '--config', str(cfg_path)]) == 2
    assert 'choose one with --object' in capsys.readouterr().err
    assert plot_main([str(out), '--object', 'pencil', '-o', str(tmp_path / 'p.png')]) == 2
    assert "no trial of object 'pencil'" in capsys.readouterr().err

    config = load_config(cfg_path)
    data = read_sweep(out).of_object('hex_bar')
    assert [t.object_name for t in data.trials] == ['hex_bar', 'hex_bar']
    result = plot_sweep(data, tmp_path / 'hex.png', config=config, n_points=5)
    assert 'hex_bar' in result.figure._suptitle.get_text()
    assert result.config_matches  # the sweep's configuration, its object switched
    grid = np.asarray(result.boundaries[0].delta_theta_p, dtype=float)  # [rad]
    expected = compute_boundaries(LiftAnalyzer(config.with_object('hex_bar')), [5.0], grid,
                                  progress=False)[0]
    np.testing.assert_allclose(result.boundaries[0].csm, expected.csm, rtol=1e-9)
    default = compute_boundaries(LiftAnalyzer(config), [5.0], grid, progress=False)[0]
    assert not np.allclose(np.nan_to_num(default.csm), np.nan_to_num(expected.csm))

    assert plot_main([str(out), '--object', 'cylinder', '--config', str(cfg_path),
                      '--n-delta-theta-p', '5']) == 0
    assert (out / 'fig7_cylinder.png').is_file() and not (out / 'fig7.png').exists()
    assert 'sweep: cylinder, 2 of 2 trials' in capsys.readouterr().out
    document = tmp_path / 'hex.md'
    assert main([str(out), '--object', 'hex_bar', '-o', str(document), '--config',
                 str(cfg_path), '--n-delta-theta-p', '5']) == 0
    text = document.read_text(encoding='utf-8')
    assert '| object | hex_bar |' in text
    assert '--object hex_bar' in text  # the command that writes it again
    assert '--objects cylinder hex_bar --friction-angles 5deg' in text  # the sweep's command
    assert 'trials present | 2 of 2' in text


def test_a_small_sweep_calibrates_end_to_end(real_document: tuple[Path, str],
                                             tmp_path: Path) -> None:
    """calibrate_csm on the real sweep writes an overlay the loader accepts, and sweep_report
    --calibrate states the configured CSM's agreement as an independent count of the table
    gives it (csm_lift against lifted, per friction angle)."""
    from dam_experiments.calibrate_csm import main as calibrate_main

    sweep_dir, _ = real_document
    overlay = tmp_path / 'cal.yaml'
    assert calibrate_main([str(sweep_dir), '-o', str(overlay), '--config', str(CONFIG),
                           '--folds', '2']) == 0
    merged = load_config(CONFIG, [overlay])
    base = load_config(CONFIG)
    # a fitted k_t goes to the object, never to the contact section
    np.testing.assert_array_equal(merged.contact.contact_stiffness_n_per_m,
                                  base.contact.contact_stiffness_n_per_m)
    fitted = merged.object.csm_tangential_stiffness_n_per_m
    assert fitted is None or fitted > 0.0
    out = tmp_path / 'docs' / 'results.md'
    out.parent.mkdir()
    assert main([str(sweep_dir), '-o', str(out), '--config', str(CONFIG), '--calibrate',
                 '--folds', '2']) == 0
    text = out.read_text(encoding='utf-8')
    assert '## 6. The CSM calibrated on this sweep' in text
    with open(sweep_dir / TABLE_FILE, encoding='utf-8', newline='') as stream:
        rows = list(csv.DictReader(stream))
    for alpha in ('5', '30'):
        mine = [r for r in rows if r['friction_angle_deg'] == alpha]
        agree = sum(r['csm_lift'] == r['lifted'] for r in mine)
        row = next(line for line in text.splitlines()
                   if line.startswith(f'| {alpha} | ') and 'of' in line and '[' in line)
        cells = [c.strip() for c in row.strip('|').split('|')]
        assert cells[3] == str(len(mine))
        assert cells[4].startswith(f'{agree} of {len(mine)}')


def test_calibrate_csm_refuses_bad_input_with_one_line(tmp_path: Path) -> None:
    from dam_experiments.calibrate_csm import main as calibrate_main

    assert calibrate_main([str(tmp_path / 'missing')]) == 2
    assert calibrate_main([str(tmp_path), '-o', str(tmp_path / 'x.txt')]) == 2
    with pytest.raises(SystemExit):
        calibrate_main([str(tmp_path), '--folds', '1'])
