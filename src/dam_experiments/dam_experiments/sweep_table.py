"""A sweep's files: the trial table, its parameters, the per-cell summary; resuming.

An output directory holds

* ``trials.csv``: one row per trial (:func:`~dam_experiments.sweep.table_columns`), appended
  as trials finish and flushed row by row, rewritten in trial order when the sweep is
  complete, so that a rerun gives the same bytes;
* ``sweep.json``: the sweep's parameters (:meth:`SweepSpec.to_dict`), the SHA-256 of the
  configuration's values, the columns and their units, written when the sweep starts;
* ``cells.csv``: per cell the number of trials, how many lifted (ground truth: the object left
  the table during the grasp), how many were off the table at the end, how many succeeded and
  the analysis answer, written when the sweep is complete.

:meth:`TrialTable.open` on a directory that already holds a sweep resumes it: it refuses a
different sweep (naming the parameter that differs), keeps every complete row whose inputs
match its trial, drops a row cut short by an interruption and rewrites the table with what it
kept; :meth:`TrialTable.pending` lists the trials still to run.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, TextIO

from dam_experiments.errors import SweepError
from dam_experiments.sweep import (
    SweepSpec,
    TrialSpec,
    config_digest,
    config_values,
    input_columns,
    table_columns,
)
from dam_experiments.sweep_lock import SweepLock

#: The classes a row's ``outcome`` may hold; a row with another (an edited table) is run again.
_OUTCOMES = ('SUCCESS', 'LIFTED_DAM_FAILED', 'FAILURE')

TABLE_FILE = 'trials.csv'
PARAMS_FILE = 'sweep.json'
CELLS_FILE = 'cells.csv'
#: Version of the directory layout and of ``sweep.json``: 3 since ``lifted`` means that a
#: lift-off happened during the grasp (with ``off_table_at_end``, the object off the table over
#: the last 0.1 s); in format 2 ``lifted`` meant off the table over the last 0.1 s (with
#: ``lift_off_time_s``, ``rolling_up_end_s`` and ``estimated_rise_mm``), in format 1 a rise of
#: ``classification.lift_height_m`` at the end.
FORMAT_VERSION = 3
#: Keys of ``sweep.json`` that must match to resume (the others are information).
_MATCHING_KEYS = ('format', 'sweep', 'config_sha256', 'columns')

CELL_COLUMNS = ['object', 'friction_angle_deg', 'k_theta_nm_per_rad', 'delta_theta_p_deg',
                'trials', 'lifted', 'p_lift', 'off_table_at_end', 'success', 'lifted_dam_failed',
                'failure', 'p_success', 'rise_final_mm_mean', 'check_lift_guaranteed',
                'worst_case_margin_n', 'csm_lift', 'csm_margin_n']

_UNITS = {
    'object': 'the object grasped: its name in the configuration\'s object.library',
    'friction_angle_deg': 'cell friction angle alpha [deg]',
    'k_theta_nm_per_rad': 'finger-1 compliant stiffness [N*m/rad] (others by stiffness_ratio)',
    'delta_theta_p_deg': 'position-joint displacement [deg]',
    'seed': 'the trial\'s seed (SeedSequence(seed, spawn_key=(i_alpha, i_dp, i_k, repeat)) for '
            'the first object, spawn_key=(i_alpha, i_dp, i_k, i_object, repeat) for the others)',
    'object_mass_kg': 'object mass as simulated [kg]',
    'object_offset_x_mm': 'object start offset, x [mm]',
    'object_offset_y_mm': 'object start offset along its axis, y [mm]',
    'table_friction': 'table-object Coulomb coefficient as simulated [-]',
    'friction_angle_sim_deg': 'finger-object friction angle as simulated [deg]',
    'phase': 'phase the controller ended in',
    'outcome': 'paper Fig. 7 class from joint signals: SUCCESS (o), LIFTED_DAM_FAILED (t), '
               'FAILURE (x)',
    'lifted': 'ground truth: the object left the table during the grasp, off it for at least '
              '50 ms (dam_sim_bridge.lift_off: no object-table contact point within 0.1 mm)',
    'lift_off_time_s': 'ground truth: first time the object was off the table for 50 ms, '
                       'from the goal [s]; empty when it never was',
    'off_table_at_end': 'ground truth: the object was off the table over the last 0.1 s of '
                        'the grasp',
    'rolling_up_end_s': 'when ROLLING_UP ended, from the goal [s]; nan when it did not end',
    'rise_final_mm': 'rise of the object centre at the end [mm]',
    'rise_max_mm': 'largest rise [mm]', 'rise_rolling_end_mm': 'rise at the end of ROLLING_UP [mm]',
    'estimated_rise_mm': 'the controller\'s estimate of the rise from the final joint angles '
                         '(Classification.lift_m) [mm]; empty when the grasp was not classified',
    'peak_tau_*_nm': 'largest |torque| of that joint during the trial [N*m]',
    'check_lift_guaranteed': '/check_lift: eq. (18) guarantees the lift (cell request)',
    'worst_case_margin_n': 'eq. (18) worst-case margin min c_z^T f_o - m_B g [N]',
    'csm_lift': 'contact stiffness model lifts', 'csm_margin_n': 'CSM margin [N]',
    'sim_time_s': 'simulated duration [s]',
}


def sweep_parameters(sweep: SweepSpec, config: Any,
                     info: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """The content of ``sweep.json``: what must match to resume, then ``info``."""
    data: dict[str, Any] = {
        'format': FORMAT_VERSION, 'sweep': sweep.to_dict(),
        'config_sha256': config_digest(config), 'config': config_values(config),
        'columns': table_columns(config),
        'n_trials': sweep.n_trials, 'units': _UNITS,
        'perturbation_distributions': (
            'u_m, u_t ~ U(-1, 1); z_x, z_y, z_a ~ N(0, 1), drawn in this order from '
            'numpy.random.default_rng(seed); mass = object.mass_kg * (1 + mass_rel * u_m); '
            'offset = position_sd_mm * (z_x, z_y); table = table_friction_coefficient * '
            '(1 + table_friction_rel * u_t); alpha = cell alpha + friction_angle_sd_deg * '
            'z_a, clipped to [0, 89] deg'),
    }
    data.update(info or {})
    return data


def _first_difference(old: Any, new: Any, path: str) -> str | None:
    """Dotted path of the first differing value, with both values; None when equal."""
    if isinstance(old, Mapping) and isinstance(new, Mapping):
        for key in sorted(set(old) | set(new), key=str):
            if key not in old or key not in new:
                return f'{path}.{key}: only in the {"new" if key in new else "stored"} sweep'
            found = _first_difference(old[key], new[key], f'{path}.{key}')
            if found:
                return found
        return None
    return None if old == new else f'{path}: stored {old!r}, now {new!r}'


def _row_line(columns: list[str], row: Mapping[str, str]) -> str:
    buffer = io.StringIO()
    csv.writer(buffer, lineterminator='\n').writerow([row[c] for c in columns])
    return buffer.getvalue()


class TrialTable:
    """The trial table of one sweep in ``directory``; see the module docstring.

    Parameters
    ----------
    directory
        Output directory (created if missing).
    sweep
        The sweep.
    config
        Its ``DamConfig``.
    info
        Extra information for ``sweep.json`` (not compared when resuming).
    """

    def __init__(self, directory: str | os.PathLike[str], sweep: SweepSpec, config: Any,
                 info: Mapping[str, Any] | None = None) -> None:
        self.directory = Path(directory)
        self.sweep = sweep
        self.columns = table_columns(config)
        self.specs = sweep.trials()
        self.parameters = sweep_parameters(sweep, config, info)
        self.rows: dict[int, dict[str, str]] = {}
        self.dropped = 0
        self._handle: TextIO | None = None
        self._lock = SweepLock(self.directory)

    @property
    def table_path(self) -> Path:
        return self.directory / TABLE_FILE

    def open(self) -> int:
        """Create or resume the directory; return the number of trials already done.

        Raises
        ------
        SweepLocked
            Another sweep writes the directory (named); the lock is held until
            :meth:`release`.
        SweepError
            The directory holds a different sweep, a table without ``sweep.json``, or a table
            with other columns.
        """
        if self.directory.exists() and not self.directory.is_dir():
            raise SweepError(f'--out {str(self.directory)!r} exists and is not a directory')
        if not self.directory.parent.is_dir():  # a typo must not create directories anywhere
            raise SweepError(f'--out {str(self.directory)!r}: the directory it goes into, '
                             f'{str(self.directory.parent)!r}, does not exist')
        self.directory.mkdir(exist_ok=True)
        self._lock.acquire()
        try:
            return self._open_locked()
        except BaseException:
            self._lock.release()
            raise

    def _open_locked(self) -> int:
        params = self.directory / PARAMS_FILE
        if params.exists():
            try:
                stored = json.loads(params.read_text(encoding='utf-8'))
            except (OSError, ValueError) as exc:
                raise SweepError(f'{params}: cannot read it ({exc})') from None
            if stored.get('format') != FORMAT_VERSION:
                raise SweepError(
                    f'{self.directory} holds a sweep of format {stored.get("format")!r}, '
                    f'written before lifted meant a lift-off during the grasp (this is '
                    f'format {FORMAT_VERSION}); it cannot be resumed: use another --out or '
                    f'remove it (sweep_plot and sweep_report still read it)')
            for key in _MATCHING_KEYS:
                diff = _first_difference(stored.get(key), self.parameters[key], key)
                if diff and key == 'config_sha256' and isinstance(stored.get('config'), dict):
                    # the digests differ: name the configuration value that does
                    diff = _first_difference(stored['config'], self.parameters['config'],
                                             'config') or diff
                if diff:
                    raise SweepError(f'{self.directory} holds a different sweep ({diff}); '
                                     f'use another --out or remove it')
        elif self.table_path.exists():
            raise SweepError(f'{self.table_path} exists without {PARAMS_FILE}; use another '
                             f'--out or remove it')
        else:
            _write_atomic(params, json.dumps(self.parameters, indent=2) + '\n')
        if self.table_path.exists():
            self._read_existing()
        self._rewrite()
        self._handle = self.table_path.open('a', encoding='utf-8', newline='')
        return len(self.rows)

    def _read_existing(self) -> None:
        text = self.table_path.read_text(encoding='utf-8')
        if not text:
            return
        lines = text.split('\n')
        header = next(csv.reader([lines[0]]), []) if lines else []
        if header != self.columns:
            raise SweepError(f'{self.table_path}: its columns {header} are not this sweep\'s '
                             f'{self.columns}')
        # The last element is what follows the last newline: a row cut short, or ''.
        complete, tail = lines[1:-1], lines[-1] if len(lines) > 1 else ''
        self.dropped = int(bool(tail.strip()))
        for line in complete:
            values = next(csv.reader([line]), [])
            row = dict(zip(self.columns, values, strict=False))
            index = _index(row.get('trial', ''), len(self.specs))
            if (len(values) != len(self.columns) or index is None or index in self.rows
                    or any(row[k] != v for k, v in input_columns(self.specs[index]).items())
                    or row.get('lifted') not in ('0', '1')
                    or row.get('off_table_at_end') not in ('0', '1')
                    or row.get('outcome') not in _OUTCOMES):
                self.dropped += 1
                continue
            self.rows[index] = row

    def _rewrite(self) -> None:
        lines = [_row_line(self.columns, dict(zip(self.columns, self.columns, strict=True)))]
        lines += [_row_line(self.columns, self.rows[i]) for i in sorted(self.rows)]
        _write_atomic(self.table_path, ''.join(lines))

    def pending(self) -> list[TrialSpec]:
        """The trials without a row, in trial order."""
        return [s for s in self.specs if s.index not in self.rows]

    def append(self, row: Mapping[str, str]) -> None:
        """Add a finished trial's row and flush it to the file."""
        if self._handle is None:
            raise SweepError('the table is not open')
        index = int(row['trial'])
        self.rows[index] = dict(row)
        self._handle.write(_row_line(self.columns, row))
        self._handle.flush()

    def _close_file(self) -> None:
        if self._handle is not None:
            self._handle.close()
            self._handle = None

    def close(self) -> None:
        """Close the file (rows stay as written) and let another sweep have the directory
        (idempotent)."""
        self._close_file()
        self._lock.release()

    def release(self) -> None:
        """The same as :meth:`close`."""
        self.close()

    @property
    def complete(self) -> bool:
        return len(self.rows) == len(self.specs)

    def finalize(self) -> None:
        """Rewrite the table in trial order and write ``cells.csv`` (a complete sweep); then
        :meth:`close`."""
        self._close_file()
        self._rewrite()
        if self.complete:
            cells = cell_summary(self.rows[i] for i in sorted(self.rows))
            text = _row_line(CELL_COLUMNS, dict(zip(CELL_COLUMNS, CELL_COLUMNS, strict=True)))
            text += ''.join(_row_line(CELL_COLUMNS, c) for c in cells)
            _write_atomic(self.directory / CELLS_FILE, text)
        self.close()

    def __enter__(self) -> TrialTable:
        self.open()
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _index(text: str, n: int) -> int | None:
    try:
        value = int(text)
    except ValueError:
        return None
    return value if 0 <= value < n else None


