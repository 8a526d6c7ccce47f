"""Facade of the lift analysis: input validation and :class:`LiftAnalyzer`.

Input conventions (those of the ``/check_lift`` service):

* ``k_theta`` [N m/rad]: one value per finger, or one value for finger 1, the others then
  follow the configured stiffness ratios (``k_theta_i = k_theta * r_i / r_1``);
* ``delta_theta_p`` [rad]: one value per finger or one for all, in
  ``[0, task.delta_theta_p_max]``;
* ``friction_angle`` [rad]: ``0 <= alpha < pi/2``; a negative value means "the configured one".

The ``check_*`` functions return clean float64 values or raise
:class:`~dam_analysis.errors.InputError` naming the field and the value.
``LiftAnalyzer.check_lift`` raises :class:`~dam_analysis.errors.NoSolutionError` when the SPCM
has no valid posture for the request (contact lost, table, joint limit, end of the branch).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dam_analysis.config import DamConfig, load_config
from dam_analysis.errors import InputError
from dam_analysis.lift import STATUS_BOUNDED, worst_case_vertical_force
from dam_analysis.model import HandModel, build_hand_model
from dam_analysis.regions import (
    Boundaries,
    LiftMap,
    PathTable,
    csm_evaluate,
    finger_table,
    lift_map,
    region_boundaries,
)
from dam_analysis.spcm import PATH_STEP_RAD, FingerContact, build_paths, plane_contact

ArrayLike = float | Sequence[float] | np.ndarray


def _as_vector(field: str, value: ArrayLike) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f'{field}: not a number or list of numbers: {value!r}') from exc
    arr = np.atleast_1d(arr)
    if arr.ndim != 1:
        raise InputError(f'{field}: expected a scalar or a flat list, got shape {arr.shape}')
    if arr.size == 0:
        raise InputError(f'{field}: empty list')
    bad = ~np.isfinite(arr)
    if np.any(bad):
        raise InputError(f'{field}: non-finite value {float(arr[bad][0])!r} in {arr.tolist()!r}')
    return arr


def check_k_theta(k_theta: ArrayLike, stiffness_ratios: np.ndarray) -> np.ndarray:
    """Validate compliant-joint stiffnesses; returns (n,) k_theta_i [N m/rad].

    One value is finger 1's stiffness; the others follow ``stiffness_ratios``.
    """
    ratios = np.asarray(stiffness_ratios, dtype=np.float64)
    arr = _as_vector('k_theta', k_theta)
    if arr.size == 1:
        arr = arr[0] * ratios / ratios[0]
    elif arr.size != ratios.size:
        raise InputError(f'k_theta: expected 1 or {ratios.size} values, got {arr.size}: '
                         f'{arr.tolist()!r}')
    if np.any(arr <= 0.0):
        raise InputError(f'k_theta: stiffness must be positive, got {arr.tolist()!r}')
    return arr


def check_delta_theta_p(delta_theta_p: ArrayLike, n_fingers: int,
                        delta_theta_p_max: float) -> np.ndarray:
    """Validate position-joint displacements; returns (n,) [rad] in ``[0, max]``."""
    arr = _as_vector('delta_theta_p', delta_theta_p)
    if arr.size == 1:
        arr = np.full(n_fingers, arr[0])
    elif arr.size != n_fingers:
        raise InputError(f'delta_theta_p: expected 1 or {n_fingers} values, got {arr.size}: '
                         f'{arr.tolist()!r}')
    if np.any(arr < 0.0):
        raise InputError(f'delta_theta_p: must be >= 0, got {arr.tolist()!r} rad')
    if np.any(arr > delta_theta_p_max + 1e-12):
        raise InputError(f'delta_theta_p: {arr.tolist()!r} rad exceeds delta_theta_p_max = '
                         f'{delta_theta_p_max!r} rad ({math.degrees(delta_theta_p_max):.6g} '
                         'deg)')
    return arr


def check_friction_angle(friction_angle: float, configured: float) -> float:
    """Validate alpha [rad]; negative selects ``configured``. Must be below pi/2."""
    arr = _as_vector('friction_angle', friction_angle)
    if arr.size != 1:
        raise InputError(f'friction_angle: expected one value, got {arr.tolist()!r}')
    alpha = float(arr[0])
    if alpha < 0.0:
        return configured
    if alpha >= 0.5 * math.pi:
        raise InputError(f'friction_angle: {alpha!r} rad ({math.degrees(alpha):.6g} deg) must '
                         'be below 90 deg')
    return alpha


@dataclass(frozen=True)
class LiftResult:
    """Answer of :meth:`LiftAnalyzer.check_lift`.

    Attributes
    ----------
    lift_guaranteed : eq. (18) holds for every admissible contact force.
    worst_case_margin : ``min c_z^T f_o - m_B g`` [N]; -inf when the worst case is unbounded,
        +inf when no admissible force exists (then lift_guaranteed is False).
    sufficient_status : (n,) per-finger ``'bounded' | 'unbounded' | 'infeasible'``.
    csm_lift : the contact stiffness model lifts the object (margin > 0, no separation).
    csm_margin : ``c_z^T f_o - m_B g`` with the CSM forces [N] (NaN on separation).
    csm_separation : (n,) bool, the CSM normal force would be negative.
    csm_forces : (n, 3) CSM force of each finger on the object [N].
    delta_theta_s : (n,) compliant displacement [rad].
    compliant_torque : (n,) tau_s = -K_theta delta_theta_s [N m].
    contact_points : (n, 3) [m]; normals : (n, 3) outward object normals n_CB.
    on_fingertip : (n,) bool.
    k_theta : (n,) [N m/rad]; delta_theta_p : (n,) [rad]; friction_angle [rad].
    """

    lift_guaranteed: bool
    worst_case_margin: float
    sufficient_status: tuple[str, ...]
    csm_lift: bool
    csm_margin: float
    csm_separation: np.ndarray
    csm_forces: np.ndarray
    delta_theta_s: np.ndarray
    compliant_torque: np.ndarray
    contact_points: np.ndarray
    normals: np.ndarray
    on_fingertip: np.ndarray
    k_theta: np.ndarray
    delta_theta_p: np.ndarray
    friction_angle: float


class LiftAnalyzer:
    """Lift analysis of the configured hand and object (sections 3.1-3.3 of the paper).

    Building it solves the first contact and caches the SPCM branch of every finger (a few
    tenths of a second); :meth:`check_lift` then costs a few Newton steps and closed forms.

    Parameters
    ----------
    config : validated configuration (``load_config()`` if None).
    path_step : grid step of the cached SPCM branch [rad].
    """

    def __init__(self, config: DamConfig | None = None,
                 path_step: float = PATH_STEP_RAD) -> None:
        self.config = config if config is not None else load_config()
        self.model: HandModel = build_hand_model(self.config)
        self.table = PathTable(self.model, build_paths(self.model, path_step))
        self._phi = 2.0 * np.pi * np.arange(self.model.cone_faces) / self.model.cone_faces
        self._cos_phi = np.cos(self._phi)  # the axial parts add no torque, no lift
        self._cache: dict[float, list] = {}

    @property
    def n_fingers(self) -> int:
        return self.model.n_fingers

    def validate(self, k_theta: ArrayLike, delta_theta_p: ArrayLike,
                 friction_angle: float = -1.0) -> tuple[np.ndarray, np.ndarray, float]:
        """Apply the ``check_*`` functions with this configuration."""
        return (check_k_theta(k_theta, self.model.stiffness_ratios),
                check_delta_theta_p(delta_theta_p, self.n_fingers,
                                    self.model.delta_theta_p_max),
                check_friction_angle(friction_angle, self.model.friction_angle))

    def spcm(self, delta_theta_p: ArrayLike) -> tuple[FingerContact, ...]:
        """SPCM states (eqs. 1-4) of all fingers; raises NoSolutionError."""
        dp = check_delta_theta_p(delta_theta_p, self.n_fingers, self.model.delta_theta_p_max)
        return tuple(p.solve(float(d)) for p, d in zip(self.table.paths, dp, strict=True))

    def check_lift(self, k_theta: ArrayLike, delta_theta_p: ArrayLike,
                   friction_angle: float = -1.0) -> LiftResult:
        """Sufficient condition (eq. 18) and CSM verdict for one request.

        Parameters
        ----------
        k_theta : (n,) or scalar [N m/rad]; delta_theta_p : (n,) or scalar [rad];
        friction_angle : alpha [rad], negative for the configured value.

        Raises
        ------
        InputError
            Malformed input (see the ``check_*`` functions).
        NoSolutionError
            No valid SPCM posture for this ``delta_theta_p``.
        """
        k, dp, alpha = self.validate(k_theta, delta_theta_p, friction_angle)
        model = self.model
        n = self.n_fingers
        mu = math.tan(alpha)
        k_t = float(model.contact_stiffness[1])
        plane = np.empty((n, 4))  # p_u, p_z, n_u, n_z
        tip = np.zeros(n, dtype=bool)
        delta_theta_s = np.empty(n)
        for i, path in enumerate(self.table.paths):
            theta_s = path.solve_theta_s(float(dp[i]))
            p_u, p_z, n_u, n_z, tip[i] = plane_contact(
                model.fingers[i], theta_s, model.theta_l0, model.theta_p0 + float(dp[i]))
            plane[i] = (p_u, p_z, n_u, n_z)
            delta_theta_s[i] = theta_s - path.theta_s0
        tau_s = -k * delta_theta_s  # tau_s = -K_theta delta_theta_s
        p_u, p_z, n_u, n_z = plane.T
        # plane forms of J^T n_in, J^T t and the vertical components (module regions/docs)
        h_n = p_z * n_u - p_u * n_z
        h_t = p_z * n_z + p_u * n_u
        cz_n, cz_t = -n_z, n_u
        ca, sa = math.cos(alpha), math.sin(alpha)
        h = ca * h_n[:, None] + sa * h_t[:, None] * self._cos_phi
        c = ca * cz_n[:, None] + sa * cz_t[:, None] * self._cos_phi
        worst = worst_case_vertical_force(h, c, tau_s)
        margin = worst.total - model.object_weight
        guaranteed = bool(np.all(worst.status == STATUS_BOUNDED) and margin > 0.0)
        # CSM (module csm): closed-form play operator with the cached slip history
        f_n = np.empty(n)
        f_t = np.empty(n)
        cache = self._csm_cache(alpha)
        for i in range(n):
            entry = cache[i]
            if entry is None:
                f_n[i], f_t[i] = self._csm_fallback(i, dp[i], k[i], alpha)
                continue
            grid, gamma, s_grid, sign = entry
            cnt = bisect.bisect_left(grid, float(dp[i]))
            prev = float(np.min(k[i] * gamma[:cnt] - s_grid[:cnt])) if cnt else math.inf
            s_end = float(np.interp(dp[i], grid, s_grid))
            denom = float(h_n[i] + sign * mu * h_t[i])
            tau = float(tau_s[i])
            cap = mu * tau / (k_t * denom) if denom > 0.0 else math.inf
            delta = s_end + min(prev, cap - s_end)
            if denom > 0.0 and delta >= cap * (1.0 - 1e-12):
                f_n[i] = tau / denom
                f_t[i] = sign * mu * f_n[i]
            else:
                f_t[i] = k_t * delta * sign
                f_n[i] = (tau - h_t[i] * f_t[i]) / h_n[i]
        sep = f_n < 0.0
        fz = f_n * cz_n + f_t * cz_t
        csm_margin = math.nan if np.any(sep) else float(fz.sum()) - model.object_weight
        inward = np.array([g.inward_direction for g in model.fingers])
        ez = np.array([0.0, 0.0, 1.0])
        base = np.array([g.base_position for g in model.fingers])
        points = base + p_u[:, None] * inward + p_z[:, None] * ez
        normals = n_u[:, None] * inward + n_z[:, None] * ez
        tangents = -n_z[:, None] * inward + n_u[:, None] * ez
        forces = -f_n[:, None] * normals + f_t[:, None] * tangents
        return LiftResult(
            lift_guaranteed=guaranteed, worst_case_margin=float(margin),
            sufficient_status=tuple(str(s) for s in worst.status),
            csm_lift=bool(not np.any(sep) and csm_margin > 0.0), csm_margin=float(csm_margin),
            csm_separation=sep, csm_forces=forces, delta_theta_s=delta_theta_s,
            compliant_torque=tau_s, contact_points=points, normals=normals,
            on_fingertip=tip, k_theta=k, delta_theta_p=dp, friction_angle=alpha)

    def _csm_cache(self, alpha: float) -> list[tuple[np.ndarray, np.ndarray, np.ndarray,
                                                     float] | None]:
        """Per finger: grid, gamma = mu tau_hat / (k_t (h_n + s mu h_t)), s * slip, s."""
        hit = self._cache.get(alpha)
        if hit is not None:
            return hit
        mu = math.tan(alpha)
        k_t = float(self.model.contact_stiffness[1])
        out: list[tuple[np.ndarray, np.ndarray, np.ndarray, float] | None] = []
        for i in range(self.n_fingers):
            path = self.table.csm_path(i)
            if not path.monotone:
                out.append(None)
                continue
            sign = path.slip_sign
            valid = np.isfinite(path.tau_hat)
            denom = path.h_n[valid] + sign * mu * path.h_t[valid]
            with np.errstate(divide='ignore', invalid='ignore'):
                gamma = np.where(denom > 0.0, mu * path.tau_hat[valid] / (k_t * denom), np.inf)
            out.append((path.delta_theta_p[valid], gamma, sign * path.slip[valid], sign))
        if len(self._cache) > 64:
            self._cache.clear()
        self._cache[alpha] = out
        return out

    def _csm_fallback(self, i: int, dp: float, k_i: float, alpha: float) -> tuple[float, float]:
        contact = self.table.paths[i].solve(dp)
        end = finger_table(self.model, i, [contact], np.array([dp]))
        ev = csm_evaluate(self.table, i, end, np.array([k_i]), alpha)
        return float(ev.f_n[0, 0]), float(ev.f_t[0, 0])

    def lift_map(self, friction_angles: ArrayLike, delta_theta_p: ArrayLike,
                 k_theta: ArrayLike) -> LiftMap:
        """Margins on an (alpha, delta_theta_p, k_theta of finger 1) grid (see regions)."""
        return lift_map(self.table, np.asarray(friction_angles, dtype=np.float64),
                        np.asarray(delta_theta_p, dtype=np.float64),
                        np.asarray(k_theta, dtype=np.float64))

    def boundaries(self, friction_angle: float, delta_theta_p: ArrayLike) -> Boundaries:
        """Lower boundaries k_theta*(delta_theta_p) of both regions for one friction angle."""
        return region_boundaries(self.table, friction_angle,
                                 np.asarray(delta_theta_p, dtype=np.float64))
