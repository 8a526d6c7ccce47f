"""A sweep directory read back: the trials of ``trials.csv`` with the sweep of ``sweep.json``.

What :mod:`dam_experiments.sweep_plot` draws: :func:`read_sweep` checks the files ``sweep``
(:mod:`dam_experiments.sweep_table`) writes and returns the trials as :class:`Trial` (the cell,
the controller's classification ``outcome`` and the ground truth ``lifted``: the object left the
table during the grasp, and ``off_table_at_end``), grouped per friction angle and per cell on
demand (:class:`SweepData`); :func:`k_axis_is_log` tells whether the sweep's ``k_theta``
axis was a log range. A sweep still running or interrupted is read as far as it got (a row
cut short is left out and counted).

Older tables are read all the same, and :attr:`SweepData.lifted_note` says how in one line
that the commands print. Format 2 (no column ``off_table_at_end``): its ``lifted`` meant off
the table over the last 0.1 s; it is read as ``off_table_at_end``, and ``lifted`` from its
``lift_off_time_s`` (a lift-off time: a lift-off), which is exact. Format 1 (no column
``lift_off_time_s`` either): its ``lifted`` is the old rule, the object centre at least
``classification.lift_height_m`` up at the end; ``off_table_at_end`` is not known.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import math
import os
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dam_common.words import counted
from dam_experiments.errors import SweepError, SweepPlotError
from dam_experiments.sweep import SweepSpec
from dam_experiments.sweep_table import PARAMS_FILE, TABLE_FILE

#: The paper's three classes (column ``outcome``), in legend order: x, triangle, o.
OUTCOMES = ('FAILURE', 'LIFTED_DAM_FAILED', 'SUCCESS')
#: Columns of ``trials.csv`` the picture needs.
REQUIRED_COLUMNS = ('trial', 'friction_angle_deg', 'k_theta_nm_per_rad', 'delta_theta_p_deg',
                    'repeat', 'outcome', 'lifted')
#: The column whose presence says that the table records lift-off (format 2 on).
LIFT_OFF_COLUMN = 'lift_off_time_s'
#: The column whose presence says that ``lifted`` means a lift-off (format 3 on).
AT_END_COLUMN = 'off_table_at_end'


@dataclass(frozen=True)
class Trial:
    """One row of ``trials.csv``, as far as the picture needs it.

    Attributes
    ----------
    index
        The trial's number (column ``trial``).
    friction_angle_deg
        The cell's friction angle alpha [deg].
    k_theta
        The cell's finger-1 compliant stiffness [N*m/rad].
    delta_theta_p_deg
        The cell's position-joint displacement [deg].
    repeat
        Repeat number within the cell.
    outcome
        The controller's classification: ``FAILURE``, ``LIFTED_DAM_FAILED`` or ``SUCCESS``.
    lifted
        Ground truth: the object left the table during the grasp, a lift-off (in a table of
        format 1: the object centre ended at least ``classification.lift_height_m`` up).
    object_name
        The object of the configuration's library (column ``object``; '' in a table from
        before objects were an axis: the configured default object).
    object_mass_kg
        The object's mass in the trial [kg] (column ``object_mass_kg``; NaN when absent or
        not a positive number: the configured mass).
    lift_off_time_s
        Ground truth: when the object was first off the table for 50 ms, from the goal [s]
        (column ``lift_off_time_s``; NaN when it never was, or in a table of format 1).
    off_table_at_end
        Ground truth: the object was off the table over the last 0.1 s of the grasp (column
        ``off_table_at_end``; format 2: its ``lifted``); None in a table of format 1.
    """

    index: int
    friction_angle_deg: float
    k_theta: float
    delta_theta_p_deg: float
    repeat: int
    outcome: str
    lifted: bool
    object_name: str = ''
    object_mass_kg: float = math.nan
    lift_off_time_s: float = math.nan
    off_table_at_end: bool | None = None

    @property
    def disagrees(self) -> bool:
        """True when the classification says lifted (SUCCESS, LIFTED_DAM_FAILED) and the
        object did not leave the table, or FAILURE and it did."""
        return (self.outcome != 'FAILURE') != self.lifted


@dataclass(frozen=True)
class Cell:
    """The trials of one grid cell at one friction angle.

    Attributes
    ----------
    k_theta, delta_theta_p_deg
        The cell [N*m/rad, deg].
    trials, lifted, success
        Trials of the cell, how many lifted (ground truth), how many the controller
        classified SUCCESS.
    """

    k_theta: float
    delta_theta_p_deg: float
    trials: int
    lifted: int
    success: int

    @property
    def p_lift(self) -> float:
        """Share of the cell's trials that lifted [-]."""
        return self.lifted / self.trials


