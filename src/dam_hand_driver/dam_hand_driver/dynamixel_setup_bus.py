"""The bus of ``dynamixel_setup`` and what the command does on it (no rclpy).

:class:`Bus`: one port opened exclusively (:func:`dam_hand_driver.dynamixel_port.open_port`),
with transactions tried again after the input is drained and a stop request looked at
between two of them. On it: the scan (:func:`scan_bus`), ``fix`` (:func:`run_fix`),
``set-id`` (:func:`run_set_id`) and the bus's part of ``zero`` (:func:`read_zero`); the
command line, the scan's report and the overlay are in
:mod:`dam_hand_driver.dynamixel_setup_cli`, which imports this module (never the other way).
"""

from __future__ import annotations

import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from dam_common.dynamixel_config import BAUD_RATES, MODELS
from dam_common.shutdown import SHUTDOWN
from dam_common.words import counted
from dam_hand_driver import dynamixel_port
from dam_hand_driver.dynamixel_goals import signed
from dam_hand_driver.dynamixel_setup_exit import EXIT_OK, PROG
from dam_hand_driver.dynamixel_table import (
    ADDR_BAUD_RATE,
    ADDR_HARDWARE_ERROR,
    ADDR_ID,
    ADDR_PRESENT_POSITION,
    ADDR_RETURN_DELAY_TIME,
    ADDR_TORQUE_ENABLE,
    DRAIN_LIMIT,
    QUIET_MS,
    TRANSACTION_TRIES,
    id_ranges,
)
from dam_hand_driver.errors import HandDriverError

if TYPE_CHECKING:
    from pathlib import Path

    from dam_common.config import DamConfig
    from dam_common.dynamixel_config import DynamixelConfig

#: Baud Rate register (address 8) values of the X series [bit/s] that the SDK can set
#: (7, 4.5 Mbit/s, it cannot).
BAUD_RATE_CODES: dict[int, int] = {9600: 0, 57600: 1, 115200: 2, 1000000: 3, 2000000: 4,
                                   3000000: 5, 4000000: 6}

#: Return Delay Time unit [s].
RETURN_DELAY_UNIT_S = 2e-6
#: The largest ID a servo can have.
MAX_ID = 252

#: After a failed transaction the input is drained until the line has been quiet this long
#: [s]: the SDK's packet timeout, as the driver's. An answer later than the SDK waited must not
#: be taken for the next one's (the SDK matches by ID only).
_QUIET_S = QUIET_MS / 1000.0
#: After a write of Baud Rate the servo switches; its next answer comes at the new rate [s].
_BAUD_SWITCH_S = 0.05

ZERO_HELP = ('Hold every finger straight (each joint at angle 0: the finger stretched out in '
             'line with its base) while the servos are read')


class SetupError(HandDriverError):
    """An operation failed (exit status 1); the message is the line printed."""


# -------------------------------------------------------------------------------------------
# Names of servos and models


def servo_label(servo_id: int, joint: str | None) -> str:
    """``servo ID 3 (finger1_position_joint)``, or ``servo ID 12`` of no joint."""
    return f'servo ID {servo_id}' + (f' ({joint})' if joint else '')


def model_text(model_number: int) -> str:
    """``XM430-W350 (model number 1020)``, or ``unknown model 1200: not supported``."""
    name = model_name(model_number)
    if name is None:
        return f'unknown model {model_number}: not supported'
    return f'{name} (model number {model_number})'


def model_name(model_number: int) -> str | None:
    """The supported model of ``model_number`` (``None``: not one of ``MODELS``)."""
    for name, spec in MODELS.items():
        if spec.model_number == model_number:
            return name
    return None


def supported_models() -> str:
    """``XC330-M288 (1240), XM430-W350 (1020)``."""
    return ', '.join(f'{name} ({spec.model_number})' for name, spec in sorted(MODELS.items()))


# -------------------------------------------------------------------------------------------
# The bus


