"""The ``dynamixel:`` section of the configuration: a hand of Dynamixel X servos on one bus.

The driver's ``backend:=dynamixel`` (:mod:`dam_hand_driver.dynamixel_device`) and the emulated
bus (:mod:`dam_sim_bridge.dynamixel_standin`) both read it. Every joint of the hand is one
servo of Dynamixel Protocol 2.0; the control-table addresses used here are shared by the
models of :data:`MODELS` (ROBOTIS e-manual, X series control tables); their current units
differ.

Units and conversions (shared by the driver and the emulated bus):

- joint angle [rad] = ``direction * (present_position - zero_offset_counts) *``
  :data:`POSITION_RAD_PER_COUNT`
- joint velocity [rad/s] = ``direction * present_velocity *`` :data:`VELOCITY_RAD_S_PER_UNIT`
- joint torque [N*m] = ``direction * present_current * current_unit_a *
  torque_constant_nm_per_a`` (an estimate from the motor current, not a torque sensor)
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from dam_common.config_node import ConfigNode

#: Encoder counts per revolution of the X series (0.088 deg per count).
COUNTS_PER_REV = 4096
#: One Present/Goal Position count [rad].
POSITION_RAD_PER_COUNT = 2.0 * math.pi / COUNTS_PER_REV
#: One Present/Goal Velocity unit, 0.229 rev/min [rad/s].
VELOCITY_RAD_S_PER_UNIT = 0.229 * 2.0 * math.pi / 60.0
#: Bus Watchdog unit (address 98) [s].
BUS_WATCHDOG_UNIT_S = 0.020
#: Baud rates of the X series and the SDK's port handler [bit/s].
BAUD_RATES = (57600, 115200, 1000000, 2000000, 3000000, 4000000)


@dataclass(frozen=True)
class ModelSpec:
    """What differs between the supported servo models (ROBOTIS e-manual control tables)."""

    model_number: int  #: Model Number (address 0)
    current_unit_a: float  #: one unit of Goal/Present Current and Current Limit [A]
    current_limit_max: int  #: the largest Current Limit (address 38) [units]
    #: Present Current (126) is the motor's current (a torque estimate through the torque
    #: constant); ``False``: it is the servo's supply (input) current, no torque estimate.
    motor_current: bool = True


#: The supported models. Their control tables share the addresses the suite uses. The
#: XC330-M288's e-manual gives its Present Current as the input current.
MODELS: dict[str, ModelSpec] = {
    'XM430-W350': ModelSpec(model_number=1020, current_unit_a=2.69e-3, current_limit_max=1193),
    'XC330-M288': ModelSpec(model_number=1240, current_unit_a=1.0e-3, current_limit_max=2352,
                            motor_current=False),
}


@dataclass(frozen=True)
class ServoConfig:
    """One joint's servo."""

    joint: str  #: joint name (``hand.joint_names``)
    role: str  #: compliant, locked or position
    servo_id: int  #: Dynamixel ID, 0..252
    model: str  #: a key of :data:`MODELS`
    direction: int  #: +1: joint angle grows with the encoder count; -1: the opposite
    zero_offset_counts: int  #: Present Position [counts] at joint angle 0
    torque_constant_nm_per_a: float  #: joint torque per motor current [N*m/A]
    current_limit_a: float  #: Current Limit written at start-up [A]

    @property
    def spec(self) -> ModelSpec:
        return MODELS[self.model]

    @property
    def current_limit_raw(self) -> int:
        """Current Limit in the model's units (rounded down: never above the configured)."""
        return int(math.floor(self.current_limit_a / self.spec.current_unit_a + 1e-9))


@dataclass(frozen=True)
class DynamixelConfig:
    """The ``dynamixel:`` section."""

    port: str  #: serial device (e.g. ``/dev/ttyUSB0``); empty: the emulated bus
    baud_rate: int  #: [bit/s], one of :data:`BAUD_RATES`
    rate_hz: float  #: bus cycles per second (one sync read and one sync write each)
    bus_watchdog_s: float  #: the servos stop this long after the host's last packet [s]
    #: The spring [N*m/rad] and damper [N*m*s/rad] that hold a current-controlled joint in
    #: MODE_HOLD or MODE_POSITION (the host's law: a current servo has no position loop).
    hold_stiffness_nm_per_rad: float
    hold_damping_nms_per_rad: float
    servos: tuple[ServoConfig, ...]  #: one per joint, in ``hand.joint_names`` order

    @property
    def bus_watchdog_raw(self) -> int:
        """Bus Watchdog (address 98) in units of 20 ms."""
        return int(round(self.bus_watchdog_s / BUS_WATCHDOG_UNIT_S))


