"""The sufficient condition for lifting the object (Kaneko et al., section 3.2, eqs. 5-18).

Conventions
-----------
* ``f_ci`` (3,) is the force finger i applies ON the object, world frame [N].
* ``J_i = a_i x (p_Ci - p_si)`` (3,), with ``a_i`` the compliant joint axis and ``p_si`` the
  compliant joint position, maps it to the compliant joint torque: ``tau_si = J_i^T f_ci``.
  With the spring law ``tau_s = -K_theta delta_theta_s`` (``delta_theta_s <= 0`` along the
  SPCM) the torque is positive: it flexes the finger into the object.
* The L-faced polyhedral cone (eq. 7) has span vectors
  ``v^k = cos(alpha) n_in + sin(alpha) (cos(phi_k) t + sin(phi_k) b)``, ``phi_k = 2 pi k / L``,
  where ``n_in = -n_CB`` points into the object, ``t = b x n_CB`` is the in-plane tangent and
  ``b`` the joint axis. For even L, ``v^0`` and ``v^{L/2}`` lie in the finger plane, so the
  cone's projection on that plane is the planar cone of half-angle alpha.

Worst case and its subtlety
---------------------------
The sufficient condition (eq. 18) asks for ``c_z^T f_o - m_B g > 0`` for every admissible
force, i.e. ``min {c_z^T E V lambda : H lambda = tau_s, lambda >= 0} > m_B g``. ``H`` (eq. 11)
is block diagonal, so the minimum is a sum of per-finger one-constraint linear programs,
solved in closed form by :func:`worst_case_vertical_force`:

* bounded case: an optimal vertex uses one span vector, ``lambda_k = tau / h_k`` with
  ``h_k = J^T v^k`` of the sign of tau (the paper's eqs. 14-17 enumerate exactly these
  vertices), value ``tau * min_{k: h_k tau > 0} (c_k / h_k)``, ``c_k = c_z^T v^k``;
* unbounded case: the admissible set has recession directions ``lambda >= 0, H lambda = 0``.
  Its extreme rays are a single span vector with ``h_k = 0`` (a cone edge through the joint
  axis) or a pair ``h_j > 0 > h_k`` (an internal force that produces no torque). If such a
  ray lowers the vertical force the worst case is ``-inf``: the cone admits an arbitrarily
  large internal force pulling the object down, and no stiffness can guarantee lift. The
  vertex enumeration of eqs. 14-17 cannot see this case; it happens when the line from the
  compliant joint to the contact point lies inside the friction cone (large alpha).
* infeasible: no admissible force yields tau (the value is ``+inf``, as for an LP).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Relative tolerance below which a span vector's joint torque counts as zero.
TORQUE_ZERO_TOL = 1e-12

STATUS_BOUNDED = 'bounded'
STATUS_UNBOUNDED = 'unbounded'
STATUS_INFEASIBLE = 'infeasible'
#: Status of a finger without an SPCM state (beyond the end of its branch): not evaluated.
STATUS_NO_SPCM = 'no_spcm'


def span_vectors(normal_object: np.ndarray, axis: np.ndarray, friction_angle: float,
                 cone_faces: int) -> np.ndarray:
    """Span vectors V_i of the L-faced polyhedral friction cone (eq. 7).

    Parameters
    ----------
    normal_object : (3,) unit outward normal n_CB of the object at the contact.
    axis : (3,) unit vector perpendicular to the normal (the joint / cylinder axis).
    friction_angle : alpha [rad], 0 <= alpha < pi/2.
    cone_faces : L >= 3.

    Returns
    -------
    (3, L) matrix ``V``; every column is a unit force direction on the object.
    """
    n_in = -np.asarray(normal_object, dtype=np.float64)
    b = np.asarray(axis, dtype=np.float64)
    t = np.cross(b, -n_in)
    phi = 2.0 * math.pi * np.arange(cone_faces) / cone_faces
    return (math.cos(friction_angle) * n_in[:, None]
            + math.sin(friction_angle) * (np.outer(t, np.cos(phi)) + np.outer(b, np.sin(phi))))


def compliant_jacobian(axis: np.ndarray, contact_point: np.ndarray,
                       joint_position: np.ndarray) -> np.ndarray:
    """J_i (3,) with ``tau_si = J_i^T f_ci``: ``J_i = a_i x (p_Ci - p_si)`` [m]."""
    return np.cross(axis, np.asarray(contact_point) - np.asarray(joint_position))


def grasp_matrix_t(contact_points: np.ndarray, object_center: np.ndarray) -> np.ndarray:
    """G^t (6, 3n) of eq. (5): ``[I_3 ... I_3; (R_B p_CBi x) ...]``.

    Parameters
    ----------
    contact_points : (n, 3) world contact points [m].
    object_center : (3,) centre of gravity p_B [m].
    """
    pts = np.asarray(contact_points, dtype=np.float64)
    blocks = []
    for p in pts:
        r = p - object_center
        skew = np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
        blocks.append(np.vstack([np.eye(3), skew]))
    return np.hstack(blocks)


def h_matrix(jacobians: np.ndarray, span: list[np.ndarray]) -> np.ndarray:
    """H (n, L n) of eq. (11): block diagonal with blocks ``J_i^T V_i`` (1, L)."""
    import scipy.linalg  # noqa: PLC0415 (here: importing scipy is a node's start-up time)

    return scipy.linalg.block_diag(*[j @ v for j, v in zip(jacobians, span, strict=True)])


def null_space_basis(h: np.ndarray) -> np.ndarray:
    """N (L n, (L-1) n) of eq. (12): orthonormal basis with ``H N = 0``."""
    import scipy.linalg  # noqa: PLC0415 (here: importing scipy is a node's start-up time)

    return scipy.linalg.null_space(h)


@dataclass(frozen=True)
class WorstCase:
    """Worst-case (smallest) vertical resultant over all admissible contact forces.

    Attributes
    ----------
    value : (n,) per-finger minimum of ``c_z^T f_ci`` [N]; -inf unbounded, +inf infeasible.
    status : (n,) object array of ``'bounded'``, ``'unbounded'``, ``'infeasible'``.
    """

    value: np.ndarray
    status: np.ndarray

    @property
    def total(self) -> float:
        """min c_z^T f_o = sum of the per-finger minima [N] (H is block diagonal)."""
        return float(np.sum(self.value))


def recession_unbounded(h: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Whether ``{lambda >= 0: h . lambda = 0}`` contains a ray with ``c . lambda < 0``.

    Parameters
    ----------
    h, c : (..., L) joint torque ``J^T v^k`` and vertical component ``c_z^T v^k`` per span
        vector.

    Returns
    -------
    (...) bool.
    """
    h = np.asarray(h, dtype=np.float64)
    c = np.asarray(c, dtype=np.float64)
    scale = np.max(np.abs(h), axis=-1, keepdims=True)
    scale = np.where(scale > 0.0, scale, 1.0)
    hn = h / scale
    zero = np.abs(hn) <= TORQUE_ZERO_TOL
    pos = hn > TORQUE_ZERO_TOL
    neg = hn < -TORQUE_ZERO_TOL
    with np.errstate(divide='ignore', invalid='ignore'):
        ratio_pos = np.where(pos, c / np.where(pos, hn, 1.0), np.inf).min(axis=-1)
        ratio_neg = np.where(neg, c / np.where(neg, -hn, 1.0), np.inf).min(axis=-1)
    zero_ray = np.any(zero & (c < 0.0), axis=-1)
    pair_ray = ratio_pos + ratio_neg < 0.0
    return zero_ray | pair_ray