class Bus:
    """One port opened exclusively through the SDK, with retried transactions.

    Parameters
    ----------
    sdk
        The ``dynamixel_sdk`` module.
    port
        The serial device.
    baud_rate
        The first baud rate [bit/s].

    Raises
    ------
    dam_hand_driver.errors.HandDriverError
        The port is missing, busy (the message names the holder's PID) or cannot be opened.
    """

    def __init__(self, sdk: Any, port: str, baud_rate: int) -> None:
        self.sdk = sdk
        self.port = port
        self.baud_rate = int(baud_rate)
        self.handler: Any = dynamixel_port.open_port(sdk, port, self.baud_rate)
        self.packets: Any = sdk.PacketHandler(2.0)

    def close(self) -> None:
        """Close the port and release its lock (idempotent)."""
        dynamixel_port.close_port(self.handler)

    def set_baud_rate(self, baud_rate: int) -> None:
        """Reopen the port at ``baud_rate`` [bit/s], keeping it locked.

        Raises
        ------
        dam_hand_driver.errors.HandDriverError
            It cannot be set, or another program took the port meanwhile.
        """
        if int(baud_rate) != self.baud_rate:
            dynamixel_port.set_baud_rate(self.handler, self.port, int(baud_rate))
            self.baud_rate = int(baud_rate)

    def drain(self) -> None:
        """Drop what arrives until the line has been quiet for :data:`_QUIET_S` (at most
        ``DRAIN_LIMIT`` of them)."""
        now = time.monotonic()
        quiet_until, give_up = now + _QUIET_S, now + DRAIN_LIMIT * _QUIET_S
        while now < quiet_until and now < give_up:
            SHUTDOWN.raise_if_requested()
            waiting = self.handler.getBytesAvailable()
            if waiting:
                self.handler.readPort(waiting)
                quiet_until = time.monotonic() + _QUIET_S
            else:
                time.sleep(0.002)
            now = time.monotonic()

    def _transact(self, call: Callable[[], tuple], tries: int = TRANSACTION_TRIES) -> tuple:
        """``call()`` (an SDK transaction returning ``(..., result, error)``) until it
        succeeds, at most ``tries`` times, the input drained after each failure."""
        for _ in range(tries):
            SHUTDOWN.raise_if_requested()
            answer = call()
            if answer[-2] == self.sdk.COMM_SUCCESS:
                break
            self.drain()
        return answer

    def broadcast_ping(self) -> tuple[dict[int, tuple[int, int]], bool]:
        """Every servo that answers a broadcast ping at the present baud rate.

        Returns
        -------
        answers
            ID -> (model number, firmware version).
        garbled
            Some answers were corrupt (two servos with one ID, noise, another baud rate).
        """
        SHUTDOWN.raise_if_requested()
        found, result = self.packets.broadcastPing(self.handler)
        garbled = result not in (self.sdk.COMM_SUCCESS, self.sdk.COMM_RX_TIMEOUT)
        if garbled:
            self.drain()
        return {int(i): (int(v[0]), int(v[1])) for i, v in found.items()}, garbled

    def ping(self, servo_id: int, tries: int = TRANSACTION_TRIES) -> int | None:
        """The model number ``servo_id`` answers a ping with (``None``: no answer)."""
        model, result, _error = self._transact(
            lambda: self.packets.ping(self.handler, servo_id), tries)
        return int(model) if result == self.sdk.COMM_SUCCESS else None

    def read(self, servo_id: int, address: int, size: int, what: str) -> int:
        """Read ``size`` bytes (1, 2 or 4) at ``address`` of ``servo_id`` (unsigned).

        Raises
        ------
        SetupError
            No answer after ``TRANSACTION_TRIES`` tries, or the servo's error (named).
        """
        read = {1: self.packets.read1ByteTxRx, 2: self.packets.read2ByteTxRx,
                4: self.packets.read4ByteTxRx}[size]
        value, result, error = self._transact(lambda: read(self.handler, servo_id, address))
        self._check(f'reading {what} (address {address}) of servo ID {servo_id}', result, error)
        return int(value)

    def write(self, servo_id: int, address: int, size: int, value: int, what: str) -> None:
        """Write ``value`` (``size`` bytes) at ``address`` of ``servo_id``.

        Raises
        ------
        SetupError
            No answer after ``TRANSACTION_TRIES`` tries, or the servo's error (named).
        """
        write = {1: self.packets.write1ByteTxRx, 2: self.packets.write2ByteTxRx,
                 4: self.packets.write4ByteTxRx}[size]
        raw = int(value) % (1 << 8 * size)
        result, error = self._transact(lambda: write(self.handler, servo_id, address, raw))
        self._check(f'writing {what} (address {address}) = {value} to servo ID {servo_id}',
                    result, error)

    def _check(self, what: str, result: int, error: int) -> None:
        if result != self.sdk.COMM_SUCCESS:
            raise SetupError(f'{what} on {self.port} at {self.baud_rate} bit/s: '
                             f'{self.packets.getTxRxResult(result)}')
        if error & 0x7F:
            raise SetupError(f'{what}: {self.packets.getRxPacketError(error)}')

    def read_positions(self, servos: Mapping[int, str]) -> dict[int, int]:
        """Present Position [counts, signed] of every servo in one Group Sync Read (one
        instant: the same values a later read of the control tables shows, if nothing moved).

        Parameters
        ----------
        servos
            ID -> joint name (for the message).

        Raises
        ------
        SetupError
            A servo's data missing after ``TRANSACTION_TRIES`` tries (named).
        """
        reader = self.sdk.GroupSyncRead(self.handler, self.packets, ADDR_PRESENT_POSITION, 4)
        for servo_id in servos:
            reader.addParam(servo_id)
        missing: list[int] = []
        for _ in range(TRANSACTION_TRIES):
            SHUTDOWN.raise_if_requested()
            result = reader.txRxPacket()
            missing = [i for i in servos if not reader.isAvailable(i, ADDR_PRESENT_POSITION, 4)]
            if result == self.sdk.COMM_SUCCESS and not missing:
                counts = signed([reader.getData(i, ADDR_PRESENT_POSITION, 4) for i in servos],
                                32)
                return {i: int(c) for i, c in zip(servos, counts, strict=True)}
            self.drain()
        names = ', '.join(servo_label(i, servos[i]) for i in missing) or 'a servo'
        raise SetupError(f'reading Present Position (address {ADDR_PRESENT_POSITION}) on '
                         f'{self.port} at {self.baud_rate} bit/s: no answer from {names}')


