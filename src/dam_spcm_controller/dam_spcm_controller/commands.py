"""Joint commands produced by the controller and the joint layout of the hand.

Joints are ordered finger by finger, base to tip, exactly as
``dam_common.config.HandConfig.joint_names``: ``finger1_compliant_joint``,
``finger1_locked_joint``, ``finger1_position_joint``, ``finger2_compliant_joint``, ...
"""

from __future__ import annotations

import enum
from collections.abc import Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dam_common.echo import brief_repr
from dam_spcm_controller._validate import finite_vector
from dam_spcm_controller.errors import InputError

if TYPE_CHECKING:  # pragma: no cover
    from dam_common.config import HandConfig

#: Joint roles of every finger, base to tip (paper Fig. 6).
JOINT_ROLES: tuple[str, str, str] = ('compliant', 'locked', 'position')


class JointMode(enum.IntEnum):
    """How a joint's setpoint is to be interpreted by the driver.

    HOLD
        Stiff position control at a fixed angle [rad] (locked joints, idle, relaxed hold).
    POSITION
        Position control tracking a moving angle [rad] (trajectories).
    TORQUE
        Joint torque [N*m]; positive flexes the finger inward.
    IMPEDANCE
        Joint impedance run by the device at its physics rate: the setpoint is the equilibrium
        ``theta_0`` [rad], :attr:`JointCommand.stiffness` and :attr:`JointCommand.damping` the
        gains; the device applies ``k (theta_0 - theta) - d theta_dot``.
    """

    HOLD = 0
    POSITION = 1
    TORQUE = 2
    IMPEDANCE = 3


@dataclass(frozen=True)
class JointCommand:
    """One command for every joint of the hand.

    Attributes
    ----------
    modes
        (3n,) int8 array of :class:`JointMode` values.
    setpoints
        (3n,) float64: angle [rad] for HOLD/POSITION joints, torque [N*m] for TORQUE joints,
        the equilibrium ``theta_0`` [rad] for IMPEDANCE joints.
    stiffness, damping
        (3n,) float64: stiffness [N*m/rad] and damping [N*m*s/rad] of IMPEDANCE joints, 0 for
        the others (``None``: all zero).
    """

    modes: np.ndarray
    setpoints: np.ndarray
    stiffness: np.ndarray | None = None
    damping: np.ndarray | None = None

    def __post_init__(self) -> None:
        for name in ('stiffness', 'damping'):
            if getattr(self, name) is None:
                object.__setattr__(self, name, np.zeros(np.shape(self.setpoints)))

    @property
    def has_impedance(self) -> bool:
        """True when at least one joint is in IMPEDANCE."""
        return bool(np.any(self.modes == JointMode.IMPEDANCE))

    def mode(self, index: int) -> JointMode:
        """The :class:`JointMode` of joint ``index``."""
        return JointMode(int(self.modes[index]))


def zero_torque_command(last: JointCommand | None, measured: np.ndarray) -> JointCommand:
    """The command that stops a grasp at once (a silence of the joint states).

    Parameters
    ----------
    last : the last command sent, or ``None`` when none was.
    measured : (3n,) the newest measured joint angles [rad].

    Returns
    -------
    JointCommand
        TORQUE and IMPEDANCE joints at zero torque, POSITION joints held at their last
        setpoint, HOLD joints as they were; with no last command every joint held where it
        was measured.
    """
    if last is None:
        return JointCommand(np.full(np.shape(measured), JointMode.HOLD, dtype=np.int8),
                            np.array(measured, dtype=np.float64))
    modes = last.modes.copy()
    setpoints = last.setpoints.copy()
    modes[modes == JointMode.IMPEDANCE] = JointMode.TORQUE
    setpoints[modes == JointMode.TORQUE] = 0.0
    modes[modes == JointMode.POSITION] = JointMode.HOLD
    return JointCommand(modes, setpoints)


