"""Facade of the lift analysis: input validation and :class:`LiftAnalyzer`.

Input conventions (those of the ``/check_lift`` service):

* ``k_theta`` [N m/rad]: one value per finger, or one value for finger 1, the others then
  follow the configured stiffness ratios (``k_theta_i = k_theta * r_i / r_1``);
* ``delta_theta_p`` [rad]: one value per finger or one for all, in
  ``[0, task.delta_theta_p_max]``;
* ``friction_angle`` [rad]: ``0 <= alpha < pi/2``; a negative value means "the configured one".

The ``check_*`` functions return clean float64 values or raise
:class:`~dam_analysis.errors.InputError` naming the field and the value.
A well-formed request beyond the end of a finger's SPCM branch (a fold of the closure, contact
lost, table, joint limit: :mod:`dam_analysis.branch_end`) is not an error: ``check_lift``
answers "no lift" (``lift_guaranteed`` and ``csm_lift`` False, both margins NaN) and says in
``LiftResult.branch_message`` where and why the branch ends.
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence

import numpy as np

from dam_analysis.csm_path import CsmPathVerdict
from dam_analysis.errors import InputError, NoSolutionError
from dam_analysis.hand_limits import HandLimits, csm_penetration
from dam_analysis.lift import STATUS_BOUNDED, STATUS_NO_SPCM, worst_case_cone
from dam_analysis.lift_result import LiftResult
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
from dam_analysis.rolling import NOT_CHECKED, RollingCheck
from dam_analysis.spcm import PATH_STEP_RAD, FingerContact, build_paths
from dam_common.config import DamConfig, load_config
from dam_common.echo import brief_repr
from dam_common.quantities import ANGLE, both_units

ArrayLike = float | Sequence[float] | np.ndarray


def _as_vector(field: str, value: ArrayLike) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f'{field}: not a number or list of numbers: '
                         f'{brief_repr(value)}') from exc
    arr = np.atleast_1d(arr)
    if arr.ndim != 1:
        raise InputError(f'{field}: expected a scalar or a flat list, got shape {arr.shape}')
    if arr.size == 0:
        raise InputError(f'{field}: empty list')
    bad = ~np.isfinite(arr)
    if np.any(bad):
        raise InputError(f'{field}: non-finite value {float(arr[bad][0])!r} in '
                         f'{brief_repr(arr)}')
    return arr


def _plain_floats(value: ArrayLike) -> list[float] | None:
    """A number or a flat non-empty list/tuple of numbers as finite floats; None otherwise
    (then the numpy path of the ``check_*`` functions decides, with its messages)."""
    try:
        if type(value) is float:
            items = [value]
        elif isinstance(value, (list, tuple)) and value \
                and all(type(v) is float or type(v) is int for v in value):
            items = [float(v) for v in value]
        elif isinstance(value, (float, int)):
            items = [float(value)]
        else:
            return None
    except OverflowError:  # an int beyond the float range
        return None
    # a non-finite sum (inf, NaN or an overflow) sends the request down the numpy path
    return items if math.isfinite(sum(items)) else None


def _interp(x: float, xp: list[float], fp: list[float]) -> float:
    """``np.interp(x, xp, fp)`` for one x inside ``[xp[0], xp[-1]]``, same arithmetic."""
    j = bisect.bisect_right(xp, x) - 1
    if j >= len(xp) - 1:
        return fp[-1]
    if j < 0:
        return fp[0]
    if xp[j] == x:
        return fp[j]
    slope = (fp[j + 1] - fp[j]) / (xp[j + 1] - xp[j])
    return slope * (x - xp[j]) + fp[j]


def unreachable_object(config: DamConfig, error: NoSolutionError) -> str:
    """Why the configuration's object cannot be analysed: the fingers make no first contact
    with it (``error``, from building the :class:`LiftAnalyzer`), naming the object."""
    obj = config.object
    return (f'object {obj.name!r} ({obj.section.describe()}) cannot be analysed with this '
            f'hand: {error}')


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
                         f'{brief_repr(arr)}')
    if np.any(arr <= 0.0):
        raise InputError(f'k_theta: stiffness must be positive, got {brief_repr(arr)}')
    return arr


def check_delta_theta_p(delta_theta_p: ArrayLike, n_fingers: int,
                        delta_theta_p_max: float) -> np.ndarray:
    """Validate position-joint displacements; returns (n,) [rad] in ``[0, max]``."""
    arr = _as_vector('delta_theta_p', delta_theta_p)
    if arr.size == 1:
        arr = np.full(n_fingers, arr[0])
    elif arr.size != n_fingers:
        raise InputError(f'delta_theta_p: expected 1 or {n_fingers} values, got {arr.size}: '
                         f'{brief_repr(arr)}')
    if np.any(arr < 0.0):
        raise InputError(f'delta_theta_p: must be >= 0, got {both_units(arr, ANGLE)}')
    if np.any(arr > delta_theta_p_max + 1e-12):
        raise InputError(f'delta_theta_p: {both_units(arr, ANGLE)} exceeds delta_theta_p_max '
                         f'{both_units(delta_theta_p_max, ANGLE)}')
    return arr


def check_friction_angle(friction_angle: float, configured: float) -> float:
    """Validate alpha [rad]; negative selects ``configured``. Must be below pi/2."""
    arr = _as_vector('friction_angle', friction_angle)
    if arr.size != 1:
        raise InputError(f'friction_angle: expected one value, got {brief_repr(arr)}')
    alpha = float(arr[0])
    if alpha < 0.0:
        return configured
    if alpha >= 0.5 * math.pi:
        raise InputError(f'friction_angle: {both_units(alpha, ANGLE)} must be below 90 deg')
    return alpha


class LiftAnalyzer:
    """Lift analysis of the configured hand and object (sections 3.1-3.3 of the paper).

    Building it solves the first contact (it raises :class:`NoSolutionError` when the fingers
    make none); the SPCM branch of every finger is cached on first use (:attr:`table`, a few
    tenths of a second, or :meth:`build` at once); :meth:`check_lift` then costs a few Newton
    steps and closed forms.

    Parameters
    ----------
    config : validated configuration (``load_config()`` if None).
    path_step : grid step of the cached SPCM branch [rad].
    """

    def __init__(self, config: DamConfig | None = None,
                 path_step: float = PATH_STEP_RAD) -> None:
        self.config = config if config is not None else load_config()
        self.model: HandModel = build_hand_model(self.config)
        self._path_step = path_step
        self._table: PathTable | None = None
        self._phi = 2.0 * np.pi * np.arange(self.model.cone_faces) / self.model.cone_faces
        self._cos_phi = np.cos(self._phi)  # the axial parts add no torque, no lift
        self._cache: dict[float, list] = {}
        # plain floats for the scalar fast path of check_lift
        self._cos_phi_list: list[float] = self._cos_phi.tolist()
        self._ratios: list[float] = np.asarray(self.model.stiffness_ratios,
                                               dtype=np.float64).tolist()
        self._dp_limit = float(self.model.delta_theta_p_max + 1e-12)
        self._k_t = float(self.model.tangential_stiffness)
        self._frames = [(g.base_position.tolist(), g.inward_direction.tolist())
                        for g in self.model.fingers]
        self._csm_data: tuple | None = None
        self.limits = HandLimits.from_config(self.config)
        self._k_n = float(self.model.contact_stiffness[0])
        self._rolling: RollingCheck | None = None
        self._branch_ends: list[float] = []
        self._same_branch: list[int] = []
        self._csm_path_verdict: CsmPathVerdict | None = None

    @property
    def table(self) -> PathTable:
        """The SPCM branch of every finger cached on a grid, built on first use (a few tenths
        of a second: a node that only needs to know the object is reachable never pays it)."""
        if self._table is None:
            table = PathTable(self.model, build_paths(self.model, self._path_step))
            self._branch_ends = [path.valid_until for path in table.paths]
            keys = [path.same_branch_key() for path in table.paths]
            #: per finger, the first finger whose branch is the same (plane_state once)
            self._same_branch = [keys.index(key) for key in keys]
            self._csm_path_verdict = CsmPathVerdict(table, self._ratios, self._k_t)
            self._table = table
        return self._table

    def build(self) -> LiftAnalyzer:
        """Build the cached branches now (:attr:`table`), so that the first request is fast;
        returns ``self``."""
        _ = self.table
        return self

    @property
    def _csm_path(self) -> CsmPathVerdict:
        verdict = self._csm_path_verdict
        if verdict is None:
            self.build()
            verdict = self._csm_path_verdict
            assert verdict is not None
        return verdict

    @property
    def rolling_cos_phi(self) -> list[float]:
        """``cos(2 pi k / L)`` of the friction cone's span vectors (eq. 7), for the rolling
        check."""
        return self._cos_phi_list

    @property
    def rolling(self) -> RollingCheck:
        """The check of the poses the object can roll into (built on first use)."""
        if self._rolling is None:
            self._rolling = RollingCheck(self.config, self.model, self.table.paths)
        return self._rolling

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

        Scalar fast path: plain floats per finger (n = 3, L = 8 is far too small for numpy to
        pay off), the SPCM from :meth:`SpcmPath.plane_state`, the worst case from
        :func:`~dam_analysis.lift.worst_case_cone` and the CSM play operator in closed form
        with the slip history cached per friction angle. The vectorised map functions of
        :mod:`dam_analysis.regions` compute the same quantities (tests compare both).

        A finger whose ``delta_theta_p`` lies beyond the end of its SPCM branch
        (``SpcmPath.valid_until``, located exactly by :mod:`dam_analysis.branch_end`) has no
        SPCM state, so no contact force: the answer is "no lift" (``lift_guaranteed`` and
        ``csm_lift`` False, both margins NaN, ``beyond_branch`` set, NaN per-finger values for
        that finger) with ``branch_message`` naming the end in degrees and the reason.

        Parameters
        ----------
        k_theta : (n,) or scalar [N m/rad]; delta_theta_p : (n,) or scalar [rad];
        friction_angle : alpha [rad], negative for the configured value.

        Raises
        ------
        InputError
            Malformed input (see the ``check_*`` functions).
        NoSolutionError
            The SPCM solver failed inside the branch (not expected; the message says where).
        """
        k, dp, alpha = self._validate_floats(k_theta, delta_theta_p, friction_angle)
        paths = self.table.paths
        states: list[tuple[float, float, float, float, float, bool] | None] = []
        for i, (path, d, end, same) in enumerate(zip(paths, dp, self._branch_ends,
                                                     self._same_branch, strict=True)):
            if same < i and dp[same] == d:  # a finger on the same branch at the same angle
                states.append(states[same])
            else:
                states.append(path.plane_state(d) if d <= end else None)
        mu = math.tan(alpha)
        ca, sa = math.cos(alpha), math.sin(alpha)
        k_t = self._k_t
        cos_phi = self._cos_phi_list
        cache = self._csm_cache(alpha)
        inf, nan = math.inf, math.nan
        d_theta_s, taus, statuses, f_ns, f_ts = [], [], [], [], []
        worst_total = csm_total = 0.0
        separated = False
        for i, state in enumerate(states):
            if state is None:  # beyond the end of the branch: no SPCM state, no force
                for out in (d_theta_s, taus, f_ns, f_ts):
                    out.append(nan)
                statuses.append(STATUS_NO_SPCM)
                continue
            theta_s, p_u, p_z, n_u, n_z, _ = state
            d_s = theta_s - paths[i].theta_s0
            tau = -k[i] * d_s  # tau_s = -K_theta delta_theta_s
            # plane forms of J^T n_in, J^T t and the vertical components (module regions/docs)
            h_n = p_z * n_u - p_u * n_z
            h_t = p_z * n_z + p_u * n_u
            cz_n, cz_t = -n_z, n_u
            # span vectors v^k (eq. 7): the axial parts add no torque and no lift
            value, status = worst_case_cone(ca * h_n, sa * h_t, ca * cz_n, sa * cz_t, cos_phi,
                                            tau)
            worst_total += value
            # CSM (module csm): closed-form play operator with the cached slip history
            entry = cache[i]
            if entry is None:
                f_n, f_t = self._csm_fallback(i, dp[i], k[i], alpha)
            else:
                grid, gamma, s_arr, s_grid, sign = entry
                cnt = bisect.bisect_left(grid, dp[i])
                prev = float((k[i] * gamma[:cnt] - s_arr[:cnt]).min()) if cnt else inf
                s_end = (_interp(dp[i], grid, s_grid) if dp[i] <= grid[-1]
                         else sign * self.table.tail_slip(i, dp[i]))
                denom = h_n + sign * mu * h_t
                cap = mu * tau / (k_t * denom) if denom > 0.0 else inf
                delta = s_end + min(prev, cap - s_end)
                if denom > 0.0 and delta >= cap * (1.0 - 1e-12):
                    f_n = tau / denom
                    f_t = sign * mu * f_n
                else:
                    f_t = k_t * delta * sign
                    f_n = (tau - h_t * f_t) / h_n
            separated = separated or f_n < 0.0
            csm_total += f_n * cz_n + f_t * cz_t
            d_theta_s.append(d_s)
            taus.append(tau)
            statuses.append(status)
            f_ns.append(f_n)
            f_ts.append(f_t)
        weight = self.model.object_weight
        beyond = [state is None for state in states]
        message = ''
        if any(beyond):
            first = beyond.index(True)
            message = 'no lift: ' + paths[first].beyond_message(dp[first])
            margin = csm_margin = nan
        else:
            margin = worst_total - weight
            csm_margin = nan if separated else csm_total - weight
        guaranteed = margin > 0.0 and all(st == STATUS_BOUNDED for st in statuses)
        rolling = NOT_CHECKED
        if guaranteed and not self.model.fingers[0].is_circle:
            rolling = self.rolling.verdict(k, dp, alpha, weight, cos_phi)
            guaranteed = rolling.holds
        penetration = csm_penetration(f_ns, self._k_n)
        path = self._csm_path.verdict(k, dp, alpha, weight, csm_margin)
        return LiftResult._with_lazy_contacts(
            (self._frames, states, f_ns, f_ts),
            lift_guaranteed=guaranteed, worst_case_margin=margin,
            sufficient_status=tuple(statuses),
            csm_lift=not separated and csm_margin > 0.0, csm_margin=csm_margin,
            delta_theta_s=np.array(d_theta_s), compliant_torque=np.array(taus),
            k_theta=np.array(k), delta_theta_p=np.array(dp), friction_angle=alpha,
            beyond_branch=np.array(beyond), branch_message=message,
            torque_limit=self.limits.torque_limit,
            within_torque_limit=self.limits.within_torque_limit(taus),
            csm_penetration=np.array(penetration),
            csm_in_domain=self.limits.csm_in_domain(penetration),
            rolling_checked=rolling.checked, rolling_margin=rolling.margin,
            rolling_turn=rolling.pose.turn if rolling.pose is not None else nan,
            rolling_slide=rolling.pose.shift[0] if rolling.pose is not None else nan,
            rolling_message=rolling.message, csm_path_lift=path.lift,
            csm_path_margin=path.margin, csm_path_delta_theta_p=path.delta_theta_p)

    def _validate_floats(self, k_theta: ArrayLike, delta_theta_p: ArrayLike,
                         friction_angle: float) -> tuple[list[float], list[float], float]:
        """:meth:`validate` as plain floats; plain numbers and lists skip numpy entirely."""
        n = self.n_fingers
        k = _plain_floats(k_theta)
        dp = _plain_floats(delta_theta_p)
        alpha = _plain_floats(friction_angle)
        ok = k is not None and dp is not None and alpha is not None and len(alpha) == 1
        if ok:
            if len(k) == 1:
                ratios = self._ratios
                k = [k[0] * r / ratios[0] for r in ratios]
            if len(dp) == 1:
                dp = dp * n
            ok = (len(k) == n and len(dp) == n and min(k) > 0.0 and min(dp) >= 0.0
                  and max(dp) <= self._dp_limit and alpha[0] < 0.5 * math.pi)
        if not ok:  # the numpy path, with its error messages
            k_arr, dp_arr, a = self.validate(k_theta, delta_theta_p, friction_angle)
            return k_arr.tolist(), dp_arr.tolist(), a
        a = alpha[0]
        return k, dp, (a if a >= 0.0 else self.model.friction_angle)

    def _csm_cache(self, alpha: float) -> list[tuple[list[float], np.ndarray, np.ndarray,
                                                     list[float], float] | None]:
        """Per finger: grid, gamma = mu tau_hat / (k_t (h_n + s mu h_t)), s * slip (array and
        list), s; None for a path with non-monotone slip (step-by-step fallback).

        One friction angle costs a handful of numpy operations on the (fingers, nodes)
        arrays of :meth:`_csm_base`; the last 64 angles are kept.
        """
        hit = self._cache.get(alpha)
        if hit is not None:
            return hit
        mu = math.tan(alpha)
        rows, tau_hat, h_n, h_t, sign = self._csm_base()
        denom = h_n + sign * mu * h_t
        gamma = np.full(denom.shape, np.inf)  # inf where sliding cannot balance the torque
        np.divide(mu * tau_hat, self._k_t * denom, out=gamma, where=denom > 0.0)
        out: list[tuple[list[float], np.ndarray, np.ndarray, list[float], float] | None] = [
            None if row is None else (row[0], gamma[row[4]], row[1], row[2], row[3])
            for row in rows]
        if len(self._cache) > 64:
            self._cache.clear()
        self._cache[alpha] = out
        return out

    def _csm_base(self) -> tuple[list[tuple | None], np.ndarray, np.ndarray, np.ndarray,
                                 np.ndarray]:
        """Friction-independent CSM data on the valid grid nodes (built once).

        Returns
        -------
        rows : per finger (grid list [rad], s * slip (m_i,) [m], its list, s, row index), None
            for a non-monotone slip; tau_hat, h_n, h_t : (r, m) [rad], [m], [m], zero-padded
            beyond a finger's valid nodes; sign : (r, 1) slip sign s.
        """
        if self._csm_data is None:
            rows: list[tuple | None] = []
            parts = []
            for i in range(self.n_fingers):
                path = self.table.csm_path(i)
                if not path.monotone:
                    rows.append(None)
                    continue
                sign = path.slip_sign
                valid = np.isfinite(path.tau_hat)
                s_arr = sign * path.slip[valid]
                rows.append((path.delta_theta_p[valid].tolist(), s_arr, s_arr.tolist(), sign,
                             len(parts)))
                parts.append((path.tau_hat[valid], path.h_n[valid], path.h_t[valid], sign))
            width = max((p[0].size for p in parts), default=0)
            stacked = [np.zeros((len(parts), width)) for _ in range(3)]
            for r, part in enumerate(parts):
                for arr, values in zip(stacked, part[:3], strict=True):
                    arr[r, :values.size] = values
            sign_col = np.array([[p[3]] for p in parts], dtype=np.float64).reshape(-1, 1)
            self._csm_data = (rows, *stacked, sign_col)
        return self._csm_data

    def _csm_fallback(self, i: int, dp: float, k_i: float, alpha: float) -> tuple[float, float]:
        contact = self.table.paths[i].solve(dp)
        end = finger_table(self.model, i, [contact], np.array([dp]))
        ev = csm_evaluate(self.table, i, end, np.array([k_i]), alpha)
        return float(ev.f_n[0, 0]), float(ev.f_t[0, 0])

    def lift_map(self, friction_angles: ArrayLike, delta_theta_p: ArrayLike,
                 k_theta: ArrayLike) -> LiftMap:
        """Margins on an (alpha, delta_theta_p, k_theta of finger 1) grid (see regions).

        For a section that can roll (not a circle) every cell where eq. (18) holds at rest is
        checked as :meth:`check_lift` checks it (:mod:`dam_analysis.rolling`); where the
        object can rest in a turned pose, ``sufficient_margin`` is the margin of the first such
        pose found (not necessarily the least; NaN: not decided), so the sufficient region is
        the guarantee ``check_lift`` gives.
        """
        result = lift_map(self.table, np.asarray(friction_angles, dtype=np.float64),
                          np.asarray(delta_theta_p, dtype=np.float64),
                          np.asarray(k_theta, dtype=np.float64))
        if self.model.fingers[0].is_circle:
            return result
        margin = result.sufficient_margin.copy()
        ratios = self._ratios
        for (a_idx, d_idx, k_idx) in zip(*np.nonzero(result.sufficient_lift), strict=True):
            k1 = float(result.k_theta[k_idx])
            verdict = self.rolling.verdict(
                [k1 * r / ratios[0] for r in ratios],
                [float(result.delta_theta_p[d_idx])] * self.n_fingers,
                float(result.friction_angle[a_idx]), self.model.object_weight,
                self._cos_phi_list, complete=False)
            if not verdict.holds:
                margin[a_idx, d_idx, k_idx] = verdict.margin
        return LiftMap(friction_angle=result.friction_angle,
                       delta_theta_p=result.delta_theta_p, k_theta=result.k_theta,
                       sufficient_margin=margin, csm_margin=result.csm_margin)

    def boundaries(self, friction_angle: float, delta_theta_p: ArrayLike) -> Boundaries:
        """Lower boundaries k_theta*(delta_theta_p) of both regions for one friction angle.

        For a section that can roll (not a circle) the sufficient boundary ``k*`` of eq. (18)
        at rest is kept only where the rolling check (:mod:`dam_analysis.rolling`) holds at
        ``k* (1 + 1e-6)`` and at ``2, 4, ..., 1024`` times ``k*``; elsewhere it is NaN (no
        guarantee). The rolling check is decided at these stiffnesses, not between them.
        """
        result = region_boundaries(self.table, friction_angle,
                                   np.asarray(delta_theta_p, dtype=np.float64))
        if self.model.fingers[0].is_circle:
            return result
        suff = result.sufficient.copy()
        ratios = self._ratios
        for d_idx, k_star in enumerate(result.sufficient):
            if not np.isfinite(k_star):
                continue
            dp = [float(result.delta_theta_p[d_idx])] * self.n_fingers
            for factor in (1.0 + 1e-6,) + tuple(2.0 ** j for j in range(1, 11)):
                k1 = float(k_star) * factor
                verdict = self.rolling.verdict([k1 * r / ratios[0] for r in ratios], dp,
                                               float(friction_angle),
                                               self.model.object_weight, self._cos_phi_list,
                                               complete=False)
                if not verdict.holds:
                    suff[d_idx] = np.nan
                    break
        return Boundaries(friction_angle=result.friction_angle,
                          delta_theta_p=result.delta_theta_p, sufficient=suff, csm=result.csm)
