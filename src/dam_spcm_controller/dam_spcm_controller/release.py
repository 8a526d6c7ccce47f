"""Letting go: release the grasped object and open the hand (no rclpy).

After DONE the controller keeps commanding the enveloping grasp, so that the object stays in
the hand. :class:`ReleaseMotion` ends that hold in three stages, all timed by the ``t`` given to
:meth:`ReleaseMotion.step`:

1. ``UNLOAD``: every joint under torque (TORQUE, or IMPEDANCE taken at its static torque
   ``k (theta_0 - theta)`` at the first step) ramps linearly to zero torque over
   ``torque_ramp_time``; the other joints HOLD their last setpoint. The object is no longer
   squeezed.
2. ``OPEN``: the compliant joints HOLD the angle they reached; the position joints follow a
   minimum-jerk motion back to the pre-shape angle ``initial_position_angle``, its peak
   speed ``approach_speed``: the fingertips uncurl and the object is let go.
3. ``OPEN_HELD``: every joint HOLDs the angle measured at the end; this command is the last.
"""

from __future__ import annotations

import enum

import numpy as np

from dam_spcm_controller._validate import finite_scalar, finite_vector
from dam_spcm_controller.commands import JointCommand, JointMode
from dam_spcm_controller.sequence import SequenceParams
from dam_spcm_controller.trajectory import MinimumJerkTrajectory

#: Shortest opening motion [s] (a position joint already open still gets a smooth stop).
MIN_OPEN_DURATION_S = 0.1


class ReleaseStage(enum.Enum):
    """Stage of a :class:`ReleaseMotion`."""

    UNLOAD = 'unload'
    OPEN = 'open'
    OPEN_HELD = 'open_held'


class ReleaseMotion:
    """Release an object held by ``last_command`` and open the hand.

    Parameters
    ----------
    params
        Torque ramp time [s], approach speed [rad/s], joint layout (pre-shape angle).
    last_command
        The command the hand follows now (the held grasp); ``None``: every joint HOLDs its
        measured angle and only the opening runs.
    t
        Time of the first step [s], any origin, as later passed to :meth:`step`.
    positions
        (3n,) measured joint angles [rad] now.

    Raises
    ------
    dam_spcm_controller.errors.InputError
        Non-finite ``t`` or positions, or positions of the wrong length.
    """

    def __init__(self, params: SequenceParams, last_command: JointCommand | None, t: float,
                 positions: np.ndarray) -> None:
        lay = params.layout
        self._p = params
        self._t0 = finite_scalar('t', t)
        pos = finite_vector('positions', positions, lay.n_joints)
        if last_command is None:
            modes = np.full(lay.n_joints, JointMode.HOLD, dtype=np.int8)
            setpoints = pos.copy()
            stiffness = np.zeros(lay.n_joints)
        else:
            modes = np.asarray(last_command.modes, dtype=np.int8).copy()
            setpoints = np.asarray(last_command.setpoints, dtype=np.float64).copy()
            stiffness = np.asarray(last_command.stiffness, dtype=np.float64)
        impedance = modes == JointMode.IMPEDANCE
        # An impedance joint starts the ramp at the torque the device applies statically now.
        setpoints[impedance] = np.clip(stiffness * (setpoints - pos), -params.torque_limit,
                                       params.torque_limit)[impedance]
        modes[impedance] = JointMode.TORQUE
        modes[modes == JointMode.POSITION] = JointMode.HOLD
        self._modes = modes
        self._tau_from = np.where(modes == JointMode.TORQUE, setpoints, 0.0)
        self._setpoints = setpoints
        self._stage = ReleaseStage.UNLOAD
        self._zero_sent = False
        self._t_stage = self._t0
        self._trajectory: MinimumJerkTrajectory | None = None

    @property
    def stage(self) -> ReleaseStage:
        """The current stage."""
        return self._stage

    @property
    def done(self) -> bool:
        """True once every joint HOLDs the open posture (the last command was returned)."""
        return self._stage is ReleaseStage.OPEN_HELD

    def step(self, t: float, positions: np.ndarray) -> JointCommand:
        """The command for time ``t`` [s] given the measured ``positions`` (3n,) [rad]."""
        t = finite_scalar('t', t)
        pos = finite_vector('positions', positions, self._p.layout.n_joints)
        if self._stage is ReleaseStage.UNLOAD:
            self._step_unload(t, pos)
        if self._stage is ReleaseStage.OPEN:
            self._step_open(t, pos)
        return JointCommand(self._modes.copy(), self._setpoints.copy())

    def _step_unload(self, t: float, pos: np.ndarray) -> None:
        ramp = self._p.torque_ramp_time
        elapsed = t - self._t_stage
        scale = 0.0 if ramp <= 0.0 or elapsed >= ramp else 1.0 - elapsed / ramp
        torque = self._modes == JointMode.TORQUE
        self._setpoints[torque] = self._tau_from[torque] * scale
        if scale > 0.0 or not self._zero_sent:
            self._zero_sent = scale == 0.0  # one command at exactly zero torque, then open
            return
        lay = self._p.layout
        self._modes[:] = JointMode.HOLD
        self._setpoints[:] = pos  # compliant (and locked) joints keep where they are
        start = pos[lay.position].copy()
        delta = lay.initial_position_angle - start
        duration = max(MIN_OPEN_DURATION_S,
                       float(np.max(np.abs(delta))) / self._p.approach_speed * 15.0 / 8.0)
        self._trajectory = MinimumJerkTrajectory(start, delta, duration)
        self._modes[lay.position] = JointMode.POSITION
        self._stage = ReleaseStage.OPEN
        self._t_stage = t

    def _step_open(self, t: float, pos: np.ndarray) -> None:
        assert self._trajectory is not None
        lay = self._p.layout
        elapsed = t - self._t_stage
        self._setpoints[lay.position] = self._trajectory.position(elapsed)
        if elapsed < self._trajectory.duration:
            return
        self._modes[:] = JointMode.HOLD
        self._setpoints[:] = pos
        self._stage = ReleaseStage.OPEN_HELD
