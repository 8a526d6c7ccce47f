"""A synthetic hand plant for the controller tests (not a simulator recording).

Every joint is a massless joint with viscous friction ``b``. In HOLD/POSITION mode a joint
follows its setpoint through a first-order servo; in TORQUE mode it moves as
``b theta_dot = tau - tau_contact``. In IMPEDANCE mode the plant plays the device as well: the
law ``tau = k (theta_0 - theta) - d theta_dot`` acts inside the step (implicitly in theta_dot:
``(b + d) theta_dot = k (theta_0 - theta) - tau_contact``). The object is modelled per finger
as a contact spring:

* compliant joint: touches the object at ``theta_c(theta_p) = theta_c0 - beta (theta_p -
  theta_p0)`` -- as the position joint curls, the object pushes the compliant joint outward,
  the essence of SPCM (paper Fig. 4);
* position joint (ENVELOPE, torque mode): a wall at ``wall_p`` where the distal link wraps the
  object.

The torque sensor reads the applied motor torque (TORQUE: the command; IMPEDANCE: the law).
Mechanical stops clamp every joint at its limits. Removing the object
(``object_present = False``) removes both springs.
"""

from __future__ import annotations

import math

import numpy as np

from dam_spcm_controller.commands import HandLayout, JointCommand, JointMode


class SyntheticHand:
    def __init__(self, layout: HandLayout, *, theta_c0_deg: float | list[float] = 20.0,
                 beta: float = 0.3, k_contact: float = 5.0, wall_p_deg: float = 85.0,
                 b: float = 0.02, servo_time: float = 0.01, k_servo: float = 2.0,
                 start_deg: tuple[float, float, float] = (0.0, 0.0, 15.0)) -> None:
        self.lay = layout
        n = layout.n_fingers
        self.n = n
        self.theta_c0 = np.radians(np.broadcast_to(theta_c0_deg, (n,))).astype(float)
        self.theta_p0 = layout.initial_position_angle
        self.beta = beta
        self.k_contact = k_contact
        self.wall_p = math.radians(wall_p_deg)
        self.b = b
        self.servo_time = servo_time
        self.k_servo = k_servo
        self.q = np.tile(np.radians(start_deg), n)
        self.qd = np.zeros(3 * n)
        self.effort = np.zeros(3 * n)
        self.object_present = np.ones(n, dtype=bool)

    def contact_torques(self) -> tuple[np.ndarray, np.ndarray]:
        """Torques the object exerts on (compliant, position) joints, opposing flexion."""
        th_c = self.q[0::3]
        th_p = self.q[2::3]
        theta_c = self.theta_c0 - self.beta * (th_p - self.theta_p0)
        pen_c = np.where(self.object_present, np.maximum(th_c - theta_c, 0.0), 0.0)
        pen_p = np.where(self.object_present, np.maximum(th_p - self.wall_p, 0.0), 0.0)
        return self.k_contact * pen_c, self.k_contact * pen_p

    def apply(self, cmd: JointCommand, dt: float) -> None:
        tau_c, tau_p = self.contact_torques()
        load = np.zeros(3 * self.n)
        load[0::3] = tau_c
        load[2::3] = tau_p
        torque = cmd.modes == JointMode.TORQUE
        impedance = cmd.modes == JointMode.IMPEDANCE
        new_q = self.q.copy()
        # torque-mode joints
        qd_t = (cmd.setpoints - load) / self.b
        new_q[torque] = self.q[torque] + dt * qd_t[torque]
        # impedance joints: the device law, implicit in the velocity
        k, d = cmd.stiffness, cmd.damping
        qd_i = (k * (cmd.setpoints - self.q) - load) / (self.b + d)
        new_q[impedance] = self.q[impedance] + dt * qd_i[impedance]
        # position-mode joints: first-order servo
        alpha = min(dt / self.servo_time, 1.0)
        servo = self.q + alpha * (cmd.setpoints - self.q)
        servoed = ~(torque | impedance)
        new_q[servoed] = servo[servoed]
        new_q = np.clip(new_q, self.lay.lower, self.lay.upper)
        self.qd = (new_q - self.q) / dt
        tau_i = k * (cmd.setpoints - self.q) - d * self.qd
        self.effort = np.where(torque, cmd.setpoints,
                               np.where(impedance, tau_i,
                                        self.k_servo * (cmd.setpoints - self.q) + load))
        self.q = new_q


def run(seq, hand: SyntheticHand, t0: float, t_end: float, dt: float = 1e-3,
        until=None, on_step=None):
    """Step controller and plant from ``t0`` to ``t_end``; return (t, list of records)."""
    t = t0
    log = []
    while t <= t_end + 1e-12:
        cmd = seq.step(t, hand.q, hand.qd, hand.effort)
        log.append((t, seq.phase, cmd, hand.q.copy(), hand.effort.copy()))
        if on_step is not None:
            on_step(t, seq, hand)
        if until is not None and until(seq):
            return t, log
        hand.apply(cmd, dt)
        t = round(t + dt, 9)
    return t, log
