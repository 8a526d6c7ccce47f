"""An independent solution of the SPCM closure (Kaneko et al., eqs. 2-4), for tests.

Written from the configuration alone, without ``dam_analysis``. In its vertical plane a finger
is three links at cumulative angles ``phi_1 = theta_s``, ``phi_2 = phi_1 + theta_l``,
``phi_3 = phi_2 + theta_p``, each pointing along ``(sin phi, -cos phi)`` from the compliant
joint; the fingertip is a sphere of radius ``r`` around the end ``T`` of the distal link and the
object a disc of radius ``R`` around ``c``. For a contact on the fingertip, eq. 2 (the point
lies on both surfaces), eq. 3 (one point) and eq. 4 (opposite normals, ``n_CF = -n_CB``) say

    T(theta_s, theta_p) - c - (R + r) (cos psi, sin psi) = 0,

two equations in ``(theta_s, psi)`` with ``n_CB = (cos psi, sin psi)``. The branch is followed
from the first contact with ``scipy.optimize.fsolve``; it ends where the Jacobian with
respect to ``(theta_s, psi)`` is singular (a fold), found with ``fsolve`` on the closure plus
``det J = 0``. The fingertip formulation holds while the closest point of the distal link to
``c`` is its end (:meth:`PlanarFinger.on_fingertip`); the callers check it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import brentq, fsolve


@dataclass(frozen=True)
class PlanarFinger:
    """One finger and the object in the finger plane (lengths [m], angles [rad])."""

    lengths: tuple[float, float, float]
    tip_radius: float
    centre: tuple[float, float]  # cylinder axis (u, z) relative to the compliant joint
    object_radius: float
    theta_l: float
    theta_p0: float

    @classmethod
    def from_config(cls, config, index: int) -> PlanarFinger:
        finger = config.hand.fingers[index]
        base = np.asarray(finger.base_position_m, dtype=float)
        rel = np.asarray(config.object.position_m, dtype=float) - base
        inward = np.asarray(finger.inward_direction, dtype=float)
        return cls(lengths=tuple(float(v) for v in config.hand.link_lengths_m),
                   tip_radius=float(config.hand.link_radius_m),
                   centre=(float(rel @ inward), float(rel[2])),
                   object_radius=float(config.object.radius_m),
                   theta_l=float(config.hand.initial_locked_angle_rad),
                   theta_p0=float(config.hand.initial_position_angle_rad))

    def _angles(self, theta_s: float, theta_p: float) -> tuple[float, float, float]:
        return theta_s, theta_s + self.theta_l, theta_s + self.theta_l + theta_p

    def joints(self, theta_s: float, theta_p: float) -> tuple[np.ndarray, np.ndarray]:
        """Position joint ``Q`` and fingertip centre ``T``, (2,) each [m]."""
        points = [np.zeros(2)]
        for length, phi in zip(self.lengths, self._angles(theta_s, theta_p), strict=True):
            points.append(points[-1] + length * np.array([math.sin(phi), -math.cos(phi)]))
        return points[2], points[3]

    def closure(self, x: np.ndarray, theta_p: float) -> np.ndarray:
        """Eqs. 2-4 on the fingertip, (2,) [m]; ``x = (theta_s, psi)``."""
        theta_s, psi = x
        _, tip = self.joints(theta_s, theta_p)
        reach = self.object_radius + self.tip_radius
        return tip - np.asarray(self.centre) - reach * np.array([math.cos(psi), math.sin(psi)])

    def jacobian(self, x: np.ndarray, theta_p: float) -> np.ndarray:
        """d closure / d (theta_s, psi), (2, 2) [m/rad]."""
        theta_s, psi = x
        d_tip = sum(length * np.array([math.cos(phi), math.sin(phi)])
                    for length, phi in zip(self.lengths, self._angles(theta_s, theta_p),
                                           strict=True))
        reach = self.object_radius + self.tip_radius
        return np.column_stack([d_tip, reach * np.array([math.sin(psi), -math.cos(psi)])])

    def on_fingertip(self, theta_s: float, theta_p: float) -> bool:
        """The closest point of the distal link to the object's axis is the fingertip centre."""
        q, tip = self.joints(theta_s, theta_p)
        return float((np.asarray(self.centre) - tip) @ (q - tip)) <= 0.0

    def tip_distance(self, theta_s: float, theta_p: float) -> float:
        """``|T - c| - (R + r)`` [m]: the fingertip's gap to the object."""
        _, tip = self.joints(theta_s, theta_p)
        return float(np.hypot(*(tip - np.asarray(self.centre)))) - (
            self.object_radius + self.tip_radius)


