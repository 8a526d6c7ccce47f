"""The robust planner's answer time (dam_analysis.planner, the core of /plan_lift).

Target (issue #12): well under a second for the default ranges. Measured in one run, in this
process (no DDS; the service adds a round trip of about a millisecond):

* the default request (configured friction angle and mass, no position tolerance);
* the issue's example ranges (alpha 3-6 deg, mass 30-50 g, position +-1 mm): the first answer,
  which builds the four extra position nodes' analyses, then warm answers;
* baseline in the same run: one ``LiftAnalyzer.check_lift`` (what /check_lift computes), so
  that a slow machine shows as a slow baseline too; the report gives the ratio.
"""

from __future__ import annotations

import math
import time

import numpy as np


def _median_s(fn, repeats: int) -> tuple[float, float]:
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return float(np.median(times)), float(np.max(times))


def run(args) -> dict:
    from dam_analysis.analysis import LiftAnalyzer
    from dam_analysis.planner import LiftPlanner, check_ranges
    from dam_common.config import load_config

    repeats = 3 if args.quick else 10
    config = load_config()
    analyzer = LiftAnalyzer(config)
    planner = LiftPlanner(config, analyzer)
    alpha = config.contact.friction_angle_rad
    dp_max = config.task.delta_theta_p_max_rad
    default = check_ranges(config, (alpha, alpha), (config.object.mass_kg,) * 2, 0.0,
                           planner.device_k_max, (0.0, dp_max), 0.01)
    example = check_ranges(config, (math.radians(3.0), math.radians(6.0)), (0.03, 0.05), 1e-3,
                           planner.device_k_max, (0.0, dp_max), 0.01)
    baseline, _ = _median_s(lambda: analyzer.check_lift(10.0, math.radians(10.0)), 2000)
    default_s, default_max = _median_s(lambda: planner.plan(default), repeats)
    start = time.perf_counter()
    plan = planner.plan(example)
    first_s = time.perf_counter() - start
    example_s, example_max = _median_s(lambda: planner.plan(example), repeats)
    return {
        'check_lift_core_ms': round(baseline * 1e3, 4),
        'plan_default_ms': round(default_s * 1e3, 1),
        'plan_default_max_ms': round(default_max * 1e3, 1),
        'plan_example_first_s': round(first_s, 2),
        'plan_example_ms': round(example_s * 1e3, 1),
        'plan_example_max_ms': round(example_max * 1e3, 1),
        'plan_example_over_check_lift': round(example_s / baseline),
        'example_answer': {'found': plan.found, 'k_theta': round(plan.k_theta, 4),
                           'delta_theta_p_deg': round(math.degrees(plan.delta_theta_p), 3)},
        'target': 'warm answer for the default ranges well under 1 s',
        'target_met': bool(default_s < 0.5 and example_s < 0.5),
    }
