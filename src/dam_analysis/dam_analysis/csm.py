"""Contact stiffness model (CSM, Kaneko et al. section 3.3): unique contact forces.

The sufficient condition (:mod:`dam_analysis.lift`) considers every force inside the friction
cone. With a contact stiffness ``K_pi`` the force is unique. The model (derived in
``docs/analysis.md``):

* The object is held fixed during the SPCM (as in section 3.2); each finger and its contact
  spring act in series. ``K_pi = diag(k_n, k_t, k_b)`` in the contact frame (normal ``n_in``
  into the object, in-plane tangent ``t = b x n_CB``, axial ``b``).
* Normal: the penetration ``f_n / k_n`` is microns (``k_n = 1e5 N/m`` against a joint stiffness
  of the order of ``k_theta / |J|^2``), so the geometry is the rigid SPCM one and the normal
  force follows from the compliant-joint torque balance
  ``tau_s = J^T f_c = h_n f_n + h_t f_t`` with ``h_n = J^T n_in``, ``h_t = J^T t`` and
  ``tau_s = -k_theta delta_theta_s``: the same torque as in the sufficient condition.
* Tangential: a spring-slider (play operator). The tangential spring stretches with the slip
  ``s``, the tangential displacement of the finger's material point at the contact relative to
  the fixed object, accumulated along the SPCM path
  (``ds/d delta_theta_p = t^T v_c``, ``v_c = (d theta_s / d theta_p) a x (p_C - p_s)
  + a x (p_C - p_p)``). The force on the object is ``f_t = k_t delta``; while
  ``|f_t| <= mu f_n`` the contact sticks, otherwise it slides with ``f_t = sign(delta) mu f_n``
  (on the cone boundary, in the direction of the finger's slip, i.e. opposing the object's
  relative slip) and ``delta`` is reset to ``f_t / k_t``.
  Where ``h_n + sign(delta) mu h_t <= 0`` sliding cannot balance the torque (self-locking) and
  the contact sticks.
* A negative normal force means the contact opens: no equilibrium (status ``'separation'``).

Along a path with monotone slip (the default geometry), the play operator has the closed form
``delta = s + min_{nodes <= current}(c - s)`` with ``c = mu f_n^slide / k_t`` proportional to
k_theta, which :func:`csm_forces_grid` evaluates with a cumulative minimum (vectorised over
k_theta); :func:`csm_forces_sequential` is the step-by-step reference for any path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

STATUS_OK = 'ok'
STATUS_SEPARATION = 'separation'
STATUS_NO_PATH = 'no_spcm'


@dataclass(frozen=True)
class CsmPath:
    """Per-finger quantities along the SPCM grid that the CSM needs (all (m,) arrays).

    Attributes
    ----------
    delta_theta_p : grid [rad].
    tau_hat : ``-delta_theta_s`` [rad]; ``tau_s = k_theta_i * tau_hat``.
    h_n, h_t : ``J^T n_in``, ``J^T t`` [m].
    cz_n, cz_t : vertical components of ``n_in`` and ``t`` [-].
    slip : accumulated tangential slip of the finger material point, along ``t`` [m].
    """

    delta_theta_p: np.ndarray
    tau_hat: np.ndarray
    h_n: np.ndarray
    h_t: np.ndarray
    cz_n: np.ndarray
    cz_t: np.ndarray
    slip: np.ndarray

    @property
    def monotone(self) -> bool:
        """True when the slip never changes direction on the valid part of the path."""
        ds = np.diff(self.slip[np.isfinite(self.slip)])
        return bool(np.all(ds >= 0.0) or np.all(ds <= 0.0))

    @property
    def slip_sign(self) -> float:
        """Direction of the (monotone) slip, +1 or -1."""
        finite = self.slip[np.isfinite(self.slip)]
        return -1.0 if finite.size and finite[-1] < 0.0 else 1.0


def _sliding_denominator(path: CsmPath, sign: float, mu: float) -> np.ndarray:
    return path.h_n + sign * mu * path.h_t


def csm_forces_grid(path: CsmPath, k_theta_i: np.ndarray, friction_angle: float,
                    k_t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """CSM contact force of one finger at every grid node, closed-form play operator.

    Only valid when ``path.monotone``.

    Parameters
    ----------
    path : CSM path data of the finger.
    k_theta_i : (K,) compliant joint stiffness of this finger [N m/rad].
    friction_angle : alpha [rad].
    k_t : tangential contact stiffness [N/m].

    Returns
    -------
    f_n, f_t : (K, m) normal and tangential force on the object [N].
    separated : (K, m) bool, the contact would have to pull (no equilibrium).
    """
    k = np.asarray(k_theta_i, dtype=np.float64)[:, None]
    mu = math.tan(friction_angle)
    sign = path.slip_sign
    denom = _sliding_denominator(path, sign, mu)
    tau = k * path.tau_hat[None, :]
    with np.errstate(divide='ignore', invalid='ignore'):
        cap = np.where(denom > 0.0, mu * tau / (k_t * denom), np.inf)  # c, (K, m)
    s = sign * path.slip[None, :]
    delta = s + np.minimum.accumulate(cap - s, axis=1)
    sliding = (denom > 0.0) & (delta >= cap * (1.0 - 1e-12))
    with np.errstate(divide='ignore', invalid='ignore'):
        f_n_slide = tau / denom
        f_t_stick = k_t * delta * sign
        f_n_stick = (tau - path.h_t * f_t_stick) / path.h_n
    f_n = np.where(sliding, f_n_slide, f_n_stick)
    f_t = np.where(sliding, sign * mu * f_n_slide, f_t_stick)
    separated = f_n < 0.0
    return f_n, f_t, separated


def csm_forces_sequential(path: CsmPath, k_theta_i: np.ndarray, friction_angle: float,
                          k_t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Step-by-step spring-slider along the grid (reference; any slip history).

    Same parameters and returns as :func:`csm_forces_grid`.
    """
    k = np.asarray(k_theta_i, dtype=np.float64)
    mu = math.tan(friction_angle)
    m = path.tau_hat.size
    f_n = np.zeros((k.size, m))
    f_t = np.zeros((k.size, m))
    delta = np.zeros(k.size)
    for j in range(m):
        ds = path.slip[j] - path.slip[j - 1] if j > 0 else 0.0
        tau = k * path.tau_hat[j]
        trial = delta + ds
        ft_trial = k_t * trial
        fn_trial = (tau - path.h_t[j] * ft_trial) / path.h_n[j]
        sign = np.where(trial >= 0.0, 1.0, -1.0)
        denom = path.h_n[j] + sign * mu * path.h_t[j]
        slide = (np.abs(ft_trial) > mu * fn_trial) & (denom > 0.0)
        with np.errstate(divide='ignore', invalid='ignore'):
            fn_slide = tau / denom
        f_n[:, j] = np.where(slide, fn_slide, fn_trial)
        f_t[:, j] = np.where(slide, sign * mu * fn_slide, ft_trial)
        delta = f_t[:, j] / k_t
    return f_n, f_t, f_n < 0.0


def vertical_force(path: CsmPath, f_n: np.ndarray, f_t: np.ndarray) -> np.ndarray:
    """``c_z^T f_ci`` [N] from the normal and tangential components."""
    return f_n * path.cz_n + f_t * path.cz_t
