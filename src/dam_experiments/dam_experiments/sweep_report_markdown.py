"""The results document as Markdown: :class:`~dam_experiments.sweep_report.SweepReport` in words.

:func:`render_markdown` writes the document ``sweep_report`` saves: a header with the sweep's
parameters and the command that generated it, the definitions of every number, a summary table
per friction angle, then the four sections (false guarantees, the CSM boundary against the
simulated one, the lift the sufficient condition misses, the disagreements and their evidence).
The same report gives the same text, byte for byte. No I/O.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

from dam_common.words import counted
from dam_experiments.sweep_report import Category, SweepReport
from dam_experiments.sweep_report_cells import LIFT_PROBABILITY
from dam_experiments.sweep_report_rows import (
    CHECKS_LIFTING,
    CHECKS_NOT_LIFTING,
    CLASSED_LIFTED,
    LIMIT_FRACTION,
    NEVER_ROSE_FRACTION,
    controller_verdicts,
    rise_class,
)

#: Cells listed per disagreement category (the figure shows them all).
MAX_LISTED_CELLS = 40
#: Headers of the summary table (one row per friction angle).
SUMMARY_HEADER = ('alpha [deg]', 'trials', 'cells', 'lifting cells', 'false guarantees',
                  'CSM agreement (end verdict)', 'CSM agreement (path verdict)',
                  'median boundary distance [decades] (compared columns of all)',
                  'columns within one k step', 'lifting cells without a guarantee')
#: Default values of the sweep's options (left out of the reconstructed command).
_SWEEP_DEFAULTS = {'repeats': 1, 'seed': 0, 'max_time_s': 8.0, 'latency_cycles': 2,
                   'trajectory_duration_s': None, 'impedance': None, 'envelope': 'impedance'}
_SWEEP_OPTIONS = {'repeats': '--repeats', 'seed': '--seed', 'mass_rel': '--mass-rel',
                  'position_sd_mm': '--position-sd', 'table_friction_rel': '--table-friction-rel',
                  'friction_angle_sd_deg': '--friction-angle-sd', 'max_time_s': '--max-time',
                  'latency_cycles': '--latency-cycles',
                  'trajectory_duration_s': '--trajectory-duration', 'impedance': '--impedance',
                  'envelope': '--envelope'}


def share(part: int, whole: int) -> str:
    """``'3 of 4 (75.0 %)'``; ``'0 of 0 (n/a)'``."""
    if not whole:
        return f'{part} of {whole} (n/a)'
    return f'{part} of {whole} ({100.0 * part / whole:.1f} %)'


def g(value: float, digits: int = 3) -> str:
    """A number with ``digits`` significant digits; ``-`` for NaN."""
    return '-' if math.isnan(value) else f'{value + 0.0:.{digits}g}'


def decades(value: float | None) -> str:
    """A distance in decades with 3 decimals; ``n/a`` for None."""
    return 'n/a' if value is None else f'{value + 0.0:.3f}'


def _cell_text(text: str) -> str:
    """Text safe inside a Markdown table cell."""
    return ' '.join(text.replace('|', '\\|').split()) or '-'


def _table(header: Sequence[str], rows: Sequence[Sequence[str]]) -> list[str]:
    lines = ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    lines += ['| ' + ' | '.join(_cell_text(c) for c in row) + ' |' for row in rows]
    return lines


def sweep_command(report: SweepReport) -> str:
    """The ``sweep`` command of the sweep, reconstructed from ``sweep.json`` (the axes as
    typed when recorded; options at their defaults left out; ``--config`` is not recorded)."""
    spec = report.data.spec
    given = report.data.parameters.get('axes_as_given')
    given = given if isinstance(given, Mapping) else {}
    parts = ['ros2 run dam_experiments sweep']
    recorded = report.data.parameters.get('sweep')
    objects = recorded.get('objects') if isinstance(recorded, Mapping) else None
    if isinstance(objects, list) and objects and all(isinstance(n, str) for n in objects):
        parts.append(f'--objects {" ".join(objects)}')  # the whole sweep's, not the report's
    for option, key, values in (('--friction-angles', 'friction_angles',
                                 spec.friction_angles_deg),
                                ('--k-theta', 'k_theta', spec.k_theta),
                                ('--delta-theta-p', 'delta_theta_p', spec.delta_theta_p_deg)):
        tokens = given.get(key)
        if not (isinstance(tokens, list) and tokens and all(isinstance(t, str) for t in tokens)):
            tokens = [f'{v:g}' for v in values]
        parts.append(f'{option} {" ".join(tokens)}')
    settings = {**spec.to_dict(), **spec.to_dict()['perturbations']}
    for name, option in _SWEEP_OPTIONS.items():
        value = settings[name]
        if value != _SWEEP_DEFAULTS.get(name, 0.0):
            parts.append(f'{option} {value:g}' if isinstance(value, float) else
                         f'{option} {value}')
    parts.append(f'--out {report.data.directory}')
    return ' '.join(parts)


def _perturbations(report: SweepReport) -> str:
    p = report.data.spec.perturbations
    if not p.any:
        return 'none (every trial is the nominal world)'
    words = []
    for name, text in (('mass_rel', 'mass +-{:g} (relative, uniform)'),
                       ('position_sd_mm', 'position sd {:g} mm'),
                       ('table_friction_rel', 'table friction +-{:g} (relative, uniform)'),
                       ('friction_angle_sd_deg', 'friction angle sd {:g} deg')):
        if getattr(p, name):
            words.append(text.format(getattr(p, name)))
    return '; '.join(words)


def _header(report: SweepReport, command: str, figures: Mapping[str, str]) -> list[str]:
    data, spec = report.data, report.data.spec
    params = data.parameters
    lines = ['# Results: the Fig. 7 sweep against the lift analysis', '',
             'Generated from a sweep directory by', '', '```bash', command, '```', '',
             'Do not edit this file: run the command again. Every number below is defined in '
             '"Definitions" and computed from the sweep\'s `trials.csv` and the analysis of '
             'the configuration. The figures are written beside it by the same command; a '
             'copy of the document without them (a repository that keeps generated figures '
             'out) shows them as missing until the command runs.', '']
    if not report.complete:
        lines += [f'**Incomplete sweep: {report.n_present} of {data.n_planned} trials are '
                  f'present.** The numbers are those of the trials present; a cell counts the '
                  f'trials it has.', '']
    if data.skipped:
        lines += [f'{counted(data.skipped, "row")} cut short (being written) left out.', '']
    if data.table_format == 1:
        lines += ['**A table of format 1: its `lifted` is the old rule**, the object centre at '
                  'least the lift height up at the end, not that the object left the table '
                  '(the table has no column `lift_off_time_s`); the classes below are the '
                  'old ones. Run the sweep again for lift-off.', '']
    elif data.table_format == 2:
        lines += ['**A table of format 2: its `lifted` meant off the table over the last 0.1 s '
                  'of the grasp** (the table has no column `off_table_at_end`); it is read as '
                  '`off_table_at_end`, and `lifted` (a lift-off) from `lift_off_time_s`.', '']
    if not report.config_matches:
        lines += ['**The configuration of the analysis is not the sweep\'s** (its SHA-256 '
                  'differs from `sweep.json`\'s `config_sha256`): the boundaries, the lift '
                  'height and the limits below are another configuration\'s.', '']
    opts = (f'max time {spec.max_time_s:g} s, latency {counted(spec.latency_cycles, "cycle")}, '
            f'trajectory duration '
            + ('configured' if spec.trajectory_duration_s is None
               else f'{spec.trajectory_duration_s:g} s')
            + f', impedance {spec.impedance or "configured"}, envelope {spec.envelope}')
    given = params.get('axes_as_given')
    typed = given.get('k_theta') if isinstance(given, Mapping) else None
    k_values = (', '.join(g(k, 4) for k in spec.k_theta) if len(spec.k_theta) <= 12 else
                f'{len(spec.k_theta)} values, {g(min(spec.k_theta))} to '
                f'{g(max(spec.k_theta))}')
    note = f'{"log" if report.log_k else "linear"} axis'
    if isinstance(typed, list) and typed:
        note = f'typed `{" ".join(str(t) for t in typed)}`; {note}'
    k_values += f' ({note})'
    rows = [
        ('object', data.object_label or 'the configured one'),
        ('friction angles alpha [deg]', ', '.join(f'{a:g}' for a in spec.friction_angles_deg)),
        ('k_theta, finger 1 [N*m/rad]', k_values),
        ('delta_theta_p [deg]', ', '.join(f'{d:g}' for d in spec.delta_theta_p_deg)),
        ('repeats per cell', str(spec.repeats)),
        ('trials present', f'{report.n_present} of {data.n_planned}'),
        ('perturbations', _perturbations(report)),
        ('seed', str(spec.seed)),
        ('trial options', opts),
        ('configuration SHA-256', f'`{params.get("config_sha256", "not recorded")}`'
         + ('' if report.config_matches else ' (not the analysis\' configuration)')),
        ('lift height', f'{report.limits.lift_height_mm:g} mm (classification.lift_height_m)'),
        ('software', str(params.get('software_version', 'not recorded'))),
    ]
    lines += ['## The sweep', ''] + _table(('parameter', 'value'), rows)
    lines += ['', 'The sweep command, as recorded in `sweep.json` (the configuration file is '
              'not recorded, only its SHA-256):', '', '```bash', sweep_command(report), '```',
              '']
    if 'fig7' in figures:
        lines += [f'![The sweep as the paper\'s Fig. 7, with the analysis\' boundaries]'
                  f'({figures["fig7"]})', '']
    return lines


def _ground_truth(report: SweepReport) -> str:
    """The definition of ``lifted`` and of the classes of what the object did."""
    h = report.limits.lift_height_mm
    f = NEVER_ROSE_FRACTION
    if not report.data.lift_off_recorded:
        return (f'* **Ground truth (format 1).** A trial lifted when the object centre ended at '
                f'least the lift height h = {h:g} mm above its start (column `lifted`). A '
                f'trial that did not lift is classed "rose then fell back" (`rise_max_mm >= h '
                f'> rise_final_mm`), "rose partly" ({f:g} h <= `rise_max_mm` < h) or "never '
                f'rose".')
    return ('* **Ground truth.** A trial lifted when the object left the table during the '
            'grasp (column `lifted`), the event eq. 18 promises: a stretch of at least 50 ms '
            'with no object-table contact point closer than 0.1 mm, read from the stand-in\'s '
            'contacts every device cycle (2 ms); its start is the lift-off time (column '
            '`lift_off_time_s`, from the goal; a bounce, shorter, is no lift-off). It holds '
            'for every shape: a polygon that rolls on a vertex raises its centroid while it '
            'touches, and an object off the table may have risen less than the lift height '
            f'h = {h:g} mm. Whether the object was still off the table over the last 0.1 s is '
            'a separate column, `off_table_at_end`: after the lift-off an object may fall '
            'back, or a column tip out of the plane until one end rests on the table, a 3-D '
            'motion the planar analysis does not speak of. A lifted trial is classed "lifted '
            'and held off the table" (`off_table_at_end` 1) or "lifted, then fell back or an '
            'end came to rest on the table"; one that did not lift "rose on the table" '
            f'(`rise_max_mm` >= {f:g} h: it rolled or tipped while touching) or "never '
            'rose".')


def _definitions(report: SweepReport) -> list[str]:
    lim = report.limits
    n_points = len(report.boundaries[0].delta_theta_p) if report.boundaries else 0
    return [
        '## Definitions', '',
        _ground_truth(report) + ' A cell\'s lift probability `p_lift` is the share of its '
        f'trials that lifted; the cell **lifts** when `p_lift >= {LIFT_PROBABILITY:g}`.',
        '* **Analysis.** Per cell, the `/check_lift` answer for the cell\'s pair at its friction '
        'angle with the sweep\'s object as configured (columns `check_lift_guaranteed`, '
        '`worst_case_margin_n`, `csm_lift`, `csm_margin_n`; the first trial\'s, they are the '
        'same for every trial of a cell). A trial\'s perturbations do not enter it.',
        '* **1. False guarantee.** A cell with `check_lift_guaranteed` 1 that does not lift. '
        'Each of its trials that did not lift is listed and classed from its columns as the '
        'ground truth says; then how it ended: "done" (`phase` DONE), "controller '
        'failure in <phase>" (FAILED, the phase named in `reason`), "still running at the '
        'time limit (<phase>)" (an active phase).',
        '* **2a. CSM agreement.** The share of the cells whose `csm_lift` (the end verdict) '
        'equals the ground truth, and of those whose `csm_path_lift` (the path verdict: the '
        'largest CSM margin on the way to `delta_theta_p`) does; "not recorded" in a table '
        'written before `/check_lift` answered the path verdict.',
        '* **2b. Boundary distance.** Per `delta_theta_p` column, the cells in ascending '
        '`k_theta`: `k_lift` is the lowest lifting `k_theta`, `k_below` the grid value just '
        'below it (which does not lift), and the simulated boundary is their geometric mean '
        '`k_sim = sqrt(k_below k_lift)`. A column that changes between lifting and not '
        'lifting more than once uses its lowest lifting `k_theta` all the same (counted as '
        '"columns with several transitions"). A column without a lifting cell ("no lift") or '
        'whose lowest `k_theta` lifts ("lifts at the lowest k_theta") is censored: its '
        'boundary lies outside the grid and it is not compared. `k_csm` is the CSM boundary '
        'at the column\'s `delta_theta_p` (`compute_boundaries` of the configuration); where '
        'the CSM lifts at no stiffness the column is "no CSM boundary", not compared. The '
        'distance is `d = log10(k_sim / k_csm)` in decades (positive: the simulation needs '
        'more stiffness than the CSM predicts); reported are the median of `|d|` and of `d` '
        'over the compared columns, and the share of them **within one k step**: `|d| <= '
        'log10(k_lift / k_below)`.',
        '* **3. Lift without a guarantee.** The share of the lifting cells whose '
        '`check_lift_guaranteed` is 0. "no stiffness is guaranteed" at a friction angle when '
        'the sufficient boundary (eq. 18; for a section that can turn on the table, with the '
        '`/check_lift` rolling check) '
        f'is finite at none of {n_points} points of `delta_theta_p` in '
        f'[0, {report.dense_right_deg:g}] deg.',
        '* **4. Disagreement categories.** Cells where `csm_lift` differs from the ground '
        'truth (CSM lifts and the simulation does not, or the reverse), and the false '
        'guarantees (`check_lift_guaranteed` 1, the cell does not lift; a lift without a '
        'guarantee is no disagreement: eq. 18 is only sufficient, section 3 counts it). The '
        'evidence is taken from the trials that side with the simulation\'s verdict (the '
        'non-lifted trials of a cell that does not lift, the lifted ones of a cell that '
        'lifts). Checks on a trial that did not lift: '
        + '; '.join(f'"{n}": {w}' for n, w in CHECKS_NOT_LIFTING)
        + '. Checks on a trial that lifted: '
        + '; '.join(f'"{n}": {w}' for n, w in CHECKS_LIFTING)
        + f'. A limit counts as reached at {100 * LIMIT_FRACTION:g} % of it: compliant joints '
        f'{lim.compliant_torque_nm:g} N*m (`device.torque_limit_nm` with the impedance on the '
        f'device, else the lower of it and `controller.torque_limit_nm`), position joints '
        f'{lim.servo_torque_nm:g} N*m (`sim.servo_force_limit_nm`); the nominal mass is '
        f'{lim.object_mass_kg:g} kg; "next to the boundary" uses the category\'s boundary (CSM '
        'or eq. 18) at the cell\'s `delta_theta_p`. A trial for which no check holds is '
        '**unexplained**.', '']


def _summary(report: SweepReport) -> list[str]:
    rows = []
    for a in report.angles:
        rows.append((f'{a.friction_angle_deg:g}', str(a.n_trials), str(a.n_cells),
                     str(a.n_lifting), str(a.n_false_guarantees),
                     share(a.n_agree, a.n_cells),
                     ('not recorded' if a.n_path_agree is None
                      else share(a.n_path_agree, a.n_cells)),
                     f'{decades(a.median_distance_dec)} ({a.n_compared} of '
                     f'{len(a.columns)} columns; no CSM boundary in '
                     f'{a.n_status("no CSM boundary")})',
                     share(a.n_within_step, a.n_compared), share(a.n_missed, a.n_lifting)))
    return ['## Summary', ''] + _table(SUMMARY_HEADER, rows) + ['']


def _controller(report: SweepReport) -> list[str]:
    """The controller's classes (``outcome``) against the ground truth (``lifted``), and the
    trials where they differ."""
    trials = [t for c in report.cells for t in c.trials]
    verdicts = controller_verdicts(trials)
    truth = ('the object left the table during the grasp' if report.data.lift_off_recorded
             else 'format 1: the object centre at least the lift height up at the end')
    header = ('alpha [deg]', 'trials', 'lifted, classed lifted', 'lifted, classed FAILURE',
              'not lifted, classed lifted', 'not lifted, classed FAILURE')
    rows = [(f'{v.friction_angle_deg:g}', str(v.n_trials), str(v.lifted_classed_lifted),
             str(v.lifted_classed_failure), str(v.unlifted_classed_lifted),
             str(v.unlifted_classed_failure)) for v in verdicts]
    lines = (['## 5. The controller\'s classes against the ground truth', '',
              f'The sections above judge by the ground truth (`lifted`: {truth}). The '
              'controller classes each grasp from its joint signals alone (`outcome`: SUCCESS '
              'or LIFTED_DAM_FAILED say lifted, FAILURE not), with the rise it estimates from '
              'the joints (`estimated_rise_mm`), as a real hand without ground truth would; '
              'where the two differ, a researcher reading only the controller\'s classes '
              'would count otherwise.', '']
             + _table(header, rows) + [''])
    odd = [t for t in trials if (t.outcome in CLASSED_LIFTED) != t.lifted]
    if not odd:
        return lines + ['No trial where they differ.', '']
    lines += [f'The {counted(len(odd), "trial")} where they differ'
              + (f' (the first {MAX_LISTED_CELLS})' if len(odd) > MAX_LISTED_CELLS else '')
              + ': the rise the stand-in measured against the controller\'s estimate.', '']
    header = ('alpha [deg]', 'k_theta [N*m/rad]', 'delta_theta_p [deg]', 'repeat', 'outcome',
              'lifted', 'lift-off [s]', 'off the table at the end', 'rise_final_mm',
              'estimated_rise_mm', 'what it did', 'reason')
    h = report.limits.lift_height_mm
    rows = [(f'{t.friction_angle_deg:g}', g(t.k_theta, 4), g(t.delta_theta_p_deg, 4),
             str(t.repeat), t.outcome, 'yes' if t.lifted else 'no', g(t.lift_off_time_s, 4),
             _yes_no(t.off_table_at_end), g(t.rise_final_mm, 4), g(t.estimated_rise_mm, 4),
             rise_class(t, h), t.reason)
            for t in odd[:MAX_LISTED_CELLS]]
    return lines + _table(header, rows) + ['']


def _yes_no(value: bool | None) -> str:
    """'yes', 'no', or '-' for not recorded."""
    return '-' if value is None else 'yes' if value else 'no'


def _false_guarantees(report: SweepReport) -> list[str]:
    n_cells = report.n_false_guarantee_cells
    n_guaranteed = sum(a.n_guaranteed for a in report.angles)
    lines = ['## 1. False guarantees', '',
             'The paper: a pair in the sufficient region (eq. 18) lifts the object, as far as '
             'the contact forces stay within the friction cones. Every exception is a finding.',
             '']
    if not n_cells:
        lines.append(f'**None**: every guaranteed cell lifts ({n_guaranteed}).')
    else:
        lines.append(f'**{counted(n_cells, "false guarantee")}**: {share(n_cells, n_guaranteed)} '
                     f'guaranteed cells do not lift. Their trials that did not lift:')
        lines.append('')
        header = ('alpha [deg]', 'k_theta [N*m/rad]', 'delta_theta_p [deg]', 'p_lift',
                  'repeat', 'rise_final_mm', 'rise_max_mm', 'phase', 'reason',
                  'worst_case_margin_n', 'class')
        rows = [(f'{f.cell.friction_angle_deg:g}', g(f.cell.k_theta, 4),
                 g(f.cell.delta_theta_p_deg, 4), f'{f.cell.p_lift:.2f}', str(f.trial.repeat),
                 g(f.trial.rise_final_mm, 4), g(f.trial.rise_max_mm, 4), f.trial.phase,
                 f.trial.reason, g(f.trial.worst_case_margin_n, 4), f.label)
                for f in report.false_guarantees]
        lines += _table(header, rows)
    if report.n_guaranteed_unlifted_trials:
        lines += ['', f'Besides, {counted(report.n_guaranteed_unlifted_trials, "trial")} '
                      'of guaranteed '
                      f'cells that lift (p_lift >= {LIFT_PROBABILITY:g}) did not lift.']
    return lines + ['']


def _boundary_distance(report: SweepReport, figures: Mapping[str, str]) -> list[str]:
    lines = ['## 2. The CSM boundary against the simulated lift boundary', '',
             'The paper: the CSM results closely match the experiments when the contact '
             'stiffness is chosen properly (here `contact.contact_stiffness_n_per_m` = '
             + ', '.join(f'{v:g}' for v in report.contact_stiffness_n_per_m) + ' N/m).', '']
    for a in report.angles:
        lines.append(
            f'* alpha {a.friction_angle_deg:g} deg: CSM agreement '
            f'{share(a.n_agree, a.n_cells)} cells'
            + ('' if a.n_path_agree is None else
               f' (path verdict {share(a.n_path_agree, a.n_cells)})')
            + f'; {counted(a.n_compared, "column")} compared, median '
            f'|d| {decades(a.median_distance_dec)} decades, median d '
            f'{decades(a.median_signed_dec)} decades, within one k step '
            f'{share(a.n_within_step, a.n_compared)}; censored: no lift '
            f'{a.n_status("no lift")}, lifts at the lowest k_theta '
            f'{a.n_status("lifts at the lowest k_theta")}; no CSM boundary '
            f'{a.n_status("no CSM boundary")}; columns with several transitions '
            f'{a.n_multi_transition}.')
    lines.append('')
    if 'boundaries' in figures:
        lines += [f'![Simulated boundary k_sim per column (bar: k_below to k_lift) against the '
                  f'CSM and eq. 18 boundaries]({figures["boundaries"]})', '']
    header = ('alpha [deg]', 'delta_theta_p [deg]', 'status', 'transitions',
              'k_below [N*m/rad]', 'k_lift [N*m/rad]', 'k_sim [N*m/rad]', 'k_csm [N*m/rad]',
              'd [decades]', 'k step [decades]', 'within one k step')
    rows = [(f'{c.friction_angle_deg:g}', g(c.delta_theta_p_deg, 4), c.status,
             str(c.transitions), g(c.k_below, 4), g(c.k_lift, 4), g(c.k_sim, 4),
             g(c.k_csm, 4), '-' if math.isnan(c.distance_dec) else decades(c.distance_dec),
             '-' if math.isnan(c.step_dec) else decades(c.step_dec),
             ('yes' if c.within_step else 'no') if c.status == 'compared' else '-')
            for a in report.angles for c in a.columns]
    return lines + _table(header, rows) + ['']


def _missed(report: SweepReport) -> list[str]:
    lines = ['## 3. Lift the sufficient condition does not guarantee', '',
             'The paper: at alpha = 30 deg eq. 18 gives no solution, while a large area lifts. '
             'The sufficient condition is strict by design; this is how much it misses.', '']
    for a in report.angles:
        note = ('' if a.sufficient_exists else
                ' The sufficient condition has no solution at this friction angle: no '
                'stiffness is guaranteed to lift at any delta_theta_p in '
                f'[0, {report.dense_right_deg:g}] deg.')
        lines.append(f'* alpha {a.friction_angle_deg:g} deg: '
                     f'{counted(a.n_lifting, "lifting cell")} '
                     f'of {a.n_cells}; without a guarantee {share(a.n_missed, a.n_lifting)}; '
                     f'guaranteed cells {a.n_guaranteed}.{note}')
    return lines + ['']


def _category_lines(c: Category, report: SweepReport) -> list[str]:
    lim = report.limits
    side = 'lifted' if c.sim_lifts else 'did not lift'
    n = len(c.trials)
    lines = [f'### {c.title}', '']
    if not c.cells:
        return lines + ['No cell.', '']
    explained = n - c.unexplained
    lines += [
        f'* {counted(len(c.cells), "cell")}; {counted(n, "trial")} of them {side}.',
        f'* Mean rise at the end {g(c.mean_rise_final_mm)} mm, mean largest rise '
        f'{g(c.mean_rise_max_mm)} mm (lift height {lim.lift_height_mm:g} mm).',
        '* What the object did: ' + ', '.join(f'{k} {v}' for k, v in c.rises) + '.',
        '* How the grasps ended: ' + ', '.join(f'{k} {v}' for k, v in c.endings) + '.',
        f'* Largest peak torque: compliant joints {g(c.max_peak_compliant_nm)} N*m (limit '
        f'{lim.compliant_torque_nm:g}), position joints {g(c.max_peak_position_nm)} N*m '
        f'(servo limit {lim.servo_torque_nm:g}).',
        '* Checks (a trial may meet several): '
        + ', '.join(f'{k} {v}' for k, v in c.checks) + '.',
        f'* Explained by at least one check: {share(explained, n)}; **unexplained: '
        f'{c.unexplained}**.', '']
    header = ('alpha [deg]', 'k_theta [N*m/rad]', 'delta_theta_p [deg]', 'p_lift',
              'k* here [N*m/rad]', 'csm_margin_n', 'worst_case_margin_n')
    rows = [(f'{x.friction_angle_deg:g}', g(x.k_theta, 4), g(x.delta_theta_p_deg, 4),
             f'{x.p_lift:.2f}', g(x.k_csm if c.boundary == 'csm' else x.k_sufficient, 4),
             g(x.csm_margin_n, 4), g(x.worst_case_margin_n, 4))
            for x in c.cells[:MAX_LISTED_CELLS]]
    lines += _table(header, rows)
    if len(c.cells) > MAX_LISTED_CELLS:
        lines += ['', f'... and {counted(len(c.cells) - MAX_LISTED_CELLS, "more cell")} '
                      '(the figure '
                      f'shows every cell).']
    return lines + ['']


#: The fixed explanation of section 4: the two known gaps between the models.
MODEL_GAPS = (
    '**The analysis holds the object fixed; in the simulation it moves.** Both the sufficient '
    'condition and the CSM take the finger posture of the SPCM path computed with the object '
    'at rest at its start on the table (`docs/analysis.md`, sections 2 and 4), and ask whether '
    'the contact forces at the end of the displacement lift it. In the simulation the object '
    'rolls, slides and rises as soon as the forces allow: the contact points move away from '
    'those the analysis used, the compliant joints deflect differently (and with them the '
    'torques `k_theta delta_theta_s`), and the table\'s reaction changes. The analysis cannot '
    'tell whether an object that starts to rise keeps rising, falls back, tips out of the '
    'plane, or rises only after the rolling-up phase; "lifted, then fell back or an end came '
    'to rest on the table", "rose on the table" and the checks "not held" and "lifted after '
    'rolling-up" count the trials where this shows.',
    '**Bullet\'s contact is not the CSM\'s spring-slider.** The CSM makes the statically '
    'indeterminate contact forces unique with a linear contact stiffness at every contact and '
    'a spring-slider for friction. The stand-in\'s contacts are {contact}; PyBullet resolves '
    'them with an iterative solver ({iterations} iterations per step, '
    '`sim.solver_iterations`) and friction as impulses bounded by the friction coefficient, '
    'without a tangential spring: the forces are shared among the fingers and the table as its '
    'solver settles them, not as the CSM\'s springs would. A CSM boundary off the simulated one '
    'by a steady factor is what another effective tangential stiffness gives (the paper\'s '
    '"when the contact stiffness is chosen properly"; section 6 when present). The table '
    'cannot separate this gap from the first: where no check holds, the disagreement stays '
    'unexplained.',
)


#: How section 4 names the stand-in's contact model (``sim.contact_model``).
CONTACT_TEXT = {
    'compliant': 'compliant at the fingers (`sim.contact_model`: the CSM\'s normal stiffness '
                 '`k_n` per contact point, critically damped) and rigid at the table',
    'rigid': 'rigid constraints (`sim.contact_model: rigid`)',
}


def _disagreements(report: SweepReport) -> list[str]:
    alphas = [a.friction_angle_deg for a in report.angles]
    lines = ['## 4. Where the simulation and the analysis disagree, and why', '']
    header = ('category', *(f'alpha {a:g} deg' for a in alphas), 'all')
    rows = [(c.title, *(str(n) for n in c.counts), str(len(c.cells)))
            for c in report.categories]
    lines += _table(header, rows) + ['']
    for c in report.categories:
        lines += _category_lines(c, report)
    lines += ['### Two known gaps between the models', '']
    for paragraph in MODEL_GAPS:
        lines += [paragraph.format(iterations=report.solver_iterations,
                                   contact=CONTACT_TEXT.get(report.contact_model,
                                                            report.contact_model)), '']
    return lines


def render_markdown(report: SweepReport, command: str,
                    figures: Mapping[str, str] | None = None) -> str:
    """The results document.

    Parameters
    ----------
    report
        :func:`~dam_experiments.sweep_report.compute_report` of the sweep.
    command
        The command that generated it (shown in the header).
    figures
        Relative links of the figures by name: ``'fig7'`` (the sweep as Fig. 7) and
        ``'boundaries'`` (simulated against analysed boundaries); missing names are left out.

    Returns
    -------
    str
        Markdown, ending with one newline.
    """
    figures = figures or {}
    lines: list[Any] = []
    lines += _header(report, command, figures)
    lines += _definitions(report)
    lines += _summary(report)
    lines += _false_guarantees(report)
    lines += _boundary_distance(report, figures)
    lines += _missed(report)
    lines += _disagreements(report)
    lines += _controller(report)
    if report.calibration is not None:
        from dam_experiments.sweep_report_calibration import (  # noqa: PLC0415
            calibration_lines,
        )

        lines += calibration_lines(report.calibration,
                                   lambda c: _category_lines(c, report), share)
    while lines and lines[-1] == '':
        lines.pop()
    return '\n'.join(lines) + '\n'
