"""The sweep's core: ranges, seeds, perturbation draws, one trial, the table and its resume.

Everything here runs in this process; the command line, the Dask runs and a real interruption
are in ``test_sweep_cli.py``.
"""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest

from dam_common.config import DamConfig, load_config
from dam_experiments.errors import SweepError
from dam_experiments.sweep import (
    Perturbations,
    SweepSpec,
    TrialSpec,
    analyzer_for,
    input_columns,
    run_trial,
    table_columns,
    trial_seed,
)
from dam_experiments.sweep_axes import parse_axis, parse_range
from dam_experiments.sweep_table import (
    CELLS_FILE,
    PARAMS_FILE,
    TABLE_FILE,
    TrialTable,
    cell_summary,
    read_table,
)


@pytest.fixture(scope='module')
def cfg() -> DamConfig:
    return load_config()


def test_linear_and_log_ranges() -> None:
    assert parse_range('--delta-theta-p', '5:60:12') == tuple(range(5, 65, 5))
    values = parse_range('--k-theta', '0.05:20:24:log')
    assert len(values) == 24 and values[0] == 0.05 and values[-1] == 20.0
    ratios = np.array(values[1:]) / np.array(values[:-1])
    assert np.allclose(ratios, ratios[0], rtol=1e-9) and ratios[0] > 1.0
    assert parse_range('--k-theta', '7') == (7.0,)
    assert parse_range('--k-theta', '3:3:1') == (3.0,)
    assert parse_range('--k-theta', '20:0.05:3:log') == (20.0, 1.0, 0.05)  # descending
    assert parse_range('--delta-theta-p', '60:5:12:lin') == tuple(range(60, 0, -5))
    assert parse_range('--k-theta', '1:3:3:LOG') == parse_range('--k-theta', '1:3:3:log')
    assert parse_axis('--k-theta', ['0.5', '1:2:2'], lower=0.0) == (0.5, 1.0, 2.0)


@pytest.mark.parametrize('token, words', [
    ('5:60', ["'5:60'", 'start:stop:count']),
    ('5:60:0', ['count 0', "'5:60:0'"]),
    ('5:60:two', ["count 'two'", "'5:60:two'"]),
    ('5:60:3:cube', ["'5:60:3:cube'"]),
    ('0:20:5:log', ['positive ends', "'0:20:5:log'"]),
    ('5:6:1', ['count 1', 'start == stop']),
    ('ten', ["'ten'", 'not a number']),
    ('nan', ["'nan'", 'not a finite number']),
])
def test_bad_ranges_are_refused_with_the_field_and_the_value(token: str,
                                                             words: list[str]) -> None:
    with pytest.raises(SweepError) as info:
        parse_axis('--delta-theta-p', [token], lower=0.0)
    message = str(info.value)
    assert message.startswith('--delta-theta-p: ')
    for word in words:
        assert word in message, message


def test_angle_axes_take_units_and_a_bare_number_is_radians() -> None:
    from dam_common.quantities import ANGLE

    degree = math.pi / 180.0
    assert parse_axis('--delta-theta-p', ['5deg:60deg:12'], lower=0.0, quantity=ANGLE,
                      unit_si=degree) == tuple(range(5, 65, 5))  # no float noise
    assert parse_axis('--delta-theta-p', ['0.5', '10deg'], lower=0.0, quantity=ANGLE,
                      unit_si=degree) == pytest.approx((math.degrees(0.5), 10.0))
    with pytest.raises(SweepError) as info:
        parse_axis('--delta-theta-p', ['5:60:12'], lower=0.0, quantity=ANGLE, unit_si=degree)
    message = str(info.value)
    assert message.startswith("--delta-theta-p: '5' has no unit, so it reads as 5 rad"), message
    assert "did you mean 5deg?" in message and "in '5:60:12'" in message, message


def test_axis_bounds_and_duplicates() -> None:
    with pytest.raises(SweepError, match=r"--delta-theta-p: -5 deg \(from '-5:5:3'\) is "
                                         r'outside \(0, inf\]'):
        parse_axis('--delta-theta-p', ['-5:5:3'], lower=0.0, lower_open=True, unit='deg')
    with pytest.raises(SweepError, match=r'--friction-angles: 90 deg .* outside \[0, 90\)'):
        parse_axis('--friction-angles', ['5', '90'], lower=0.0, upper=90.0, upper_open=True,
                   unit='deg')
    with pytest.raises(SweepError, match='--k-theta: 10 is given twice'):
        parse_axis('--k-theta', ['5:10:2', '10'], lower=0.0)


