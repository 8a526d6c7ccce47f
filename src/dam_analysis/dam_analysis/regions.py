"""Lift regions in the k_theta - delta_theta_p plane (Kaneko et al., Fig. 5(b) and Fig. 7).

For fixed geometry (one ``delta_theta_p``) every contact torque is ``tau_si = k_theta r_i
tau_hat_i`` (``r_i`` the stiffness ratio, ``tau_hat_i = -delta_theta_si``), so

* the sufficient worst case is linear in k_theta: ``margin = k_theta A(dp) - m_B g`` with
  ``A = sum_i r_i tau_hat_i a_i^+`` (:func:`dam_analysis.lift.worst_case_coefficients`), unless
  a finger's worst case is unbounded (then no k_theta works);
* the CSM force while every contact slides is linear too:
  ``margin = k_theta B(dp) - m_B g``, ``B = sum_i r_i tau_hat_i (cz_n + s mu cz_t) /
  (h_n + s mu h_t)``; where a contact still sticks at that k_theta the boundary is refined by
  bisection on the exact CSM margin.

:class:`PathTable` caches the SPCM branch of every finger on a fine grid; :func:`lift_map`
evaluates both margins for whole arrays of friction angles, displacements and stiffnesses.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dam_analysis.csm import CsmPath, csm_forces_sequential
from dam_analysis.errors import NoSolutionError
from dam_analysis.lift import worst_case_coefficients
from dam_analysis.model import HandModel, distal_gap_partials
from dam_analysis.spcm import FingerContact, SpcmPath, build_paths, contact_state, plane_joints

#: Gauss-Legendre points of :meth:`PathTable.tail_slip`.
TAIL_QUADRATURE_NODES = 12
_GAUSS_LEGENDRE = tuple(v.tolist() for v in np.polynomial.legendre.leggauss(
    TAIL_QUADRATURE_NODES))


def cone_arrays(normal_object: np.ndarray, axis: np.ndarray, friction_angle: float,
                cone_faces: int) -> np.ndarray:
    """Span vectors for many contacts at once: (..., 3) normals -> (..., 3, L) (eq. 7)."""
    n_in = -np.asarray(normal_object, dtype=np.float64)
    b = np.broadcast_to(np.asarray(axis, dtype=np.float64), n_in.shape)
    t = np.cross(b, -n_in)
    phi = 2.0 * np.pi * np.arange(cone_faces) / cone_faces
    return (math.cos(friction_angle) * n_in[..., None]
            + math.sin(friction_angle) * (t[..., None] * np.cos(phi) + b[..., None] * np.sin(phi)))


@dataclass(frozen=True)
class FingerTable:
    """SPCM quantities of one finger at the grid nodes or at requested displacements.

    All arrays have a leading dimension m (the nodes); invalid nodes hold NaN.
    """

    delta_theta_p: np.ndarray  # (m,) [rad]
    tau_hat: np.ndarray  # (m,) -delta_theta_s [rad]
    contact_point: np.ndarray  # (m, 3) [m]
    normal_object: np.ndarray  # (m, 3)
    jacobian: np.ndarray  # (m, 3) J_i [m]
    slip_rate: np.ndarray  # (m,) d slip / d delta_theta_p along t [m/rad]
    axis: np.ndarray  # (3,)

    @property
    def tangent(self) -> np.ndarray:
        """(m, 3) in-plane tangent ``t = b x n_CB``."""
        return np.cross(np.broadcast_to(self.axis, self.normal_object.shape),
                        self.normal_object)


def finger_table(model: HandModel, index: int, contacts: list[FingerContact | None],
                 delta_theta_p: np.ndarray) -> FingerTable:
    """Assemble a :class:`FingerTable` from SPCM states (None marks an invalid node)."""
    geometry = model.fingers[index]
    m = len(contacts)
    tau_hat = np.full(m, np.nan)
    point = np.full((m, 3), np.nan)
    normal = np.full((m, 3), np.nan)
    rate = np.full(m, np.nan)  # d theta_s / d theta_p
    joint_p = np.full((m, 2), np.nan)  # the position joint in the plane [m]
    for j, fc in enumerate(contacts):
        if fc is None:
            continue
        tau_hat[j] = -fc.delta_theta_s
        point[j] = fc.contact_point
        normal[j] = fc.normal_object
        rate[j] = fc.dtheta_s_dtheta_p
        joint_p[j] = fc.joints[2]
    # every node at once (np.cross per node was half of building the table: start-up time)
    a = geometry.joint_axis
    axes = np.broadcast_to(a, point.shape)
    jac = np.cross(axes, point - geometry.base_position)
    v_c = rate[:, None] * jac + np.cross(axes, point - geometry.to_world(joint_p))
    slip_rate = np.einsum('ij,ij->i', v_c, np.cross(axes, normal))
    return FingerTable(delta_theta_p=np.asarray(delta_theta_p, dtype=np.float64),
                       tau_hat=tau_hat, contact_point=point, normal_object=normal,
                       jacobian=jac, slip_rate=slip_rate, axis=a)


def contacts_at(paths: tuple[SpcmPath, ...], index: int, delta_theta_p: np.ndarray
                ) -> list[FingerContact | None]:
    """SPCM states of one finger at many displacements (None where there is no solution)."""
    out: list[FingerContact | None] = []
    for d in np.asarray(delta_theta_p, dtype=np.float64):
        try:
            out.append(paths[index].solve(float(d)))
        except NoSolutionError:
            out.append(None)
    return out


class PathTable:
    """The SPCM branch of every finger cached on a fine grid, with CSM slip histories.

    Parameters
    ----------
    model : hand at first contact.
    paths : cached continuation paths (built if None).
    """

    def __init__(self, model: HandModel, paths: tuple[SpcmPath, ...] | None = None) -> None:
        self.model = model
        self.paths = paths if paths is not None else build_paths(model)
        self.grid: list[FingerTable] = []
        self.slip: list[np.ndarray] = []
        for i, path in enumerate(self.paths):
            contacts: list[FingerContact | None] = []
            for d, th in zip(path.delta_theta_p, path.theta_s, strict=True):
                if math.isfinite(th):
                    contacts.append(contact_state(model.fingers[i], float(th), model.theta_l0,
                                                  model.theta_p0 + float(d),
                                                  float(model.theta_s0[i])))
                else:
                    contacts.append(None)
            table = finger_table(model, i, contacts, path.delta_theta_p)
            self.grid.append(table)
            # accumulated slip (trapezoidal rule on the grid)
            rate = table.slip_rate
            inc = 0.5 * (rate[1:] + rate[:-1]) * np.diff(table.delta_theta_p)
            self.slip.append(np.concatenate([[0.0], np.cumsum(inc)]))

    def slip_at(self, index: int, delta_theta_p: np.ndarray) -> np.ndarray:
        """Accumulated slip [m] of a finger at arbitrary displacements.

        Linear interpolation of the grid values up to the last valid node,
        :meth:`tail_slip` between it and the branch end, NaN beyond the end.
        """
        dp = np.asarray(delta_theta_p, dtype=np.float64)
        out = np.array(np.interp(dp, self.grid[index].delta_theta_p, self.slip[index]),
                       dtype=np.float64)
        path = self.paths[index]
        tail = (dp > path.delta_theta_p[path.last_node]) & (dp <= path.valid_until)
        out[dp > path.valid_until] = np.nan
        if np.any(tail):
            flat, where = out.reshape(-1), np.flatnonzero(tail)
            for j, d in zip(where, dp.reshape(-1)[where], strict=True):
                flat[j] = self.tail_slip(index, float(d))
        return out

    def tail_slip(self, index: int, delta_theta_p: float) -> float:
        """Accumulated slip [m] between the last valid grid node and the branch end.

        The slip rate ``t^T v_C`` contains ``d theta_s / d theta_p``, which grows like
        ``(end - delta_theta_p)^(-1/2)`` towards a fold, so the trapezoidal rule of the grid
        cannot reach the end. The increment from the last node is integrated with the
        substitution ``delta_theta_p = end - u^2`` (a smooth integrand ``2 u t^T v_C``) by
        Gauss-Legendre quadrature of :data:`TAIL_QUADRATURE_NODES` points on the exact SPCM
        states. In the finger plane ``(a x x)^T (a x n_CB) = x^T n_CB``, so the rate of
        :func:`finger_table` is ``(d theta_s/d theta_p) (p_C - p_s)^T n_CB
        + (p_C - p_p)^T n_CB`` with ``d theta_s/d theta_p = -g_p / g_s``.

        Parameters
        ----------
        index : finger; delta_theta_p : displacement [rad], at most the branch end.

        Returns
        -------
        The slip along ``t`` [m].
        """
        path = self.paths[index]
        node = path.last_node
        dp_a = float(path.delta_theta_p[node])
        if delta_theta_p <= dp_a:
            return float(np.interp(delta_theta_p, self.grid[index].delta_theta_p,
                                   self.slip[index]))
        end = path.valid_until
        model, geometry = self.model, path.geometry
        u_a, u_b = math.sqrt(end - dp_a), math.sqrt(max(end - delta_theta_p, 0.0))
        half, mid = 0.5 * (u_a - u_b), 0.5 * (u_a + u_b)
        total = 0.0
        for x, w in zip(*_GAUSS_LEGENDRE, strict=True):
            u = mid + half * x
            dp = end - u * u
            theta_s, p_u, p_z, n_u, n_z, _ = path.plane_state(dp)
            theta_p = model.theta_p0 + dp
            _, g_s, g_p = distal_gap_partials(geometry, theta_s, model.theta_l0, theta_p)
            _, _, q_u, q_z, _, _ = plane_joints(geometry, theta_s, model.theta_l0, theta_p)
            rate = (-g_p / g_s) * (p_u * n_u + p_z * n_z) + ((p_u - q_u) * n_u
                                                             + (p_z - q_z) * n_z)
            total += w * 2.0 * u * rate
        return float(self.slip[index][node]) + half * total

    def csm_path(self, index: int, upto: float | None = None,
                 end: FingerTable | None = None) -> CsmPath:
        """CSM path data of a finger: grid nodes below ``upto`` plus an optional end node."""
        g = self.grid[index]
        sel = slice(None) if upto is None else g.delta_theta_p < upto
        parts = [_csm_fields(g, self.slip[index], sel)]
        if end is not None:
            parts.append(_csm_fields(end, self.slip_at(index, end.delta_theta_p),
                                     slice(None)))
        return CsmPath(*[np.concatenate([p[k] for p in parts]) for k in range(7)])


def _csm_fields(table: FingerTable, slip: np.ndarray, sel: slice | np.ndarray
                ) -> tuple[np.ndarray, ...]:
    n_in = -table.normal_object[sel]
    t = table.tangent[sel]
    jac = table.jacobian[sel]
    return (table.delta_theta_p[sel], table.tau_hat[sel], np.einsum('mj,mj->m', jac, n_in),
            np.einsum('mj,mj->m', jac, t), n_in[:, 2], t[:, 2], slip[sel])


def sufficient_coefficients(table: FingerTable, friction_angle: float, cone_faces: int
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Per node ``a^+`` (worst vertical force per unit torque) and the unbounded flag."""
    v = cone_arrays(table.normal_object, table.axis, friction_angle, cone_faces)  # (m, 3, L)
    h = np.einsum('mj,mjl->ml', table.jacobian, v)
    c = v[:, 2, :]
    a_plus, _, unbounded = worst_case_coefficients(h, c)
    return a_plus, unbounded


