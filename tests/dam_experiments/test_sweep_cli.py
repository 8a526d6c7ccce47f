"""``sweep`` end to end on a small sweep of short trials: in this process, on local worker
processes, on a loopback Dask cluster (``dask scheduler`` and two ``dask worker`` processes),
and interrupted by a real SIGINT and resumed. Every run must give the same table.

The trials stop after 0.6 s of simulated time (the fingers are still closing: the pipeline is
under test here, the grasps are in ``test_experiment.py``), about 0.2 s each.
"""

from __future__ import annotations

import contextlib
import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import psutil
import pytest

from dam_experiments.sweep_cli import main
from dam_experiments.sweep_table import (
    CELLS_FILE,
    FORMAT_VERSION,
    PARAMS_FILE,
    TABLE_FILE,
    read_table,
)
from ros_testing import installed_executable

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG = REPO_ROOT / 'config' / 'dam.yaml'
#: 2 friction angles x 2 k_theta x 1 delta_theta_p x 2 repeats, every perturbation on.
SWEEP = ['--friction-angles', '5deg', '30deg', '--k-theta', '0.5', '10', '--delta-theta-p',
         '10deg', '--repeats', '2', '--mass-rel', '0.2', '--position-sd', '1mm',
         '--table-friction-rel', '0.2', '--friction-angle-sd', '2deg', '--max-time', '0.6',
         '--config', str(CONFIG), '--quiet']
N_TRIALS = 8


def _env() -> dict[str, str]:
    """This process's environment with the source tree on PYTHONPATH (as conftest does)."""
    src = [str(p) for p in sorted((REPO_ROOT / 'src').iterdir()) if (p / 'setup.py').is_file()]
    return {**os.environ, 'PYTHONPATH': ':'.join(src + [os.environ.get('PYTHONPATH', '')])}


def _sweep_command(out: Path, *extra: str) -> list[str]:
    return [sys.executable, '-m', 'dam_experiments.sweep_cli', *SWEEP, '--out', str(out), *extra]


@pytest.fixture(scope='module')
def reference(tmp_path_factory: pytest.TempPathFactory) -> str:
    """The table of the sweep run in this process (``--workers 1``)."""
    out = tmp_path_factory.mktemp('reference')
    assert main([*SWEEP, '--out', str(out), '--workers', '1']) == 0
    return (out / TABLE_FILE).read_text(encoding='utf-8')


def test_the_table_holds_every_trial(reference: str, tmp_path: Path) -> None:
    rows = [line.split(',') for line in reference.splitlines()]
    header = rows[0]
    assert header[:7] == ['trial', 'object', 'friction_angle_deg', 'k_theta_nm_per_rad',
                          'delta_theta_p_deg', 'repeat', 'seed']
    assert {r[1] for r in rows[1:]} == {'cylinder'}  # the configured object, named
    for name in ('outcome', 'lifted', 'rise_final_mm', 'peak_tau_finger1_compliant_nm',
                 'check_lift_guaranteed', 'worst_case_margin_n', 'csm_margin_n'):
        assert name in header
    assert [int(r[0]) for r in rows[1:]] == list(range(N_TRIALS))
    masses = {r[header.index('object_mass_kg')] for r in rows[1:]}
    assert len(masses) == N_TRIALS  # every trial drew its own world


