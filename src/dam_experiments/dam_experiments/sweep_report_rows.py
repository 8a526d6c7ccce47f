"""A sweep's trials with every column the results document reads, and what each one did.

:func:`read_rows` reads, for the trials :func:`~dam_experiments.sweep_results.read_sweep` kept,
the columns of ``trials.csv`` the report (:mod:`dam_experiments.sweep_report`) needs besides
those of the picture: the phase and reason, the rises, the simulated mass, the peak torques and
the analysis columns, and where the table has them (format 2 on) the end of ROLLING_UP and the
controller's estimated rise, checked (naming the file, the line, the trial and the value).
:func:`rise_class`, :func:`ending` and :func:`trial_label` say in words what a trial did, from
its columns alone, by lift-off (:mod:`dam_sim_bridge.lift_off`) and whether the object was off
the table at the end, for every shape; :func:`checks` lists the checks of the evidence that
hold for it.
"""

from __future__ import annotations

import csv
import io
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

from dam_experiments.errors import SweepPlotError
from dam_experiments.sweep_results import SweepData
from dam_experiments.sweep_table import TABLE_FILE

#: A trial "never rose" when its largest rise stayed below this share of the lift height [-].
NEVER_ROSE_FRACTION = 0.1
#: Columns the report needs besides those of :data:`~dam_experiments.sweep_results.
#: REQUIRED_COLUMNS` (and at least one ``peak_tau_*_compliant_nm`` and ``*_position_nm``).
REPORT_COLUMNS = ('phase', 'reason', 'rise_final_mm', 'rise_max_mm', 'rise_rolling_end_mm',
                  'object_mass_kg', 'check_lift_guaranteed', 'worst_case_margin_n',
                  'csm_lift', 'csm_margin_n')
#: A peak torque at least this share of a limit counts as having reached it [-].
LIMIT_FRACTION = 0.98
#: Columns of format 2 the report reads when present (a table of format 1 has none of them).
OPTIONAL_COLUMNS = ('rolling_up_end_s', 'estimated_rise_mm')
#: Phases in which a grasp is still running (it was cut at the time limit).
RUNNING_PHASES = ('IDLE', 'APPROACH', 'ROLLING_UP', 'ENVELOPE')
_PHASE_IN_REASON = re.compile(r'(?:during (?:phase )?|phase )(approach|rolling_up|envelope)\b')


# ------------------------------------------------------------------------------------------
# The table's rows


@dataclass(frozen=True)
class TrialRow:
    """One trial with the columns the report reads.

    Attributes
    ----------
    index, repeat
        Trial number and repeat within the cell.
    friction_angle_deg, k_theta, delta_theta_p_deg
        The cell [deg, N*m/rad, deg].
    outcome, phase, reason
        The controller's class, the phase it ended in and the failure reason or the
        classifier's explanation.
    lifted
        Ground truth: the object left the table during the grasp, a lift-off (format 1: the
        object centre ended at least the lift height up).
    rise_final_mm, rise_max_mm, rise_rolling_end_mm
        Rise of the object centre at the end, its largest rise, its rise at the end of
        ROLLING_UP (NaN when that phase did not end) [mm].
    object_mass_kg
        Object mass as simulated [kg].
    peak_compliant_nm, peak_position_nm
        Largest peak |torque| over the fingers' compliant, position joints [N*m].
    guaranteed, worst_case_margin_n, csm_lift, csm_margin_n
        The cell's ``/check_lift`` answer: eq. (18) holds, its margin [N], the CSM verdict and
        its margin [N].
    lift_off_known
        The table records lift-off (format 2 on): ``lifted`` means that the object left the
        table and the four columns below are there.
    lift_off_time_s, rolling_up_end_s
        When the object was first off the table for 50 ms, when ROLLING_UP ended, both from
        the goal [s] (NaN: it never lifted off; ROLLING_UP did not end; not recorded).
    off_table_at_end
        Ground truth: the object was off the table over the last 0.1 s of the grasp (None:
        not recorded, format 1).
    estimated_rise_mm
        The controller's estimate of the rise from the joints [mm] (NaN: not classified, or
        not recorded).
    csm_path_lift, csm_path_margin_n
        The CSM's path verdict of ``/check_lift`` and its margin [N] (None, NaN: a table
        written before ``/check_lift`` answered it).
    """

    index: int
    repeat: int
    friction_angle_deg: float
    k_theta: float
    delta_theta_p_deg: float
    outcome: str
    phase: str
    reason: str
    lifted: bool
    rise_final_mm: float
    rise_max_mm: float
    rise_rolling_end_mm: float
    object_mass_kg: float
    peak_compliant_nm: float
    peak_position_nm: float
    guaranteed: bool
    worst_case_margin_n: float
    csm_lift: bool
    csm_margin_n: float
    lift_off_known: bool = True
    lift_off_time_s: float = math.nan
    rolling_up_end_s: float = math.nan
    estimated_rise_mm: float = math.nan
    off_table_at_end: bool | None = None
    csm_path_lift: bool | None = None
    csm_path_margin_n: float = math.nan


