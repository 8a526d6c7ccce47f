"""Clean (bumpless) start and stop of torque commands.

On activation the controller must not make the hand jump: every joint is first commanded to
hold exactly its measured angle, and any torque command starts from zero and is ramped in.
On cancel or failure the torque is ramped back to zero.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dam_spcm_controller._validate import finite_scalar, finite_vector
from dam_spcm_controller.commands import JointCommand, JointMode


def hold_measured(positions: np.ndarray) -> JointCommand:
    """Command every joint to HOLD its measured angle.

    Parameters
    ----------
    positions
        (3n,) measured joint angles [rad].

    Returns
    -------
    JointCommand
        All modes :attr:`JointMode.HOLD`, setpoints equal to ``positions`` (a copy).
    """
    pos = finite_vector('positions', positions)
    return JointCommand(modes=np.full(pos.shape[0], JointMode.HOLD, dtype=np.int8),
                        setpoints=pos.copy())


@dataclass(frozen=True)
class LinearRamp:
    """A value that moves linearly from ``start_value`` to ``end_value``.

    Attributes
    ----------
    t_start
        Time the ramp begins [s].
    duration
        Ramp time [s], non-negative (zero jumps to ``end_value`` at ``t_start``).
    start_value, end_value
        Values (same unit as the ramped quantity, e.g. N*m or a scale factor) at both ends.
    """

    t_start: float
    duration: float
    start_value: float = 0.0
    end_value: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, 't_start', finite_scalar('t_start', self.t_start))
        object.__setattr__(self, 'duration',
                           finite_scalar('duration', self.duration, nonnegative=True))
        object.__setattr__(self, 'start_value', finite_scalar('start_value', self.start_value))
        object.__setattr__(self, 'end_value', finite_scalar('end_value', self.end_value))

    def fraction(self, t: float) -> float:
        """Completed fraction in [0, 1] at time ``t`` [s]."""
        if t <= self.t_start:
            return 0.0 if self.duration > 0.0 else 1.0
        if self.duration <= 0.0 or t >= self.t_start + self.duration:
            return 1.0
        return (t - self.t_start) / self.duration

    def value(self, t: float) -> float:
        """Ramped value at time ``t`` [s]."""
        f = self.fraction(t)
        return self.start_value + (self.end_value - self.start_value) * f

    def done(self, t: float) -> bool:
        """True once the ramp has reached ``end_value``."""
        return self.fraction(t) >= 1.0


def ramp_torque_in(t: float, t_activation: float, ramp_time: float,
                   torque: np.ndarray) -> np.ndarray:
    """Scale a torque command from zero at activation to full after ``ramp_time`` [s].

    Parameters
    ----------
    t, t_activation
        Current time and activation time [s].
    ramp_time
        Ramp length [s], non-negative.
    torque
        Torque command at full scale [N*m].
    """
    scale = LinearRamp(t_activation, ramp_time, 0.0, 1.0).value(t)
    return scale * np.asarray(torque, dtype=np.float64)


def ramp_torque_out(t: float, t_release: float, ramp_time: float,
                    torque_at_release: np.ndarray) -> np.ndarray:
    """Fade a torque command linearly from its value at release to zero over ``ramp_time``."""
    scale = LinearRamp(t_release, ramp_time, 1.0, 0.0).value(t)
    return scale * np.asarray(torque_at_release, dtype=np.float64)