def test_two_runs_give_the_same_table(reference: str, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    """Determinism, and the default parallel path: two local worker processes (a Dask
    LocalCluster) finish the trials in another order and write the same bytes."""
    assert main([*SWEEP, '--out', str(tmp_path), '--workers', '2']) == 0
    assert (tmp_path / TABLE_FILE).read_text(encoding='utf-8') == reference
    out = capsys.readouterr().out
    assert 'on 2 local worker processes' in out and f'{N_TRIALS} trials in' in out
    cells = read_table(tmp_path / CELLS_FILE)
    assert len(cells) == 4 and all(c['trials'] == '2' for c in cells)
    params = json.loads((tmp_path / PARAMS_FILE).read_text(encoding='utf-8'))
    assert params['sweep']['k_theta'] == [0.5, 10.0] and params['n_trials'] == N_TRIALS
    assert params['sweep']['perturbations']['mass_rel'] == 0.2
    assert str(REPO_ROOT) not in json.dumps(params['sweep'])


def _dask() -> list[str]:
    exe = Path(sys.executable).with_name('dask')
    found = str(exe) if exe.is_file() else shutil.which('dask')
    if found is None:
        pytest.fail('the dask command is not installed (scripts/requirements/python.txt)')
    return [found]


@contextlib.contextmanager
def _cluster(d: Path, workers: int = 2
             ) -> Iterator[tuple[str, list[subprocess.Popen[bytes]], Callable[[int], None]]]:
    """``dask scheduler`` and ``workers`` ``dask worker`` processes on 127.0.0.1 (ports chosen
    by the system), logs in ``d``; yields the scheduler's address, the processes (scheduler,
    worker 1, worker 2, ...) and ``start_worker(i)``, which starts worker ``i`` (appended to the
    processes)."""
    from distributed import Client

    file = d / 'scheduler.json'
    procs: list[subprocess.Popen[bytes]] = []
    grace = 0.1  # [s] for the processes to end by themselves
    env = _env()
    logs = []

    def start(args: list[str], name: str) -> None:
        log = (d / f'{name}.log').open('wb')
        logs.append(log)
        procs.append(subprocess.Popen([*_dask(), *args], stdout=log, stderr=subprocess.STDOUT,
                                      env=env, cwd=d))

    try:
        start(['scheduler', '--host', '127.0.0.1', '--port', '0', '--no-dashboard',
               '--scheduler-file', str(file)], 'scheduler')
        deadline = time.monotonic() + 60.0
        while not (file.is_file() and file.stat().st_size) and time.monotonic() < deadline:
            assert procs[0].poll() is None, (d / 'scheduler.log').read_text()
            time.sleep(0.05)
        address = json.loads(file.read_text())['address']
        assert address.startswith('tcp://127.0.0.1:')

        def start_worker(i: int) -> None:
            start(['worker', '--scheduler-file', str(file), '--host', '127.0.0.1',
                   '--nthreads', '1', '--no-nanny', '--no-dashboard',
                   '--local-directory', str(d / f'worker{i}')], f'worker{i}')

        for i in range(1, workers + 1):
            start_worker(i)
        with Client(address, timeout='30s') as client:
            client.wait_for_workers(workers, timeout=60)
        yield address, procs, start_worker
        with Client(address, timeout='30s') as client:
            client.shutdown()  # the scheduler closes the workers, then itself
        grace = 10.0
    finally:
        for proc in procs:
            try:
                proc.wait(timeout=grace)
            except subprocess.TimeoutExpired:  # the set-up failed, or the shutdown did
                proc.kill()
                proc.wait()
        for log in logs:
            log.close()


@pytest.fixture(scope='module')
def loopback_cluster(tmp_path_factory: pytest.TempPathFactory) -> Iterator[str]:
    """A loopback cluster (:func:`_cluster`) for the module; yields the scheduler's address."""
    with _cluster(tmp_path_factory.mktemp('dask')) as (address, _procs, _start):
        yield address


@pytest.mark.parametrize('replaced', [False, True], ids=['other_finishes', 'newcomer_finishes'])
def test_a_worker_that_leaves_mid_sweep_loses_nothing(reference: str, tmp_path: Path,
                                                      replaced: bool) -> None:
    """A worker is stopped (SIGTERM) once the first rows are in: the other one of two
    finishes the sweep, with the same table; or, where it was the only one, a worker that
    joins afterwards does (it has nothing the first one held: whatever a trial needs travels
    with the trial)."""
    out = tmp_path / 'out'
    with _cluster(tmp_path, workers=1 if replaced else 2) as (address, procs, start_worker):
        proc = subprocess.Popen(_sweep_command(out, '--scheduler', address), env=_env(),
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            table = out / TABLE_FILE
            deadline = time.monotonic() + 120.0
            while not (table.is_file() and table.read_text().count('\n') >= 2):
                assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
                time.sleep(0.01)
            procs[1].terminate()
            if replaced:
                try:  # a graceful close waits for the trial in hand (long on a busy machine)
                    procs[1].wait(timeout=60)
                except subprocess.TimeoutExpired:  # then it leaves the hard way
                    procs[1].kill()
                    procs[1].wait(timeout=30)
                start_worker(2)
            _out, err = proc.communicate(timeout=120)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
    assert proc.returncode == 0, err
    assert 'Traceback' not in err, err
    assert table.read_text(encoding='utf-8') == reference


def test_resume_runs_edited_rows_again(reference: str, tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    """Rows whose ``lifted``, ``off_table_at_end`` or ``outcome`` is not a value the sweep
    writes (an edited table) are dropped on resume and run again."""
    (tmp_path / TABLE_FILE).parent.mkdir(exist_ok=True)
    assert main([*SWEEP, '--out', str(tmp_path), '--workers', '1']) == 0
    rows = read_table(tmp_path / TABLE_FILE)
    rows[1]['lifted'] = 'x'
    rows[2]['off_table_at_end'] = ''
    rows[4]['outcome'] = 'LIFTED'
    with (tmp_path / TABLE_FILE).open('w', encoding='utf-8', newline='') as handle:
        writer = csv.DictWriter(handle, list(rows[0]), lineterminator='\n')
        writer.writeheader()
        writer.writerows(rows)
    capsys.readouterr()
    assert main([*SWEEP, '--out', str(tmp_path), '--workers', '1']) == 0
    out = capsys.readouterr().out
    assert f'resuming: {N_TRIALS - 3} done, 3 to run (3 incomplete, malformed or repeated ' \
           'rows dropped)' in out, out
    assert (tmp_path / TABLE_FILE).read_text(encoding='utf-8') == reference
    table = read_table(tmp_path / TABLE_FILE)
    lifted = sum(r['lifted'] == '1' for r in table)
    held = sum(r['off_table_at_end'] == '1' for r in table)
    assert f'lifted (left the table) {lifted}, off the table at the end {held}, ' in out


def test_loopback_dask_cluster_gives_the_same_table(reference: str, loopback_cluster: str,
                                                    tmp_path: Path,
                                                    capsys: pytest.CaptureFixture[str]) -> None:
    from distributed import Client

    assert main([*SWEEP, '--out', str(tmp_path), '--scheduler', loopback_cluster]) == 0
    assert f'on the Dask cluster at {loopback_cluster}' in capsys.readouterr().out
    assert (tmp_path / TABLE_FILE).read_text(encoding='utf-8') == reference
    with Client(loopback_cluster, timeout='30s') as client:  # both workers took trials
        ran = client.run(lambda: len(__import__('dam_experiments.sweep').sweep._ANALYZERS))
    assert sorted(ran.values()) == [1, 1]


def test_interrupted_sweep_resumes_without_redoing_trials(
        reference: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A real SIGINT to the command after a few rows: it finishes the running trial, keeps
    the rows and exits with 130; the same sweep again runs only the missing trials and ends
    with the reference table."""
    table = tmp_path / TABLE_FILE
    proc = subprocess.Popen(_sweep_command(tmp_path, '--workers', '1'), env=_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120.0
        rows = 0
        while rows < 2 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
            rows = table.read_text().count('\n') - 1 if table.is_file() else 0
        assert proc.poll() is None, 'the sweep ended before it could be interrupted'
        children = psutil.Process(proc.pid).children(recursive=True)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert 'Traceback' not in err
    assert 'interrupted:' in out and 'run the same command again' in out
    assert 'stopping after the running trial' in err
    _, alive = psutil.wait_procs(children, timeout=10)
    assert not alive
    kept = read_table(table)
    assert 2 <= len(kept) < N_TRIALS
    assert not (tmp_path / CELLS_FILE).exists()

    assert main([*SWEEP, '--out', str(tmp_path), '--workers', '1']) == 0
    out = capsys.readouterr().out
    todo = N_TRIALS - len(kept)
    assert f'resuming: {len(kept)} done, {todo} to run' in out
    assert f'\nsweep: {todo} trials in ' in out  # only the missing ones ran
    assert table.read_text(encoding='utf-8') == reference
    assert all(row in read_table(table) for row in kept)


def test_sigint_stops_a_background_sweep_on_local_workers(tmp_path: Path) -> None:
    """Started as a shell starts a background job (``&``: SIGINT ignored), on local worker
    processes: ``kill -INT`` stops it all the same, with its rows kept and its workers gone."""
    table = tmp_path / TABLE_FILE
    proc = subprocess.Popen(_sweep_command(tmp_path, '--workers', '2'), env=_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_IGN))
    try:
        deadline = time.monotonic() + 120.0
        while not (table.is_file() and table.read_text().count('\n') >= 2):
            assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
            time.sleep(0.01)
        children = psutil.Process(proc.pid).children(recursive=True)
        proc.send_signal(signal.SIGINT)
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == 130, err
    assert 'interrupted:' in out, out
    assert 'Traceback' not in err, err
    _, alive = psutil.wait_procs(children, timeout=10)
    assert not alive
    assert 1 <= len(read_table(table)) < N_TRIALS


@pytest.mark.parametrize('args, words', [
    (['--k-theta', '0.05:20:0:log'], ['--k-theta', 'count 0', "'0.05:20:0:log'"]),
    (['--delta-theta-p', '5deg:70deg:14'], ['--delta-theta-p: 70 deg exceeds']),
    (['--friction-angles', '5deg', '95deg'], ['--friction-angles: 95 deg', 'outside [0, 90)']),
    (['--delta-theta-p', '5:60:12'], ["--delta-theta-p: '5' has no unit", 'did you mean 5deg?']),
    (['--k-theta', '1', '--mass-rel', '1.5'], ['--mass-rel (mass_rel): 1.5']),
    (['--repeats', '0'], ['--repeats (repeats): 0']),
    (['--workers', '0'], ['--workers: 0']),
    (['--objects', 'cylinder', 'pencil'], ["--objects: 'pencil' is not in the object library",
                                           'hex_bar']),
    (['--objects', 'hex_bar', 'hex_bar'], ['--objects (objects)', 'distinct']),
])
def test_bad_arguments_are_refused(args: list[str], words: list[str], tmp_path: Path,
                                   capsys: pytest.CaptureFixture[str]) -> None:
    base = {'--k-theta': ['1'], '--delta-theta-p': ['10deg']}
    flat = [a for k, v in base.items() if k not in args for a in (k, *v)]
    assert main([*flat, *args, '--out', str(tmp_path / 'x'), '--config', str(CONFIG)]) == 2
    err = capsys.readouterr().err
    assert err.startswith('sweep: ')
    for word in words:
        assert word in err, err
    assert not (tmp_path / 'x').exists()


def test_an_unreachable_scheduler_fails_at_once_and_writes_nothing(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    import socket

    from dam_experiments import sweep_cli

    with socket.socket() as sock:  # a port nobody listens on
        sock.bind(('127.0.0.1', 0))
        port = sock.getsockname()[1]
    monkeypatch.setattr(sweep_cli, 'CONNECT_TIMEOUT_S', 2.0)
    start = time.monotonic()
    status = main([*SWEEP, '--out', str(tmp_path / 'x'), '--scheduler',
                   f'tcp://127.0.0.1:{port}'])
    assert status == 1
    assert time.monotonic() - start < 15.0
    err = capsys.readouterr().err
    assert err.startswith(f"sweep: cannot reach the Dask scheduler at 'tcp://127.0.0.1:{port}'")
    assert not (tmp_path / 'x').exists()


def test_a_server_that_never_answers_or_is_a_worker_is_refused_in_time(
        tmp_path: Path, loopback_cluster: str, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    """A TCP server that accepts the connection and never speaks hung the command; a
    worker's address is no scheduler's."""
    import socket

    from distributed import Client

    from dam_experiments import sweep_cli

    monkeypatch.setattr(sweep_cli, 'CONNECT_TIMEOUT_S', 2.0)
    with socket.socket() as silent:
        silent.bind(('127.0.0.1', 0))
        silent.listen(4)  # the kernel accepts; nobody ever reads or writes
        port = silent.getsockname()[1]
        start = time.monotonic()
        status = main([*SWEEP, '--out', str(tmp_path / 'x'), '--scheduler',
                       f'tcp://127.0.0.1:{port}'])
        assert time.monotonic() - start < 10.0
    assert status == 1
    err = capsys.readouterr().err
    assert err == (f"sweep: cannot reach the Dask scheduler at 'tcp://127.0.0.1:{port}': no "
                   'answer within 2 s (is it a Dask scheduler?)\n')
    with Client(loopback_cluster, timeout='30s') as client:
        worker = next(iter(client.scheduler_info()['workers']))
    assert main([*SWEEP, '--out', str(tmp_path / 'x'), '--scheduler', worker]) == 1
    assert "it answers as 'Worker', not as a Dask scheduler" in capsys.readouterr().err
    assert not (tmp_path / 'x').exists()


def test_another_sweep_in_the_same_directory_is_refused(reference: str, tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]
                                                        ) -> None:
    (tmp_path / PARAMS_FILE).write_text(json.dumps({'format': FORMAT_VERSION,
                                                    'sweep': {'seed': 5}}))
    assert main([*SWEEP, '--out', str(tmp_path), '--workers', '1']) == 2
    assert 'holds a different sweep' in capsys.readouterr().err
    # a sweep of format 1 (lifted by the old rise rule) or 2 (lifted: off the table at the
    # end) is not resumed into: its rows mean something else
    for old in (1, 2):
        (tmp_path / PARAMS_FILE).write_text(json.dumps({'format': old, 'sweep': {'seed': 5}}))
        assert main([*SWEEP, '--out', str(tmp_path), '--workers', '1']) == 2
        err = capsys.readouterr().err
        assert len(err.splitlines()) == 1 and f'holds a sweep of format {old}' in err
        assert 'written before lifted meant a lift-off during the grasp' in err
        assert 'it cannot be resumed' in err and not (tmp_path / TABLE_FILE).exists()


def test_a_bare_perturbation_is_in_si_units_and_an_implausible_one_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ['--k-theta', '1', '--delta-theta-p', '10deg', '--out', str(tmp_path / 'x')]
    for option, word, meant in (('--position-sd', '1', '1mm'),
                                ('--friction-angle-sd', '2', '2deg')):
        with pytest.raises(SystemExit) as info:
            main([*base, option, word])
        assert info.value.code == 2
        err = capsys.readouterr().err
        assert f'argument {option}: ' in err and f'did you mean {meant}?' in err, err
    assert not (tmp_path / 'x').exists()


def test_installed_command() -> None:
    """``ros2 run dam_experiments sweep`` finds it; the core imports no rclpy."""
    exe = installed_executable('dam_experiments', 'sweep')
    proc = subprocess.run([str(exe), '--help'], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr
    for option in ('--friction-angles', '--k-theta', '--delta-theta-p', '--repeats',
                   '--workers', '--scheduler', 'start:stop:count:log'):
        assert option in proc.stdout
    code = ('import sys, dam_experiments.sweep_cli, dam_experiments.sweep_table; '
            'assert "rclpy" not in sys.modules, "the sweep imports rclpy"')
    subprocess.run([sys.executable, '-c', code], check=True, timeout=60, env=_env())


def test_a_second_sweep_on_a_busy_directory_is_refused_naming_the_first(
        reference: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Two sweeps started on one directory: the second is refused at once (exit 1, not a
    'bad arguments' 2), naming the first; the first finishes with the reference table, and
    once it is done (or killed) the directory is free again."""
    table = tmp_path / TABLE_FILE
    first = subprocess.Popen(_sweep_command(tmp_path, '--workers', '1'), env=_env(),
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120.0
        while not table.is_file() and first.poll() is None and time.monotonic() < deadline:
            time.sleep(0.01)
        assert first.poll() is None, 'the first sweep ended before the second started'
        assert main([*SWEEP, '--out', str(tmp_path), '--workers', '1']) == 1
        err = capsys.readouterr().err
        assert f'is being written by another sweep (PID {first.pid} on ' in err, err
        _out, first_err = first.communicate(timeout=300)
    finally:
        if first.poll() is None:
            first.kill()
            first.wait()
    assert first.returncode == 0, first_err
    assert table.read_text(encoding='utf-8') == reference  # no trial run twice or lost
    # The first is gone: the same command now takes the directory (all done: nothing to run).
    assert main([*SWEEP, '--out', str(tmp_path), '--workers', '1']) == 0
    assert 'resuming: 8 done, 0 to run' in capsys.readouterr().out


def test_a_killed_sweep_leaves_no_stale_lock(tmp_path: Path) -> None:
    from dam_experiments.sweep_lock import SweepLock, SweepLocked

    holder = subprocess.Popen(
        [sys.executable, '-c', 'import sys, time\n'
         'from dam_experiments.sweep_lock import SweepLock\n'
         f'SweepLock({str(tmp_path)!r}).acquire(); print("locked", flush=True)\n'
         'time.sleep(60)'], env=_env(), stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == 'locked'
        with pytest.raises(SweepLocked, match=f'PID {holder.pid}'):
            SweepLock(tmp_path).acquire()
    finally:
        holder.kill()
        holder.wait()
    lock = SweepLock(tmp_path)
    lock.acquire()  # the kernel dropped the killed holder's lock
    lock.release()


def test_an_object_the_analysis_cannot_answer_for_is_refused_before_any_trial(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A 1 mm rod: the loader takes it, no finger reaches it; every trial failed the same way
    and a rerun 'retried' them (exit 1). Refused at once, exit 2, the object named."""
    import yaml

    data = yaml.safe_load(CONFIG.read_text(encoding='utf-8'))
    data['object']['library']['rod_1mm'] = {'shape': 'circle', 'radius_m': 0.001,
                                            'length_m': 0.1, 'mass_kg': 0.002}
    data['object']['default'] = 'rod_1mm'
    config = tmp_path / 'dam.yaml'
    config.write_text(yaml.safe_dump(data), encoding='utf-8')
    out = tmp_path / 'out'
    assert main(['--k-theta', '10', '--delta-theta-p', '10deg', '--out', str(out), '--workers',
                 '1', '--config', str(config)]) == 2
    err = capsys.readouterr().err
    assert "object 'rod_1mm' cannot be analysed with this hand" in err, err
    assert 'does not reach the object' in err, err
    assert not (out / TABLE_FILE).exists()


def test_objects_are_an_axis_each_trial_grasping_its_own(tmp_path: Path) -> None:
    """Two objects of the library: each cell once per object, the object named in the table
    and in cells.csv, the world's mass and the analysis columns the object's own (the
    analysis asked afresh here for the object as configured), and the first object's trials
    drawn as in a sweep of it alone."""
    import math

    import numpy as np

    from dam_analysis.analysis import LiftAnalyzer
    from dam_common.config import load_config

    grid = ['--friction-angles', '5deg', '--k-theta', '10', '--delta-theta-p', '10deg',
            '--mass-rel', '0.2', '--max-time', '0.6', '--config', str(CONFIG), '--quiet',
            '--workers', '1']
    assert main([*grid, '--objects', 'cylinder', 'hex_bar', '--out', str(tmp_path / 'two')]) == 0
    assert main([*grid, '--out', str(tmp_path / 'one')]) == 0
    rows = read_table(tmp_path / 'two' / TABLE_FILE)
    assert [r['object'] for r in rows] == ['cylinder', 'hex_bar']
    alone = read_table(tmp_path / 'one' / TABLE_FILE)
    assert alone[0]['seed'] == rows[0]['seed'] and alone[0]['object'] == 'cylinder'
    assert rows[1]['seed'] != rows[0]['seed']
    config = load_config(CONFIG)
    for row in rows:
        obj = config.objects[row['object']]
        u = (float(row['object_mass_kg']) / obj.mass_kg - 1.0) / 0.2  # the drawn U(-1, 1)
        assert -1.0 <= u <= 1.0
        answer = LiftAnalyzer(config.with_object(row['object'])).check_lift(
            [10.0], [math.radians(10.0)], friction_angle=math.radians(5.0))
        assert int(row['check_lift_guaranteed']) == int(answer.lift_guaranteed)
        assert float(row['csm_margin_n']) == pytest.approx(float(answer.csm_margin), rel=1e-5)
    margins = [float(r['csm_margin_n']) for r in rows]
    assert not np.isclose(margins[0], margins[1])  # two objects, two analyses
    cells = read_table(tmp_path / 'two' / CELLS_FILE)
    assert [c['object'] for c in cells] == ['cylinder', 'hex_bar']
    params = json.loads((tmp_path / 'two' / PARAMS_FILE).read_text(encoding='utf-8'))
    assert params['sweep']['objects'] == ['cylinder', 'hex_bar']


def test_the_outcome_counts_say_which_disagree_with_the_ground_truth() -> None:
    """"lifted 5, SUCCESS 3, LIFTED_DAM_FAILED 1, FAILURE 4" read inconsistent: one FAILURE
    had lifted the object; the line says so."""
    from dam_experiments.sweep_table import outcome_counts

    trials = ([('SUCCESS', True)] * 3 + [('LIFTED_DAM_FAILED', True)]
              + [('FAILURE', True)] + [('FAILURE', False)] * 3)
    assert outcome_counts(trials) == ('SUCCESS 3, LIFTED_DAM_FAILED 1, FAILURE 4 (1 of them '
                                      'did leave the table)')
    assert outcome_counts([('SUCCESS', False), ('FAILURE', False)]) == (
        'SUCCESS 1 (it never left the table), LIFTED_DAM_FAILED 0, FAILURE 1')


def test_one_of_everything_is_said_in_the_singular(tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    """"1 trials (1 friction angles x ... 1 repeats)"."""
    assert main(['--friction-angles', '5deg', '--k-theta', '10', '--delta-theta-p', '20deg',
                 '--max-time', '0.6', '--config', str(CONFIG), '--out', str(tmp_path),
                 '--workers', '1', '--quiet']) == 0
    out = capsys.readouterr().out
    assert ('sweep: 1 trial (object cylinder, 1 friction angle x 1 k_theta x 1 delta_theta_p x '
            '1 repeat)') in out
    assert '1 of 1 row in ' in out and '1 trials' not in out and '1 repeats' not in out


def test_the_local_cluster_serves_no_dashboard_unless_asked(
        caplog: pytest.LogCaptureFixture) -> None:
    """Dask's LocalCluster started a dashboard nobody asked for: a second sweep said ``Port
    8787 is already in use``. Without ``--dashboard`` the scheduler takes a free loopback port
    (8787 is held here while the cluster starts) and serves no dashboard."""
    import socket
    import urllib.error
    import urllib.request
    import warnings

    from distributed import LocalCluster

    from dam_experiments.sweep_cli import local_cluster_options

    holder = socket.socket()
    try:
        holder.bind(('', 8787))
        holder.listen()
    except OSError:  # something else holds it already: the same condition
        pass
    try:
        with warnings.catch_warnings(record=True) as caught, caplog.at_level('INFO'):
            warnings.simplefilter('always')
            with LocalCluster(n_workers=1, threads_per_worker=1, processes=False,
                              **local_cluster_options(None)) as cluster:
                port = cluster.scheduler.http_server.port
                try:
                    status = urllib.request.urlopen(f'http://127.0.0.1:{port}/status',
                                                    timeout=30).status
                except urllib.error.HTTPError as exc:
                    status = exc.code
    finally:
        holder.close()
    said = [str(w.message) for w in caught] + caplog.messages
    assert not any('already in use' in text for text in said), said
    assert port != 8787 and status == 404, (port, status)  # no dashboard page
    assert local_cluster_options(':8787') == {'dashboard_address': ':8787'}
