"""Cost of one lockstep sweep trial, against the physics alone; the 480-trial grid on request.

1. Trial: :func:`~dam_experiments.sweep.run_trial` of the configured default cell (friction
   angle ``contact.friction_angle_deg``, ``task.k_theta_nm_per_rad``,
   ``task.delta_theta_p_deg``, the sweep's default options: a whole grasp, about 5 s
   simulated), as ``sweep`` runs it for each grid point: a fresh :class:`HandWorld` stepped in
   lockstep with the controller core (at the device rate, the device's physics substeps in
   between), then the analysis answer (the analysis itself is built before the clock starts,
   once per process as in a sweep worker). Several trials: median, minimum and maximum of the
   wall-clock and CPU times.
2. Baseline in the same run: a bare world of the same model (built the same way) stepping
   the same number of physics steps with no controller, no commands and no reads: what the
   physics alone costs (the ratio is reported).
3. Where the trial's time goes, in separate trials (the timers cost a little): the time
   inside ``stepSimulation`` during the grasp (the grasp's own physics: contacts and servos
   cost more than the bare world's), so that the report splits the trial into that physics and
   everything else (controller, slew, command checks, state reads: Python). Target: the
   trial's median wall time within 1.25x of its own grasp physics.
4. Grid, only with ``--grid`` (about 15 minutes on a slow day: run it on a quiet machine): the
   sweep command over 480 trials (2 friction angles x 12 ``delta_theta_p`` x 20 ``k_theta``)
   on two local workers, target under 5 minutes; the parallel efficiency
   ``wall(1) / (2 wall(2))``
   of a 96-trial part of it with ``--workers 1`` (in the command's process) and
   ``--workers 2`` (the default Dask LocalCluster, its start-up included), the two tables
   identical; and its ceiling in the same run: two processes stepping the bare physics at
   once against one alone. Target: the sweep's efficiency at least 85 % of that ceiling.
"""

from __future__ import annotations

import filecmp
import math
import multiprocessing
import os
import statistics
import subprocess
import tempfile
import time
from pathlib import Path

from ros_testing import installed_executable

#: The grid of the ``--grid`` measurement (480 trials).
GRID_ARGS = ('--friction-angles', '5deg', '30deg', '--k-theta', '0.05:20:20:log',
             '--delta-theta-p', '5deg:60deg:12')
GRID_TRIALS = 2 * 20 * 12
#: A part of it for the parallel efficiency, run with one and with two workers (96 trials).
EFFICIENCY_ARGS = ('--friction-angles', '5deg', '30deg', '--k-theta', '0.05:20:6:log',
                   '--delta-theta-p', '5deg:60deg:8')
EFFICIENCY_TRIALS = 2 * 6 * 8


def _spread(samples: list[float], unit: str, digits: int = 3) -> dict[str, float]:
    """Median, minimum and maximum of ``samples``, keys suffixed with ``unit``."""
    return {f'median_{unit}': round(statistics.median(samples), digits),
            f'min_{unit}': round(min(samples), digits),
            f'max_{unit}': round(max(samples), digits)}


def _default_trial():
    """The configuration, the one-cell sweep of the configured default pair and its trial."""
    from dam_common.config import load_config
    from dam_experiments.sweep import SweepSpec

    config = load_config()
    sweep = SweepSpec(friction_angles_deg=(math.degrees(config.contact.friction_angle_rad),),
                      k_theta=(float(config.task.k_theta_nm_per_rad),),
                      delta_theta_p_deg=(math.degrees(config.task.delta_theta_p_rad),))
    return config, sweep, sweep.trials()[0]


