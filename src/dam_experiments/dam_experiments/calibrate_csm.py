"""``ros2 run dam_experiments calibrate_csm INPUT... -o overlay.yaml``: fit the CSM to grasps.

::

    ros2 run dam_experiments calibrate_csm SWEEP_DIR [-o FILE.yaml] [--config YAML]
    ros2 run dam_experiments calibrate_csm BAG_OR_DIR... -o FILE.yaml [--config YAML]

The inputs are one sweep directory (``trials.csv``: pair, friction angle, object, mass and the
ground truth ``lifted`` of every trial: the object left the table during the grasp, the lift
eq. 18 and the CSM predict, whatever it did after; a table of format 2, whose ``lifted`` meant
off the table at the end, is read with a note, ``lifted`` from its lift-off times, and one of
format 1, whose ``lifted`` is the old rise rule, with a note) or episode bags
(``dam_recorder``'s, one grasp each: the pair, friction angle and object as run, and the
controller's outcome: SUCCESS or LIFTED_DAM_FAILED count as lifted, FAILURE as not, ABORTED,
REJECTED and UNKNOWN are left out) or directories holding them: a real hand's grasps calibrate
the same way. The fit
(:mod:`dam_analysis.csm_calibration`) gives the friction angle of every recorded friction
angle (unless ``--fixed-friction-angle``) and the effective tangential contact stiffness with
their profile-likelihood intervals, says which the data do not determine, checks the fit on
held-out folds and writes a configuration overlay (default ``SWEEP_DIR/csm_calibration.yaml``)
with the values the data determine, which ``load_config(path, [FILE])`` and
``check_lift_server --ros-args -p config_overlay:=FILE`` accept.

Exit status: 0 written; 2 bad input (no grasp, a malformed table or bag, several objects
without ``--object``, a bad configuration or option, an output that cannot be written), with
one line on stderr naming the problem; 130 interrupted.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dam_analysis.csm_calibration import ALPHA_HALF_WIDTH, ALPHA_SEARCH_BOUNDS
from dam_common.command_line import CommandLineParser
from dam_common.ros_args import strip_ros_args
from dam_common.words import counted
from dam_experiments.csm_calibration_run import (
    DEFAULT_FOLDS,
    Calibration,
    calibrate,
    grasps_for_width,
    interval_text,
    overlay,
)
from dam_experiments.errors import SweepPlotError
from dam_experiments.sweep_report_rows import CLASSED_LIFTED as LIFTED_OUTCOMES

PROG = 'calibrate_csm'
DEFAULT_OUTPUT = 'csm_calibration.yaml'
NOT_LIFTED_OUTCOMES = ('FAILURE',)


def cells_from_sweep(directory: Path, config: Any, object_name: str | None
                     ) -> tuple[Any, Any, str, list[str]]:
    """The grasp cells of a sweep directory, the configuration with its object, a label and
    notes (an incomplete sweep, a configuration that is not the sweep's)."""
    from dam_experiments.sweep import config_digest  # noqa: PLC0415
    from dam_experiments.sweep_results import one_object, read_sweep  # noqa: PLC0415

    whole = read_sweep(directory)
    notes = []
    if whole.parameters.get('config_sha256') != config_digest(config):
        notes.append(f'the configuration {str(config.source)!r} is not the sweep\'s (its '
                     f'config_sha256 differs): the analysis is this configuration\'s')
    if len(whole.trials) < whole.n_planned:
        notes.append(f'the sweep holds {len(whole.trials)} of its '
                     f'{counted(whole.n_planned, "trial")}')
    if whole.lifted_note is not None:
        notes.append(whole.lifted_note)
    data = one_object(whole, object_name)
    cells, config = cells_of_sweep(data, config)
    return cells, config, f'sweep {directory}', notes


def cells_of_sweep(data: Any, config: Any) -> tuple[Any, Any]:
    """The grasp cells of a sweep of one object (one per trial, table order) and the
    configuration with the sweep's object; a trial without a mass has the configured one."""
    from dam_analysis.csm_outcomes import GraspCells  # noqa: PLC0415
    from dam_experiments.sweep_results import analysis_config  # noqa: PLC0415

    config = analysis_config(data, config)
    nominal = config.object.mass_kg
    trials = data.trials
    cells = GraspCells(
        friction_angle=np.radians([t.friction_angle_deg for t in trials]),
        k_theta=np.array([t.k_theta for t in trials]),
        delta_theta_p=np.radians([t.delta_theta_p_deg for t in trials]),
        object_mass=np.array([nominal if math.isnan(t.object_mass_kg) else t.object_mass_kg
                              for t in trials]),
        lifted=np.array([1.0 if t.lifted else 0.0 for t in trials]))
    return cells, config


def cells_from_bags(paths: Sequence[Path], config: Any, object_name: str | None
                    ) -> tuple[Any, Any, str, int]:
    """The grasp cells of episode bags (or directories of them); also how many were left
    out (an outcome that says nothing of a lift)."""
    from dam_analysis.csm_outcomes import GraspCells  # noqa: PLC0415
    from dam_recorder.bag_reading import locate, read_bag_metadata  # noqa: PLC0415
    from dam_recorder.errors import DamRecorderError  # noqa: PLC0415

    bags: list[Path] = []
    for path in paths:
        try:
            bags.extend(locate(path)[1])
        except DamRecorderError as exc:
            raise SweepPlotError(str(exc)) from exc
    rows, skipped, objects = [], 0, set()
    for bag in bags:
        try:
            episode = read_bag_metadata(bag).episode()
        except DamRecorderError as exc:
            raise SweepPlotError(f'{bag}: {exc}') from exc
        if episode is None:
            raise SweepPlotError(f'{bag}: not an episode bag (no dam_episode metadata)')
        s = episode.summary
        if s.outcome_name not in LIFTED_OUTCOMES + NOT_LIFTED_OUTCOMES:
            skipped += 1
            continue
        name = s.object or config.object.name
        if object_name is not None and name != object_name:
            continue
        if not s.k_theta or not s.delta_theta_p:
            raise SweepPlotError(f'{bag}: the episode has no k_theta or delta_theta_p as run')
        if max(s.delta_theta_p) - min(s.delta_theta_p) > 1e-9:
            raise SweepPlotError(f'{bag}: the fingers ran different delta_theta_p '
                                 f'{list(s.delta_theta_p)!r}; the calibration needs one')
        objects.add(name)
        rows.append((s.friction_angle, s.k_theta[0], s.delta_theta_p[0],
                     s.outcome_name in LIFTED_OUTCOMES))
    if len(objects) > 1:
        raise SweepPlotError(f'the bags hold grasps of {len(objects)} objects '
                             f'({", ".join(sorted(objects))}): choose one with --object NAME')
    if not rows:
        raise SweepPlotError(f'no grasp with a lift outcome in {counted(len(bags), "bag")} '
                             f'({skipped} left out: aborted, rejected or unknown)')
    if objects:
        try:
            config = config.with_object(objects.pop())
        except Exception as exc:  # noqa: BLE001 - ConfigError names the library
            raise SweepPlotError(str(exc)) from exc
    arr = np.array(rows, dtype=np.float64)
    cells = GraspCells(friction_angle=arr[:, 0], k_theta=arr[:, 1], delta_theta_p=arr[:, 2],
                       object_mass=np.full(len(rows), config.object.mass_kg),
                       lifted=arr[:, 3])
    return cells, config, counted(len(bags), 'episode bag'), skipped


#: How a recorded friction angle's search range is made (it differs per angle).
_SEARCH = (f'recorded +- {math.degrees(ALPHA_HALF_WIDTH):g} deg within '
           f'[{math.degrees(ALPHA_SEARCH_BOUNDS[0]):g}, {math.degrees(ALPHA_SEARCH_BOUNDS[1]):g}]'
           ' deg')


def report_lines(result: Calibration) -> list[str]:
    """The printed summary of a calibration."""
    fit = result.fit
    lines = [f'{counted(fit.cells, "grasp")}, verdict {result.verdict!r}, {fit.level:.0%} '
             f'profile-likelihood intervals (ends to the grid step: 0.25 deg, 0.25 decade)']
    for rec, iv in zip(fit.recorded_friction_angle, fit.friction_angle, strict=True):
        if not fit.fitted_friction_angle:
            lines.append(f'friction angle {math.degrees(rec):g} deg: as recorded (not fitted)')
            continue
        lines.append(f'friction angle recorded {math.degrees(rec):g} deg: searched in '
                     f'[{math.degrees(iv.grid_low):.4g}, {math.degrees(iv.grid_high):.4g}] deg '
                     f'({_SEARCH}), fitted {interval_text(iv, scale=180.0 / math.pi)} deg '
                     f'({iv.status})')
    kt = fit.log10_tangential_stiffness
    lines.append(f'tangential stiffness k_t: fitted {interval_text(kt, log10=True)} N/m '
                 f'({kt.status}); configured {result.configured_tangential_stiffness:.4g} N/m')
    sg = fit.sigma
    remark = ''
    if sg.at_grid_end and sg.estimate == sg.grid_high:
        remark = ' -- at the top of its range: the margin explains little of the outcomes'
    elif sg.at_grid_end:
        remark = ' -- at the bottom of its range: the margin separates the outcomes perfectly'
    lines.append(f'link spread sigma: {interval_text(sg)} N{remark}')
    for g in result.groups:
        held = (f', held out ({result.folds}-fold) {g.held_out} of {g.cells}'
                if g.held_out >= 0 else '')
        lines.append(f'agreement at {g.recorded_deg:g} deg: configured end {g.configured_end}, '
                     f'configured path {g.configured_path}, fitted {g.fitted} of {g.cells}'
                     f'{held}')
    for rec, iv in zip(fit.recorded_friction_angle, fit.friction_angle, strict=True):
        if fit.fitted_friction_angle and iv.determined:
            width = math.degrees(iv.high - iv.low)
            n = _group_size(result, rec)
            lines.append(f'friction angle {math.degrees(rec):g} deg: interval width '
                         f'{width:.3g} deg from {counted(n, "grasp")}; of the same design, a '
                         'width of 2 deg '
                         f'needs about {counted(round(grasps_for_width(n, width, 2.0)), "grasp")}'
                         ', of 1 deg '
                         f'about {grasps_for_width(n, width, 1.0):.0f}')
    lines.append(f'/check_lift (end verdict) agrees with {result.end_agreement_configured} of '
                 f'{counted(result.cells, "grasp")} as configured, '
                 f'{result.end_agreement_overlay} with the '
                 f'fitted values: '
                 + ('the overlay holds them' if result.overlay_helps
                    else 'no better, the overlay holds none'))
    if result.verdict == 'path':
        lines.append('note: the values were fitted to the path verdict; /check_lift answers the '
                     'end verdict (--verdict end fits that one)')
    return lines


def _group_size(result: Calibration, recorded: float) -> int:
    for g in result.groups:
        if math.isclose(g.recorded_deg, math.degrees(recorded), abs_tol=1e-6):
            return g.cells
    return 0


def _parse(argv: Sequence[str]) -> argparse.Namespace:
    p = CommandLineParser(
        prog=PROG,
        description='Fit the contact stiffness model (friction angle, tangential stiffness) '
                    'to observed lift / no-lift outcomes of a sweep or of episode bags, '
                    'with confidence intervals and a k-fold check, and write a '
                    'configuration overlay with the fitted values.')
    p.add_argument('inputs', type=Path, nargs='+', metavar='INPUT',
                   help='one sweep directory (trials.csv), or episode bags or directories '
                        'of them')
    p.add_argument('-o', '--output', type=Path, default=None, metavar='FILE.yaml',
                   help=f'the overlay (default: SWEEP_DIR/{DEFAULT_OUTPUT}; required for bags)')
    p.add_argument('--config', type=Path, default=None, metavar='YAML',
                   help='configuration of the analysis (default: DAM_CONFIG or the installed '
                        'config/dam.yaml)')
    p.add_argument('--object', default=None, metavar='NAME',
                   help='the object to calibrate for, of inputs holding several')
    p.add_argument('--verdict', choices=('path', 'end'), default='path',
                   help='the CSM verdict the outcomes are fitted to: the largest margin on '
                        'the way to delta_theta_p (path, default) or the margin at its end')
    p.add_argument('--fixed-friction-angle', action='store_true',
                   help='take the recorded friction angles as they are (fit k_t only)')
    p.add_argument('--folds', type=int, default=DEFAULT_FOLDS, metavar='K',
                   help=f'k-fold check of the agreement on held-out grasps (default '
                        f'{DEFAULT_FOLDS}; 0: none)')
    p.add_argument('--level', type=float, default=0.9,
                   help='confidence level of the intervals (default 0.9)')
    p.add_argument('--lapse', type=float, default=0.02,
                   help='probability of an outcome against any margin (default 0.02)')
    p.add_argument('--seed', type=int, default=0, help='seed of the fold split (default 0)')
    args = p.parse_args(argv)
    if not 0.0 < args.level < 1.0:
        p.error(f'--level: {args.level} must lie in (0, 1)')
    if not 0.0 < args.lapse < 0.5:
        p.error(f'--lapse: {args.lapse} must lie in (0, 0.5)')
    if args.folds < 0 or args.folds == 1:
        p.error(f'--folds: {args.folds} must be 0 or at least 2')
    return args


def _is_sweep(path: Path) -> bool:
    return (path / 'trials.csv').is_file()


def _check_inputs(inputs: Sequence[Path]) -> bool:
    """Whether the inputs are one sweep directory; refuse what is neither."""
    for path in inputs:
        if not path.exists():
            raise SweepPlotError(f'{path}: no such directory')
        if not path.is_dir():
            raise SweepPlotError(f'{path} is a file: give a sweep directory (trials.csv) or '
                                 f'episode bag directories (metadata.yaml) or directories '
                                 f'holding them')
    if len(inputs) == 1 and _is_sweep(inputs[0]):
        return True
    for path in inputs:
        if _is_sweep(path):
            raise SweepPlotError(f'{path} is a sweep: give one sweep directory alone')
    return False


def _check_output(output: Path) -> None:
    if output.suffix.lower() not in ('.yaml', '.yml'):
        raise SweepPlotError(f'output {str(output)!r}: the overlay must be a .yaml file')
    if output.is_dir():
        raise SweepPlotError(f'output {str(output)!r} is a directory')
    if not output.parent.is_dir():
        raise SweepPlotError(f'output {str(output)!r}: directory {str(output.parent)!r} '
                             f'does not exist')
    existed = output.exists()
    try:  # before a minute of fitting, not after
        with open(output, 'a', encoding='utf-8'):
            pass
    except OSError as exc:
        raise SweepPlotError(f'output {str(output)!r} cannot be written: {exc.strerror}'
                             ) from exc
    if not existed:
        output.unlink()


def main(argv: Sequence[str] | None = None) -> int:
    """``calibrate_csm``; see the module docstring."""
    from dam_common.config import load_config  # noqa: PLC0415
    from dam_common.errors import DamCommonError  # noqa: PLC0415

    args = _parse(strip_ros_args(sys.argv[1:] if argv is None else argv))
    try:
        sweep = _check_inputs(args.inputs)
        if args.output is None and not sweep:
            raise SweepPlotError(f'{args.inputs[0]} holds no trials.csv: for episode bags, '
                                 f'-o FILE.yaml is required')
        output = args.output if args.output is not None else args.inputs[0] / DEFAULT_OUTPUT
        _check_output(output)
        config = load_config(args.config)
        skipped = 0
        notes = []
        if sweep:
            cells, config, source, notes = cells_from_sweep(args.inputs[0], config,
                                                            args.object)
        else:
            cells, config, source, skipped = cells_from_bags(args.inputs, config, args.object)
        folds = min(args.folds, cells.size)
        folds = 0 if folds < 2 else folds
        for note in notes:
            sys.stderr.write(f'{PROG}: note: {note}\n')
        sys.stderr.write(f'{PROG}: fitting {counted(cells.size, "grasp")} of {config.object.name} '
                         f'(a few minutes for a few hundred)\n')
        sys.stderr.flush()
        result = calibrate(cells, config, verdict=args.verdict,
                           fit_friction_angle=not args.fixed_friction_angle, lapse=args.lapse,
                           level=args.level, folds=folds, seed=args.seed)
        text = overlay(result, config, source, config.object.name)
        try:
            output.write_text(text, encoding='utf-8')
        except OSError as exc:
            raise SweepPlotError(f'cannot write {str(output)!r}: {exc.strerror}') from exc
    except (SweepPlotError, DamCommonError) as exc:
        sys.stderr.write(f'{PROG}: {" ".join(str(exc).split())}\n')
        return 2
    if skipped:
        print(f'{PROG}: left out {counted(skipped, "episode")} '
              'whose outcome says nothing of a lift')
    print('\n'.join(f'{PROG}: {line}' for line in report_lines(result)))
    print(f'{PROG}: wrote {output}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