def first_contact(finger: PlanarFinger) -> np.ndarray:
    """``(theta_s, psi)`` where the closing fingertip first touches the object (theta_p0)."""
    theta_p = finger.theta_p0
    lo = 0.0
    while finger.tip_distance(lo + math.radians(0.5), theta_p) > 0.0:
        lo += math.radians(0.5)
    theta_s = brentq(finger.tip_distance, lo, lo + math.radians(0.5), args=(theta_p,),
                     xtol=1e-15)
    _, tip = finger.joints(theta_s, theta_p)
    rel = tip - np.asarray(finger.centre)
    return np.array([theta_s, math.atan2(rel[1], rel[0])])


def _solve(finger: PlanarFinger, start: np.ndarray, theta_p: float) -> np.ndarray | None:
    x = fsolve(finger.closure, start, args=(theta_p,), fprime=finger.jacobian, xtol=1e-14,
               full_output=True)[0]
    # judged by the residual: fsolve also reports "no further improvement" once converged
    if np.max(np.abs(finger.closure(x, theta_p))) > 1e-15:
        return None
    return x


@dataclass(frozen=True)
class ReferenceBranch:
    """The branch followed on a grid and its fold.

    Attributes
    ----------
    delta_theta_p : (m,) grid of solved displacements [rad]; states : (m, 2) ``(theta_s, psi)``.
    fold_delta_theta_p : displacement of the fold [rad]; fold_state : (2,) there.
    """

    finger: PlanarFinger
    delta_theta_p: np.ndarray
    states: np.ndarray
    fold_delta_theta_p: float
    fold_state: np.ndarray


def follow_branch(finger: PlanarFinger, step: float = math.radians(0.25),
                  dp_max: float = math.radians(90.0)) -> ReferenceBranch:
    """Continuation in ``delta_theta_p`` until the solution ceases or ``det J`` changes sign,
    then ``fsolve`` on ``(closure, det J) = 0`` for ``(theta_s, psi, theta_p)``."""
    x = first_contact(finger)
    dps, states = [0.0], [x]
    det0 = np.linalg.det(finger.jacobian(x, finger.theta_p0))
    dp = 0.0
    while dp + step <= dp_max:
        guess = states[-1]
        if len(states) > 1:  # linear predictor
            guess = 2.0 * states[-1] - states[-2]
        nxt = _solve(finger, guess, finger.theta_p0 + dp + step)
        if nxt is None or np.linalg.det(finger.jacobian(nxt, finger.theta_p0 + dp + step)) \
                * det0 <= 0.0 or abs(nxt[0] - states[-1][0]) > 0.1:
            break
        dp += step
        dps.append(dp)
        states.append(nxt)
    else:
        raise AssertionError('the reference branch has no fold below dp_max')

    def fold_equations(y: np.ndarray) -> np.ndarray:
        x_, theta_p = y[:2], y[2]
        return np.append(finger.closure(x_, theta_p), np.linalg.det(finger.jacobian(x_, theta_p))
                         * 1e2)

    start = np.append(states[-1], finger.theta_p0 + dp)
    y, _, _, msg = fsolve(fold_equations, start, full_output=True, xtol=1e-14)
    assert np.max(np.abs(fold_equations(y))) < 1e-15, (fold_equations(y), msg)
    return ReferenceBranch(finger, np.array(dps), np.array(states), float(y[2] - finger.theta_p0),
                           y[:2])


def theta_s_near_fold(branch: ReferenceBranch, delta_theta_p: float) -> np.ndarray:
    """``(theta_s, psi)`` on the branch between its last grid point and the fold.

    Near the fold two solutions are close; the branch's one lies between the last grid state
    and the fold in ``theta_s``, where the fingertip distance changes sign (Brent's method).
    """
    finger = branch.finger
    theta_p = finger.theta_p0 + delta_theta_p
    lo, hi = float(branch.states[-1][0]), float(branch.fold_state[0])
    theta_s = brentq(finger.tip_distance, lo, hi, args=(theta_p,), xtol=1e-16, rtol=1e-15)
    _, tip = finger.joints(theta_s, theta_p)
    rel = tip - np.asarray(finger.centre)
    return np.array([theta_s, math.atan2(rel[1], rel[0])])