@dataclass(frozen=True)
class CsmEval:
    """CSM result of one finger for K stiffnesses at D displacements.

    f_n, f_t, fz : (K, D) normal, tangential and vertical force on the object [N];
    separated : (K, D) bool, the contact would have to pull (no equilibrium).
    """

    f_n: np.ndarray
    f_t: np.ndarray
    fz: np.ndarray
    separated: np.ndarray


def csm_evaluate(table: PathTable, index: int, end: FingerTable, k_theta_i: np.ndarray,
                 friction_angle: float, tangential_stiffness: float | None = None) -> CsmEval:
    """CSM forces of one finger at the displacements of ``end`` (exact SPCM end states).

    ``tangential_stiffness`` [N/m] replaces the model's (``HandModel.tangential_stiffness``)
    when given.

    The slip history is taken from the grid nodes below each displacement; the play operator
    is evaluated in closed form (cumulative minimum) when the slip is monotone, otherwise step
    by step (:func:`dam_analysis.csm.csm_forces_sequential`).
    """
    k_t = float(table.model.tangential_stiffness if tangential_stiffness is None
                else tangential_stiffness)
    k = np.atleast_1d(np.asarray(k_theta_i, dtype=np.float64))
    mu = math.tan(friction_angle)
    full = table.csm_path(index)
    dp_end = end.delta_theta_p
    n_k, n_d = k.size, dp_end.size
    end_path = CsmPath(*_csm_fields(end, table.slip_at(index, dp_end), slice(None)))
    if not full.monotone:
        return _csm_sequential_each(table, index, end, k, friction_angle, k_t)
    sign = full.slip_sign
    denom_g = full.h_n + sign * mu * full.h_t
    with np.errstate(divide='ignore', invalid='ignore'):
        gamma_g = np.where(denom_g > 0.0, mu * full.tau_hat / (k_t * denom_g), np.inf)
    s_g = sign * full.slip
    gamma_g = np.where(np.isnan(gamma_g), np.inf, gamma_g)  # invalid nodes never cap
    s_g = np.where(np.isfinite(s_g), s_g, 0.0)
    # prefix minimum over nodes strictly below each requested displacement
    prefix = np.minimum.accumulate(k[:, None] * gamma_g[None, :] - s_g[None, :], axis=1)
    count = np.searchsorted(full.delta_theta_p, dp_end, side='left')  # nodes below dp
    prev = np.where(count[None, :] > 0, prefix[:, np.maximum(count - 1, 0)], np.inf)
    denom_e = end_path.h_n + sign * mu * end_path.h_t
    tau_e = k[:, None] * end_path.tau_hat[None, :]
    with np.errstate(divide='ignore', invalid='ignore'):
        cap_e = np.where(denom_e > 0.0, mu * tau_e / (k_t * denom_e), np.inf)
        s_e = np.broadcast_to(sign * end_path.slip, (n_k, n_d))
        delta = s_e + np.minimum(prev, cap_e - s_e)
        sliding = (denom_e > 0.0) & (delta >= cap_e * (1.0 - 1e-12))
        f_n_slide = tau_e / denom_e
        f_t_stick = k_t * delta * sign
        f_n_stick = (tau_e - end_path.h_t * f_t_stick) / end_path.h_n
    f_n = np.where(sliding, f_n_slide, f_n_stick)
    f_t = np.where(sliding, sign * mu * f_n_slide, f_t_stick)
    fz = f_n * end_path.cz_n + f_t * end_path.cz_t
    return CsmEval(f_n=f_n, f_t=f_t, fz=fz, separated=f_n < 0.0)