# -------------------------------------------------------------------------------------------
# Scan


@dataclass(frozen=True)
class FoundServo:
    """A servo that answered a broadcast ping (and a ping of its own ID)."""
    servo_id: int
    model_number: int
    firmware_version: int
    baud_rates: tuple[int, ...]  #: [bit/s] where it answered, in the order tried
    return_delay_raw: int | None  #: Return Delay Time [2 us] (None: not read, unknown model)
    hardware_error: int | None  #: Hardware Error Status bits (None: not read)

    @property
    def supported(self) -> bool:
        """Its model is one of ``MODELS``."""
        return model_name(self.model_number) is not None


@dataclass(frozen=True)
class ScanResult:
    """What a scan found."""
    baud_rates: tuple[int, ...]  #: tried [bit/s], in order
    answered: dict[int, tuple[int, ...]]  #: baud rate -> the IDs that answered there
    garbled: tuple[int, ...]  #: baud rates whose answers were partly corrupt
    servos: tuple[FoundServo, ...]  #: by ID (one per ID and model)


def baud_rate_order(configured: int, given: Sequence[int] | None) -> tuple[int, ...]:
    """The baud rates to try [bit/s]: ``given`` in its order, else ``BAUD_RATES`` with the
    configured one first (duplicates dropped)."""
    rates = list(given) if given else [configured, *BAUD_RATES]
    return tuple(dict.fromkeys(int(r) for r in rates))


def scan_bus(bus: Bus, baud_rates: Sequence[int], say: Callable[[str], None]) -> ScanResult:
    """Broadcast-ping at each baud rate; confirm each answer with a ping of its ID and read
    Return Delay Time and Hardware Error Status of the supported models (once per servo).

    Parameters
    ----------
    bus
        The open port.
    baud_rates
        [bit/s], in order.
    say
        Prints one line of progress.
    """
    answered: dict[int, tuple[int, ...]] = {}
    garbled: list[int] = []
    found: dict[tuple[int, int], FoundServo] = {}
    for rate in baud_rates:
        bus.set_baud_rate(rate)
        answers, bad = bus.broadcast_ping()
        confirmed: list[int] = []
        for servo_id, (model, firmware) in sorted(answers.items()):
            if bus.ping(servo_id) != model:  # a garbled answer, not a servo
                bad = True
                continue
            confirmed.append(servo_id)
            key = (servo_id, model)
            if key in found:
                old = found[key]
                found[key] = FoundServo(servo_id, model, old.firmware_version,
                                        (*old.baud_rates, rate), old.return_delay_raw,
                                        old.hardware_error)
                continue
            delay = error = None
            if model_name(model) is not None:
                delay = bus.read(servo_id, ADDR_RETURN_DELAY_TIME, 1, 'Return Delay Time')
                error = bus.read(servo_id, ADDR_HARDWARE_ERROR, 1, 'Hardware Error Status')
            found[key] = FoundServo(servo_id, model, firmware, (rate,), delay, error)
        answered[rate] = tuple(confirmed)
        if bad:
            garbled.append(rate)
        say(f'{rate} bit/s: ' + (f'{counted(len(confirmed), "servo")}, ID {id_ranges(confirmed)}'
                                 if confirmed
                                 else 'no servo')
            + (' (some answers were garbled: two servos with one ID, or noise)' if bad else ''))
    servos = tuple(sorted(found.values(), key=lambda s: (s.servo_id, s.model_number)))
    return ScanResult(tuple(baud_rates), answered, tuple(garbled), servos)


