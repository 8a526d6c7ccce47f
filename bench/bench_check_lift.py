"""/check_lift round trip against a trivial std_srvs/Trigger round trip, same run.

Target (issue): p50 within 1.5x of the Trigger p50; p99 under 5 ms. Both servers are separate
processes; one client calls them alternately so that both see the same machine load.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

from ros_testing import RosClient, installed_executable, node_process

BENCH_DIR = Path(__file__).resolve().parent


def _round_trip(client: RosClient, cli, request) -> float:
    start = time.perf_counter()
    future = cli.call_async(request)
    done = client.wait_future(future, 5.0)
    elapsed = time.perf_counter() - start
    if not done:
        raise RuntimeError('service call timed out')
    return elapsed


def run(args) -> dict:
    from std_srvs.srv import Trigger

    from dam_interfaces.srv import CheckLift

    n = 300 if args.quick else 3000
    rng = np.random.default_rng(7)
    with node_process([installed_executable('dam_analysis', 'check_lift_server')]), \
            node_process([sys.executable, str(BENCH_DIR / 'trigger_server.py'),
                          '/bench/trigger']):
        client = RosClient()
        try:
            check = client.node.create_client(CheckLift, '/check_lift')
            trigger = client.node.create_client(Trigger, '/bench/trigger')
            for cli in (check, trigger):
                if not cli.wait_for_service(timeout_sec=30.0):
                    raise RuntimeError(f'{cli.srv_name} did not appear')
            requests = []
            for _ in range(n):
                req = CheckLift.Request()
                req.k_theta = [float(rng.uniform(0.05, 2.0))]
                req.delta_theta_p = [float(rng.uniform(0.0, math.radians(65.0)))]
                req.friction_angle = float(rng.choice([-1.0, math.radians(1.0),
                                                       math.radians(5.0), math.radians(30.0)]))
                requests.append(req)
            for i in range(100):  # warm-up
                _round_trip(client, check, requests[i])
                _round_trip(client, trigger, Trigger.Request())
            t_check = np.empty(n)
            t_trigger = np.empty(n)
            for i in range(n):
                t_check[i] = _round_trip(client, check, requests[i])
                t_trigger[i] = _round_trip(client, trigger, Trigger.Request())
        finally:
            client.close()
    p50_c, p99_c = np.percentile(t_check, [50, 99]) * 1e3
    p50_t, p99_t = np.percentile(t_trigger, [50, 99]) * 1e3
    ratio = p50_c / p50_t
    return {
        'calls_each': n,
        'check_lift_p50_ms': round(p50_c, 4),
        'check_lift_p99_ms': round(p99_c, 4),
        'trigger_p50_ms': round(p50_t, 4),
        'trigger_p99_ms': round(p99_t, 4),
        'p50_ratio_check_lift_over_trigger': round(ratio, 3),
        'target': 'p50 ratio <= 1.5 and check_lift p99 < 5 ms',
        'target_met': bool(ratio <= 1.5 and p99_c < 5.0),
    }
