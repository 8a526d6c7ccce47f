"""The CSM calibration's measured targets (issue #21), with the time a fit takes.

1. **Recovery on synthetic outcomes.** Outcomes drawn 100 times from the CSM itself (probit
   link, lapse 0.02) with known values at two recorded friction angles (10 and 25 deg, 15
   ``k_theta`` x 6 ``delta_theta_p`` x 2 repeats each; ``k_t`` 300 N/m, ``sigma`` 0.2 N):
   the share of draws whose 90 % interval holds each true value. Target: at least 85 % for
   every parameter.
2. **The stand-in sweep** (``sweeps/fig7``, made by ``scripts/results.sh``; skipped when
   absent): the friction angle fitted with the analysis told nothing of it against the one
   the stand-in ran (target: within 2 deg), and the fitted CSM's agreement with the
   simulated outcome per friction angle (target: at least 90 %).

``fit_time_s`` is the median time of one fit on the precomputed margins (the synthetic case);
``cube_time_s`` the margins' evaluation on the parameter grid, once per data set.
"""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path
from typing import Any

import numpy as np

from dam_analysis.csm_calibration import draw_outcomes, fit_outcomes, margin_cube
from dam_analysis.csm_outcomes import CellMargins, GraspCells
from dam_analysis.model import build_hand_model
from dam_analysis.regions import PathTable
from dam_common.config import load_config

REPO_ROOT = Path(__file__).resolve().parents[1]
TRUE_ALPHA_DEG = (10.0, 25.0)
TRUE_LOG_KT = math.log10(300.0)
TRUE_SIGMA = 0.2
LAPSE = 0.02


def _synthetic(config: Any, draws: int) -> dict[str, Any]:
    table = PathTable(build_hand_model(config))
    k, dp = np.meshgrid(np.geomspace(0.2, 20.0, 15), [5.0, 10.0, 20.0, 30.0, 40.0, 55.0],
                        indexing='ij')
    parts = [(a, np.tile(k.ravel(), 2), np.tile(dp.ravel(), 2)) for a in TRUE_ALPHA_DEG]
    alpha = np.concatenate([np.full(p[1].size, math.radians(p[0])) for p in parts])
    cells = GraspCells(alpha, np.concatenate([p[1] for p in parts]),
                       np.radians(np.concatenate([p[2] for p in parts])),
                       np.full(alpha.size, config.object.mass_kg), np.zeros(alpha.size))
    margins = CellMargins(table, cells.k_theta, cells.delta_theta_p, cells.object_mass,
                          config.task.gravity_m_per_s2)
    started = time.monotonic()
    cube = margin_cube(cells, margins, alpha_half_width=math.radians(8.0), log_kt_step=0.25)
    cube_time = time.monotonic() - started
    truth = np.concatenate([
        margins.margins(math.radians(a), 10.0 ** TRUE_LOG_KT, 'path')[members]
        for a, members in zip(TRUE_ALPHA_DEG, cube.members, strict=True)])
    order = np.concatenate(cube.members)
    margin = np.empty(cells.size)
    margin[order] = truth
    rng = np.random.default_rng(2026)
    hits = {'alpha_10': 0, 'alpha_25': 0, 'log_kt': 0, 'sigma': 0}
    times = []
    for _ in range(draws):
        lifted = draw_outcomes(margin, TRUE_SIGMA, LAPSE, rng)
        started = time.monotonic()
        fit = fit_outcomes(cube, lifted, lapse=LAPSE)
        times.append(time.monotonic() - started)
        for key, iv, true in (('alpha_10', fit.friction_angle[0], math.radians(10.0)),
                              ('alpha_25', fit.friction_angle[1], math.radians(25.0)),
                              ('log_kt', fit.log10_tangential_stiffness, TRUE_LOG_KT),
                              ('sigma', fit.sigma, TRUE_SIGMA)):
            hits[key] += iv.contains(true)
    coverage = {f'coverage_{k}': v / draws for k, v in hits.items()}
    return {'synthetic_cells': cells.size, 'draws': draws, **coverage,
            'coverage_target': 0.85, 'cube_time_s': round(cube_time, 2),
            'fit_time_s': round(statistics.median(times), 3)}


def _stand_in(config: Any) -> dict[str, Any]:
    from dam_experiments.calibrate_csm import cells_of_sweep
    from dam_experiments.csm_calibration_run import calibrate
    from dam_experiments.sweep_results import one_object, read_sweep

    directory = REPO_ROOT / 'sweeps' / 'fig7'
    if not (directory / 'trials.csv').is_file():
        return {'stand_in': 'skipped: no sweeps/fig7 (bash scripts/results.sh makes it)'}
    cells, config = cells_of_sweep(one_object(read_sweep(directory), None), config)
    started = time.monotonic()
    result = calibrate(cells, config, folds=5)
    out: dict[str, Any] = {'stand_in_trials': cells.size,
                           'stand_in_time_s': round(time.monotonic() - started, 1)}
    ok = True
    for rec, iv, g in zip(result.fit.recorded_friction_angle, result.fit.friction_angle,
                          result.groups, strict=True):
        name = f'{math.degrees(rec):g}deg'
        error = math.degrees(iv.estimate - rec) if math.isfinite(iv.estimate) else math.nan
        out[f'alpha_{name}_fitted_deg'] = round(math.degrees(iv.estimate), 2)
        out[f'alpha_{name}_status'] = iv.status
        out[f'alpha_{name}_error_deg'] = round(error, 2)
        out[f'agreement_{name}'] = round(g.fitted / g.cells, 3)
        out[f'agreement_{name}_held_out'] = round(g.held_out / g.cells, 3)
        ok &= abs(error) <= 2.0 and g.fitted / g.cells >= 0.9
    out['log10_k_t'] = result.fit.log10_tangential_stiffness.estimate
    out['stand_in_targets_met'] = ok
    return out


def run(args: Any) -> dict[str, Any]:
    config = load_config(REPO_ROOT / 'config' / 'dam.yaml')
    report = _synthetic(config, draws=20 if args.quick else 100)
    coverage_ok = all(v >= 0.85 for k, v in report.items() if k.startswith('coverage_')
                      and k != 'coverage_target')
    report.update(_stand_in(config))
    report['target_met'] = bool(coverage_ok and report.get('stand_in_targets_met', True))
    return report