def _table_rows(table: Any) -> tuple[list[str], list[tuple[int, dict[str, str]]]]:
    """Header and complete rows (with their line numbers) of ``trials.csv``, a row being
    written left out as :func:`~dam_experiments.sweep_results.read_sweep` does."""
    try:
        text = table.read_text(encoding='utf-8')
        if text and not text.endswith('\n') and '\n' in text:
            text = text[:text.rfind('\n') + 1]
        reader = csv.DictReader(io.StringIO(text, newline=''))
        header = list(reader.fieldnames or [])
        rows = []
        for row in reader:
            if None not in row.values() and None not in row:
                rows.append((reader.line_num, row))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise SweepPlotError(f'{table}: cannot read it ({exc})') from None
    return header, rows


#: Columns that may hold ``-inf``: the worst case of eq. 18 is unbounded (the friction cone
#: admits an arbitrarily low vertical force; ``LiftResult.worst_case_margin``).
_MAY_BE_MINUS_INF = ('worst_case_margin_n', 'csm_margin_n', 'csm_path_margin_n')


def _float(table: Any, line: int, row: Mapping[str, str], column: str) -> float:
    """A number of the row; ``nan`` is allowed (a margin without analysis, a phase that did
    not end), empty too in :data:`OPTIONAL_COLUMNS` (not classified) and a column the table
    lacks is NaN there, ``-inf`` in the margin columns (unbounded); any other infinity or text
    is not."""
    if column in OPTIONAL_COLUMNS and not row.get(column):
        return math.nan
    text = row[column]
    try:
        value = float(text)
    except ValueError:
        value = math.inf
    if value == -math.inf and column in _MAY_BE_MINUS_INF:
        return value
    if math.isinf(value):
        raise SweepPlotError(f'{table}, line {line} (trial {row["trial"]!r}): {column} '
                             f'{text!r} is not a number')
    return value


def _flag(table: Any, line: int, row: Mapping[str, str], column: str) -> bool:
    if row[column] not in ('0', '1'):
        raise SweepPlotError(f'{table}, line {line} (trial {row["trial"]!r}): {column} '
                             f'{row[column]!r} is not 0 or 1')
    return row[column] == '1'


