"""Full lift map (Fig. 5(b) grid) with the closed form against one linear program per point.

Grid: friction angles 1, 5, 30 deg x 200 delta_theta_p in [0, 65] deg x 200 k_theta (finger 1,
log-spaced 0.1-100 N m/rad). The fast path is ``LiftAnalyzer.lift_map`` (SPCM once per
displacement, closed-form worst case and CSM as array operations); the one-off
``LiftAnalyzer`` construction is timed separately and not part of ``map_time_s``.

Baseline: the sufficient condition (eq. 18) solved point by point as the LP

    min c_z^T sum_i f_ci   s.t.  J_i^T f_ci = tau_si,  f_ci in the L-faced cone of finger i,

(scipy.optimize.linprog, HiGHS) with the cone written by its faces, built here from the SPCM
contact geometry (``LiftAnalyzer.spcm``). All 120 000 LPs would take minutes, so a deterministic
random subset is solved (600 points, 150 with --quick), its per-point cost extrapolated to the
full grid, and its verdicts (lift or not) and margins compared with the fast map's.

Target: ``map_time_s < 1`` and ``speedup >= 20`` (speedup = extrapolated LP time of the full
grid / map time), with identical verdicts on the subset.
"""

from __future__ import annotations

import math
import time

import numpy as np
from scipy.optimize import linprog

from dam_analysis.analysis import LiftAnalyzer
from dam_analysis.errors import NoSolutionError
from dam_common.config import load_config

ALPHAS_DEG = (1.0, 5.0, 30.0)
N_DP = 200
N_K = 200
K_RANGE = (0.1, 100.0)  # N m/rad, finger 1


def cone_faces_h(normal_object: np.ndarray, axis: np.ndarray, alpha: float,
                 n_faces: int) -> np.ndarray:
    """Inward face normals (L, 3) of the L-faced friction cone: ``M f >= 0`` inside.

    Edges ``e_k = cos(alpha) n_in + sin(alpha) (cos(phi_k) t + sin(phi_k) b)`` with
    ``n_in = -n_CB``, ``b`` the joint axis, ``t = b x n_CB``; the face between edges k and k+1
    has the normal ``e_k x e_k+1``, flipped if needed to point to the cone's axis ``n_in``.
    """
    n_in = -normal_object
    t = np.cross(axis, normal_object)
    phi = 2.0 * math.pi * np.arange(n_faces) / n_faces
    edges = (math.cos(alpha) * n_in[None, :]
             + math.sin(alpha) * (np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * axis))
    faces = np.cross(edges, np.roll(edges, -1, axis=0))
    return faces * np.where(faces @ n_in < 0.0, -1.0, 1.0)[:, None]


def lp_margin(analyzer: LiftAnalyzer, alpha: float, delta_theta_p: float, k_theta: float
              ) -> float:
    """Worst-case margin ``min c_z^T f_o - m_B g`` [N] of eq. (18) by one LP.

    Parameters
    ----------
    alpha : friction angle [rad]; delta_theta_p : position-joint displacement [rad];
    k_theta : finger 1's compliant stiffness [N m/rad] (others by the configured ratios).

    Returns
    -------
    The margin; ``-inf`` if the LP is unbounded, NaN if it is infeasible or no SPCM posture
    exists. Lift is guaranteed iff the margin is > 0.
    """
    model = analyzer.model
    try:
        contacts = analyzer.spcm(delta_theta_p)
    except NoSolutionError:
        return math.nan  # no SPCM posture: no lift
    n = model.n_fingers
    ratios = np.asarray(model.stiffness_ratios, dtype=np.float64)
    c = np.zeros(3 * n)
    a_eq = np.zeros((n, 3 * n))
    b_eq = np.empty(n)
    a_ub = np.zeros((n * model.cone_faces, 3 * n))
    for i, (finger, contact) in enumerate(zip(model.fingers, contacts, strict=True)):
        sl = slice(3 * i, 3 * i + 3)
        c[3 * i + 2] = 1.0  # c_z^T f_ci
        a_eq[i, sl] = np.cross(finger.joint_axis, contact.contact_point - finger.base_position)
        b_eq[i] = -k_theta * ratios[i] / ratios[0] * contact.delta_theta_s  # tau_s
        faces = cone_faces_h(np.asarray(contact.normal_object), finger.joint_axis, alpha,
                             model.cone_faces)
        a_ub[i * model.cone_faces:(i + 1) * model.cone_faces, sl] = -faces
    res = linprog(c, A_ub=a_ub, b_ub=np.zeros(a_ub.shape[0]), A_eq=a_eq, b_eq=b_eq,
                  bounds=[(None, None)] * (3 * n), method='highs')
    if res.status == 0:
        return float(res.fun - model.object_weight)
    if res.status == 3:
        return -math.inf  # unbounded below: an internal force can pull the object down
    if res.status == 2:
        return math.nan
    raise RuntimeError(f'LP failed: {res.message}')