def worst_case_coefficients(h: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray,
                                                                    np.ndarray]:
    """Linear coefficients of the per-finger worst case (vectorised closed form of the LP).

    For a bounded finger the minimum of ``c . lambda`` subject to ``h . lambda = tau``,
    ``lambda >= 0`` is ``a_plus * tau`` for tau > 0 and ``a_minus * tau`` for tau < 0
    (a vertex uses a single span vector: eqs. 14-17).

    Parameters
    ----------
    h, c : (..., L) as in :func:`recession_unbounded`.

    Returns
    -------
    a_plus : (...) ``min_{h_k > 0} c_k / h_k`` [N/(N m)] (+inf if no such k).
    a_minus : (...) ``max_{h_k < 0} c_k / h_k`` (-inf if no such k).
    unbounded : (...) bool from :func:`recession_unbounded`.
    """
    h = np.asarray(h, dtype=np.float64)
    c = np.asarray(c, dtype=np.float64)
    scale = np.max(np.abs(h), axis=-1, keepdims=True)
    tol = TORQUE_ZERO_TOL * np.where(scale > 0.0, scale, 1.0)
    pos = h > tol
    neg = h < -tol
    with np.errstate(divide='ignore', invalid='ignore'):
        a_plus = np.where(pos, c / np.where(pos, h, 1.0), np.inf).min(axis=-1)
        a_minus = np.where(neg, c / np.where(neg, h, 1.0), -np.inf).max(axis=-1)
    return a_plus, a_minus, recession_unbounded(h, c)