def no_servo_message(port: str, baud_rates: Sequence[int]) -> str:
    """The refusal when nothing answers."""
    return (f'no servo answers on {port} at any of ' + ', '.join(str(r) for r in baud_rates)
            + ' bit/s: check the supply (a servo\'s LED blinks once at power-up), the cable '
            'and the adapter (TTL or RS-485, as the servos); the servos must speak Protocol '
            '2.0')


def find_rate(bus: Bus, baud_rates: Sequence[int], ids: Sequence[int]) -> int | None:
    """The first baud rate [bit/s] at which one of ``ids`` answers a ping (``None``: none)."""
    for rate in baud_rates:
        bus.set_baud_rate(rate)
        for servo_id in ids:
            if bus.ping(servo_id, tries=1) is not None:
                return rate
    return None


# -------------------------------------------------------------------------------------------
# Subcommands on the bus


@dataclass
class Context:
    """What every subcommand needs."""
    sdk: Any
    config: DamConfig
    dxl: DynamixelConfig
    config_path: Path
    overlays: tuple[Path, ...]
    port: str
    baud_rates: tuple[int, ...]
    say: Callable[[str], None]

    def joints(self) -> dict[int, str]:
        """ID -> joint name of the configured servos."""
        return {s.servo_id: s.joint for s in self.dxl.servos}

    def open(self) -> Bus:
        """The port, open at the first baud rate."""
        return Bus(self.sdk, self.port, self.baud_rates[0])


def run_fix(ctx: Context, bus: Bus, target: int) -> int:
    """``fix``: Return Delay Time 0 and Baud Rate ``target`` [bit/s], torque off, on every
    servo found."""
    ctx.say(f'scanning {ctx.port} at ' + ', '.join(str(r) for r in ctx.baud_rates)
            + ' bit/s')
    result = scan_bus(bus, ctx.baud_rates, ctx.say)
    if not result.servos:
        raise SetupError(no_servo_message(ctx.port, ctx.baud_rates))
    joints = ctx.joints()
    failures: list[str] = []
    changed: dict[int, int] = {}  # ID -> model number, to check at the target rate
    for servo in result.servos:
        label = servo_label(servo.servo_id, joints.get(servo.servo_id))
        if not servo.supported:
            failures.append(f'{label} is {model_text(servo.model_number)} (supported: '
                            f'{supported_models()}): left as it is')
            continue
        rate = target if target in servo.baud_rates else servo.baud_rates[0]
        bus.set_baud_rate(rate)
        done = []
        bus.write(servo.servo_id, ADDR_TORQUE_ENABLE, 1, 0, 'Torque Enable')
        if servo.return_delay_raw:
            bus.write(servo.servo_id, ADDR_RETURN_DELAY_TIME, 1, 0, 'Return Delay Time')
            done.append(f'Return Delay Time {servo.return_delay_raw} -> 0')
        if target not in servo.baud_rates:
            bus.write(servo.servo_id, ADDR_BAUD_RATE, 1, BAUD_RATE_CODES[target], 'Baud Rate')
            done.append(f'Baud Rate {rate} -> {target} bit/s (register {BAUD_RATE_CODES[target]})')
            time.sleep(_BAUD_SWITCH_S)
        changed[servo.servo_id] = servo.model_number
        ctx.say(f'{label}: torque off' + (', ' + ', '.join(done) if done else
                                          ', nothing else to change'))
    bus.set_baud_rate(target)
    for servo_id, model in changed.items():
        label = servo_label(servo_id, joints.get(servo_id))
        if bus.ping(servo_id) != model:
            failures.append(f'{label} does not answer at {target} bit/s after the fix')
            continue
        delay = bus.read(servo_id, ADDR_RETURN_DELAY_TIME, 1, 'Return Delay Time')
        if delay:
            failures.append(f'{label} still has Return Delay Time {delay}')
    if failures:
        raise SetupError('; '.join(failures))
    ctx.say(f'{counted(len(changed), "servo")} at {target} bit/s with Return Delay Time 0 (torque '
            f'off); check with: {PROG} scan --port {ctx.port}')
    if target != ctx.dxl.baud_rate:
        ctx.say(f'note: set dynamixel.baud_rate: {target} in the configuration (it says '
                f'{ctx.dxl.baud_rate})')
    return EXIT_OK


