"""The driver's torque slew limit: how fast the commands it sends may change (no rclpy).

The device bounds the rate of change of every torque it applies (``docs/device_protocol.md``,
"Torque slew limit"); the driver bounds the change its own commands ask for, so that the bound
also holds against a device that does not slew. Per command frame (one per state frame) it
moves

* a TORQUE setpoint by at most ``rate * period`` [N*m] (:func:`slew_torque`), starting from
  the joint's measured torque when the joint enters TORQUE;
* an IMPEDANCE equilibrium ``theta_0`` by at most ``rate * period / k`` [rad], so that the
  torque change the command causes, ``k * |delta theta_0|``, is at most ``rate * period``;
  starting, when the joint enters IMPEDANCE or its gains change, from the equilibrium at which
  the law gives the measured torque: ``theta + (tau + d theta_dot) / k``.

The step is per frame, not per elapsed time: the device applies a command for at least one of
its cycles, so a late frame slows the ramp down instead of making it steeper. The law's response
to the joint's own motion is not slewed here (that would put a rate limit, one frame late, into
the impedance loop); the device limits it.
"""

from __future__ import annotations

import numpy as np

from dam_common.device_protocol import JointMode
from dam_common.scalars import clip
from dam_hand_driver.errors import ParameterError

_TORQUE = int(JointMode.TORQUE)
_IMPEDANCE = int(JointMode.IMPEDANCE)


def slew_torque(previous_nm: np.ndarray, target_nm: np.ndarray, limit_nm: float,
                rate_nm_per_s: float, dt_s: float) -> np.ndarray:
    """Clamp ``target_nm`` to +-``limit_nm`` and move towards it from ``previous_nm`` by at
    most ``rate_nm_per_s * dt_s`` [N*m]."""
    target = np.clip(target_nm, -limit_nm, limit_nm)
    step = rate_nm_per_s * max(0.0, dt_s)
    return previous_nm + np.clip(target - previous_nm, -step, step)


class CommandSlew:
    """The per-frame slew of the TORQUE setpoints and IMPEDANCE equilibria of all joints.

    Parameters
    ----------
    n_joints
        Number of joints.
    torque_limit_nm
        Actuator limit [N*m]: TORQUE setpoints are clamped to +-this.
    rate_nm_per_s
        Slew limit [N*m/s] (``device.torque_rate_limit_nm_per_s``), positive.
    period_s
        One device cycle [s] (``1 / device.rate_hz``): the time one command frame stands for.

    Raises
    ------
    ParameterError
        A limit, rate or period that is not a positive finite number.
    """

    def __init__(self, n_joints: int, torque_limit_nm: float, rate_nm_per_s: float,
                 period_s: float) -> None:
        for name, value in (('torque_limit_nm', torque_limit_nm),
                            ('rate_nm_per_s', rate_nm_per_s), ('period_s', period_s)):
            if not (np.isfinite(value) and value > 0.0):
                raise ParameterError(f'{name} {value!r} must be a positive number')
        self.n_joints = int(n_joints)
        self.torque_limit_nm = float(torque_limit_nm)
        self.rate_nm_per_s = float(rate_nm_per_s)
        self.period_s = float(period_s)
        #: Largest change of a TORQUE setpoint, or of ``k theta_0``, per frame [N*m].
        self.max_change_nm = self.rate_nm_per_s * self.period_s
        # Per joint, as plain lists (a frame touches nine numbers: numpy's per-call overhead
        # would dominate): the mode, the torque [N*m] or theta_0 [rad] sent last, the gains.
        self._modes: list[int] = [0] * self.n_joints
        self._sent: list[float] = [0.0] * self.n_joints
        self._stiffness: list[float] = [0.0] * self.n_joints
        self._damping: list[float] = [0.0] * self.n_joints

    def reset(self) -> None:
        """Forget the commands sent so far: every joint starts afresh from its measurement."""
        self._modes = [0] * self.n_joints

    def step(self, modes: np.ndarray, setpoints: np.ndarray, stiffness: np.ndarray,
             damping: np.ndarray, theta_rad: np.ndarray, theta_dot_rad_per_s: np.ndarray,
             torque_nm: np.ndarray) -> np.ndarray:
        """The setpoints to send in this frame.

        Parameters
        ----------
        modes
            (n,) :class:`~dam_common.device_protocol.JointMode` values of the command.
        setpoints
            (n,) commanded setpoints (SI): torque [N*m] (TORQUE), angle [rad] (POSITION,
            IMPEDANCE ``theta_0``), ignored (HOLD).
        stiffness, damping
            (n,) impedance gains [N*m/rad], [N*m*s/rad]; ``stiffness > 0`` on IMPEDANCE joints.
        theta_rad, theta_dot_rad_per_s, torque_nm
            (n,) the state frame this command answers: angles [rad], velocities [rad/s] and
            torque-sensor readings [N*m].

        Returns
        -------
        numpy.ndarray
            (n,) setpoints with the TORQUE torques and IMPEDANCE equilibria slewed; the others
            as given.
        """
        m = np.asarray(modes, dtype=np.int64).tolist()
        out = np.asarray(setpoints, dtype=float).tolist()
        k = np.asarray(stiffness, dtype=float).tolist()
        d = np.asarray(damping, dtype=float).tolist()
        theta = np.asarray(theta_rad, dtype=float).tolist()
        theta_dot = np.asarray(theta_dot_rad_per_s, dtype=float).tolist()
        tau = np.asarray(torque_nm, dtype=float).tolist()
        limit = self.torque_limit_nm
        step = self.rate_nm_per_s * max(0.0, self.period_s)
        max_change = self.max_change_nm
        old_modes, old_k, old_d = self._modes, self._stiffness, self._damping
        sent = [0.0] * self.n_joints
        new_k = [0.0] * self.n_joints
        new_d = [0.0] * self.n_joints
        for i, mode in enumerate(m):
            if mode == _TORQUE:
                # slew_torque, from the measured torque when the joint enters TORQUE
                previous = (clip(tau[i], -limit, limit) if old_modes[i] != _TORQUE
                            else self._sent[i])
                target = clip(out[i], -limit, limit)
                out[i] = previous + clip(target - previous, -step, step)
                sent[i] = out[i]
            elif mode == _IMPEDANCE:
                if old_modes[i] != _IMPEDANCE or k[i] != old_k[i] or d[i] != old_d[i]:
                    # restart where the law gives the measured torque
                    previous = theta[i] + (clip(tau[i], -limit, limit)
                                           + d[i] * theta_dot[i]) / k[i]
                else:
                    previous = self._sent[i]
                shift = max_change / k[i]
                gap = out[i] - previous
                if not abs(gap) <= shift:
                    out[i] = previous + clip(gap, -shift, shift)
                sent[i] = out[i]
                new_k[i] = k[i]
                new_d[i] = d[i]
        self._sent = sent
        self._modes = m
        self._stiffness = new_k
        self._damping = new_d
        return np.array(out)