def _trials(n: int) -> dict:
    """Wall and CPU time [s] of ``n`` default trials, and the simulated time of one [s]."""
    from dam_experiments.sweep import analyzer_for, run_trial

    config, sweep, spec = _default_trial()
    analyzer_for(config)  # once per process, as in a sweep worker
    run_trial(spec, sweep, config)  # warm-up: imports, caches
    walls: list[float] = []
    cpus: list[float] = []
    rows: set[tuple[str, ...]] = set()
    for _ in range(n):
        result = run_trial(spec, sweep, config)
        walls.append(result.wall_time_s)
        cpus.append(result.cpu_time_s)
        rows.add(tuple(result.row.values()))
    if len(rows) != 1:
        raise RuntimeError('the same trial gave different rows')
    row = result.row
    return {'walls': walls, 'cpus': cpus, 'sim_time_s': float(row['sim_time_s']),
            'phase': row['phase'], 'outcome': row['outcome']}


def _physics_in_trials(n: int) -> list[float]:
    """Time [s] spent in ``stepSimulation`` during each of ``n`` default trials."""
    import dam_sim_bridge.world as world_module
    from dam_experiments.sweep import run_trial

    config, sweep, spec = _default_trial()
    spent = [0.0]
    untimed = world_module.HandWorld

    class TimedWorld(untimed):  # the stepSimulation calls of the trial, timed
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            step = self._step_simulation

            def timed_step() -> None:
                start = time.perf_counter()
                step()
                spent[0] += time.perf_counter() - start

            self._step_simulation = timed_step

    samples = []
    world_module.HandWorld = TimedWorld  # run_trial imports it from the module at each call
    try:
        for _ in range(n):
            spent[0] = 0.0
            run_trial(spec, sweep, config)
            samples.append(spent[0])
    finally:
        world_module.HandWorld = untimed
    return samples


def _bare_physics(sim_time_s: float, n: int) -> list[float]:
    """Wall time [s] of a fresh world (same model) stepping ``sim_time_s`` with no
    controller: construction and bare ``stepSimulation`` calls, ``n`` times."""
    from dam_common.config import load_config
    from dam_experiments.quiet_stdout import quiet_stdout
    from dam_sim_bridge.world import HandWorld

    config = load_config()
    walls = []
    for _ in range(n):
        start = time.monotonic()
        with quiet_stdout():
            world = HandWorld(config)
        with world:
            steps = round(sim_time_s / world.time_step_s)
            step = world.client.stepSimulation
            for _ in range(steps):
                step()
        walls.append(time.monotonic() - start)
    return walls


def _bare_physics_worker(sim_time_s: float, n: int, start, queue) -> None:
    """A process of the ceiling: import and build, wait for ``start``, then ``n`` bare runs."""
    _bare_physics(sim_time_s, 1)  # imports and caches before the clock
    start.wait()
    began = time.monotonic()
    _bare_physics(sim_time_s, n)
    queue.put(time.monotonic() - began)


def _bare_physics_in_processes(sim_time_s: float, n: int, processes: int) -> float:
    """Wall time [s] of ``processes`` processes each running ``n`` bare-physics runs at once
    (the longest of them; their start-up is not counted)."""
    context = multiprocessing.get_context('spawn')
    start = context.Barrier(processes)
    queue = context.Queue()
    workers = [context.Process(target=_bare_physics_worker, args=(sim_time_s, n, start, queue))
               for _ in range(processes)]
    for worker in workers:
        worker.start()
    walls = [queue.get(timeout=600.0) for _ in workers]
    for worker in workers:
        worker.join()
    return max(walls)


def _parallel_ceiling(sim_time_s: float, n: int = 12) -> dict[str, float]:
    """What two processes of bare physics reach together: ``wall(1 process) / wall(2 at
    once)``, each doing the same ``n`` runs (1.0: perfectly parallel)."""
    alone = _bare_physics_in_processes(sim_time_s, n, 1)
    together = _bare_physics_in_processes(sim_time_s, n, 2)
    return {'ceiling_bare_physics_runs': n, 'ceiling_one_process_wall_s': round(alone, 2),
            'ceiling_two_processes_wall_s': round(together, 2),
            'ceiling_parallel_efficiency': round(alone / together, 3)}


def _sweep_wall(args: tuple[str, ...], workers: int, out: Path) -> float:
    """Wall time [s] of the sweep command with ``args`` on ``workers`` local workers."""
    sweep = installed_executable('dam_experiments', 'sweep')
    start = time.monotonic()
    subprocess.run([str(sweep), *args, '--workers', str(workers), '--out', str(out),
                    '--quiet'], check=True, stdin=subprocess.DEVNULL, env=dict(os.environ))
    return time.monotonic() - start