def _csm_sequential_each(table: PathTable, index: int, end: FingerTable, k: np.ndarray,
                         friction_angle: float, k_t: float) -> CsmEval:
    n_d = end.delta_theta_p.size
    out = [np.zeros((k.size, n_d)) for _ in range(3)]
    sep = np.zeros((k.size, n_d), dtype=bool)
    for d in range(n_d):
        one = FingerTable(end.delta_theta_p[d:d + 1], end.tau_hat[d:d + 1],
                          end.contact_point[d:d + 1], end.normal_object[d:d + 1],
                          end.jacobian[d:d + 1], end.slip_rate[d:d + 1], end.axis)
        path = table.csm_path(index, upto=float(end.delta_theta_p[d]), end=one)
        f_n, f_t, s = csm_forces_sequential(path, k, friction_angle, k_t)
        out[0][:, d] = f_n[:, -1]
        out[1][:, d] = f_t[:, -1]
        out[2][:, d] = f_n[:, -1] * path.cz_n[-1] + f_t[:, -1] * path.cz_t[-1]
        sep[:, d] = s[:, -1]
    return CsmEval(f_n=out[0], f_t=out[1], fz=out[2], separated=sep)


@dataclass(frozen=True)
class LiftMap:
    """Margins on a friction-angle x displacement x stiffness grid.

    Attributes
    ----------
    friction_angle : (A,) [rad]; delta_theta_p : (D,) [rad]; k_theta : (K,) [N m/rad].
    sufficient_margin : (A, D, K) worst-case ``c_z^T f_o - m_B g`` [N] (-inf unbounded, NaN
        where the SPCM has no solution).
    csm_margin : (A, D, K) CSM ``c_z^T f_o - m_B g`` [N] (NaN: no SPCM or separation).
    sufficient_lift, csm_lift : (A, D, K) bool, margin > 0.
    """

    friction_angle: np.ndarray
    delta_theta_p: np.ndarray
    k_theta: np.ndarray
    sufficient_margin: np.ndarray
    csm_margin: np.ndarray

    @property
    def sufficient_lift(self) -> np.ndarray:
        return np.nan_to_num(self.sufficient_margin, nan=-1.0) > 0.0

    @property
    def csm_lift(self) -> np.ndarray:
        return np.nan_to_num(self.csm_margin, nan=-1.0) > 0.0