def parse_dynamixel(node: ConfigNode, joint_names: tuple[str, ...], joint_roles: tuple[str, ...],
                    joint_limits_rad: tuple[tuple[float, float], ...]) -> DynamixelConfig:
    """Validate the ``dynamixel:`` section.

    Parameters
    ----------
    node
        The section's cursor (:class:`dam_common.config_node.ConfigNode`).
    joint_names, joint_roles
        (n,) the hand's joint names and each one's role.
    joint_limits_rad
        (n,) each joint's (lower, upper) limit [rad]: both must fall inside the encoder's
        0..4095 counts given the joint's ``zero_offset_counts`` and ``direction``.

    Raises
    ------
    ConfigError
        A missing or unknown key, a joint without a servo or a servo of no joint, a duplicate
        ID, an unknown model, a bad value; the message names the key.
    """
    node.only_keys({'port', 'baud_rate', 'rate_hz', 'bus_watchdog_s', 'hold_stiffness_nm_per_rad',
                    'hold_damping_nms_per_rad', 'servos'})
    port_node = node.child('port')
    if not isinstance(port_node.raw, str):
        raise port_node.error(f'expected a device path or \'\' (the emulated bus), got '
                              f'{port_node.raw!r}')
    baud_node = node.child('baud_rate')
    baud = baud_node.integer()
    if baud not in BAUD_RATES:
        raise baud_node.error(f'{baud} bit/s is not a Dynamixel baud rate {list(BAUD_RATES)}')
    rate_node = node.child('rate_hz')
    rate = rate_node.number(positive=True)
    if rate > 2000.0:
        raise rate_node.error(f'{rate!r} Hz: nine servos cannot be read faster than 2000 Hz')
    wd_node = node.child('bus_watchdog_s')
    watchdog = wd_node.number(positive=True)
    units = watchdog / BUS_WATCHDOG_UNIT_S
    if not 1 <= round(units) <= 127 or abs(units - round(units)) > 1e-6:
        raise wd_node.error(f'{watchdog!r} s is not a multiple of 0.02 s in [0.02, 2.54] s '
                            f'(the Bus Watchdog counts 20 ms units, 1..127)')
    if watchdog < 2.0 / rate:
        raise wd_node.error(f'{watchdog!r} s is shorter than two bus cycles at {rate!r} Hz: '
                            f'the servos would stop between two cycles')
    servos_node = node.child('servos')
    mapping = servos_node.require_mapping()
    unknown = sorted(str(k) for k in mapping if k not in joint_names)
    if unknown:
        raise servos_node.error(f'no joint named {unknown} (joints: {list(joint_names)})')
    servos: list[ServoConfig] = []
    ids: dict[int, str] = {}
    for joint, role, limits in zip(joint_names, joint_roles, joint_limits_rad, strict=True):
        snode = servos_node.child(joint)
        snode.only_keys({'id', 'model', 'direction', 'zero_offset_counts',
                         'torque_constant_nm_per_a', 'current_limit_a'})
        id_node = snode.child('id')
        servo_id = id_node.integer(minimum=0, maximum=252)
        if servo_id in ids:
            raise id_node.error(f'ID {servo_id} is also the servo of {ids[servo_id]}')
        ids[servo_id] = joint
        model_node = snode.child('model')
        model = model_node.string()
        if model not in MODELS:
            raise model_node.error(f'unknown model {model!r} (supported: {sorted(MODELS)})')
        dir_node = snode.child('direction')
        direction = dir_node.integer()
        if direction not in (1, -1):
            raise dir_node.error(f'expected 1 or -1, got {direction!r}')
        zero_node = snode.child('zero_offset_counts')
        zero = zero_node.integer(minimum=0, maximum=COUNTS_PER_REV - 1)
        ends = [zero + direction * lim / POSITION_RAD_PER_COUNT for lim in limits]
        if min(ends) < 0.0 or max(ends) > COUNTS_PER_REV - 1:
            raise zero_node.error(
                f'{zero} puts the joint limits [{math.degrees(limits[0]):.4g}, '
                f'{math.degrees(limits[1]):.4g}] deg at counts {ends[0]:.0f} and {ends[1]:.0f}, '
                f'outside the encoder\'s 0..{COUNTS_PER_REV - 1}')
        kt = snode.child('torque_constant_nm_per_a').number(positive=True)
        limit_node = snode.child('current_limit_a')
        limit = limit_node.number(positive=True)
        spec = MODELS[model]
        if limit > spec.current_limit_max * spec.current_unit_a + 1e-9:
            raise limit_node.error(
                f'{limit!r} A is above the {model}\'s largest Current Limit '
                f'({spec.current_limit_max * spec.current_unit_a:.4g} A)')
        if limit < spec.current_unit_a:
            raise limit_node.error(f'{limit!r} A is below one current unit of the {model} '
                                   f'({spec.current_unit_a:g} A)')
        servos.append(ServoConfig(joint=joint, role=role, servo_id=servo_id, model=model,
                                  direction=direction, zero_offset_counts=zero,
                                  torque_constant_nm_per_a=kt, current_limit_a=limit))
    return DynamixelConfig(
        port=port_node.raw, baud_rate=baud, rate_hz=rate, bus_watchdog_s=watchdog,
        hold_stiffness_nm_per_rad=node.child('hold_stiffness_nm_per_rad').number(positive=True),
        hold_damping_nms_per_rad=node.child('hold_damping_nms_per_rad').number(
            nonnegative=True),
        servos=tuple(servos))
