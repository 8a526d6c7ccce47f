"""``ros2 run dam_experiments sweep``: the paper's Fig. 7 as a sweep of lockstep DAM grasps.

::

    ros2 run dam_experiments sweep --friction-angles 5deg 30deg --k-theta 0.05:20:24:log \\
        --delta-theta-p 5deg:60deg:12 --out DIR [--objects NAME ...] [--repeats N] \\
        [--workers N] [--scheduler ADDRESS] [--dashboard [ADDRESS]]

Runs every trial of :class:`~dam_experiments.sweep.SweepSpec` (:func:`~dam_experiments.sweep.
run_trial`) on all local cores (a Dask ``LocalCluster`` of one single-threaded worker process
per core; ``--workers 1`` runs them in this process, without Dask) or on a Dask cluster
(``--scheduler tcp://HOST:PORT``); the local cluster serves Dask's dashboard only with
``--dashboard [ADDRESS]`` (default ``:8787``); shows progress with the time left, and writes
``DIR/trials.csv``, ``DIR/sweep.json`` and ``DIR/cells.csv``
(:mod:`dam_experiments.sweep_table`). Ctrl-C (SIGINT) or SIGTERM stops it with the finished
trials kept; the same command again runs only the missing ones.

One sweep at a time writes a directory: a second one started on it is refused with a message
naming the first (PID, host, start, command line; ``DIR/.sweep.lock``), exit status 1.

Exit status: 0 done; 1 some trials failed (their rows are missing: a rerun retries them), the
scheduler cannot be reached, or another sweep writes DIR; 2 bad arguments; 130 interrupted.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import signal
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from dam_common.command_line import CommandLineParser
from dam_common.quantities import ANGLE, LENGTH, argument, in_degrees
from dam_common.words import counted
from dam_experiments.errors import SweepError
from dam_experiments.sweep import (
    MAX_FRICTION_ANGLE_DEG,
    Perturbations,
    SweepSpec,
    TrialResult,
    TrialSpec,
    analyzer_for,
    run_trial,
)
from dam_experiments.sweep_axes import parse_axis
from dam_experiments.sweep_lock import SweepLocked
from dam_experiments.sweep_table import (
    CELLS_FILE,
    PARAMS_FILE,
    TABLE_FILE,
    TrialTable,
    outcome_counts,
)

PROG = 'sweep'
#: Longest wait for the first worker of a ``--scheduler`` cluster [s].
WORKER_WAIT_S = 60.0
#: One degree [rad]: the sweep's angle axes are in degrees.
DEGREE = math.pi / 180.0
#: Longest wait for a ``--scheduler`` to answer [s].
CONNECT_TIMEOUT_S = 10.0


def _millimetres(parse: Callable[[str], Any]) -> Callable[[str], float]:
    """An argparse ``type=``: the length ``parse`` reads [m] in millimetres (12 digits)."""

    def millimetres(text: str) -> float:
        return float(f'{float(parse(text)) * 1e3:.12g}')

    millimetres.__name__ = 'length'
    return millimetres


def _parse(argv: Sequence[str]) -> argparse.Namespace:
    p = CommandLineParser(
        prog=PROG,
        description='DAM grasps in the lockstep simulator over objects x friction angles x '
                    'k_theta x delta_theta_p (paper Fig. 7), optionally perturbed and repeated '
                    'per cell; one CSV row per trial. Axes take values and ranges '
                    'start:stop:count (linear) or start:stop:count:log; angles take their '
                    'unit (5deg:60deg:12; a bare number is radians).',
        epilog='Rerun the same command to resume an interrupted sweep: finished trials are '
               'kept. Exit status: 0 done, 1 trials failed, 2 bad arguments, 130 interrupted.')
    g = p.add_argument_group('the grid')
    g.add_argument('--objects', '--object', nargs='+', metavar='NAME', default=None,
                   help='objects of the configuration\'s object library to grasp, an axis '
                        '(default: the configured one)')
    g.add_argument('--friction-angles', '--alpha', nargs='+', metavar='ANGLE', default=None,
                   help='finger-object friction angles, e.g. 5deg 30deg (default: the '
                        'configured one)')
    g.add_argument('--k-theta', nargs='+', metavar='K', required=True,
                   help='finger-1 compliant stiffness [N*m/rad], e.g. 0.05:20:24:log')
    g.add_argument('--delta-theta-p', nargs='+', metavar='ANGLE', required=True,
                   help='position-joint displacement, e.g. 5deg:60deg:12')
    g.add_argument('--out', type=Path, required=True, metavar='DIR',
                   help=f'output directory ({TABLE_FILE}, {PARAMS_FILE}, {CELLS_FILE})')
    g.add_argument('--repeats', type=int, default=1, metavar='N',
                   help='trials per cell (default 1); use with perturbations')
    g.add_argument('--seed', type=int, default=0, help='base seed of the trials (default 0)')
    d = p.add_argument_group(
        'perturbations, drawn per trial from its seed (default: none)')
    d.add_argument('--mass-rel', type=float, default=0.0, metavar='FRAC',
                   help='object mass m_B (1 + FRAC u), u ~ U(-1, 1)')
    d.add_argument('--position-sd', type=_millimetres(argument(LENGTH, low=0.0)), default=0.0,
                   metavar='LENGTH',
                   help='object start offset in x and y, each ~ N(0, SD^2) (0.5mm; bare: m)')
    d.add_argument('--table-friction-rel', type=float, default=0.0, metavar='FRAC',
                   help='table friction mu_t (1 + FRAC u), u ~ U(-1, 1)')
    d.add_argument('--friction-angle-sd', type=in_degrees(argument(ANGLE, low=0.0)),
                   default=0.0, metavar='ANGLE',
                   help=f'friction angle alpha + N(0, SD^2) (1deg; bare: rad), clipped to '
                        f'[0, {MAX_FRICTION_ANGLE_DEG:g}] deg')
    t = p.add_argument_group('each trial')
    t.add_argument('--max-time', type=float, default=8.0, metavar='S',
                   help='simulated time limit [s] (default 8: a whole grasp takes 5-6 s)')
    t.add_argument('--trajectory-duration', type=float, default=None, metavar='S',
                   help='position-joint motion time [s] (default: the configured 3 s)')
    t.add_argument('--latency-cycles', type=int, default=2, metavar='N',
                   help='device cycles from a state to its command (default 2)')
    t.add_argument('--impedance', choices=('device', 'controller'), default=None,
                   help='where the compliant-joint impedance runs (default: configured)')
    t.add_argument('--envelope', choices=('impedance', 'constant-torque'), default='impedance',
                   help='ENVELOPE keeps the SPCM impedance (default) or applies the paper\'s '
                        'constant torque')
    t.add_argument('--config', default=None, help='configuration file (default: DAM_CONFIG '
                   'or the installed config/dam.yaml)')
    r = p.add_argument_group('where it runs')
    r.add_argument('--workers', type=int, default=None, metavar='N',
                   help='local worker processes (default: one per core); 1: in this process')
    r.add_argument('--scheduler', default=None, metavar='ADDRESS',
                   help='run on the Dask cluster of this scheduler (tcp://HOST:PORT)')
    r.add_argument('--dashboard', nargs='?', const=':8787', default=None, metavar='ADDRESS',
                   help="serve the local cluster's Dask dashboard at ADDRESS (default :8787; "
                        'without the option no dashboard and no port of its own)')
    r.add_argument('--quiet', action='store_true', help='no progress bar')
    return p.parse_args(argv)


def build_sweep(args: argparse.Namespace, config: Any) -> SweepSpec:
    """The :class:`SweepSpec` of the parsed arguments, checked against ``config``.

    Raises
    ------
    SweepError
        A bad range or option, naming the option and the value.
    """
    alphas = (parse_axis('--friction-angles', args.friction_angles, lower=0.0, upper=90.0,
                         upper_open=True, unit='deg', quantity=ANGLE, unit_si=DEGREE)
              if args.friction_angles else
              (round(math.degrees(float(config.contact.friction_angle_rad)), 9),))
    sweep = SweepSpec(
        friction_angles_deg=alphas,
        k_theta=parse_axis('--k-theta', args.k_theta, lower=0.0, lower_open=True,
                           unit='N*m/rad'),
        delta_theta_p_deg=parse_axis('--delta-theta-p', args.delta_theta_p, lower=0.0,
                                     lower_open=True, unit='deg', quantity=ANGLE,
                                     unit_si=DEGREE),
        repeats=args.repeats, seed=args.seed,
        perturbations=Perturbations(
            mass_rel=args.mass_rel, position_sd_mm=args.position_sd,
            table_friction_rel=args.table_friction_rel,
            friction_angle_sd_deg=args.friction_angle_sd),
        max_time_s=args.max_time, latency_cycles=args.latency_cycles,
        trajectory_duration_s=args.trajectory_duration, impedance=args.impedance,
        envelope=args.envelope,
        objects=tuple(args.objects) if args.objects else (config.object.name,))
    sweep.check_against(config)
    if args.workers is not None and args.workers < 1:
        raise SweepError(f'--workers: {args.workers} must be at least 1')
    if args.workers is not None and args.scheduler:
        raise SweepError('--workers and --scheduler exclude each other (the cluster\'s '
                         'workers run the trials)')
    return sweep


def _local_cores() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


OnResult = Callable[[TrialSpec, 'TrialResult | None', 'BaseException | None'], None]


class StopRequest:
    """Signal handler of the in-process run: the first SIGINT or SIGTERM lets the running
    trial finish (its row is kept) and then stops; a second one stops at once."""

    def __init__(self) -> None:
        self.requested = False

    def __call__(self, signum: int, frame: object) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.requested = True
        sys.stderr.write(f'{PROG}: stopping after the running trial (again: at once)\n')


def run_in_process(pending: Sequence[TrialSpec], sweep: SweepSpec, config: Any,
                   on_result: OnResult, stop: StopRequest | None = None) -> None:
    """Run the trials one after the other in this process; raise ``KeyboardInterrupt``
    between two trials once ``stop`` is requested."""
    for spec in pending:
        if stop is not None and stop.requested:
            raise KeyboardInterrupt
        try:
            result = run_trial(spec, sweep, config)
        except Exception as exc:  # noqa: BLE001 - reported, the sweep goes on
            on_result(spec, None, exc)
        else:
            on_result(spec, result, None)


def run_on_dask(client: Any, pending: Sequence[TrialSpec], sweep: SweepSpec, config: Any,
                on_result: OnResult) -> None:
    """Run the trials as Dask tasks on ``client``'s cluster, reporting each as it finishes.

    A task is :func:`run_trial` of one trial, with the configuration in its arguments (not
    scattered: a worker that leaves takes no data with it, the scheduler gives its tasks to
    the others). On an interruption the remaining tasks are cancelled.
    """
    from distributed import as_completed  # noqa: PLC0415 - only when Dask runs the sweep

    futures = client.map(run_trial, list(pending), sweep=sweep, config=config, pure=False)
    by_key = {f.key: s for f, s in zip(futures, pending, strict=True)}
    try:
        for future in as_completed(futures):
            spec = by_key[future.key]
            if future.status == 'error':
                on_result(spec, None, future.exception())
            else:
                on_result(spec, future.result(), None)
            future.release()
    finally:
        client.cancel(futures)


def _run_stoppable(pending: Sequence[TrialSpec], sweep: SweepSpec, config: Any,
                   on_result: OnResult) -> None:
    """:func:`run_in_process` with :class:`StopRequest` on SIGINT and SIGTERM."""
    stop = StopRequest()
    previous = {sig: signal.signal(sig, stop) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        run_in_process(pending, sweep, config, on_result, stop)
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def main(argv: Sequence[str] | None = None) -> int:
    """``sweep``: run the sweep; see the module docstring for the exit status."""
    from dam_experiments.entry_points import InterruptOnSignals  # noqa: PLC0415

    args = _parse(sys.argv[1:] if argv is None else argv)
    with InterruptOnSignals():  # SIGTERM as SIGINT, from the start; a background job's too
        try:
            prepared = _prepare(args)
        except KeyboardInterrupt:  # loading, the analyses, the scheduler, the table's lock
            return _fail('interrupted before any trial ran', 130)
        if isinstance(prepared, int):
            return prepared
        config, sweep, table, done, client = prepared
        try:
            return _run(args, sweep, config, table, done, client)
        finally:
            table.release()
            if client is not None:
                client.close()


def _fail(message: str, status: int = 2) -> int:
    sys.stderr.write(f'{PROG}: {message}\n')
    return status


def _prepare(args: argparse.Namespace) -> int | tuple[Any, SweepSpec, TrialTable, int, Any]:
    """The configuration, the sweep, its table (opened and locked), the trials already done
    and the Dask client of ``--scheduler`` (or ``None``); an exit status when refused."""
    from dam_common.config import load_config  # noqa: PLC0415
    from dam_common.errors import DamCommonError  # noqa: PLC0415

    try:
        config = load_config(args.config)
        sweep = build_sweep(args, config)
    except (SweepError, DamCommonError, OSError) as exc:
        return _fail(str(exc))
    # An object the loader takes but the analysis cannot (a finger that never reaches it)
    # fails every trial the same way: refused before anything runs, naming the object.
    from dam_analysis.errors import DamAnalysisError  # noqa: PLC0415 - slow import

    for name in sweep.objects:
        try:
            analyzer_for(config.with_object(name))
        except DamAnalysisError as exc:
            return _fail(f'object {name!r} cannot be analysed with this hand, so no trial can '
                         f'run: {exc}')
    client = None
    if args.scheduler:  # before any file is written: a wrong address leaves nothing behind
        try:
            client = _connect(args.scheduler)
        except SweepError as exc:
            return _fail(str(exc), 1)
    try:
        from dam_common.version import software_version  # noqa: PLC0415

        table = TrialTable(args.out, sweep, config,
                           info={'software_version': software_version(),
                                 'axes_as_given': {
                                     'objects': args.objects,
                                     'friction_angles': args.friction_angles,
                                     'k_theta': args.k_theta,
                                     'delta_theta_p': args.delta_theta_p}})
        done = table.open()
    except SweepLocked as exc:  # not a bad argument: the same command works later
        if client is not None:
            client.close()
        return _fail(str(exc), 1)
    except (SweepError, DamCommonError, OSError) as exc:
        if client is not None:
            client.close()
        return _fail(str(exc))
    except BaseException:
        if client is not None:
            client.close()
        raise
    return config, sweep, table, done, client


def _run(args: argparse.Namespace, sweep: SweepSpec, config: Any, table: TrialTable,
         done: int, client: Any = None) -> int:
    from tqdm import tqdm  # noqa: PLC0415

    pending = table.pending()
    n = len(table.specs)
    workers = args.workers if args.workers is not None else _local_cores()
    where = (f'the Dask cluster at {args.scheduler}' if args.scheduler else
             'this process' if workers == 1 else f'{workers} local worker processes')
    objects = (f'{len(sweep.objects)} objects x ' if len(sweep.objects) > 1 else
               f'object {sweep.objects[0]}, ' if sweep.objects else '')
    print(f'{PROG}: {counted(n, "trial")} ({objects}'
          f'{counted(len(sweep.friction_angles_deg), "friction angle")} x '
          f'{len(sweep.k_theta)} k_theta x {len(sweep.delta_theta_p_deg)} delta_theta_p x '
          f'{counted(sweep.repeats, "repeat")}) into {args.out}', flush=True)
    if done or table.dropped:
        print(f'{PROG}: resuming: {done} done, {len(pending)} to run'
              + (f' ({counted(table.dropped, "incomplete, malformed or repeated row")} dropped)'
                 if table.dropped else ''),
              flush=True)
    if sweep.repeats > 1 and not sweep.perturbations.any:
        print(f'{PROG}: note: --repeats {sweep.repeats} without perturbations repeats the '
              f'same trial (the simulation is deterministic)', flush=True)
    failures: list[tuple[TrialSpec, BaseException]] = []
    costs: list[tuple[float, float]] = []
    tty = sys.stderr.isatty()
    bar = tqdm(total=n, initial=done, unit='trial', desc=PROG, disable=args.quiet,
               file=sys.stderr, dynamic_ncols=tty, mininterval=0.5 if tty else 10.0,
               smoothing=0.05)
    lifted = sum(int(r['lifted']) for r in table.rows.values())

    def on_result(spec: TrialSpec, result: TrialResult | None,
                  error: BaseException | None) -> None:
        nonlocal lifted
        if result is None:
            failures.append((spec, error or RuntimeError('no result')))
            bar.write(f'{PROG}: trial {spec.index} (alpha {spec.friction_angle_deg:g} deg, '
                      f'k_theta {spec.k_theta:g}, delta_theta_p {spec.delta_theta_p_deg:g} '
                      f'deg, repeat {spec.repeat}) failed: {error!r}', file=sys.stderr)
            return
        table.append(result.row)
        costs.append((result.wall_time_s, result.cpu_time_s))
        lifted += int(result.row['lifted'])
        bar.update(1)
        bar.set_postfix_str(f'lifted {lifted}/{len(table.rows)}', refresh=False)

    wall0 = time.monotonic()
    try:
        if pending:
            print(f'{PROG}: running {counted(len(pending), "trial")} on {where}', flush=True)
            if client is not None:
                try:
                    run_on_dask(client, pending, sweep, config, on_result)
                except (KeyboardInterrupt, SystemExit):
                    raise
                except Exception as exc:  # noqa: BLE001 - the cluster failed, not a trial
                    bar.close()
                    table.close()
                    sys.stderr.write(
                        f'{PROG}: the Dask cluster at {args.scheduler} failed: '
                        f'{type(exc).__name__}: {exc}; {len(table.rows)} of '
                        f'{counted(n, "trial")} are '
                        f'kept in {args.out / TABLE_FILE}, run the same command again to '
                        f'finish the rest\n')
                    return 1
            elif workers == 1:
                _run_stoppable(pending, sweep, config, on_result)
            else:
                _run_local_cluster(workers, pending, sweep, config, on_result,
                                   dashboard=args.dashboard)
    except KeyboardInterrupt:
        bar.close()
        table.close()
        print(f'{PROG}: interrupted: {len(table.rows)} of {counted(n, "trial")} done, kept in '
              f'{args.out / TABLE_FILE}; run the same command again to finish the rest',
              flush=True)
        return 130
    bar.close()
    table.finalize()
    elapsed = time.monotonic() - wall0
    if costs:
        wall = sum(c[0] for c in costs) / len(costs)
        cpu = sum(c[1] for c in costs) / len(costs)
        print(f'{PROG}: {counted(len(costs), "trial")} in {elapsed:.1f} s; per trial '
              f'{wall:.2f} s wall, '
              f'{cpu:.2f} s CPU (mean)', flush=True)
    outcomes = [(r['outcome'], r['lifted'] == '1') for r in table.rows.values()]
    held = sum(int(r['off_table_at_end']) for r in table.rows.values())
    print(f'{PROG}: {len(table.rows)} of {counted(n, "row")} in {args.out / TABLE_FILE}: lifted '
          f'(left the table) {lifted}, off the table at the end {held}, '
          + outcome_counts(outcomes), flush=True)
    if failures:
        spec, error = failures[0]
        sys.stderr.write(f'{PROG}: {counted(len(failures), "trial")} '
                         f'failed (first: trial {spec.index}: '
                         f'{error!r}); their rows are missing, a rerun retries them\n')
        return 1
    print(f'{PROG}: wrote {args.out / TABLE_FILE}, {args.out / CELLS_FILE} and '
          f'{args.out / PARAMS_FILE}', flush=True)
    return 0


def local_cluster_options(dashboard: str | None) -> dict[str, Any]:
    """The ``LocalCluster`` options for the dashboard: at ``dashboard`` when asked for, else
    none. Dask's scheduler serves HTTP even without its dashboard, at port 8787 by default
    (a second sweep said ``Port 8787 is already in use``): without one it is given a free
    port of the loopback interface."""
    if dashboard is not None:
        return {'dashboard_address': dashboard}
    return {'dashboard_address': None,
            'scheduler_kwargs': {'dashboard': False, 'dashboard_address': '127.0.0.1:0'}}


def _run_local_cluster(workers: int, pending: Sequence[TrialSpec], sweep: SweepSpec,
                       config: Any, on_result: OnResult, dashboard: str | None = None) -> None:
    from distributed import Client, LocalCluster  # noqa: PLC0415 - slow import

    # The worker processes inherit an ignored SIGINT: Ctrl-C in a terminal reaches the whole
    # process group, and only this process is to handle it (it closes the cluster).
    # Their logs are silenced below CRITICAL: a worker whose scheduler closes first on Ctrl-C
    # logs a heartbeat failure with a traceback (a CI run caught one); a trial's error comes
    # back through its future and is reported by this process.
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                               silence_logs=logging.CRITICAL,
                               **local_cluster_options(dashboard))
    finally:
        signal.signal(signal.SIGINT, previous)
    with cluster, Client(cluster) as client:
        if dashboard is not None:
            print(f'{PROG}: Dask dashboard at {client.dashboard_link}', flush=True)
        run_on_dask(client, pending, sweep, config, on_result)


def _probe_scheduler(address: str, timeout_s: float) -> None:
    """Ask whatever listens at ``address`` who it is (Dask's ``identity`` operation), within
    ``timeout_s`` [s] in all: ``distributed.Client`` waits without end for a peer that
    accepts the connection and never answers its handshake.

    Raises
    ------
    SweepError
        No answer in time, a broken connection, or an answer that is not a scheduler's (a
        worker's address, for example), named in the message.
    """
    import asyncio  # noqa: PLC0415

    from distributed.comm import connect  # noqa: PLC0415 - slow import

    async def identity() -> Any:
        comm = await connect(address, timeout=timeout_s)
        try:
            await comm.write({'op': 'identity', 'reply': True})
            return await comm.read()
        finally:
            comm.abort()

    async def bounded() -> Any:
        return await asyncio.wait_for(identity(), timeout_s)

    try:
        answer = asyncio.run(bounded())
    except TimeoutError:
        raise SweepError(f'cannot reach the Dask scheduler at {address!r}: no answer within '
                         f'{timeout_s:g} s (is it a Dask scheduler?)') from None
    except Exception as exc:  # noqa: BLE001 - whatever answers there is no Dask scheduler
        raise SweepError(f'cannot reach the Dask scheduler at {address!r}: '
                         f'{type(exc).__name__}: {exc}') from None
    kind = answer.get('type') if isinstance(answer, dict) else None
    if kind != 'Scheduler':
        raise SweepError(f'cannot reach the Dask scheduler at {address!r}: it answers as '
                         f'{kind or type(answer).__name__!r}, not as a Dask scheduler')


def _connect(address: str) -> Any:
    """A Dask client of the scheduler at ``address`` with at least one worker.

    Raises
    ------
    SweepError
        The scheduler does not answer within :data:`CONNECT_TIMEOUT_S` (:func:`_probe_scheduler`
        first), or has no worker within :data:`WORKER_WAIT_S`.
    """
    from distributed import Client  # noqa: PLC0415 - slow import

    _probe_scheduler(address, CONNECT_TIMEOUT_S)
    try:
        client = Client(address, timeout=f'{CONNECT_TIMEOUT_S:g}s')
    except Exception as exc:  # noqa: BLE001 - whatever answers there is no Dask scheduler
        raise SweepError(f'cannot reach the Dask scheduler at {address!r}: '
                         f'{type(exc).__name__}: {exc}') from None
    try:
        client.wait_for_workers(1, timeout=WORKER_WAIT_S)
    except TimeoutError:
        client.close()
        raise SweepError(f'the Dask scheduler at {address!r} has no worker after '
                         f'{WORKER_WAIT_S:g} s') from None
    except BaseException:
        client.close()
        raise
    return client


if __name__ == '__main__':
    sys.exit(main())
