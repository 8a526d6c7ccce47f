"""From joint commands to Dynamixel goal values, and from present values to SI (no I/O).

The pure core of :mod:`dam_hand_driver.dynamixel_device`, vectorised over the nine servos.

Roles and operating modes (``docs/dynamixel.md``):

- compliant joints run in **current control** (Operating Mode 0). The host computes the joint
  torque every bus cycle and writes it as Goal Current through the torque constant:
  MODE_IMPEDANCE ``tau = k (theta_0 - theta) - d theta_dot`` (the paper's impedance law with
  the driver's slew-limited equilibrium), MODE_TORQUE the slew-limited torque, MODE_HOLD and
  MODE_POSITION a stiff spring to the held or commanded angle (``hold_stiffness``,
  ``hold_damping``); the torque is clipped to ``device.torque_limit_nm`` and the Goal Current
  to the servo's Current Limit.
- locked and position joints run in **current-based position control** (Operating Mode 5):
  the servo's own position loop follows Goal Position while Goal Current (the configured
  Current Limit) caps its torque, so that a finger pressing on the object or the table is
  never driven beyond what the configuration allows. MODE_TORQUE and MODE_IMPEDANCE do not
  exist for them (:func:`mode_error`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from dam_common.device_protocol import JointMode
from dam_common.dynamixel_config import (
    POSITION_RAD_PER_COUNT,
    VELOCITY_RAD_S_PER_UNIT,
    DynamixelConfig,
)

#: Operating Mode (address 11) values used.
CURRENT_CONTROL = 0
CURRENT_BASED_POSITION = 5
#: The role that runs in current control; the others run in current-based position control.
CURRENT_ROLE = 'compliant'

_HOLD = int(JointMode.HOLD)
_POSITION = int(JointMode.POSITION)
_TORQUE = int(JointMode.TORQUE)
_IMPEDANCE = int(JointMode.IMPEDANCE)


@dataclass(frozen=True)
class ServoTable:
    """The servos of a :class:`DynamixelConfig` as (n,) arrays, joint order."""

    ids: tuple[int, ...]
    joints: tuple[str, ...]
    direction: np.ndarray  #: +1 / -1
    zero_counts: np.ndarray  #: Present Position at joint angle 0 [counts]
    torque_per_unit: np.ndarray  #: joint torque of one current unit [N*m] (kt * unit)
    current_limit_raw: np.ndarray  #: Current Limit [units]
    current_mode: np.ndarray  #: bool: the servo runs in current control

    @classmethod
    def from_config(cls, dxl: DynamixelConfig) -> ServoTable:
        servos = dxl.servos
        return cls(
            ids=tuple(s.servo_id for s in servos),
            joints=tuple(s.joint for s in servos),
            direction=np.array([s.direction for s in servos], dtype=np.float64),
            zero_counts=np.array([s.zero_offset_counts for s in servos], dtype=np.float64),
            torque_per_unit=np.array([s.torque_constant_nm_per_a * s.spec.current_unit_a
                                      for s in servos]),
            current_limit_raw=np.array([s.current_limit_raw for s in servos], dtype=np.int64),
            current_mode=np.array([s.role == CURRENT_ROLE for s in servos]),
        )

    @property
    def operating_modes(self) -> np.ndarray:
        """(n,) Operating Mode per servo."""
        return np.where(self.current_mode, CURRENT_CONTROL, CURRENT_BASED_POSITION)

    def label(self, j: int) -> str:
        """``ID 3 (finger1_position_joint)``: how messages name a servo."""
        return f'ID {self.ids[j]} ({self.joints[j]})'


def signed(raw: np.ndarray, bits: int) -> np.ndarray:
    """Two's complement of unsigned ``bits``-bit register values (int64)."""
    raw = np.asarray(raw, dtype=np.int64)
    return np.where(raw >= 1 << (bits - 1), raw - (1 << bits), raw)