def test_sweep_checked_against_the_configuration(cfg: DamConfig) -> None:
    SweepSpec((5.0,), (10.0,), (65.0,)).check_against(cfg)
    with pytest.raises(SweepError, match='--delta-theta-p: 70 deg exceeds'):
        SweepSpec((5.0,), (10.0,), (70.0,)).check_against(cfg)
    with pytest.raises(SweepError, match='--k-theta: 150 N.m/rad exceeds the device limit'):
        SweepSpec((5.0,), (150.0,), (10.0,)).check_against(cfg)
    with pytest.raises(SweepError, match='--trajectory-duration: 10 s'):
        SweepSpec((5.0,), (1.0,), (10.0,), trajectory_duration_s=10.0).check_against(cfg)
    with pytest.raises(SweepError, match=r'--repeats \(repeats\): 0 must be'):
        SweepSpec((5.0,), (1.0,), (10.0,), repeats=0)


def test_trials_and_seeds() -> None:
    sweep = SweepSpec((5.0, 30.0), (0.5, 1.0, 2.0), (10.0, 20.0), repeats=2, seed=7)
    trials = sweep.trials()
    assert len(trials) == sweep.n_trials == 24
    assert [t.index for t in trials] == list(range(24))
    assert (trials[0].friction_angle_deg, trials[0].delta_theta_p_deg, trials[0].k_theta,
            trials[0].repeat) == (5.0, 10.0, 0.5, 0)
    assert (trials[1].k_theta, trials[1].repeat) == (0.5, 1)
    assert (trials[-1].friction_angle_deg, trials[-1].delta_theta_p_deg,
            trials[-1].k_theta) == (30.0, 20.0, 2.0)
    seeds = [t.seed for t in trials]
    assert len(set(seeds)) == 24 and all(0 <= s < 2 ** 53 for s in seeds)
    assert sweep.trials() == trials  # stable
    other = dataclasses.replace(sweep, seed=8).trials()
    assert not set(seeds) & {t.seed for t in other}
    # SeedSequence is stable across numpy versions: a pinned value
    assert trial_seed(0, (0, 0, 0), 0) == 8885800452657194
    assert trials[5].seed == trial_seed(7, (0, 0, 2), 1)


def test_perturbation_draws(cfg: DamConfig) -> None:
    nominal = Perturbations().draw(123, 5.0, 0.04, 0.5)
    assert (nominal.object_mass_kg, nominal.object_offset_m, nominal.table_friction,
            nominal.friction_angle_deg) == (0.04, (0.0, 0.0), 0.5, 5.0)
    p = Perturbations(mass_rel=0.2, position_sd_mm=2.0, table_friction_rel=0.3,
                      friction_angle_sd_deg=3.0)
    draws = [p.draw(s, 5.0, 0.04, 0.5) for s in range(4000)]
    mass = np.array([d.object_mass_kg for d in draws])
    offsets = np.array([d.object_offset_m for d in draws])
    table = np.array([d.table_friction for d in draws])
    alpha = np.array([d.friction_angle_deg for d in draws])
    assert 0.032 <= mass.min() < 0.0325 and 0.0475 < mass.max() <= 0.048
    assert mass.mean() == pytest.approx(0.04, rel=0.01)
    assert offsets.std(axis=0) == pytest.approx([2e-3, 2e-3], rel=0.05)
    assert 0.35 <= table.min() and table.max() <= 0.65
    assert alpha.min() == 0.0 and (alpha == 0.0).mean() == pytest.approx(0.048, abs=0.015)
    assert p.draw(99, 5.0, 0.04, 0.5) == draws[99]  # the seed decides
    # turning one perturbation on leaves the others' draws as they were
    only_mass = Perturbations(mass_rel=0.2).draw(99, 5.0, 0.04, 0.5)
    assert only_mass.object_mass_kg == draws[99].object_mass_kg
    assert only_mass.object_offset_m == (0.0, 0.0) and only_mass.table_friction == 0.5
    assert Perturbations(friction_angle_sd_deg=200.0).draw(1, 80.0, 0.04, 0.5) \
        .friction_angle_deg in (0.0, 89.0)


