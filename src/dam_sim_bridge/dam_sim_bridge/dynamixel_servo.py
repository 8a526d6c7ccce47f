"""One emulated Dynamixel X-series servo: its control table and the rules of reading and writing.

No I/O and no physics: :class:`DynamixelServo` keeps a control table as long as its model's
(little-endian fields at the addresses of the ROBOTIS e-manual, X series, Protocol 2.0) and
answers PING, READ, WRITE and REBOOT with an error code and parameters; the bus
(:mod:`dam_sim_bridge.dynamixel_bus`) frames them, the stand-in
(:mod:`dam_sim_bridge.dynamixel_standin`) reads the goals and writes the present values.

Emulated rules (X-series e-manual behaviour as far as it is known here):

* The table ends where the model's e-manual table ends (:attr:`ServoModel.table_end`: after
  Indirect Data 56 at address 661 on the XM430-W350, after Indirect Data 20 at 227 on the
  XC330-M288): a read or write that reaches past it gives Access Error. Inside it, the items of
  :data:`FIELDS` are emulated; every other address (e.g. Indirect Address and Data, the
  XC330's Startup Configuration and PWM Slope, the XM430's gap 252..577) reads as zero and
  gives Access Error when written.
* EEPROM fields (address < 64) cannot be written while Torque Enable is 1 (Access Error,
  nothing written); read-only fields and addresses of no emulated field give Access Error; a
  write that covers only part of a field gives Data Length Error.
* Baud Rate (8) takes the model's values (:data:`BAUD_RATES_BPS`; 0..7 on the XM430-W350,
  0..6 on the XC330-M288, whose fastest rate is 4 Mbit/s): others give Data Range Error. The
  servo hears the line only at that rate (:attr:`DynamixelServo.baud_rate_bps`; the bus
  compares it with the host's).
* Values outside a field's range give Data Range Error; Goal Current beyond +-Current Limit,
  Goal PWM beyond PWM Limit, Goal Velocity beyond Velocity Limit and, in position mode (3),
  Goal Position outside Min..Max Position Limit give Data Limit Error (in modes 4 and 5 the
  Goal Position range is +-1,048,575). A write with any error writes nothing.
* A hardware error (Hardware Error Status, address 70) sets the Alert bit of every status
  packet. If one of its bits is enabled in Shutdown (63) the torque goes off and a write of
  Torque Enable = 1 gives Result Fail (with the Alert bit) and leaves it off. REBOOT clears the
  error, turns torque off and restores the RAM defaults; the EEPROM is kept.
* Bus Watchdog (98): with torque on and a non-zero value, a servo that is not fed
  (:meth:`DynamixelServo.heard`; which packets feed it is the bus's ``watchdog_feed``) for
  ``value * 20 ms`` of the device clock stops (no torque output) and shows 255 (-1); then
  writes of Goal PWM/Current/Velocity/Position give Data Range Error, until 0 is written to
  Bus Watchdog.
* Goal Position starts at the Present Position of the moment the RAM is (re)initialised.
* Drive Mode, the gains, profiles and LED are stored but have no effect.
"""

from __future__ import annotations

from dataclasses import dataclass

from dam_sim_bridge.dynamixel_packets import MAX_ID, ErrorCode, from_le, le_bytes

#: First RAM address: fields below are EEPROM.
RAM_START = 64
#: Bus Watchdog unit [s].
WATCHDOG_UNIT_S = 0.020
#: Bus Watchdog value that marks a tripped watchdog (-1 as a signed byte).
WATCHDOG_TRIPPED = 255
#: Goal Position range outside position mode [counts].
EXTENDED_POSITION_LIMIT = 1_048_575
#: Return Delay Time unit [s].
RETURN_DELAY_UNIT_S = 2e-6
#: Baud Rate (address 8) values of the X series and their line rates [bit/s] (e-manual).
BAUD_RATES_BPS: dict[int, int] = {0: 9600, 1: 57600, 2: 115200, 3: 1_000_000, 4: 2_000_000,
                                  5: 3_000_000, 6: 4_000_000, 7: 4_500_000}
