"""The lockstep DAM experiment (HandWorld + DamSequence, no ROS) and the joint-signal
classifier checked against the simulator's ground truth on recorded runs.

The recordings are made once per session (a few seconds of CPU); ``dam_experiment --fixtures
DIR`` writes the same signals as ``.npz`` files for inspection.
"""

from __future__ import annotations

import csv
import dataclasses
import math
from pathlib import Path

import numpy as np
import pytest

from dam_common.config import DamConfig, load_config
from dam_experiments.experiment import (
    PHASE_CODES,
    ExperimentResult,
    main,
    run_experiment,
    save_signals,
)
from dam_sim_bridge.world import HandWorld
from dam_spcm_controller.classification import (
    ClassifierSettings,
    HandGeometry,
    Outcome,
    classify_from_joints,
    classify_with_object_height,
)
from dam_spcm_controller.commands import HandLayout
from dam_spcm_controller.sequence import Phase

DP = math.radians(10.0)


@pytest.fixture(scope='module')
def cfg() -> DamConfig:
    return load_config()


@pytest.fixture(scope='module')
def recorded(cfg: DamConfig) -> dict[str, ExperimentResult]:
    """Three recorded grasps at alpha = 5 deg, delta_theta_p = 10 deg: far below both
    analysis regions (k 0.5), inside the CSM region only (k 3), inside the sufficient region
    (k 10)."""
    with HandWorld(cfg) as world:
        return {name: run_experiment(cfg, k, DP, world=world, record=True, settle_after=1.0)
                for name, k in (('weak', 0.5), ('csm', 3.0), ('stiff', 10.0))}


def test_stiff_pair_lifts_and_holds(recorded: dict[str, ExperimentResult]) -> None:
    r = recorded['stiff']
    assert r.phase is Phase.DONE, r.failure_reason
    assert list(r.phase_times) == ['APPROACH', 'ROLLING_UP', 'ENVELOPE', 'DONE']
    assert r.lifted and r.off_table_at_end and r.lift_final > 0.005
    assert r.lift_rolling_end > 0.005  # the SPCM lifted it, the envelope kept it up
    assert r.outcome is Outcome.SUCCESS, r.joint_reason
    # the object is still up one second after DONE
    sig = r.signals
    done = sig['phase'] == PHASE_CODES[Phase.DONE]
    assert done.sum() > 50
    assert np.all(sig['object_position'][done, 2] - sig['object_position'][0, 2] > 0.005)


def test_weak_pair_does_not_lift(recorded: dict[str, ExperimentResult]) -> None:
    r = recorded['weak']
    assert not r.lifted and not r.off_table_at_end and r.lift_max < 0.002
    assert r.outcome is not Outcome.SUCCESS


def test_lift_grows_with_stiffness(recorded: dict[str, ExperimentResult]) -> None:
    """Paper Fig. 7 trend at a fixed displacement: more stiffness, more lift."""
    lifts = [recorded[n].lift_rolling_end for n in ('weak', 'csm', 'stiff')]
    assert lifts[0] < 0.001 < lifts[1] <= lifts[2] + 0.002


def test_classifier_agrees_with_the_ground_truth(
        cfg: DamConfig, recorded: dict[str, ExperimentResult]) -> None:
    """Recorded simulator signals as classification fixtures: the joint-only outcome matches
    the outcome from the true object height."""
    geometry = HandGeometry.from_config(cfg)
    layout = HandLayout.from_hand_config(cfg.hand)
    settings = ClassifierSettings.from_config(cfg)
    for name, r in recorded.items():
        final_q = r.signals['positions'][-1]
        final_tau = r.signals['efforts'][-1]
        z = r.signals['object_position'][:, 2]
        joints = classify_from_joints(geometry, layout.lower, layout.upper, final_q,
                                      final_tau, settings)
        truth = classify_with_object_height(joints, float(z[-1]), float(z[0]),
                                            settings.lift_height)
        assert joints.outcome is truth, (name, joints.reason)
        if joints.estimate.found:  # the fitted centre is the true one within 2 mm
            assert joints.lift_m == pytest.approx(float(z[-1] - z[0]), abs=2e-3), name