def _write_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + '.tmp')
    tmp.write_text(text, encoding='utf-8')
    os.replace(tmp, path)


def read_table(path: str | os.PathLike[str]) -> list[dict[str, str]]:
    """The rows of a ``trials.csv`` (or ``cells.csv``) as dictionaries of strings."""
    with Path(path).open(encoding='utf-8', newline='') as handle:
        return list(csv.DictReader(handle))


def cell_summary(rows: Iterable[Mapping[str, str]]) -> list[dict[str, str]]:
    """Per cell of an object (in order of first appearance): trials, lifts, outcomes, the
    analysis.

    ``p_lift`` is the share of trials whose object lifted (ground truth: it left the table
    during the grasp), ``off_table_at_end`` how many ended off the table, ``p_success`` the
    share the controller classified SUCCESS; the analysis columns are the cell's (the same for
    every trial of a cell).
    """
    cells: dict[tuple[str, str, str, str], list[Mapping[str, str]]] = {}
    for row in rows:
        key = (row.get('object', ''), row['friction_angle_deg'], row['k_theta_nm_per_rad'],
               row['delta_theta_p_deg'])
        cells.setdefault(key, []).append(row)
    out = []
    for (name, alpha, k, dp), group in cells.items():
        n = len(group)
        lifted = sum(int(r['lifted']) for r in group)
        at_end = sum(int(r['off_table_at_end']) for r in group)
        counts = {o: sum(r['outcome'] == o for r in group)
                  for o in ('SUCCESS', 'LIFTED_DAM_FAILED', 'FAILURE')}
        rises = [float(r['rise_final_mm']) for r in group]
        first = group[0]
        out.append({
            'object': name, 'friction_angle_deg': alpha, 'k_theta_nm_per_rad': k,
            'delta_theta_p_deg': dp,
            'trials': str(n), 'lifted': str(lifted), 'p_lift': f'{lifted / n:.6g}',
            'off_table_at_end': str(at_end),
            'success': str(counts['SUCCESS']),
            'lifted_dam_failed': str(counts['LIFTED_DAM_FAILED']),
            'failure': str(counts['FAILURE']), 'p_success': f'{counts["SUCCESS"] / n:.6g}',
            'rise_final_mm_mean': f'{math.fsum(rises) / n:.6g}',
            'check_lift_guaranteed': first['check_lift_guaranteed'],
            'worst_case_margin_n': first['worst_case_margin_n'],
            'csm_lift': first['csm_lift'], 'csm_margin_n': first['csm_margin_n']})
    return out