@dataclass(frozen=True)
class SweepData:
    """A sweep directory as read by :func:`read_sweep`.

    Attributes
    ----------
    directory
        The directory.
    spec
        The sweep's parameters (``sweep.json``'s ``sweep``).
    parameters
        All of ``sweep.json``.
    trials
        The complete rows of ``trials.csv``, in file order.
    skipped
        Rows cut short (a sweep still writing its table) that were left out.
    table_format
        3: ``lifted`` is a lift-off and ``off_table_at_end`` is a column; 2: no column
        ``off_table_at_end``, read from the old ``lifted`` (``lifted`` from
        ``lift_off_time_s``); 1: no column ``lift_off_time_s`` either (the old 5 mm rule).
    """

    directory: Path
    spec: SweepSpec
    parameters: Mapping[str, Any]
    trials: tuple[Trial, ...]
    skipped: int = 0
    table_format: int = 3

    @property
    def lift_off_recorded(self) -> bool:
        """``lifted`` means that the object left the table (format 2 on; format 1: the old
        5 mm rule)."""
        return self.table_format >= 2

    @property
    def lifted_note(self) -> str | None:
        """One line for a table of format 1 or 2 (None otherwise): how its ``lifted`` was
        read."""
        table = self.directory / TABLE_FILE
        if self.table_format == 2:
            return (f'{table} has no column {AT_END_COLUMN!r} (written before format 3): its '
                    f'lifted meant off the table over the last 0.1 s, read as '
                    f'{AT_END_COLUMN}; lifted (a lift-off) is read from {LIFT_OFF_COLUMN}')
        if self.table_format == 1:
            return (f'{table} has no column {LIFT_OFF_COLUMN!r} (written before format 2): '
                    f'its lifted is the old rule, the object centre at least '
                    f'classification.lift_height_m up at the end, not that it left the table; '
                    f'run the sweep again for lift-off')
        return None

    @property
    def objects(self) -> tuple[str, ...]:
        """The objects found in the table, in table order ('' for a table without the
        column)."""
        return tuple(dict.fromkeys(t.object_name for t in self.trials))

    @property
    def object_label(self) -> str:
        """The named objects, comma-separated, for titles and summaries ('' for none)."""
        return ', '.join(name for name in self.objects if name)

    def of_object(self, name: str) -> SweepData:
        """The trials of one object (``objects`` of the spec reduced to it), for a picture or
        a report of that object.

        Raises
        ------
        SweepPlotError
            ``name`` is not an object of the table (the message lists them).
        """
        if name not in self.objects:
            raise SweepPlotError(f'{self.directory}: no trial of object {name!r} (its objects: '
                                 f'{", ".join(repr(n) for n in self.objects)})')
        spec = dataclasses.replace(self.spec, objects=(name,) if name else ())
        return dataclasses.replace(
            self, spec=spec, trials=tuple(t for t in self.trials if t.object_name == name))

    @property
    def friction_angles_deg(self) -> tuple[float, ...]:
        """The friction angles found in the table, ascending [deg]."""
        return tuple(sorted({t.friction_angle_deg for t in self.trials}))

    @property
    def repeats(self) -> int:
        """Trials per cell of the sweep."""
        return self.spec.repeats

    @property
    def n_planned(self) -> int:
        """Trials of the whole sweep."""
        return self.spec.n_trials

    def at(self, friction_angle_deg: float) -> list[Trial]:
        """The trials at one friction angle."""
        return [t for t in self.trials if t.friction_angle_deg == friction_angle_deg]

    def cells(self, friction_angle_deg: float) -> list[Cell]:
        """The cells at one friction angle that have trials, in order of first appearance."""
        groups: dict[tuple[float, float], list[Trial]] = {}
        for t in self.at(friction_angle_deg):
            groups.setdefault((t.k_theta, t.delta_theta_p_deg), []).append(t)
        return [Cell(k, dp, len(g), sum(t.lifted for t in g),
                     sum(t.outcome == 'SUCCESS' for t in g)) for (k, dp), g in groups.items()]


def output_path(given: Path | None, directory: Path, default_name: str,
                object_name: str | None) -> Path:
    """Where a picture or document of a sweep goes: ``given``, else ``directory /
    default_name``, with ``_NAME`` before the suffix for one object (``fig7_hex_bar.png``)."""
    if given is not None:
        return given
    default = Path(default_name)
    if object_name is not None:  # one output per object of the sweep
        return directory / f'{default.stem}_{object_name}{default.suffix}'
    return directory / default


def one_object(data: SweepData, name: str | None) -> SweepData:
    """The sweep's trials of the object ``name``; ``None``: of its only object.

    Raises
    ------
    SweepPlotError
        ``name`` is None and the sweep has several objects (the message lists them and
        says how to choose), or ``name`` is not one of them.
    """
    if name is not None:
        return data.of_object(name)
    if len(data.objects) > 1:
        raise SweepPlotError(f'{data.directory}: a sweep of {len(data.objects)} objects '
                             f'({", ".join(data.objects)}): choose one with --object NAME '
                             f'(one picture or report per object)')
    return data