def test_signals_round_trip_through_npz(recorded: dict[str, ExperimentResult],
                                        tmp_path: Path) -> None:
    r = recorded['stiff']
    path = save_signals(r, tmp_path / 'stiff.npz')
    with np.load(path) as data:
        assert data['positions'].shape == r.signals['positions'].shape
        assert data['positions'].shape[1] == 9
        assert str(data['outcome']) == 'SUCCESS' and bool(data['lifted'])
        assert bool(data['off_table_at_end']) is r.off_table_at_end is True
        assert float(data['k_theta']) == 10.0
    assert path.stat().st_size < 200_000


def test_bad_arguments(cfg: DamConfig) -> None:
    with pytest.raises(ValueError, match='latency_cycles'):
        run_experiment(cfg, 1.0, DP, latency_cycles=0)
    with pytest.raises(ValueError, match='max_time'):
        run_experiment(cfg, 1.0, DP, max_time=math.nan)
    assert main(['--k-theta', '-1', '--delta-theta-p', '10deg']) == 2


def test_command_line_writes_csv(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / 'grid.csv'
    assert main(['--k-theta', '0.5', '--delta-theta-p', '10deg', '--max-time', '3',
                 '--out', str(out)]) == 0
    text = out.read_text(encoding='utf-8').splitlines()
    assert text[0].startswith('object,alpha_deg,k_theta_nm_per_rad,delta_theta_p_deg,phase')
    assert len(text) == 2 and text[1].startswith('cylinder,')  # the configured object
    assert 'no' in text[1]  # k 0.5 is outside both analysis regions
    assert 'k_theta' in capsys.readouterr().out


def test_command_line_grasps_each_object_named(tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    """--object takes names of the library: a row per object, each grasping its own (the
    analysis columns of that object, asked afresh here); an unknown name exits 2 naming the
    known ones."""
    import csv

    from dam_analysis.analysis import LiftAnalyzer
    from dam_common.config import load_config

    out = tmp_path / 'grid.csv'
    assert main(['--object', 'cylinder', 'hex_bar', '--k-theta', '3', '--delta-theta-p',
                 '20deg', '--alpha', '5deg', '--max-time', '1', '--out', str(out)]) == 0
    with out.open(encoding='utf-8', newline='') as handle:
        rows = list(csv.DictReader(handle))
    assert [r['object'] for r in rows] == ['cylinder', 'hex_bar']
    config = load_config()
    for row in rows:
        answer = LiftAnalyzer(config.with_object(row['object'])).check_lift(
            [3.0], [math.radians(20.0)], friction_angle=math.radians(5.0))
        assert row['csm_region'] == ('yes' if answer.csm_lift else 'no')
        assert row['sufficient_region'] == ('yes' if answer.lift_guaranteed else 'no')
    printed = capsys.readouterr().out
    assert 'hex_bar' in printed and 'cylinder' in printed
    assert main(['--object', 'pencil', '--k-theta', '3', '--delta-theta-p', '20deg']) == 2
    assert "'pencil' is not in the object library" in capsys.readouterr().err
    assert main(['--object', 'hex_bar', 'hex_bar', '--k-theta', '3']) == 2
    assert 'must be distinct, non-empty names' in capsys.readouterr().err


def test_an_object_the_analysis_cannot_answer_for_is_no_grasp(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A 1 mm rod no finger reaches: refused, exit 2, the object named (it was grasped and
    called SUCCESS with the object never touched)."""
    import yaml

    from dam_common.config import default_config_path

    data = yaml.safe_load(default_config_path().read_text(encoding='utf-8'))
    data['object']['library']['rod_1mm'] = {'shape': 'circle', 'radius_m': 0.001,
                                            'length_m': 0.1, 'mass_kg': 0.002}
    config = tmp_path / 'dam.yaml'
    config.write_text(yaml.safe_dump(data), encoding='utf-8')
    assert main(['--config', str(config), '--object', 'rod_1mm', '--k-theta', '5',
                 '--delta-theta-p', '10deg']) == 2
    captured = capsys.readouterr()
    assert "object 'rod_1mm' cannot be analysed with this hand" in captured.err, captured.err
    assert 'SUCCESS' not in captured.out


@pytest.mark.parametrize('on_device, envelope_mode', [(True, 4), (False, 1)])
def test_the_experiment_runs_the_impedance_where_configured(
        cfg: DamConfig, on_device: bool, envelope_mode: int) -> None:
    """Impedance on the device (default): the world's compliant joints end in IMPEDANCE (the
    world runs the law every physics step); in the controller: TORQUE. Both lift the object
    at k_theta 10 inside the sufficient region."""
    from dam_common.device_protocol import JointMode as WireMode

    assert int(WireMode.IMPEDANCE) == 4 and int(WireMode.TORQUE) == 1
    with HandWorld(cfg) as world:
        r = run_experiment(cfg, 10.0, DP, world=world, impedance_on_device=on_device)
        assert r.phase is Phase.DONE and r.lifted, r.failure_reason or r.joint_reason
        assert world.joint_modes()[0::3].tolist() == [envelope_mode] * 3
        assert r.lift_final > 0.005


@pytest.mark.parametrize(('name', 'k_theta', 'delta_theta_p_deg'), [
    ('hex_bar', 5.0, 40.0), ('hex_bar', 10.0, 10.0), ('square_bar', 10.0, 10.0),
    ('hex_pencil', 10.0, 10.0), ('elliptic_column', 10.0, 10.0)])
def test_column_objects_are_classified_no_better_than_the_ground_truth(
        cfg: DamConfig, name: str, k_theta: float, delta_theta_p_deg: float) -> None:
    """A turned polygon or ellipse: the joints do not fix its orientation, and the classifier
    takes the lowest pose they allow, so it never calls an object lifted that is not (the
    pencil, the bars and the ellipse at 10 deg stay below 5 mm in the stand-in), and it sees
    the hexagonal bar that the stand-in lifts by about 2 cm."""
    result = run_experiment(cfg.with_object(name), k_theta, math.radians(delta_theta_p_deg))
    assert result.phase is Phase.DONE, result.joint_reason
    if not result.lifted:
        assert result.outcome is Outcome.FAILURE, (result.joint_reason, result.lift_final)
    if name == 'hex_bar' and k_theta == 5.0:
        assert result.lifted and result.lift_final > 0.015, result.lift_final
        assert result.outcome is Outcome.SUCCESS, result.joint_reason


def test_the_section_fit_over_one_symmetry_period_equals_the_full_turn(cfg: DamConfig) -> None:
    """A hexagon repeats every 60 deg: the fit over one period finds the pose of the fit over
    the whole turn; and a stop request ends the fit."""
    from dam_common.polygon_section import ConvexPolygon
    from dam_spcm_controller.object_estimate import FitInterrupted, estimate_section

    config = cfg.with_object('hex_bar')
    world = HandWorld(config)
    try:
        run_experiment(config, 5.0, math.radians(40.0), world=world)
        positions = world.joint_states().positions
    finally:
        world.close()
    geometry = HandGeometry.from_config(config)
    hexagon = geometry.section
    assert hexagon is not None and hexagon.symmetry_period == pytest.approx(math.pi / 3.0)
    full_turn = dataclasses.replace(geometry, section=ConvexPolygon(hexagon.vertices))
    assert full_turn.section.symmetry_period == pytest.approx(2.0 * math.pi)
    one_period = estimate_section(geometry, positions)
    whole = estimate_section(full_turn, positions)
    np.testing.assert_allclose(one_period.centre, whole.centre, atol=2e-5)
    assert math.remainder(one_period.orientation - whole.orientation,
                          math.pi / 3.0) == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(FitInterrupted):
        estimate_section(geometry, positions, stop=lambda: True)


def test_the_table_prints_both_rises_and_says_which_is_which(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """One grasp had two rises, the joints' estimate (run.sh: 9.8 mm) and the stand-in's
    (bag plot: 8.09 mm), each printed alone; the table prints both, named."""
    out = tmp_path / 'grid.csv'
    assert main(['--k-theta', '10', '--delta-theta-p', '10deg', '--out', str(out)]) == 0
    printed = capsys.readouterr().out.splitlines()
    header = next(line for line in printed if line.lstrip().startswith('object'))
    assert header.split()[-6:] == ['rise', 'max', 'est', 'suff', 'csm', 'reason']
    assert ("(rise, max: the stand-in's, at the end and highest; est: the rise estimated "
            'from the joints; -: not estimated)') in printed
    [row] = list(csv.DictReader(out.open(encoding='utf-8')))
    assert row['outcome'] == 'SUCCESS' and row['estimated_rise_mm']
    line = next(line for line in printed if line.startswith('cylinder'))
    rise, _, est = line.split()[8:11]
    assert rise == f'{float(row["lift_final_mm"]):.1f}mm'
    assert est == f'{float(row["estimated_rise_mm"]):.1f}mm'
    assert printed[-1] == f'wrote 1 row to {out}'  # not "1 rows"
