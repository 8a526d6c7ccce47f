"""The experiments' commands on SIGINT and SIGTERM at any moment, as installed (``ros2 run
dam_experiments ...`` runs the same executables): exit status 130 and one line, never a
traceback; what a command finished is kept (a user review: a signal while ``sweep`` built its
analyses gave a traceback, and ``dam_experiment`` lost every grasp done to Ctrl-C or to an
``--out`` in a missing directory, found after the last grasp)."""

from __future__ import annotations

import csv
import signal
import subprocess
import time
from pathlib import Path

import pytest

from ros_testing import installed_executable, stop_with_signal, wait_for_signal_handlers

#: Long enough that no command ends before its signal (a 0.6 s grasp costs about 0.2 s).
GRID = ['--k-theta', *[str(k) for k in (0.5, 1, 2, 3, 5, 7, 10, 12, 15, 20)],
        '--delta-theta-p', '5deg', '10deg', '20deg', '--max-time', '0.6']


def _start(executable: str, *args: str) -> subprocess.Popen:
    """The command, once its signal handlers are in place (its entry point's first lines)."""
    proc = subprocess.Popen([str(installed_executable('dam_experiments', executable)), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for_signal_handlers(proc)
    return proc


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM], ids=['INT', 'TERM'])
@pytest.mark.parametrize('delay_s', [0.0, 0.3, 1.5])
@pytest.mark.parametrize('executable', ['sweep', 'dam_experiment'])
def test_a_signal_while_a_command_starts_or_works_is_a_clean_stop(
        executable: str, delay_s: float, signum: int, tmp_path: Path) -> None:
    out = tmp_path / ('sweep' if executable == 'sweep' else 'grid.csv')
    proc = _start(executable, *GRID, '--out', str(out), *(['--quiet', '--workers', '1']
                                                          if executable == 'sweep' else []))
    time.sleep(delay_s)
    assert proc.poll() is None, proc.communicate()
    stdout, stderr = stop_with_signal(proc, signum)
    assert proc.returncode == 130, (stdout, stderr)
    assert 'Traceback' not in stderr, stderr
    assert 'interrupted' in stdout + stderr, (stdout, stderr)


def test_dam_experiment_keeps_the_grasps_done_when_interrupted(tmp_path: Path) -> None:
    out = tmp_path / 'grid.csv'
    proc = _start('dam_experiment', *GRID, '--out', str(out))
    deadline = time.monotonic() + 120.0
    while not (out.is_file() and out.read_text().count('\n') >= 3):  # header and two rows
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.01)
    stdout, stderr = stop_with_signal(proc, signal.SIGINT)
    assert proc.returncode == 130, stderr
    with out.open(newline='', encoding='utf-8') as handle:
        rows = list(csv.DictReader(handle))
    assert 2 <= len(rows) < 30
    assert all(None not in row.values() and row['outcome'] for row in rows)  # whole rows
    done = f'interrupted after {len(rows)} grasps; {len(rows)} rows written to {out}'
    assert done in stderr, stderr
    # the table's header and its legend line, then one line per grasp
    lines = stdout.splitlines()
    assert lines[1].startswith('(rise, max:'), lines[:2]
    printed = [line for line in lines[2:] if line.strip()]
    assert len(printed) == len(rows)  # each grasp printed is a row of the file


def test_dam_experiment_refuses_an_out_it_cannot_write_before_any_grasp(tmp_path: Path) -> None:
    out = tmp_path / 'missing' / 'grid.csv'
    started = time.monotonic()
    result = subprocess.run([str(installed_executable('dam_experiments', 'dam_experiment')),
                             *GRID, '--out', str(out)], capture_output=True, text=True,
                            timeout=120)
    assert result.returncode == 2, result
    assert result.stderr == (f'dam_experiment: cannot write {out}: No such file or '
                             f'directory\n')
    assert result.stdout == ''  # not one grasp ran
    assert time.monotonic() - started < 60.0