def run_set_id(ctx: Context, bus: Bus, old: int, new: int) -> int:
    """``set-id``: torque off, then ID ``old`` becomes ``new``."""
    rate = find_rate(bus, ctx.baud_rates, [old])
    if rate is None:
        raise SetupError(f'no servo ID {old} answers on {ctx.port} at any of '
                         + ', '.join(str(r) for r in ctx.baud_rates) + f' bit/s ({PROG} scan '
                         f'lists the servos that answer)')
    model = bus.ping(old)
    if model is None:
        raise SetupError(f'servo ID {old} stopped answering at {rate} bit/s')
    if model_name(model) is None:
        raise SetupError(f'servo ID {old} is {model_text(model)} (supported: '
                         f'{supported_models()}): its ID is not changed here')
    taken = bus.ping(new)
    if taken is not None:
        raise SetupError(f'ID {new} is taken: a servo of {model_text(taken)} answers as ID '
                         f'{new} at {rate} bit/s (give that one another ID first)')
    bus.write(old, ADDR_TORQUE_ENABLE, 1, 0, 'Torque Enable')
    bus.write(old, ADDR_ID, 1, new, 'ID')
    if bus.ping(new) != model:
        raise SetupError(f'servo ID {old} was given ID {new} but does not answer as ID {new}')
    ctx.say(f'servo ID {old} ({model_text(model)}, {rate} bit/s) is now ID {new}')
    for cfg in ctx.dxl.servos:
        if cfg.servo_id == new:
            also = ('' if cfg.model == model_name(model) else
                    f'; the configuration says {cfg.model} for that joint')
            ctx.say(f'ID {new} is the servo of {cfg.joint} in {ctx.config.source}{also}')
            break
    else:
        ctx.say(f'note: ID {new} is no joint\'s servo in {ctx.config.source}')
    return EXIT_OK


def read_zero(ctx: Context, bus: Bus, section: bool) -> tuple[int, dict[int, str],
                                                              dict[int, int]]:
    """``zero`` on the bus: find the configured servos, check their models (and, without
    ``section``, the baud rate) against the configuration, then read Present Position of all
    of them in one sync read.

    Returns
    -------
    baud_rate
        Where the servos answer [bit/s].
    models
        ID -> the model found.
    positions
        ID -> Present Position [counts].

    Raises
    ------
    SetupError
        No configured servo answers; a servo missing, of an unknown model or (without
        ``section``) of another model than configured; (without ``section``) the servos at
        another baud rate than ``dynamixel.baud_rate``; a servo's position missing.
    """
    servos = ctx.dxl.servos
    joints = ctx.joints()
    rate = find_rate(bus, ctx.baud_rates, list(joints))
    if rate is None:
        raise SetupError('no configured servo (ID ' + ', '.join(str(i) for i in joints)
                         + f') answers on {ctx.port} at any of '
                         + ', '.join(str(r) for r in ctx.baud_rates) + ' bit/s')
    problems: list[str] = []
    models: dict[int, str] = {}
    for cfg in servos:
        label = servo_label(cfg.servo_id, cfg.joint)
        model = bus.ping(cfg.servo_id)
        name = model_name(model) if model is not None else None
        if model is None:
            problems.append(f'{label} does not answer at {rate} bit/s')
        elif name is None:
            problems.append(f'{label} is {model_text(model)} (supported: '
                            f'{supported_models()})')
        elif name != cfg.model and not section:
            problems.append(f'{label} is {model_text(model)}, the configuration says '
                            f'{cfg.model} ({cfg.spec.model_number}) (--section writes the '
                            f'models found)')
        else:
            models[cfg.servo_id] = name
    if problems:
        raise SetupError('; '.join(problems))
    if rate != ctx.dxl.baud_rate and not section:
        raise SetupError(f'the servos answer at {rate} bit/s, dynamixel.baud_rate is '
                         f'{ctx.dxl.baud_rate}: {PROG} fix --port {ctx.port} sets them to it '
                         f'(or --section writes the baud rate found)')
    ctx.say(f'{ZERO_HELP}.')
    ctx.say(f'reading Present Position of {len(servos)} servos on {ctx.port} at {rate} bit/s')
    return rate, models, bus.read_positions(joints)