def run(args) -> dict:
    n_lp = 150 if args.quick else 600
    config = load_config()
    start = time.perf_counter()
    analyzer = LiftAnalyzer(config)
    construct_s = time.perf_counter() - start
    alphas = np.radians(ALPHAS_DEG)
    dps = np.radians(np.linspace(0.0, 65.0, N_DP))
    dps = np.minimum(dps, analyzer.model.delta_theta_p_max)
    ks = np.geomspace(*K_RANGE, N_K)

    analyzer.lift_map(alphas[:1], dps[:5], ks[:5])  # warm-up (imports, caches of small size)
    repeats = 3 if args.quick else 5
    times = []
    for _ in range(repeats):
        start = time.perf_counter()
        result = analyzer.lift_map(alphas, dps, ks)
        times.append(time.perf_counter() - start)
    map_time = float(np.median(times))
    fast = result.sufficient_lift

    rng = np.random.default_rng(20240501)
    flat = rng.choice(fast.size, size=n_lp, replace=False)
    idx = np.unravel_index(flat, fast.shape)
    margins = np.empty(n_lp)
    start = time.perf_counter()
    for j, (a, d, k) in enumerate(zip(*idx, strict=True)):
        margins[j] = lp_margin(analyzer, float(alphas[a]), float(dps[d]), float(ks[k]))
    lp_time = time.perf_counter() - start
    verdicts = np.nan_to_num(margins, nan=-1.0) > 0.0
    fast_margin = result.sufficient_margin[idx]
    bounded = np.isfinite(margins)
    # the same kind of answer (finite / -inf / NaN) and, where finite, the same value
    same_kind = np.array_equal(np.isnan(margins), np.isnan(fast_margin)) and np.array_equal(
        np.isneginf(margins), np.isneginf(fast_margin))
    margin_err = float(np.max(np.abs(margins[bounded] - fast_margin[bounded]), initial=0.0))
    per_point = lp_time / n_lp
    full_lp = per_point * fast.size
    agree = float(np.mean(verdicts == fast[idx]))
    speedup = full_lp / map_time
    return {
        'grid': f'{len(alphas)} x {N_DP} x {N_K}',
        'analyzer_construction_s': round(construct_s, 3),
        'map_time_s': round(map_time, 4),
        'map_time_runs_s': [round(t, 4) for t in times],
        'lp_points': n_lp,
        'lp_points_lifting': int(verdicts.sum()),
        'lp_time_per_point_ms': round(per_point * 1e3, 3),
        'lp_time_full_s_extrapolated': round(full_lp, 1),
        'speedup': round(speedup, 1),
        'agreement_fraction': agree,
        'lp_points_bounded': int(bounded.sum()),
        'lp_points_unbounded': int(np.isneginf(margins).sum()),
        'lp_points_no_spcm_or_infeasible': int(np.isnan(margins).sum()),
        'margin_kind_agrees': bool(same_kind),
        'max_abs_margin_difference_n': margin_err,
        'target': 'map_time_s < 1 and speedup >= 20; on the subset the same verdicts and '
                  'margins within 1e-6 N',
        'target_met': bool(map_time < 1.0 and speedup >= 20.0 and agree == 1.0 and same_kind
                           and margin_err < 1e-6),
    }