def analysis_config(data: SweepData, config: Any) -> Any:
    """``config`` with the object of the sweep ``data`` (of one object) in place of its
    default: what the analysis of its trials assumes.

    Raises
    ------
    SweepPlotError
        The sweep has several objects, or its object is not in the configuration's library.
    """
    names = data.objects
    if len(names) > 1:
        raise SweepPlotError(f'{data.directory}: {len(names)} objects: choose one first')
    if not names or not names[0]:
        return config
    if names[0] not in config.objects:
        raise SweepPlotError(f'the sweep\'s object {names[0]!r} is not in the object library '
                             f'of the configuration {str(config.source)!r} (known: '
                             f'{", ".join(sorted(config.objects))}); pass the sweep\'s with '
                             f'--config')
    return config.with_object(names[0])


def _fail_row(table: Path, line: int, trial: str, message: str) -> SweepPlotError:
    return SweepPlotError(f'{table}, line {line} (trial {trial!r}): {message}')


def _number(table: Path, line: int, row: Mapping[str, str], column: str, low: float,
            high: float = math.inf, low_open: bool = True) -> float:
    text = row[column]
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    inside = (value > low if low_open else value >= low) and value < high
    if not (math.isfinite(value) and inside):
        bound = f'{"(" if low_open else "["}{low:g}, {high:g})'
        raise _fail_row(table, line, row['trial'], f'{column} {text!r} is not a number in '
                                                   f'{bound}')
    return value


def _trial(table: Path, line: int, row: Mapping[str, str], table_format: int) -> Trial:
    """One row of a table of format ``table_format``, checked."""
    try:
        index = int(row['trial'])
        repeat = int(row['repeat'])
    except ValueError:
        raise _fail_row(table, line, row['trial'], f'trial {row["trial"]!r} and repeat '
                                                   f'{row["repeat"]!r} must be whole numbers'
                        ) from None
    if row['outcome'] not in OUTCOMES:
        raise _fail_row(table, line, row['trial'], f'outcome {row["outcome"]!r} is not one of '
                                                   f'{", ".join(OUTCOMES)}')
    for column in ('lifted', AT_END_COLUMN) if table_format >= 3 else ('lifted',):
        if row[column] not in ('0', '1'):
            raise _fail_row(table, line, row['trial'], f'{column} {row[column]!r} is not 0 or 1')
    lift_off = _lift_off_time(table, line, row, table_format)
    lifted, at_end = row['lifted'] == '1', None
    if table_format == 2:  # its lifted: off the table at the end, after a lift-off
        lifted, at_end = not math.isnan(lift_off), lifted
    elif table_format >= 3:
        at_end = row[AT_END_COLUMN] == '1'
        if at_end and not lifted:
            raise _fail_row(table, line, row['trial'], f'{AT_END_COLUMN} 1 with lifted 0 (an '
                                                       f'object off the table lifted off)')
    return Trial(index=index,
                 friction_angle_deg=_number(table, line, row, 'friction_angle_deg', 0.0, 90.0,
                                            low_open=False),
                 k_theta=_number(table, line, row, 'k_theta_nm_per_rad', 0.0),
                 delta_theta_p_deg=_number(table, line, row, 'delta_theta_p_deg', 0.0),
                 repeat=repeat, outcome=row['outcome'], lifted=lifted,
                 object_name=row.get('object') or '',
                 object_mass_kg=_optional_mass(row.get('object_mass_kg')),
                 lift_off_time_s=lift_off, off_table_at_end=at_end)


def _lift_off_time(table: Path, line: int, row: Mapping[str, str], table_format: int
                   ) -> float:
    """The row's ``lift_off_time_s`` [s]: NaN when absent (format 1) or empty (no lift-off,
    which a lifted trial cannot be, nor in format 2 one off the table at the end), else a
    finite number; in format 3 a trial with a lift-off time is lifted."""
    if LIFT_OFF_COLUMN not in row:
        return math.nan
    text = row[LIFT_OFF_COLUMN]
    if not text:
        if row['lifted'] == '1':
            raise _fail_row(table, line, row['trial'], f'lifted 1 without a {LIFT_OFF_COLUMN} '
                                                       f'(a lifted object lifted off)')
        return math.nan
    if table_format >= 3 and row['lifted'] != '1':
        raise _fail_row(table, line, row['trial'], f'{LIFT_OFF_COLUMN} {text!r} with lifted '
                                                   f'{row["lifted"]!r} (a lift-off is a lift)')
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise _fail_row(table, line, row['trial'], f'{LIFT_OFF_COLUMN} {text!r} is not a time '
                                                   f'[s] (empty: no lift-off)')
    return value