#: Baud Rate value from the factory (57600 bit/s).
FACTORY_BAUD_RATE = 1

# Hardware Error Status bits (address 70).
HW_INPUT_VOLTAGE = 0x01
HW_OVERHEATING = 0x04
HW_MOTOR_ENCODER = 0x08
HW_ELECTRICAL_SHOCK = 0x10
HW_OVERLOAD = 0x20

#: Operating Mode values (address 11).
MODE_CURRENT, MODE_VELOCITY, MODE_POSITION = 0, 1, 3
MODE_EXTENDED_POSITION, MODE_CURRENT_POSITION, MODE_PWM = 4, 5, 16
OPERATING_MODES = (MODE_CURRENT, MODE_VELOCITY, MODE_POSITION, MODE_EXTENDED_POSITION,
                   MODE_CURRENT_POSITION, MODE_PWM)


@dataclass(frozen=True)
class ServoModel:
    """Model-specific facts of an X-series servo (e-manual control table defaults)."""

    name: str
    model_number: int
    current_unit_a: float  #: one unit of Goal/Present Current [A]
    current_limit: int  #: Current Limit default and largest value [units]
    pwm_limit: int  #: PWM Limit default [units of 0.113 %]
    velocity_limit: int  #: Velocity Limit default [0.229 rev/min]
    temperature_limit: int  #: [deg C]
    max_voltage_limit: int  #: [0.1 V]
    min_voltage_limit: int  #: [0.1 V]
    input_voltage: int  #: the emulated Present Input Voltage [0.1 V]
    baud_rate_max: int  #: the largest Baud Rate value (a key of :data:`BAUD_RATES_BPS`)
    table_end: int  #: one past the last address of the control table [bytes]

    def baud_rate_value(self, bps: int) -> int:
        """The Baud Rate (address 8) value of a line rate.

        Parameters
        ----------
        bps
            Line rate [bit/s].

        Returns
        -------
        int
            The value, 0..:attr:`baud_rate_max`.

        Raises
        ------
        ValueError
            The model has no such rate.
        """
        for value, rate in BAUD_RATES_BPS.items():
            if rate == int(bps) and value <= self.baud_rate_max:
                return value
        rates = [BAUD_RATES_BPS[v] for v in range(self.baud_rate_max + 1)]
        raise ValueError(f'{self.name} has no baud rate of {bps!r} bit/s (its rates: {rates})')


#: The emulated models by name.
SERVO_MODELS: dict[str, ServoModel] = {
    'XM430-W350': ServoModel('XM430-W350', 1020, 2.69e-3, 1193, 885, 200, 80, 160, 95, 120,
                             baud_rate_max=7, table_end=662),
    'XC330-M288': ServoModel('XC330-M288', 1240, 1.0e-3, 2352, 885, 445, 70, 70, 35, 50,
                             baud_rate_max=6, table_end=228),
}
#: Firmware Version the emulated servos report.
FIRMWARE_VERSION = 48
#: Present Temperature the emulated servos report [deg C].
PRESENT_TEMPERATURE = 30


@dataclass(frozen=True)
class Field:
    """One control-table item."""

    name: str
    address: int
    size: int  #: [bytes]
    writable: bool
    signed: bool = False
    minimum: int | None = None  #: Data Range Error below (None: any value of the size)
    maximum: int | None = None