@pytest.mark.parametrize('kwargs, words', [
    ({'mass_rel': 1.0}, ['--mass-rel (mass_rel): 1.0', '[0, 1)']),
    ({'table_friction_rel': -0.1}, ['--table-friction-rel', '-0.1']),
    ({'position_sd_mm': math.inf}, ['--position-sd', 'inf']),
    ({'friction_angle_sd_deg': math.nan}, ['--friction-angle-sd', 'nan']),
])
def test_bad_perturbations_are_refused(kwargs: dict[str, float], words: list[str]) -> None:
    with pytest.raises(SweepError) as info:
        Perturbations(**kwargs)
    for word in words:
        assert word in str(info.value)


def test_sweep_round_trips_through_its_dictionary() -> None:
    sweep = SweepSpec((5.0,), (0.5, 7.0), (10.0,), repeats=3, seed=2,
                      perturbations=Perturbations(mass_rel=0.1), max_time_s=3.0,
                      trajectory_duration_s=1.0, impedance='device',
                      envelope='constant-torque')
    assert SweepSpec.from_dict(sweep.to_dict()) == sweep
    with pytest.raises(SweepError, match=r"unknown key \['bogus'\]"):
        SweepSpec.from_dict({**sweep.to_dict(), 'bogus': 1})
    with pytest.raises(SweepError, match=r"unknown keys \['bogus', 'extra'\]"):
        SweepSpec.from_dict({**sweep.to_dict(), 'extra': 2, 'bogus': 1})
    assert sweep.sequence_overrides() == {'envelope_constant_torque': True,
                                          'impedance_on_device': True,
                                          'trajectory_duration': 1.0}


def test_a_trial_depends_only_on_its_inputs_and_seed(cfg: DamConfig) -> None:
    """Two runs of a perturbed trial that reaches contact give the same row; the row records
    the drawn world and the cell's /check_lift answer."""
    sweep = SweepSpec((5.0,), (10.0,), (10.0,), seed=3, max_time_s=2.0,
                      trajectory_duration_s=0.5,
                      perturbations=Perturbations(mass_rel=0.2, position_sd_mm=0.5,
                                                  table_friction_rel=0.2,
                                                  friction_angle_sd_deg=1.0))
    spec = sweep.trials()[0]
    first = run_trial(spec, sweep, cfg)
    again = run_trial(spec, sweep, cfg)
    assert first.row == again.row
    row = first.row
    assert list(row) == table_columns(cfg)
    draw = sweep.perturbations.draw(spec.seed, 5.0, 0.04, 0.5)
    assert float(row['object_mass_kg']) == pytest.approx(draw.object_mass_kg, rel=1e-5)
    assert float(row['object_mass_kg']) != 0.04
    assert float(row['object_offset_x_mm']) == pytest.approx(draw.object_offset_m[0] * 1e3,
                                                             abs=1e-4)
    assert float(row['friction_angle_sim_deg']) != 5.0
    assert row['phase'] == 'ROLLING_UP'  # reached contact within 2 s
    assert float(row['peak_tau_finger1_compliant_nm']) > 0.01
    answer = analyzer_for(cfg).check_lift([10.0], [math.radians(10.0)],
                                          friction_angle=math.radians(5.0))
    assert row['check_lift_guaranteed'] == '1' and answer.lift_guaranteed
    assert float(row['worst_case_margin_n']) == pytest.approx(answer.worst_case_margin,
                                                              rel=1e-5)
    assert float(row['csm_margin_n']) == pytest.approx(answer.csm_margin, rel=1e-5)
    assert first.wall_time_s > 0.0 and first.cpu_time_s > 0.0


def _fake_row(spec: TrialSpec, columns: list[str], lifted: int) -> dict[str, str]:
    row = dict.fromkeys(columns, '0')
    row.update(input_columns(spec), outcome='SUCCESS' if lifted else 'FAILURE',
               lifted=str(lifted), rise_final_mm='8' if lifted else '0', reason='a, "b"')
    return row