def read_rows(data: SweepData) -> list[TrialRow]:
    """The trials of ``data`` with every column the report reads, in table order.

    Raises
    ------
    SweepPlotError
        ``trials.csv`` lacks a column of :data:`REPORT_COLUMNS` or the peak torques, or a value
        is malformed (naming the file, the line, the trial and the value).
    """
    table = data.directory / TABLE_FILE
    header, rows = _table_rows(table)
    missing = [c for c in REPORT_COLUMNS if c not in header]
    compliant = [c for c in header if c.startswith('peak_tau_') and c.endswith('_compliant_nm')]
    position = [c for c in header if c.startswith('peak_tau_') and c.endswith('_position_nm')]
    if not compliant:
        missing.append('peak_tau_<finger>_compliant_nm')
    if not position:
        missing.append('peak_tau_<finger>_position_nm')
    if missing:
        raise SweepPlotError(f'{table}: no column {missing[0]!r}, which the report needs '
                             f'(its columns: {", ".join(header)})')
    by_index: dict[int, tuple[int, dict[str, str]]] = {}
    for line, row in rows:
        try:
            by_index.setdefault(int(row['trial']), (line, row))
        except ValueError:
            continue  # read_sweep refuses it
    out = []
    for t in data.trials:
        if t.index not in by_index:
            raise SweepPlotError(f'{table}: trial {t.index} is gone (the table changed while '
                                 f'it was read); run the command again')
        line, row = by_index[t.index]
        values = {c: _float(table, line, row, c) for c in (
            'rise_final_mm', 'rise_max_mm', 'rise_rolling_end_mm', 'object_mass_kg',
            'worst_case_margin_n', 'csm_margin_n', *OPTIONAL_COLUMNS, *compliant, *position)}
        out.append(TrialRow(
            index=t.index, repeat=t.repeat, friction_angle_deg=t.friction_angle_deg,
            k_theta=t.k_theta, delta_theta_p_deg=t.delta_theta_p_deg, outcome=t.outcome,
            phase=row['phase'], reason=row['reason'], lifted=t.lifted,
            rise_final_mm=values['rise_final_mm'], rise_max_mm=values['rise_max_mm'],
            rise_rolling_end_mm=values['rise_rolling_end_mm'],
            object_mass_kg=values['object_mass_kg'],
            peak_compliant_nm=max(values[c] for c in compliant),
            peak_position_nm=max(values[c] for c in position),
            guaranteed=_flag(table, line, row, 'check_lift_guaranteed'),
            worst_case_margin_n=values['worst_case_margin_n'],
            csm_lift=_flag(table, line, row, 'csm_lift'),
            csm_margin_n=values['csm_margin_n'], lift_off_known=data.lift_off_recorded,
            lift_off_time_s=t.lift_off_time_s, rolling_up_end_s=values['rolling_up_end_s'],
            estimated_rise_mm=values['estimated_rise_mm'],
            off_table_at_end=t.off_table_at_end,
            csm_path_lift=(_flag(table, line, row, 'csm_path_lift')
                           if 'csm_path_lift' in header else None),
            csm_path_margin_n=(_float(table, line, row, 'csm_path_margin_n')
                               if 'csm_path_margin_n' in header else math.nan)))
    return out


# ------------------------------------------------------------------------------------------
# What happened in one trial


def failed_phase(reason: str) -> str:
    """The phase a controller failure reason names (lower case), ``'approach'`` for a finger
    that closed without contact, ``'an unnamed phase'`` otherwise."""
    found = _PHASE_IN_REASON.search(reason)
    if found:
        return found.group(1)
    return 'approach' if 'without contact' in reason else 'an unnamed phase'


def ending(trial: TrialRow) -> str:
    """How the grasp ended, from ``phase`` (and the failure reason): ``'done'``, ``'controller
    failure in <phase>'``, ``'aborted'`` or ``'still running at the time limit (<phase>)'``."""
    if trial.phase == 'DONE':
        return 'done'
    if trial.phase == 'FAILED':
        return f'controller failure in {failed_phase(trial.reason)}'
    if trial.phase == 'ABORTED':
        return 'aborted'
    return f'still running at the time limit ({trial.phase.lower()})'


def lifted_late(trial: TrialRow, lift_height_mm: float) -> bool:
    """A lifted trial left the table only once ROLLING_UP had ended (its lift-off time at
    or after the end of ROLLING_UP); in a table of format 1, it reached the lift height only
    then (its rise at the end of ROLLING_UP is a number below ``lift_height_mm``)."""
    if not trial.lift_off_known:
        return (math.isfinite(trial.rise_rolling_end_mm)
                and trial.rise_rolling_end_mm < lift_height_mm)
    return (math.isfinite(trial.rolling_up_end_s) and trial.lifted
            and trial.lift_off_time_s >= trial.rolling_up_end_s)


