"""Joint impedance of the compliant joints (paper section 3.2).

Every finger ``i`` has one compliant joint ``s_i`` driven by the impedance law

.. math:: \\tau_{si} = k_{\\theta i} (\\theta_{0i} - \\theta_i) - d \\dot\\theta_i,

saturated at the torque limit. The equilibrium :math:`\\theta_{0i}` is the posture latched at
first contact, so that with :math:`\\Delta\\theta_{si} = \\theta_i - \\theta_{0i}` the static
torque is the paper's :math:`\\tau_s = -K_\\theta \\Delta\\theta_s` and :math:`\\tau_s = 0` in
the initial state. ``K_theta = diag(k_theta_1 .. k_theta_n)`` with
``k_theta_i = stiffness_ratio_i * k_theta`` (paper: ``k_theta2 = k_theta3 = k_theta1 / 2``).

The law runs in one of two places: by default on the device, which receives ``theta_0``,
``k_theta_i`` and ``d`` in its joint mode IMPEDANCE and applies the law at its physics rate
(``docs/device_protocol.md``); with ``impedance_on_device`` false, in the controller, which
calls :func:`impedance_torque` every cycle and sends the torque. The functions here are the
reference of that law (the stand-in's and the lockstep experiment's are checked against the
same closed forms).

All functions are vectorised over fingers and free of ROS.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dam_spcm_controller._validate import finite_scalar, finite_vector


def finger_stiffness(k_theta: float, stiffness_ratios: np.ndarray) -> np.ndarray:
    """Per-finger compliant-joint stiffness ``k_theta_i = ratio_i * k_theta``.

    Parameters
    ----------
    k_theta
        Stiffness of finger 1 (the paper's ``k_theta``) [N*m/rad], positive.
    stiffness_ratios
        (n,) ``k_theta_i / k_theta`` [-], positive.

    Returns
    -------
    numpy.ndarray
        (n,) diagonal of ``K_theta`` [N*m/rad].
    """
    k = finite_scalar('k_theta', k_theta, positive=True)
    ratios = finite_vector('stiffness_ratios', stiffness_ratios, positive=True)
    return k * ratios


def delta_theta_s(theta: np.ndarray, theta_0: np.ndarray) -> np.ndarray:
    """Compliant-joint displacement from the contact posture, ``theta - theta_0`` [rad]."""
    return np.asarray(theta, dtype=np.float64) - np.asarray(theta_0, dtype=np.float64)


def tau_s_static(k_theta_i: np.ndarray, theta: np.ndarray, theta_0: np.ndarray) -> np.ndarray:
    """Static compliant torque ``tau_s = -K_theta delta_theta_s`` [N*m] (no damping, no limit)."""
    return -np.asarray(k_theta_i, dtype=np.float64) * delta_theta_s(theta, theta_0)


@dataclass(frozen=True)
class ImpedanceGains:
    """Gains of the compliant joints of all fingers.

    Attributes
    ----------
    k_theta_i
        (n,) stiffness per finger [N*m/rad], positive.
    damping
        Joint damping ``d`` [N*m*s/rad], non-negative, the same for every finger.
    torque_limit
        Symmetric saturation ``|tau| <= torque_limit`` [N*m], positive.
    """

    k_theta_i: np.ndarray
    damping: float
    torque_limit: float

    def __post_init__(self) -> None:
        object.__setattr__(self, 'k_theta_i',
                           finite_vector('k_theta_i', self.k_theta_i, positive=True))
        object.__setattr__(self, 'damping',
                           finite_scalar('damping', self.damping, nonnegative=True))
        object.__setattr__(self, 'torque_limit',
                           finite_scalar('torque_limit', self.torque_limit, positive=True))

    @classmethod
    def from_ratios(cls, k_theta: float, stiffness_ratios: np.ndarray, damping: float,
                    torque_limit: float) -> ImpedanceGains:
        """Gains with ``k_theta_i = stiffness_ratio_i * k_theta`` (see :func:`finger_stiffness`)."""
        return cls(finger_stiffness(k_theta, stiffness_ratios), damping, torque_limit)

    @property
    def n_fingers(self) -> int:
        return int(self.k_theta_i.shape[0])


def impedance_torque(gains: ImpedanceGains, theta_0: np.ndarray, theta: np.ndarray,
                     theta_dot: np.ndarray) -> np.ndarray:
    """Saturated impedance torque of the compliant joints.

    ``tau_i = clip(k_theta_i (theta_0i - theta_i) - d theta_dot_i, -limit, +limit)``.

    Parameters
    ----------
    gains
        Stiffness, damping and torque limit.
    theta_0
        (n,) equilibrium (contact posture) [rad].
    theta
        (n,) measured compliant-joint angles [rad]; positive = flexion inward.
    theta_dot
        (n,) measured compliant-joint velocities [rad/s].

    Returns
    -------
    numpy.ndarray
        (n,) torque command [N*m]; positive flexes the finger towards the object.

    Raises
    ------
    InputError
        An array has the wrong length or holds NaN/inf.
    """
    n = gains.n_fingers
    theta_0 = finite_vector('theta_0', theta_0, n)
    theta = finite_vector('theta', theta, n)
    theta_dot = finite_vector('theta_dot', theta_dot, n)
    return _impedance_unchecked(gains.k_theta_i, gains.damping, gains.torque_limit,
                                theta_0, theta, theta_dot)


def _impedance_unchecked(k_theta_i: np.ndarray, damping: float, torque_limit: float,
                         theta_0: np.ndarray, theta: np.ndarray,
                         theta_dot: np.ndarray) -> np.ndarray:
    """:func:`impedance_torque` without input checks, for the control loop (internal)."""
    tau = k_theta_i * (theta_0 - theta) - damping * theta_dot
    return np.clip(tau, -torque_limit, torque_limit)