_FIELDS = (
    Field('model_number', 0, 2, False), Field('model_information', 2, 4, False),
    Field('firmware_version', 6, 1, False), Field('id', 7, 1, True, maximum=MAX_ID),
    Field('baud_rate', 8, 1, True, maximum=7), Field('return_delay_time', 9, 1, True),
    Field('drive_mode', 10, 1, True, maximum=13),
    Field('operating_mode', 11, 1, True, maximum=16),
    Field('secondary_id', 12, 1, True), Field('protocol_type', 13, 1, True, 1, 2),
    Field('homing_offset', 20, 4, True, True, -EXTENDED_POSITION_LIMIT,
          EXTENDED_POSITION_LIMIT),
    Field('moving_threshold', 24, 4, True, maximum=1023),
    Field('temperature_limit', 31, 1, True, maximum=100),
    Field('max_voltage_limit', 32, 2, True), Field('min_voltage_limit', 34, 2, True),
    Field('pwm_limit', 36, 2, True, maximum=885), Field('current_limit', 38, 2, True),
    Field('velocity_limit', 44, 4, True, maximum=1023),
    Field('max_position_limit', 48, 4, True, maximum=4095),
    Field('min_position_limit', 52, 4, True, maximum=4095),
    Field('shutdown', 63, 1, True),
    Field('torque_enable', 64, 1, True, maximum=1), Field('led', 65, 1, True, maximum=1),
    Field('status_return_level', 68, 1, True, maximum=2),
    Field('registered_instruction', 69, 1, False),
    Field('hardware_error_status', 70, 1, False),
    Field('velocity_i_gain', 76, 2, True, maximum=16383),
    Field('velocity_p_gain', 78, 2, True, maximum=16383),
    Field('position_d_gain', 80, 2, True, maximum=16383),
    Field('position_i_gain', 82, 2, True, maximum=16383),
    Field('position_p_gain', 84, 2, True, maximum=16383),
    Field('feedforward_2nd_gain', 88, 2, True, maximum=16383),
    Field('feedforward_1st_gain', 90, 2, True, maximum=16383),
    Field('bus_watchdog', 98, 1, True, maximum=127),
    Field('goal_pwm', 100, 2, True, True), Field('goal_current', 102, 2, True, True),
    Field('goal_velocity', 104, 4, True, True),
    Field('profile_acceleration', 108, 4, True, maximum=32767),
    Field('profile_velocity', 112, 4, True, maximum=32767),
    Field('goal_position', 116, 4, True, True),
    Field('realtime_tick', 120, 2, False), Field('moving', 122, 1, False),
    Field('moving_status', 123, 1, False), Field('present_pwm', 124, 2, False, True),
    Field('present_current', 126, 2, False, True),
    Field('present_velocity', 128, 4, False, True),
    Field('present_position', 132, 4, False, True),
    Field('velocity_trajectory', 136, 4, False, True),
    Field('position_trajectory', 140, 4, False, True),
    Field('present_input_voltage', 144, 2, False),
    Field('present_temperature', 146, 1, False),
)
#: Control-table items by name.
FIELDS: dict[str, Field] = {f.name: f for f in _FIELDS}
_FIELD_AT: list[Field | None] = [None] * max(f.address + f.size for f in _FIELDS)
for _f in _FIELDS:
    for _a in range(_f.address, _f.address + _f.size):
        _FIELD_AT[_a] = _f
_MEASURED_START, _MEASURED_END = 124, 148  # Present PWM .. Present Temperature
_GOALS = frozenset(('goal_pwm', 'goal_current', 'goal_velocity', 'goal_position'))


@dataclass(frozen=True)
class Status:
    """A servo's answer before framing: the error byte and the parameters."""

    error: int  #: :class:`ErrorCode` in the low 7 bits, the Alert bit 0x80
    params: bytes = b''