@dataclass(frozen=True)
class HandLayout:
    """Where the joints of each role sit in the (3n,) joint arrays, and their limits.

    Attributes
    ----------
    joint_names
        (3n,) names ``<finger>_<role>_joint`` in array order.
    stiffness_ratios
        (n,) ``k_theta_i / k_theta`` [-].
    lower, upper
        (3n,) joint limits [rad].
    initial_locked_angle, initial_position_angle
        Pre-shape of the locked and position joints [rad] (paper section 4: 15 deg).
    """

    joint_names: tuple[str, ...]
    stiffness_ratios: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    initial_locked_angle: float
    initial_position_angle: float

    def __post_init__(self) -> None:
        n_joints = len(self.joint_names)
        if n_joints == 0 or n_joints % 3:
            raise InputError(f'joint_names must hold three joints per finger, got {n_joints}')
        n = n_joints // 3
        object.__setattr__(self, 'stiffness_ratios',
                           finite_vector('stiffness_ratios', self.stiffness_ratios, n,
                                         positive=True))
        lower = finite_vector('lower', self.lower, n_joints)
        upper = finite_vector('upper', self.upper, n_joints)
        if (lower >= upper).any():
            i = int(np.flatnonzero(lower >= upper)[0])
            raise InputError(f'joint limits of {self.joint_names[i]} are empty: '
                             f'[{lower[i]!r}, {upper[i]!r}] rad')
        object.__setattr__(self, 'lower', lower)
        object.__setattr__(self, 'upper', upper)

    @classmethod
    def from_hand_config(cls, hand: HandConfig) -> HandLayout:
        """Layout of a validated ``dam_common.config.HandConfig``."""
        n = hand.n_fingers
        lower = np.tile([hand.joint_limits_rad[r][0] for r in JOINT_ROLES], n)
        upper = np.tile([hand.joint_limits_rad[r][1] for r in JOINT_ROLES], n)
        return cls(joint_names=tuple(hand.joint_names),
                   stiffness_ratios=np.asarray(hand.stiffness_ratios, dtype=np.float64),
                   lower=lower, upper=upper,
                   initial_locked_angle=float(hand.initial_locked_angle_rad),
                   initial_position_angle=float(hand.initial_position_angle_rad))

    @property
    def n_fingers(self) -> int:
        return len(self.joint_names) // 3

    @property
    def n_joints(self) -> int:
        return len(self.joint_names)

    @property
    def compliant(self) -> slice:
        """Slice of the compliant joints in a (3n,) array."""
        return slice(0, None, 3)

    @property
    def locked(self) -> slice:
        """Slice of the locked joints in a (3n,) array."""
        return slice(1, None, 3)

    @property
    def position(self) -> slice:
        """Slice of the position-controlled joints in a (3n,) array."""
        return slice(2, None, 3)

    def index_of(self, names: Sequence[str]) -> np.ndarray:
        """Positions in ``names`` of this layout's joints, in layout order.

        Use it to reorder a message's arrays: ``values[layout.index_of(msg_names)]``.

        Parameters
        ----------
        names
            Joint names in the order of some message (extra names are ignored).

        Raises
        ------
        InputError
            A joint of the layout is missing from ``names`` or appears twice.
        """
        where: dict[str, int] = {}
        for i, name in enumerate(names):
            if name in where:
                raise InputError(f'joint name {brief_repr(name)} appears twice (positions '
                                 f'{where[name]} '
                                 f'and {i})')
            where[name] = i
        missing = [n for n in self.joint_names if n not in where]
        if missing:
            raise InputError(f'joint names missing: {missing}')
        return np.array([where[n] for n in self.joint_names], dtype=np.intp)

    def finger_name(self, finger: int) -> str:
        """Name of finger ``finger`` (0-based), taken from its compliant joint name."""
        return self.joint_names[3 * finger].rsplit('_compliant_joint', 1)[0]