def worst_case_vertical_force(h: np.ndarray, c: np.ndarray, tau_s: np.ndarray) -> WorstCase:
    """Fast exact worst case ``min c_z^T f_ci`` per finger (eqs. 9-18 as an LP, closed form).

    Parameters
    ----------
    h : (n, L) ``J_i^T v_i^k``  [m].
    c : (n, L) ``c_z^T v_i^k`` [-].
    tau_s : (n,) compliant joint torques [N m].
    """
    tau = np.asarray(tau_s, dtype=np.float64)
    a_plus, a_minus, unbounded = worst_case_coefficients(h, c)
    with np.errstate(invalid='ignore'):
        value = np.where(tau > 0.0, a_plus * tau, np.where(tau < 0.0, a_minus * tau, 0.0))
    value = np.where(np.isnan(value), np.inf, value)
    status = np.where(np.isinf(value) & (value > 0), STATUS_INFEASIBLE, STATUS_BOUNDED)
    feasible = status != STATUS_INFEASIBLE
    value = np.where(unbounded & feasible, -np.inf, value)
    status = np.where(unbounded & feasible, STATUS_UNBOUNDED, status).astype(object)
    return WorstCase(value=value, status=status)


def worst_case_cone(h_0: float, h_1: float, c_0: float, c_1: float,
                    cos_phi: Sequence[float], tau: float) -> tuple[float, str]:
    """Worst case of one finger in pure float math (the scalar twin of the numpy functions).

    For a contact in the finger plane the span vectors of eq. (7) give
    ``h_k = J^T v^k = h_0 + h_1 cos(phi_k)`` and ``c_k = c_z^T v^k = c_0 + c_1 cos(phi_k)``
    (with ``h_0 = cos(alpha) J^T n_in``, ``h_1 = sin(alpha) J^T t``, ``c_0 = cos(alpha)
    c_z^T n_in``, ``c_1 = sin(alpha) c_z^T t``; the axial parts add no torque and no lift).
    Same closed form of the one-constraint LP (eqs. 14-18) as :func:`recession_unbounded`,
    :func:`worst_case_coefficients` and :func:`worst_case_vertical_force` applied to
    ``h_0 + h_1 * cos_phi``, with the same tolerances and floating-point operations (scalar
    loops beat numpy at L = 8). ``max |h_k|`` is taken at the extreme ``cos(phi_k)``: rounding
    is monotone, so the computed ``h_k`` are monotone in ``cos(phi_k)`` as the exact ones are.

    Parameters
    ----------
    h_0, h_1 : [m]; c_0, c_1 : [-]; finite.
    cos_phi : L values ``cos(2 pi k / L)``.
    tau : compliant joint torque tau_s [N m].

    Returns
    -------
    value : minimum of ``c_z^T f_c`` [N]; -inf unbounded, +inf infeasible.
    status : ``'bounded'``, ``'unbounded'`` or ``'infeasible'``.
    """
    scale = max(abs(h_0 + h_1 * max(cos_phi)), abs(h_0 + h_1 * min(cos_phi)))
    if not scale > 0.0:
        scale = 1.0
    tol = TORQUE_ZERO_TOL * scale
    inf = math.inf
    a_plus, a_minus = inf, -inf  # min c/h over h > tol, max c/h over h < -tol
    r_pos = r_neg = inf  # min c/|hn| over the positive and the negative hn = h / scale
    zero_ray = False
    for x in cos_phi:
        hk = h_0 + h_1 * x
        ck = c_0 + c_1 * x
        hn = hk / scale
        if hn > TORQUE_ZERO_TOL:
            if ck / hn < r_pos:
                r_pos = ck / hn
        elif hn < -TORQUE_ZERO_TOL:
            if ck / -hn < r_neg:
                r_neg = ck / -hn
        elif ck < 0.0:
            zero_ray = True
        if hk > tol:
            if ck / hk < a_plus:
                a_plus = ck / hk
        elif hk < -tol and ck / hk > a_minus:
            a_minus = ck / hk
    if tau > 0.0:
        value = a_plus * tau
    elif tau < 0.0:
        value = a_minus * tau
    else:
        value = 0.0
    if value == inf or value != value:
        return inf, STATUS_INFEASIBLE
    if zero_ray or r_pos + r_neg < 0.0:  # a torque-free internal force pulls down
        return -inf, STATUS_UNBOUNDED
    return value, STATUS_BOUNDED