#: What the object did (:func:`rise_class`), in a table that records lift-off.
RISE_CLASSES = ('lifted and held off the table',
                'lifted, then fell back or an end came to rest on the table',
                'rose on the table', 'never rose')


def rise_class(trial: TrialRow, lift_height_mm: float) -> str:
    """What the object did, by lift-off, ``off_table_at_end``, the rise columns and the lift
    height ``h`` [mm] (:data:`RISE_CLASSES`).

    Lifted (a lift-off): ``'lifted and held off the table'`` (off it at the end) or ``'lifted,
    then fell back or an end came to rest on the table'`` (touching it at the end: it fell
    back, or a column tipped out of the plane onto one end). Not lifted: ``'rose on the
    table'`` (``rise_max >= NEVER_ROSE_FRACTION h``: it rolled or tipped while touching, as a
    polygon turning on a vertex does) or ``'never rose'``. In a table of format 1 (no lift-off
    recorded), lifted: ``'lifted after the rolling-up phase'`` (:func:`lifted_late`) or
    ``'lifted'``; not lifted: ``'rose then fell back'`` (``rise_max >= h > rise_final``),
    ``'rose partly'`` (``NEVER_ROSE_FRACTION h <= rise_max < h``) or ``'never rose'``.
    """
    h = lift_height_mm
    if not trial.lift_off_known:
        if trial.lifted:
            return 'lifted after the rolling-up phase' if lifted_late(trial, h) else 'lifted'
        if trial.rise_max_mm >= h:
            return 'rose then fell back'
        return 'rose partly' if trial.rise_max_mm >= NEVER_ROSE_FRACTION * h else 'never rose'
    if trial.lifted:
        return RISE_CLASSES[0] if trial.off_table_at_end else RISE_CLASSES[1]
    return RISE_CLASSES[2] if trial.rise_max_mm >= NEVER_ROSE_FRACTION * h else RISE_CLASSES[3]


def trial_label(trial: TrialRow, lift_height_mm: float) -> str:
    """``'<rise class>; <ending>'`` (:func:`rise_class`, :func:`ending`)."""
    return f'{rise_class(trial, lift_height_mm)}; {ending(trial)}'


# ------------------------------------------------------------------------------------------
# The checks of the evidence


def next_to_boundary(k_theta: float, k_star: float, grid: Sequence[float]) -> bool:
    """True when no value of ``grid`` lies strictly between ``k_theta`` and a finite boundary
    ``k_star`` [N*m/rad]: a boundary offset below one grid step would flip the cell."""
    if not math.isfinite(k_star):
        return False
    low, high = sorted((k_theta, k_star))
    return not any(low < k < high for k in grid)


@dataclass(frozen=True)
class Limits:
    """What the checks compare with.

    Attributes
    ----------
    lift_height_mm
        ``classification.lift_height_m`` [mm].
    compliant_torque_nm
        The compliant joints' torque limit during the trials [N*m]: ``device.torque_limit_nm``
        with the impedance on the device (the sweep's ``impedance``, or when not given
        ``controller.impedance_on_device``), else the lower of it and
        ``controller.torque_limit_nm`` (the controller's torque commands).
    servo_torque_nm
        ``sim.servo_force_limit_nm``: the position joints' servo limit [N*m].
    object_mass_kg
        ``object.mass_kg``: the mass the analysis assumes [kg].
    """

    lift_height_mm: float
    compliant_torque_nm: float
    servo_torque_nm: float
    object_mass_kg: float

    @classmethod
    def from_config(cls, config: Any, impedance: str | None = None) -> Limits:
        """The limits of ``config`` for trials run with the sweep's ``impedance`` option
        (``'device'``, ``'controller'`` or None: the configured one)."""
        on_device = (impedance == 'device' if impedance is not None
                     else bool(config.controller.impedance_on_device))
        device = float(config.device.torque_limit_nm)
        return cls(lift_height_mm=1e3 * float(config.classification.lift_height_m),
                   compliant_torque_nm=(device if on_device else
                                        min(device, float(config.controller.torque_limit_nm))),
                   servo_torque_nm=float(config.sim.servo_force_limit_nm),
                   object_mass_kg=float(config.object.mass_kg))


