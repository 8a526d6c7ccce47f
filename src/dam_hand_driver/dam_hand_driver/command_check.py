"""The checks of a ``/hand/command`` and its joint commands in SI units (no ROS).

The driver node (:mod:`dam_hand_driver.driver_node`) takes the fields out of a
``dam_interfaces/HandCommand`` and hands them to :func:`check_joint_commands`: a command is
accepted as a whole or rejected with a reason naming the field and the value.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import NamedTuple

import numpy as np

from dam_common.device_protocol import JointMode
from dam_common.echo import brief_repr
from dam_hand_driver.errors import HandDriverError

#: HandCommand mode (MODE_TORQUE 0, MODE_POSITION 1, MODE_HOLD 2, MODE_IMPEDANCE 3) -> wire
#: protocol mode (the values differ: map explicitly).
WIRE_MODES: dict[int, JointMode] = {
    0: JointMode.TORQUE,
    1: JointMode.POSITION,
    2: JointMode.HOLD,
    3: JointMode.IMPEDANCE,
}


class CommandRejected(HandDriverError, ValueError):
    """A HandCommand message is malformed; the message names the field and the value."""


class CommandItem(NamedTuple):
    """One validated joint command of a HandCommand message (SI units)."""

    joint: int  #: index in the configured joint order
    mode: JointMode  #: wire mode
    setpoint: float  #: [N*m] TORQUE, [rad] POSITION and IMPEDANCE (theta_0), 0 HOLD
    stiffness: float = 0.0  #: k [N*m/rad] (IMPEDANCE only, else 0)
    damping: float = 0.0  #: d [N*m*s/rad] (IMPEDANCE only, else 0)


def check_joint_commands(names: Sequence[str], modes: Sequence[int], setpoints: Sequence[float],
                         stiffness: Sequence[float], damping: Sequence[float],
                         index: Mapping[str, int], torque_limit_nm: float,
                         lower_rad: np.ndarray, upper_rad: np.ndarray,
                         max_stiffness_nm_per_rad: float, max_damping_nms_per_rad: float
                         ) -> list[CommandItem]:
    """Check the fields of a HandCommand; one :class:`CommandItem` per named joint.

    Parameters
    ----------
    names, modes, setpoints
        Joint names, HandCommand modes (:data:`WIRE_MODES`) and setpoints ([N*m] torque,
        [rad] angle or impedance equilibrium), one per joint named.
    stiffness, damping
        Empty, or one per joint named: impedance stiffness [N*m/rad] and damping
        [N*m*s/rad] (read for MODE_IMPEDANCE joints only).
    index
        Joint name -> index in the configured order.
    torque_limit_nm
        Largest accepted ``|torque|`` [N*m].
    lower_rad, upper_rad
        (n,) joint limits [rad] (POSITION setpoints and IMPEDANCE equilibria).
    max_stiffness_nm_per_rad, max_damping_nms_per_rad
        Largest accepted impedance stiffness [N*m/rad] and damping [N*m*s/rad].

    Raises
    ------
    CommandRejected
        Length mismatch, unknown or duplicate joint name, unknown mode, non-finite setpoint,
        torque beyond ``torque_limit_nm``, angle or equilibrium outside the joint limits,
        MODE_IMPEDANCE without gains, stiffness not in (0, max], damping not in [0, max].
    """
    if not (len(names) == len(modes) == len(setpoints)):
        raise CommandRejected(f'name, mode and setpoint differ in length: {len(names)}, '
                              f'{len(modes)}, {len(setpoints)}')
    for field, values in (('stiffness', stiffness), ('damping', damping)):
        if values and len(values) != len(names):
            raise CommandRejected(f'{field} has {len(values)} entries for {len(names)} names '
                                  f'(expected none or one per name)')
    seen: set[str] = set()
    out: list[CommandItem] = []
    for i, (name, mode, value) in enumerate(zip(names, modes, setpoints, strict=True)):
        if name not in index:
            raise CommandRejected(f'unknown joint name {brief_repr(name)} (known: '
                                  f'{sorted(index)})')
        if name in seen:
            raise CommandRejected(f'joint {name!r} appears more than once')
        seen.add(name)
        if int(mode) not in WIRE_MODES:
            raise CommandRejected(f'joint {name!r}: mode {int(mode)} is not MODE_TORQUE (0), '
                                  f'MODE_POSITION (1), MODE_HOLD (2) or MODE_IMPEDANCE (3)')
        wire = WIRE_MODES[int(mode)]
        sp = float(value)
        if not math.isfinite(sp):
            raise CommandRejected(f'joint {name!r}: setpoint {sp!r} is not finite')
        j = index[name]
        if wire is JointMode.TORQUE and abs(sp) > torque_limit_nm:
            raise CommandRejected(f'joint {name!r}: torque {sp!r} N*m is beyond the limit '
                                  f'+-{torque_limit_nm!r} N*m')
        if wire is JointMode.POSITION and not lower_rad[j] <= sp <= upper_rad[j]:
            raise CommandRejected(f'joint {name!r}: angle {sp!r} rad is outside the joint '
                                  f'limits [{float(lower_rad[j])!r}, {float(upper_rad[j])!r}] rad')
        if wire is not JointMode.IMPEDANCE:
            out.append(CommandItem(j, wire, sp))
            continue
        if not stiffness or not damping:
            raise CommandRejected(f'joint {name!r}: MODE_IMPEDANCE needs stiffness and damping '
                                  f'(got {len(stiffness)} and {len(damping)} entries)')
        if not lower_rad[j] <= sp <= upper_rad[j]:
            raise CommandRejected(f'joint {name!r}: impedance equilibrium theta_0 {sp!r} rad is '
                                  f'outside the joint limits [{float(lower_rad[j])!r}, '
                                  f'{float(upper_rad[j])!r}] rad')
        k, d = float(stiffness[i]), float(damping[i])
        if not (math.isfinite(k) and 0.0 < k <= max_stiffness_nm_per_rad):
            raise CommandRejected(f'joint {name!r}: stiffness {k!r} N*m/rad is outside '
                                  f'(0, {max_stiffness_nm_per_rad!r}] N*m/rad')
        if not (math.isfinite(d) and 0.0 <= d <= max_damping_nms_per_rad):
            raise CommandRejected(f'joint {name!r}: damping {d!r} N*m*s/rad is outside '
                                  f'[0, {max_damping_nms_per_rad!r}] N*m*s/rad')
        out.append(CommandItem(j, wire, sp, k, d))
    return out