def test_table_resumes_and_refuses_another_sweep(cfg: DamConfig, tmp_path: Path) -> None:
    sweep = SweepSpec((5.0, 30.0), (1.0, 10.0), (10.0,), repeats=2)
    specs = sweep.trials()
    out = tmp_path / 'run'
    table = TrialTable(out, sweep, cfg, info={'note': 'first'})
    assert table.open() == 0 and len(table.pending()) == 8
    for i in (5, 0, 3):
        table.append(_fake_row(specs[i], table.columns, lifted=int(i == 3)))
    table.close()
    with (out / TABLE_FILE).open('a', encoding='utf-8') as handle:  # an interrupted write
        handle.write('6,30,1,10,0')
    again = TrialTable(out, sweep, cfg, info={'note': 'information is not compared'})
    assert again.open() == 3 and again.dropped == 1
    assert [s.index for s in again.pending()] == [1, 2, 4, 6, 7]
    text = (out / TABLE_FILE).read_text(encoding='utf-8')
    assert text.endswith('\n') and [r['trial'] for r in read_table(out / TABLE_FILE)] == \
        ['0', '3', '5']
    for spec in again.pending():
        again.append(_fake_row(spec, again.columns, lifted=0))
    again.finalize()
    rows = read_table(out / TABLE_FILE)
    assert [int(r['trial']) for r in rows] == list(range(8)) and rows[0]['reason'] == 'a, "b"'
    cells = read_table(out / CELLS_FILE)
    assert len(cells) == 4 and cells[0]['trials'] == '2'
    assert [c['p_lift'] for c in cells] == ['0', '0.5', '0', '0']
    assert (out / PARAMS_FILE).is_file()

    changed = dataclasses.replace(sweep, k_theta=(1.0, 12.0))
    with pytest.raises(SweepError, match=r'holds a different sweep \(sweep\.k_theta: stored '
                                         r'\[1\.0, 10\.0\], now \[1\.0, 12\.0\]\)'):
        TrialTable(out, changed, cfg).open()
    light = dataclasses.replace(cfg, object=dataclasses.replace(cfg.object, mass_kg=0.03))
    with pytest.raises(SweepError, match=r'holds a different sweep \(config\.object\.mass_kg: '
                                         r'stored 0\.04, now 0\.03\)'):
        TrialTable(out, sweep, light).open()
    # A sweep.json of before the values were kept: the digests alone
    params = json.loads((out / PARAMS_FILE).read_text())
    del params['config']
    (out / PARAMS_FILE).write_text(json.dumps(params))
    with pytest.raises(SweepError, match=r'\(config_sha256: stored'):
        TrialTable(out, sweep, light).open()


def test_rows_of_other_trials_are_dropped(cfg: DamConfig, tmp_path: Path) -> None:
    """A row whose inputs do not match its trial number (edited by hand) is run again."""
    sweep = SweepSpec((5.0,), (1.0, 10.0), (10.0,))
    specs = sweep.trials()
    table = TrialTable(tmp_path, sweep, cfg)
    table.open()
    wrong = _fake_row(specs[1], table.columns, 0)
    wrong['trial'] = '0'
    table.append(wrong)
    table.append(_fake_row(specs[1], table.columns, 0))
    table.close()
    again = TrialTable(tmp_path, sweep, cfg)
    assert again.open() == 1 and again.dropped == 1
    assert [s.index for s in again.pending()] == [0]


def test_cell_summary_counts_outcomes() -> None:
    rows = [{'friction_angle_deg': '5', 'k_theta_nm_per_rad': '1', 'delta_theta_p_deg': '10',
             'lifted': str(v), 'off_table_at_end': str(e), 'outcome': o,
             'rise_final_mm': str(r), 'check_lift_guaranteed': '0',
             'worst_case_margin_n': '-0.1', 'csm_lift': '1', 'csm_margin_n': '0.2'}
            for v, e, o, r in ((1, 1, 'SUCCESS', 8.0), (1, 0, 'LIFTED_DAM_FAILED', 6.0),
                               (0, 0, 'FAILURE', 1.0))]
    [cell] = cell_summary(rows)
    assert (cell['trials'], cell['lifted'], cell['p_lift'], cell['off_table_at_end'],
            cell['success'], cell['lifted_dam_failed'], cell['failure'], cell['p_success'],
            cell['rise_final_mm_mean']) == ('3', '2', '0.666667', '1', '1', '1', '1',
                                            '0.333333', '5')


def test_an_output_whose_parent_does_not_exist_is_refused_not_created(
        cfg: DamConfig, tmp_path: Path) -> None:
    sweep = SweepSpec((5.0,), (1.0,), (10.0,))
    out = tmp_path / 'typo' / 'deeper' / 'run'
    with pytest.raises(SweepError, match='does not exist'):
        TrialTable(out, sweep, cfg, info={}).open()
    assert not (tmp_path / 'typo').exists()