def enumerate_worst_case(jacobians: np.ndarray, span: list[np.ndarray], tau_s: np.ndarray
                         ) -> tuple[float, int]:
    """The literal procedure of eqs. (10)-(17): enumerate one span vector per finger.

    For every combination ``k = (k_1, ..., k_n)`` the selection matrices are built
    (``S`` picks lambda_i^{k_i}, eq. 14; ``S*`` the other L-1 components of every finger,
    eq. 15), ``Phi = -D^{-1} S* H^# tau_s`` with ``D = S* N`` (eq. 16) and
    ``f_o = E V (I - N D^{-1} S*) H^# tau_s`` (eq. 17). Combinations with a singular ``D``
    or with ``S lambda < 0`` are not admissible.

    Parameters
    ----------
    jacobians : (n, 3) J_i.
    span : n arrays (3, L), the V_i.
    tau_s : (n,) [N m].

    Returns
    -------
    min_fz : smallest ``c_z^T f_o`` over the admissible combinations [N] (+inf if none).
    n_admissible : number of admissible combinations.

    Notes
    -----
    This enumerates vertices only: it cannot detect an unbounded worst case (see the module
    docstring); :func:`worst_case_vertical_force` does.
    """
    n = len(span)
    n_faces = span[0].shape[1]
    h = h_matrix(jacobians, span)
    h_pinv = np.linalg.pinv(h)
    null = null_space_basis(h)
    import scipy.linalg  # noqa: PLC0415 (here: importing scipy is a node's start-up time)

    big_v = scipy.linalg.block_diag(*span)  # V (3n, L n)
    e = np.hstack([np.eye(3)] * n)  # E (3, 3n)
    ev = e @ big_v
    lam0 = h_pinv @ np.asarray(tau_s, dtype=np.float64)
    best = math.inf
    count = 0
    eye = np.eye(n * n_faces)
    for combo in itertools.product(range(n_faces), repeat=n):
        chosen = [i * n_faces + k for i, k in enumerate(combo)]
        others = [j for j in range(n * n_faces) if j not in chosen]
        s_star = eye[others]
        d = s_star @ null
        if np.linalg.cond(d) > 1e12:  # singular D: the chosen edge gives no torque
            continue
        phi = -np.linalg.solve(d, s_star @ lam0)
        lam = lam0 + null @ phi
        if np.any(lam[chosen] < -1e-12 * max(1.0, np.abs(lam).max())):
            continue
        fz = float((ev @ lam)[2])
        count += 1
        best = min(best, fz)
    return best, count