def _optional_mass(text: str | None) -> float:
    try:
        value = float(text) if text else math.nan
    except ValueError:
        return math.nan
    return value if math.isfinite(value) and value > 0.0 else math.nan


def read_sweep(directory: str | os.PathLike[str]) -> SweepData:
    """Read ``sweep.json`` and the complete rows of ``trials.csv`` of a sweep directory.

    Parameters
    ----------
    directory
        A ``sweep --out`` directory.

    Returns
    -------
    SweepData
        The sweep and its trials (at least one).

    Raises
    ------
    SweepPlotError
        The directory, ``sweep.json`` or ``trials.csv`` is missing or unreadable, the table
        has no trial or lacks a needed column, a value is malformed (naming the file, the
        line, the trial and the value), or a trial number is repeated.
    """
    root = Path(directory)
    if not root.exists():
        raise SweepPlotError(f'{root}: no such directory')
    if not root.is_dir():
        raise SweepPlotError(f'{root} is not a directory')
    params_path, table = root / PARAMS_FILE, root / TABLE_FILE
    if not table.is_file():
        raise SweepPlotError(f'{table}: no such file (not a sweep directory, or the sweep '
                             f'has not started)')
    if not params_path.is_file():
        raise SweepPlotError(f'{params_path}: no such file (the sweep writes it first)')
    try:
        parameters = json.loads(params_path.read_text(encoding='utf-8'))
    except (OSError, UnicodeDecodeError, ValueError) as exc:
        raise SweepPlotError(f'{params_path}: cannot read it ({exc})') from None
    if not isinstance(parameters, dict) or not isinstance(parameters.get('sweep'), dict):
        raise SweepPlotError(f'{params_path}: no "sweep" parameters in it')
    try:
        spec = SweepSpec.from_dict(parameters['sweep'])
    except SweepError as exc:
        raise SweepPlotError(f'{params_path}: {exc}') from None
    try:
        text = table.read_text(encoding='utf-8')
        trials, skipped = [], 0
        seen: dict[int, int] = {}  # trial number -> line
        if text and not text.endswith('\n') and '\n' in text:
            # The last row is being written (rows end with a newline): cut short, even when
            # it has all its fields.
            text = text[:text.rfind('\n') + 1]
            skipped += 1
        reader = csv.DictReader(io.StringIO(text, newline=''))
        header = reader.fieldnames
        if not header:
            raise SweepPlotError(f'{table} is empty: no header, no trials')
        missing = [c for c in REQUIRED_COLUMNS if c not in header]
        if missing:
            raise SweepPlotError(f'{table}: no column {missing[0]!r} (its columns: '
                                 f'{", ".join(header)})')
        table_format = (3 if AT_END_COLUMN in header else 2 if LIFT_OFF_COLUMN in header
                        else 1)
        for row in reader:
            if None in row.values() or None in row:  # cut short or too long
                skipped += 1
                continue
            trial = _trial(table, reader.line_num, row, table_format)
            if trial.index in seen:
                raise _fail_row(table, reader.line_num, row['trial'],
                                f'trial {trial.index} is in the table twice (first on line '
                                f'{seen[trial.index]})')
            seen[trial.index] = reader.line_num
            trials.append(trial)
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise SweepPlotError(f'{table}: cannot read it ({exc})') from None
    if not trials:
        raise SweepPlotError(f'{table} holds no trials (only its header)' if not skipped else
                             f'{table} holds no complete trial ({counted(skipped, "row")} '
                             'cut short)')
    return SweepData(root, spec, parameters, tuple(trials), skipped, table_format)


def k_axis_is_log(parameters: Mapping[str, Any]) -> bool:
    """Whether the sweep's ``k_theta`` axis is a log range.

    As typed (``sweep.json``'s ``axes_as_given.k_theta``): any ``start:stop:count:log``
    token. Without that record: at least three values with a constant ratio and unequal
    differences.
    """
    given = parameters.get('axes_as_given')
    tokens = given.get('k_theta') if isinstance(given, Mapping) else None
    if isinstance(tokens, list) and tokens and all(isinstance(t, str) for t in tokens):
        return any(len(p := t.split(':')) == 4 and p[3].strip().lower() == 'log'
                   for t in tokens)
    values = np.sort(np.asarray(parameters.get('sweep', {}).get('k_theta', []), dtype=float))
    if values.size < 3 or not np.all(values > 0.0):
        return False
    ratios, steps = values[1:] / values[:-1], np.diff(values)
    return bool(np.allclose(ratios, ratios[0], rtol=1e-4)
                and not np.allclose(steps, steps[0], rtol=1e-4))