def end_tables(table: PathTable, delta_theta_p: np.ndarray) -> list[FingerTable]:
    """Exact SPCM states of every finger at the given displacements (same for all fingers)."""
    dp = np.asarray(delta_theta_p, dtype=np.float64)
    return [finger_table(table.model, i, contacts_at(table.paths, i, dp), dp)
            for i in range(table.model.n_fingers)]


def lift_map(table: PathTable, friction_angle: np.ndarray, delta_theta_p: np.ndarray,
             k_theta: np.ndarray, tangential_stiffness: float | None = None) -> LiftMap:
    """Both margins on a full grid; ``k_theta`` is finger 1's stiffness (others by ratio).

    ``tangential_stiffness`` [N/m] replaces the model's CSM tangential stiffness when given.

    Vectorised: the SPCM states are solved once per displacement, the sufficient margin is
    ``k_theta A(dp) - m_B g`` and the CSM play operator is a cumulative minimum.
    """
    alphas = np.atleast_1d(np.asarray(friction_angle, dtype=np.float64))
    dp = np.atleast_1d(np.asarray(delta_theta_p, dtype=np.float64))
    k = np.atleast_1d(np.asarray(k_theta, dtype=np.float64))
    model = table.model
    ends = end_tables(table, dp)
    weight = model.object_weight
    suff = np.empty((alphas.size, dp.size, k.size))
    csm = np.empty_like(suff)
    for a_idx, alpha in enumerate(alphas):
        coeff = np.zeros(dp.size)
        unbounded = np.zeros(dp.size, dtype=bool)
        fz_csm = np.zeros((k.size, dp.size))
        bad_csm = np.zeros((k.size, dp.size), dtype=bool)
        for i, end in enumerate(ends):
            ratio = float(model.stiffness_ratios[i])
            a_plus, unb = sufficient_coefficients(end, float(alpha), model.cone_faces)
            coeff += ratio * end.tau_hat * np.where(end.tau_hat > 0.0, a_plus, 0.0)
            unbounded |= unb & (end.tau_hat > 0.0)
            ev = csm_evaluate(table, i, end, ratio * k, float(alpha), tangential_stiffness)
            fz_csm += ev.fz
            bad_csm |= ev.separated
        s = k[None, :] * coeff[:, None] - weight
        s = np.where(unbounded[:, None], -np.inf, s)
        suff[a_idx] = s  # NaN propagates where the SPCM has no solution
        c = fz_csm.T - weight
        csm[a_idx] = np.where(bad_csm.T, np.nan, c)
    return LiftMap(friction_angle=alphas, delta_theta_p=dp, k_theta=k,
                   sufficient_margin=suff, csm_margin=csm)