def _grid(sim_time_s: float) -> dict:
    """The sweep command over :data:`GRID_ARGS` (480 trials) on two workers; the parallel
    efficiency from one to two workers on :data:`EFFICIENCY_ARGS`, whose two tables must be
    identical, and its ceiling (:func:`_parallel_ceiling`)."""
    report: dict[str, object] = {'grid_trials': GRID_TRIALS}
    with tempfile.TemporaryDirectory(prefix='dam-bench-grid-') as tmp:
        wall = _sweep_wall(GRID_ARGS, 2, Path(tmp) / 'grid')
        report['grid_workers2_wall_s'] = round(wall, 1)
        report['grid_workers2_trials_per_s'] = round(GRID_TRIALS / wall, 2)
        report['grid_under_300_s'] = wall < 300.0
        walls = {w: _sweep_wall(EFFICIENCY_ARGS, w, Path(tmp) / f'workers{w}') for w in (1, 2)}
        report['efficiency_trials'] = EFFICIENCY_TRIALS
        for w, t in walls.items():
            report[f'efficiency_workers{w}_wall_s'] = round(t, 1)
        report['efficiency_tables_identical'] = filecmp.cmp(
            Path(tmp) / 'workers1' / 'trials.csv', Path(tmp) / 'workers2' / 'trials.csv',
            shallow=False)
    efficiency = walls[1] / (2.0 * walls[2])
    report['parallel_efficiency_1_to_2_workers'] = round(efficiency, 3)
    report.update(_parallel_ceiling(sim_time_s))
    report['efficiency_over_ceiling'] = round(
        efficiency / float(report['ceiling_parallel_efficiency']), 3)
    return report


def run(args) -> dict:
    n = 3 if args.quick else 9
    trials = _trials(n)
    sim = trials['sim_time_s']
    bare = _bare_physics(sim, n)
    wall = statistics.median(trials['walls'])
    bare_wall = statistics.median(bare)
    speed = sim / wall
    report: dict[str, object] = {
        'trials': n,
        'trial_phase': trials['phase'],
        'trial_outcome': trials['outcome'],
        'trial_sim_time_s': sim,
        **{f'trial_wall_{k}': v for k, v in _spread(trials['walls'], 's').items()},
        **{f'trial_cpu_{k}': v for k, v in _spread(trials['cpus'], 's').items()},
        'lockstep_speed_factor': round(speed, 2),
        **{f'baseline_bare_physics_wall_{k}': v for k, v in _spread(bare, 's').items()},
        'baseline_bare_physics_speed_factor': round(sim / bare_wall, 2),
        'trial_over_bare_physics_wall_ratio': round(wall / bare_wall, 2),
    }
    physics = _physics_in_trials(max(3, n // 3))
    grasp_physics = statistics.median(physics)
    report.update({
        **{f'trial_grasp_physics_{k}': v for k, v in _spread(physics, 's').items()},
        'grasp_physics_over_bare_physics_ratio': round(grasp_physics / bare_wall, 2),
        'trial_rest_s': round(wall - grasp_physics, 3),
        'trial_over_grasp_physics_wall_ratio': round(wall / grasp_physics, 2),
    })
    grid = getattr(args, 'grid', False)
    if grid:
        report.update(_grid(sim))
    report['load_average_1_5_15_min'] = [round(v, 2) for v in os.getloadavg()]
    report['target'] = ('median wall time of one whole default trial <= 1.25x its own grasp '
                        'physics'
                        + ('; with --grid: 480 trials < 300 s on 2 workers, parallel '
                           'efficiency >= 85 % of the bare-physics ceiling' if grid else ''))
    met = wall <= 1.25 * grasp_physics
    if grid:
        met = (met and bool(report['grid_under_300_s'])
               and float(report['efficiency_over_ceiling']) >= 0.85)
    report['target_met'] = bool(met)
    return report