#: The controller's outcomes that say "lifted" (the object held off the table).
LIFTED_OUTCOMES = ('SUCCESS', 'LIFTED_DAM_FAILED')


def outcome_counts(trials: Iterable[tuple[str, bool]],
                   names: Mapping[str, str] | None = None) -> str:
    """The outcome counts of ``trials`` ((outcome, lifted) pairs, ``lifted`` the ground truth:
    the object left the table), with the trials whose ground truth disagrees with their
    outcome said beside their count, so that the line adds up:
    ``'SUCCESS 3, LIFTED_DAM_FAILED 1, FAILURE 4 (1 of them did leave the table)'``.

    Parameters
    ----------
    trials : (outcome, lifted) per trial.
    names : the words for each outcome (default: its name).
    """
    pairs = list(trials)
    parts = []
    for outcome in ('SUCCESS', 'LIFTED_DAM_FAILED', 'FAILURE'):
        mine = [lifted for o, lifted in pairs if o == outcome]
        text = f'{(names or {}).get(outcome, outcome)} {len(mine)}'
        if outcome in LIFTED_OUTCOMES:
            odd = sum(not lifted for lifted in mine)
            why = 'never left the table'
        else:
            odd = sum(bool(lifted) for lifted in mine)
            why = 'did leave the table'
        if odd:
            text += f' ({"it" if len(mine) == 1 else f"{odd} of them"} {why})'
        parts.append(text)
    return ', '.join(parts)

