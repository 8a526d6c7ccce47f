"""Minimum-jerk (quintic) trajectory of the position-controlled joints.

The position joints move from ``theta_start`` (paper section 4: 15 deg) by ``delta_theta_p``
(paper: to 80 deg) over ``duration`` seconds along

.. math:: \\theta(t) = \\theta_{start} + \\Delta\\theta_p\\, s(\\tau),\\quad
          s(\\tau) = 10\\tau^3 - 15\\tau^4 + 6\\tau^5,\\quad \\tau = t / T,

which has zero velocity and zero acceleration at both ends and is monotonic. Before ``t = 0``
the trajectory rests at the start, after ``t = T`` at the goal.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dam_spcm_controller._validate import finite_scalar, finite_vector


def minimum_jerk_profile(tau: float) -> tuple[float, float, float]:
    """Normalised quintic ``s(tau)`` and its first two derivatives with respect to ``tau``.

    ``tau`` is clamped to [0, 1]; outside that interval the derivatives are zero.
    """
    if tau <= 0.0:
        return 0.0, 0.0, 0.0
    if tau >= 1.0:
        return 1.0, 0.0, 0.0
    t2 = tau * tau
    t3 = t2 * tau
    s = t3 * (10.0 - 15.0 * tau + 6.0 * t2)
    ds = 30.0 * t2 * (1.0 - 2.0 * tau + t2)
    dds = 60.0 * tau * (1.0 - 3.0 * tau + 2.0 * t2)
    return s, ds, dds


@dataclass(frozen=True)
class MinimumJerkTrajectory:
    """Quintic point-to-point motion of one or more joints, all with the same timing.

    Attributes
    ----------
    theta_start
        (n,) start angles [rad].
    delta_theta_p
        (n,) displacement [rad] (the paper's ``delta_theta_p``; may be zero or negative).
    duration
        Motion time ``T`` [s], positive.
    """

    theta_start: np.ndarray
    delta_theta_p: np.ndarray
    duration: float

    def __post_init__(self) -> None:
        start = finite_vector('theta_start', np.atleast_1d(self.theta_start))
        object.__setattr__(self, 'theta_start', start)
        object.__setattr__(self, 'delta_theta_p',
                           finite_vector('delta_theta_p', self.delta_theta_p, len(start)))
        object.__setattr__(self, 'duration',
                           finite_scalar('duration', self.duration, positive=True))

    @property
    def theta_goal(self) -> np.ndarray:
        """(n,) final angles ``theta_start + delta_theta_p`` [rad]."""
        return self.theta_start + self.delta_theta_p

    def phase(self, t: float) -> float:
        """Normalised time ``t / T`` clamped to [0, 1] (``t`` in seconds since the start)."""
        return min(max(t / self.duration, 0.0), 1.0)

    def evaluate(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Angles [rad], velocities [rad/s] and accelerations [rad/s^2] at time ``t`` [s].

        ``t`` is measured from the start of the motion; it is clamped to [0, T].
        """
        s, ds, dds = minimum_jerk_profile(t / self.duration)
        T = self.duration
        d = self.delta_theta_p
        return self.theta_start + d * s, d * (ds / T), d * (dds / (T * T))

    def position(self, t: float) -> np.ndarray:
        """Angles [rad] at time ``t`` [s] (see :meth:`evaluate`)."""
        s, _, _ = minimum_jerk_profile(t / self.duration)
        return self.theta_start + self.delta_theta_p * s