@dataclass(frozen=True)
class Boundaries:
    """Lower boundaries k_theta*(delta_theta_p) of both lift regions for one friction angle.

    sufficient, csm : (D,) smallest finger-1 stiffness that lifts [N m/rad]; NaN where no
    stiffness does (unbounded worst case, non-positive slope, no SPCM solution).
    """

    friction_angle: float
    delta_theta_p: np.ndarray
    sufficient: np.ndarray
    csm: np.ndarray


def region_boundaries(table: PathTable, friction_angle: float, delta_theta_p: np.ndarray,
                      tangential_stiffness: float | None = None) -> Boundaries:
    """Region boundaries from the linear structure in k_theta (no grid search over k).

    Sufficient: ``k* = m_B g / A(dp)``. CSM: ``k* = m_B g / B(dp)`` from the all-sliding slope,
    verified with the exact CSM margin at k*; where some contact still sticks there, the
    boundary is refined by bisection on the exact margin.
    """
    model = table.model
    dp = np.atleast_1d(np.asarray(delta_theta_p, dtype=np.float64))
    ends = end_tables(table, dp)
    weight = model.object_weight
    mu = math.tan(friction_angle)
    a_coef = np.zeros(dp.size)
    b_coef = np.zeros(dp.size)
    unbounded = np.zeros(dp.size, dtype=bool)
    for i, end in enumerate(ends):
        ratio = float(model.stiffness_ratios[i])
        a_plus, unb = sufficient_coefficients(end, friction_angle, model.cone_faces)
        a_coef += ratio * end.tau_hat * a_plus
        unbounded |= unb
        path = table.csm_path(i)
        sign = path.slip_sign
        f = _csm_fields(end, table.slip_at(i, dp), slice(None))
        h_n, h_t, cz_n, cz_t = f[2], f[3], f[4], f[5]
        b_coef += ratio * end.tau_hat * (cz_n + sign * mu * cz_t) / (h_n + sign * mu * h_t)
    with np.errstate(divide='ignore', invalid='ignore'):
        k_suff = np.where((a_coef > 0.0) & ~unbounded, weight / a_coef, np.nan)
        k_csm = np.where(b_coef > 0.0, weight / b_coef, np.nan)

    def csm_margin(k_val: float, d: int) -> float:
        total = 0.0
        for i, end in enumerate(ends):
            one = FingerTable(end.delta_theta_p[d:d + 1], end.tau_hat[d:d + 1],
                              end.contact_point[d:d + 1], end.normal_object[d:d + 1],
                              end.jacobian[d:d + 1], end.slip_rate[d:d + 1], end.axis)
            ev = csm_evaluate(table, i, one, np.array([k_val * model.stiffness_ratios[i]]),
                              friction_angle, tangential_stiffness)
            if ev.separated[0, 0]:
                return math.nan
            total += float(ev.fz[0, 0])
        return total - weight

    for d in range(dp.size):
        if not math.isfinite(k_csm[d]):
            continue
        m0 = csm_margin(float(k_csm[d]), d)
        if math.isfinite(m0) and abs(m0) <= 1e-9 * weight:
            continue
        # some contact sticks at the sliding estimate: bisection on the exact margin
        lo, hi = float(k_csm[d]) / 64.0, float(k_csm[d]) * 64.0
        m_lo, m_hi = csm_margin(lo, d), csm_margin(hi, d)
        if not (math.isfinite(m_lo) and math.isfinite(m_hi) and m_lo <= 0.0 < m_hi):
            k_csm[d] = math.nan
            continue
        for _ in range(80):
            mid = math.sqrt(lo * hi)
            if csm_margin(mid, d) > 0.0:
                hi = mid
            else:
                lo = mid
        k_csm[d] = hi
    return Boundaries(friction_angle=friction_angle, delta_theta_p=dp, sufficient=k_suff,
                      csm=k_csm)