def state_si(table: ServoTable, current_raw: np.ndarray, velocity_raw: np.ndarray,
             position_raw: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Present Current (int16), Velocity (int32) and Position (int32), signed register
    values, to joint angle [rad], velocity [rad/s] and torque estimate [N*m], each (n,)."""
    d = table.direction
    q = d * (np.asarray(position_raw, dtype=np.float64) - table.zero_counts) \
        * POSITION_RAD_PER_COUNT
    dq = d * np.asarray(velocity_raw, dtype=np.float64) * VELOCITY_RAD_S_PER_UNIT
    tau = d * np.asarray(current_raw, dtype=np.float64) * table.torque_per_unit
    return q, dq, tau


def position_counts(table: ServoTable, theta_rad: np.ndarray) -> np.ndarray:
    """(n,) Goal Position [counts] of joint angles [rad] (rounded, within 0..4095)."""
    counts = table.zero_counts + table.direction * np.asarray(theta_rad) / POSITION_RAD_PER_COUNT
    return np.clip(np.rint(counts), 0, 4095).astype(np.int64)


def mode_error(table: ServoTable, joint: int, mode: int) -> str | None:
    """Why ``mode`` cannot drive ``joint`` on this bus (``None``: it can)."""
    if table.current_mode[joint] or mode in (_HOLD, _POSITION):
        return None
    name = {_TORQUE: 'MODE_TORQUE', _IMPEDANCE: 'MODE_IMPEDANCE'}.get(mode, str(mode))
    return (f'joint {table.joints[joint]!r}: {name} needs a servo in current control; on the '
            f'Dynamixel bus only the compliant joints are, {table.joints[joint]} runs in '
            f'current-based position control (MODE_POSITION or MODE_HOLD)')


def update_hold(hold_rad: np.ndarray, previous_modes: np.ndarray, modes: np.ndarray,
                position_rad: np.ndarray) -> np.ndarray:
    """The angles HOLD keeps: a joint that switches to HOLD holds where it is now."""
    switched = (np.asarray(modes) == _HOLD) & (np.asarray(previous_modes) != _HOLD)
    return np.where(switched, position_rad, hold_rad)


def goals_raw(table: ServoTable, position_rad: np.ndarray, velocity_rad_s: np.ndarray,
              modes: Sequence[int] | np.ndarray, setpoints: np.ndarray, stiffness: np.ndarray,
              damping: np.ndarray, hold_rad: np.ndarray, torque_limit_nm: float,
              hold_stiffness: float, hold_damping: float
              ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Goal Current and Goal Position of every servo for one bus cycle.

    Parameters
    ----------
    table
        The servos.
    position_rad, velocity_rad_s
        (n,) the joints' present angle [rad] and velocity [rad/s].
    modes, setpoints, stiffness, damping
        (n,) the driver's slew-limited command (as :meth:`HandDevice.send` receives it).
    hold_rad
        (n,) the angle each HOLD joint keeps [rad] (:func:`update_hold`).
    torque_limit_nm
        ``device.torque_limit_nm``: the largest joint torque of a current-controlled joint.
    hold_stiffness, hold_damping
        The spring [N*m/rad] and damper [N*m*s/rad] that hold a current-controlled joint in
        MODE_HOLD or MODE_POSITION.

    Returns
    -------
    goal_current, goal_position, torque
        (n,) int64 Goal Current [units] (the Current Limit for current-based position
        servos), int64 Goal Position [counts] (the present position for current-controlled
        servos), and the joint torque the current servos are asked for [N*m] (0 elsewhere).
    """
    m = np.asarray(modes, dtype=np.int64)
    q = np.asarray(position_rad, dtype=np.float64)
    dq = np.asarray(velocity_rad_s, dtype=np.float64)
    sp = np.nan_to_num(np.asarray(setpoints, dtype=np.float64))
    target = np.where(m == _HOLD, hold_rad, sp)  # POSITION and HOLD: an angle
    spring = hold_stiffness * (target - q) - hold_damping * dq
    impedance = np.asarray(stiffness) * (sp - q) - np.asarray(damping) * dq
    tau = np.select([m == _TORQUE, m == _IMPEDANCE], [sp, impedance], spring)
    tau = np.where(table.current_mode, np.clip(tau, -torque_limit_nm, torque_limit_nm), 0.0)
    current = np.rint(tau / (table.direction * table.torque_per_unit)).astype(np.int64)
    current = np.clip(current, -table.current_limit_raw, table.current_limit_raw)
    current = np.where(table.current_mode, current, table.current_limit_raw)
    goal_position = position_counts(table, np.where(table.current_mode, q, target))
    return current, goal_position, tau
