"""The main job on a loaded machine: ``run.sh`` 20 times beside two CPU-burning processes.

1. The real-time factor of the stand-in on simulated time: one grasp of the configured pair
   on an idle machine (the baseline), one beside one CPU-burning process and one beside two,
   in the same run, each read from the driver's ``/diagnostics`` (``real_time_factor``, device
   time per wall time over its last second) while the grasp runs, with the grasp's wall time
   and the controller's result. Target: at least 0.95 idle and 0.8 beside one burner, every
   grasp SUCCESS.
2. ``bash scripts/run.sh`` (bring-up, ``/check_lift``, the grasp, the episode recorder, the
   picture, the tear-down) ``--runs`` times (20; 3 with ``--quick``) with two CPU-burning
   processes beside it: every outcome, every episode bag's completeness (the recorder's
   ``dam_episode.complete``), the wall time of each run. Target: every outcome SUCCESS and
   every episode complete.
"""

from __future__ import annotations

import math
import os
import re
import subprocess
import tempfile
import time
from pathlib import Path

import numpy as np
from grasp_testing import config_with_free_ports, grasp_stack

from ros_testing import cpu_burners

REPO_ROOT = Path(__file__).resolve().parents[1]
RUNS = 20
_RESULT = re.compile(r'^result: (\w+)', re.MULTILINE)
_BAG = re.compile(r'^\s+bag:\s+(\S+)', re.MULTILINE)
#: Lines of a failed run's output kept in the report.
FAILURE_LINES = 12


def _grasp_real_time_factor(config: Path, burners: int) -> dict[str, object]:
    """One grasp of the configured pair on simulated time; the driver's real-time factors."""
    from diagnostic_msgs.msg import DiagnosticArray

    factors: list[float] = []

    def take(msg: DiagnosticArray) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            value = float(values.get('real_time_factor', 'nan'))
            if math.isfinite(value):
                factors.append(value)

    with grasp_stack(config) as grasper:
        grasper.client.node.create_subscription(DiagnosticArray, '/diagnostics', take, 10)
        grasper.reset_world()
        with cpu_burners(burners):
            factors.clear()
            t0 = time.monotonic()
            result = grasper.result(grasper.send(10.0, math.radians(10.0)), 120.0).result
            wall = time.monotonic() - t0
    during = factors[1:] or factors  # the first may cover the time before the goal
    return {'outcome': result.outcome_name, 'grasp_wall_s': round(wall, 2),
            'real_time_factor_median': round(float(np.median(during)), 3) if during else None,
            'real_time_factor_min': round(float(np.min(during)), 3) if during else None}


def _run_sh(env: dict[str, str]) -> dict[str, object]:
    """One ``run.sh``: its outcome, its episode bag's completeness, its wall time."""
    t0 = time.monotonic()
    proc = subprocess.run(['bash', str(REPO_ROOT / 'scripts' / 'run.sh')], env=env,
                          capture_output=True, text=True, timeout=600, check=False)
    wall = time.monotonic() - t0
    out = proc.stdout + proc.stderr
    outcome = _RESULT.search(out)
    bag = _BAG.search(out)
    complete = ''
    if bag:
        complete = subprocess.run(
            ['python', str(REPO_ROOT / 'scripts' / 'lib' / 'episode_complete.py'),
             bag.group(1)], capture_output=True, text=True, check=False).stdout.strip()
    return {'exit': proc.returncode, 'outcome': outcome.group(1) if outcome else None,
            'episode_complete': complete or None, 'wall_s': round(wall, 1),
            'last_lines': [] if proc.returncode == 0 else out.splitlines()[-FAILURE_LINES:]}


def run(args) -> dict[str, object]:
    runs = 3 if args.quick else RUNS
    with tempfile.TemporaryDirectory(prefix='bench-run-') as tmp:
        config = config_with_free_ports(Path(tmp))
        os.environ['DAM_CONFIG'] = str(config)
        idle = _grasp_real_time_factor(config, 0)
        one_burner = _grasp_real_time_factor(config, 1)
        loaded = _grasp_real_time_factor(config, 2)
        env = dict(os.environ, DAM_RUN_DIR=str(Path(tmp) / 'run'),
                   DAM_BAG_DIR=str(Path(tmp) / 'bags'))
        results = []
        with cpu_burners(2):
            for i in range(runs):
                results.append(_run_sh(env))
                print(f'  run {i + 1}/{runs}: {results[-1]["outcome"]}, episode complete '
                      f'{results[-1]["episode_complete"]}, {results[-1]["wall_s"]} s',
                      flush=True)
    outcomes = [r['outcome'] for r in results]
    complete = [r['episode_complete'] for r in results]
    walls = [float(r['wall_s']) for r in results]
    factors_met = bool(
        (idle['real_time_factor_median'] or 0.0) >= 0.95
        and (one_burner['real_time_factor_median'] or 0.0) >= 0.8
        and all(g['outcome'] == 'SUCCESS' for g in (idle, one_burner, loaded)))
    runs_met = all(o == 'SUCCESS' for o in outcomes) and all(c == 'true' for c in complete)
    return {
        'idle_grasp': idle,
        'grasp_one_burner': one_burner,
        'loaded_grasp_two_burners': loaded,
        'real_time_factor_idle': idle['real_time_factor_median'],
        'real_time_factor_one_burner': one_burner['real_time_factor_median'],
        'real_time_factor_target': 'idle >= 0.95, one burner >= 0.8, every grasp SUCCESS',
        'real_time_factor_target_met': factors_met,
        'runs_beside_two_burners': runs,
        'outcomes': {o: outcomes.count(o) for o in sorted(set(map(str, outcomes)))},
        'episodes_complete': complete.count('true'),
        'run_wall_s_median': round(float(np.median(walls)), 1),
        'run_wall_s_max': round(float(np.max(walls)), 1),
        'failed_runs': [{'run': i + 1, 'exit': r['exit'], 'outcome': r['outcome'],
                         'last_lines': r['last_lines']}
                        for i, r in enumerate(results) if r['exit'] != 0][:3],
        'runs_target': 'every outcome SUCCESS and every episode complete',
        'runs_target_met': runs_met,
        'target_met': factors_met and runs_met,
    }