class DynamixelServo:
    """The control table and instruction handling of one X-series servo.

    Parameters
    ----------
    servo_id
        Its ID (0..252), written to address 7.
    model
        A key of :data:`SERVO_MODELS`.

    Raises
    ------
    ValueError
        Unknown model or ID out of range.
    """

    def __init__(self, servo_id: int, model: str) -> None:
        if model not in SERVO_MODELS:
            raise ValueError(f'unknown servo model {model!r} (emulated: {sorted(SERVO_MODELS)})')
        if not 0 <= int(servo_id) <= MAX_ID:
            raise ValueError(f'servo ID {servo_id!r} is outside 0..{MAX_ID}')
        self.model = SERVO_MODELS[model]
        #: The control table, :attr:`ServoModel.table_end` bytes.
        self.table = bytearray(self.model.table_end)
        self._last_heard_s: float | None = None
        self._eeprom_defaults(int(servo_id))
        self._ram_defaults()

    # ---------------------------------------------------------------------------------------
    # Table access

    def get(self, name: str) -> int:
        """The value of control-table item ``name`` (signed items as signed integers)."""
        f = FIELDS[name]
        return from_le(self.table[f.address:f.address + f.size], f.signed)

    def set(self, name: str, value: int) -> None:
        """Store ``value`` in item ``name`` without any check (the servo's own updates).

        Raises
        ------
        OverflowError
            The value does not fit the item.
        """
        f = FIELDS[name]
        self.table[f.address:f.address + f.size] = le_bytes(int(value), f.size)

    def _eeprom_defaults(self, servo_id: int) -> None:
        m = self.model
        for name, value in (('model_number', m.model_number), ('firmware_version',
                                                               FIRMWARE_VERSION),
                            ('id', servo_id), ('baud_rate', FACTORY_BAUD_RATE),
                            ('return_delay_time', 250),
                            ('operating_mode', MODE_POSITION), ('secondary_id', 255),
                            ('protocol_type', 2), ('moving_threshold', 10),
                            ('temperature_limit', m.temperature_limit),
                            ('max_voltage_limit', m.max_voltage_limit),
                            ('min_voltage_limit', m.min_voltage_limit),
                            ('pwm_limit', m.pwm_limit), ('current_limit', m.current_limit),
                            ('velocity_limit', m.velocity_limit),
                            ('max_position_limit', 4095), ('min_position_limit', 0),
                            ('shutdown', HW_OVERHEATING | HW_ELECTRICAL_SHOCK | HW_OVERLOAD)):
            self.set(name, value)

    def _ram_defaults(self) -> None:
        measured = self.table[_MEASURED_START:_MEASURED_END]  # what the sensors tell
        self.table[RAM_START:] = bytes(len(self.table) - RAM_START)
        self.table[_MEASURED_START:_MEASURED_END] = measured
        for name, value in (('status_return_level', 2), ('velocity_i_gain', 1920),
                            ('velocity_p_gain', 100), ('position_p_gain', 800),
                            ('present_input_voltage', self.model.input_voltage),
                            ('present_temperature', PRESENT_TEMPERATURE)):
            self.set(name, value)
        self.set('goal_position', self.get('present_position'))
        self._last_heard_s = None

    # ---------------------------------------------------------------------------------------
    # State the bus and the stand-in read

    @property
    def servo_id(self) -> int:
        """The current ID (address 7)."""
        return self.table[7]

    @property
    def status_return_level(self) -> int:
        """0: only PING answers, 1: PING and READ, 2: every instruction."""
        return self.table[68]

    @property
    def baud_rate_bps(self) -> int:
        """The line rate of its Baud Rate (address 8) [bit/s]."""
        return BAUD_RATES_BPS[self.table[8]]

    @property
    def return_delay_s(self) -> float:
        """Return Delay Time [s]."""
        return self.table[9] * RETURN_DELAY_UNIT_S

    @property
    def hardware_error(self) -> int:
        """Hardware Error Status bits (address 70)."""
        return self.table[70]

    @property
    def torque_enabled(self) -> bool:
        """Torque Enable (address 64) is 1."""
        return self.table[64] == 1

    @property
    def watchdog_tripped(self) -> bool:
        """Bus Watchdog shows its error value 255."""
        return self.table[98] == WATCHDOG_TRIPPED

    @property
    def output_enabled(self) -> bool:
        """The motor produces torque: torque on, no hardware error, watchdog not tripped."""
        return self.torque_enabled and not self.hardware_error and not self.watchdog_tripped

    def alert(self) -> int:
        """The Alert bit (0x80) when a hardware error is set, else 0."""
        return 0x80 if self.hardware_error else 0

    def status(self, code: ErrorCode = ErrorCode.NONE, params: bytes = b'') -> Status:
        """A :class:`Status` with ``code`` and the Alert bit if due."""
        return Status(int(code) | self.alert(), params)

    # ---------------------------------------------------------------------------------------
    # Instructions

    def ping(self) -> Status:
        """PING: model number (LE16) and firmware version."""
        return self.status(params=bytes(self.table[0:2]) + bytes(self.table[6:7]))

    def read(self, address: int, length: int, now_s: float) -> Status:
        """READ ``length`` bytes from ``address``.

        Parameters
        ----------
        address
            First address.
        length
            Number of bytes [bytes].
        now_s
            Device clock [s], for Realtime Tick (address 120).

        Returns
        -------
        Status
            The bytes (zeros where no item is emulated), or Data Length Error (length 0) or
            Access Error (reaching past the model's table).
        """
        if length <= 0:
            return self.status(ErrorCode.DATA_LENGTH)
        if address < 0 or address + length > len(self.table):
            return self.status(ErrorCode.ACCESS)
        self.set('realtime_tick', int(now_s * 1000.0) % 32768)
        return self.status(params=bytes(self.table[address:address + length]))

    def write(self, address: int, data: bytes) -> Status:
        """WRITE ``data`` from ``address`` (all items or none).

        Parameters
        ----------
        address
            First address.
        data
            The bytes, covering whole items.

        Returns
        -------
        Status
            No error, or Access, Data Length, Data Range, Data Limit or Result Fail (torque
            requested during a hardware error) error; nothing is written on an error.
        """
        if not data:
            return self.status(ErrorCode.DATA_LENGTH)
        end = address + len(data)
        if address < 0 or end > len(self.table):
            return self.status(ErrorCode.ACCESS)
        items: list[tuple[Field, int]] = []
        a = address
        while a < end:
            f = _FIELD_AT[a] if a < len(_FIELD_AT) else None
            if f is None or not f.writable:
                return self.status(ErrorCode.ACCESS)
            if f.address != a or f.address + f.size > end:
                return self.status(ErrorCode.DATA_LENGTH)
            raw = data[a - address:a - address + f.size]
            items.append((f, from_le(raw, f.signed)))
            a += f.size
        code = self._check(items)
        if code != ErrorCode.NONE:
            return self.status(code)
        for f, value in items:
            if f.name == 'bus_watchdog' and value == 0:
                self._last_heard_s = None
            self.table[f.address:f.address + f.size] = le_bytes(value, f.size)
        return self.status()

    def _check(self, items: list[tuple[Field, int]]) -> ErrorCode:
        """The error of writing ``items`` (name, value), or NONE."""
        new = {f.name: v for f, v in items}

        def value(name: str) -> int:
            return new[name] if name in new else self.get(name)

        torque_on = self.torque_enabled
        for f, v in items:
            if f.address < RAM_START and torque_on:
                return ErrorCode.ACCESS
            if ((f.minimum is not None and v < f.minimum)
                    or (f.maximum is not None and v > f.maximum)):
                return ErrorCode.DATA_RANGE
            if f.name in _GOALS and self.watchdog_tripped:
                return ErrorCode.DATA_RANGE
        if 'operating_mode' in new and new['operating_mode'] not in OPERATING_MODES:
            return ErrorCode.DATA_RANGE
        if 'current_limit' in new and new['current_limit'] > self.model.current_limit:
            return ErrorCode.DATA_RANGE
        if 'baud_rate' in new and new['baud_rate'] > self.model.baud_rate_max:
            return ErrorCode.DATA_RANGE
        if 'goal_current' in new and abs(new['goal_current']) > value('current_limit'):
            return ErrorCode.DATA_LIMIT
        if 'goal_pwm' in new and abs(new['goal_pwm']) > value('pwm_limit'):
            return ErrorCode.DATA_LIMIT
        if 'goal_velocity' in new and abs(new['goal_velocity']) > value('velocity_limit'):
            return ErrorCode.DATA_LIMIT
        if 'goal_position' in new:
            goal = new['goal_position']
            if value('operating_mode') == MODE_POSITION:
                if not value('min_position_limit') <= goal <= value('max_position_limit'):
                    return ErrorCode.DATA_LIMIT
            elif abs(goal) > EXTENDED_POSITION_LIMIT:
                return ErrorCode.DATA_LIMIT
        if new.get('torque_enable') == 1 and self.hardware_error & self.table[63]:
            return ErrorCode.RESULT_FAIL
        return ErrorCode.NONE

    def reboot(self) -> Status:
        """REBOOT: clear the hardware error, torque off, RAM to its defaults (EEPROM kept).

        Returns
        -------
        Status
            The answer, sent before the reboot (with the Alert bit of the error it clears).
        """
        answer = self.status()
        self._ram_defaults()
        return answer

    # ---------------------------------------------------------------------------------------
    # Faults and the watchdog

    def set_hardware_error(self, bits: int) -> None:
        """Latch Hardware Error Status ``bits``; torque off when Shutdown enables one of them.

        Parameters
        ----------
        bits
            Bits of address 70 (``HW_*``), 0..255; 0 changes nothing.

        Raises
        ------
        ValueError
            ``bits`` is not a byte.
        """
        if not 0 <= int(bits) <= 0xFF:
            raise ValueError(f'hardware error bits {bits!r} are not a byte')
        self.table[70] |= int(bits)
        if self.table[70] & self.table[63]:
            self.table[64] = 0

    def heard(self, now_s: float) -> None:
        """An instruction packet that feeds the Bus Watchdog arrived at ``now_s`` [s] of the
        device clock (which packets do is the bus's ``watchdog_feed``)."""
        self.check_watchdog(now_s)
        self._last_heard_s = now_s

    def check_watchdog(self, now_s: float) -> bool:
        """Trip the Bus Watchdog if it has waited too long.

        Parameters
        ----------
        now_s
            Device clock [s].

        Returns
        -------
        bool
            ``True`` if it tripped in this call.
        """
        wd = self.table[98]
        if wd == 0 or wd == WATCHDOG_TRIPPED or not self.torque_enabled:
            if not self.torque_enabled or wd == 0:
                self._last_heard_s = None  # the interval starts with torque and watchdog on
            return False
        if self._last_heard_s is None:
            self._last_heard_s = now_s
            return False
        if now_s - self._last_heard_s > wd * WATCHDOG_UNIT_S + 1e-9:
            self.table[98] = WATCHDOG_TRIPPED
            return True
        return False

    def set_present(self, position: int, velocity: int, current: int) -> None:
        """Store the measured state (the stand-in's physics).

        Parameters
        ----------
        position
            Shaft position [counts, 4096 per rev], before the Homing Offset (added here).
        velocity
            [0.229 rev/min]
        current
            [model current units], clipped to the int16 range.
        """
        pos = int(position) + self.get('homing_offset')
        self.set('present_position', max(-2**31, min(2**31 - 1, pos)))
        self.set('present_velocity', max(-2**31, min(2**31 - 1, int(velocity))))
        cur = max(-32768, min(32767, int(current)))
        self.set('present_current', cur)
        limit = max(1, self.get('current_limit'))
        pwm_limit = self.get('pwm_limit')
        self.set('present_pwm', max(-pwm_limit, min(pwm_limit, cur * pwm_limit // limit)))
        moving = abs(int(velocity)) > self.get('moving_threshold')
        self.table[122] = int(moving)
        in_position = abs(self.get('goal_position') - pos) <= self.get('moving_threshold')
        self.table[123] = int(in_position and self.get('operating_mode') in (
            MODE_POSITION, MODE_EXTENDED_POSITION, MODE_CURRENT_POSITION))