#: The checks, by side: (name, what it says).
CHECKS_NOT_LIFTING = (
    ('controller failure', 'the controller ended the grasp (phase FAILED)'),
    ('time limit', 'the grasp was still running at the time limit'),
    ('compliant torque limit', 'a compliant joint reached the compliant torque limit'),
    ('servo limit', 'a position joint reached its servo torque limit'),
    ('heavier object', 'the object was heavier than the analysis assumes'),
    ('next to the boundary', 'no grid k_theta lies between the cell and the boundary'),
)
CHECKS_LIFTING = (
    ('lifted after rolling-up', 'the object left the table only after ROLLING_UP, the phase '
                                'the analysis covers'),
    ('not held', 'the object left the table but was not off it at the end (it fell back, or '
                 'an end came to rest on the table): a lift that barely held'),
    ('lighter object', 'the object was lighter than the analysis assumes'),
    ('next to the boundary', 'no grid k_theta lies between the cell and the boundary'),
)


def checks(trial: TrialRow, k_star: float, k_grid: Sequence[float], sim_lifts: bool,
           limits: Limits) -> list[str]:
    """The names of the checks of :data:`CHECKS_LIFTING` (``sim_lifts``) or
    :data:`CHECKS_NOT_LIFTING` that hold for a trial; ``k_star`` [N*m/rad] is the boundary
    of ``'next to the boundary'`` at the trial's ``delta_theta_p`` (NaN: none), ``k_grid``
    the sweep's ``k_theta`` values."""
    near = next_to_boundary(trial.k_theta, k_star, k_grid)
    mass = trial.object_mass_kg
    if sim_lifts:
        found = {'lifted after rolling-up': lifted_late(trial, limits.lift_height_mm),
                 'not held': trial.off_table_at_end is False,
                 'lighter object': mass < limits.object_mass_kg * (1.0 - 1e-9),
                 'next to the boundary': near}
        names = CHECKS_LIFTING
    else:
        found = {'controller failure': trial.phase == 'FAILED',
                 'time limit': trial.phase in RUNNING_PHASES,
                 'compliant torque limit': (trial.peak_compliant_nm
                                            >= LIMIT_FRACTION * limits.compliant_torque_nm),
                 'servo limit': (trial.peak_position_nm
                                 >= LIMIT_FRACTION * limits.servo_torque_nm),
                 'heavier object': mass > limits.object_mass_kg * (1.0 + 1e-9),
                 'next to the boundary': near}
        names = CHECKS_NOT_LIFTING
    return [name for name, _ in names if found[name]]


# ------------------------------------------------------------------------------------------
# The controller's classes against the ground truth

#: The controller's classes that say the object was lifted (the paper's triangle and circle).
CLASSED_LIFTED = ('SUCCESS', 'LIFTED_DAM_FAILED')


@dataclass(frozen=True)
class ControllerVerdicts:
    """At one friction angle, the trials by ground truth (``lifted``: the object left the
    table during the grasp) and by the controller's class (``outcome``: lifted for
    :data:`CLASSED_LIFTED`, else FAILURE)."""

    friction_angle_deg: float
    lifted_classed_lifted: int
    lifted_classed_failure: int
    unlifted_classed_lifted: int
    unlifted_classed_failure: int

    @property
    def n_trials(self) -> int:
        return (self.lifted_classed_lifted + self.lifted_classed_failure
                + self.unlifted_classed_lifted + self.unlifted_classed_failure)


def controller_verdicts(trials: Sequence[TrialRow]) -> tuple[ControllerVerdicts, ...]:
    """The four counts per friction angle, in ascending order of the angle."""
    counts: dict[float, list[int]] = {}
    for t in trials:
        slot = counts.setdefault(t.friction_angle_deg, [0, 0, 0, 0])
        slot[(0 if t.lifted else 2) + (0 if t.outcome in CLASSED_LIFTED else 1)] += 1
    return tuple(ControllerVerdicts(alpha, *counts[alpha]) for alpha in sorted(counts))
