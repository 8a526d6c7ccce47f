"""An emulated Dynamixel Protocol 2.0 bus on a pseudo-terminal.

:class:`DynamixelBus` opens a pty and plays every servo of a list of
:class:`~dam_sim_bridge.dynamixel_servo.DynamixelServo` on it: any Protocol 2.0 host (the
``dynamixel_sdk`` ``PortHandler(path)`` + ``PacketHandler(2.0)``) opens :attr:`port_path` (or
the symlink :attr:`link_path`) as it would open a USB serial adapter.

**Baud rate.** Bytes move at pty speed, but the rate the host sets counts as on a real bus:
a servo hears the line only when the host's rate is within 3 % (the e-manual's UART margin)
of its Baud Rate (address 8); the others receive garbage, so they neither act, answer nor feed
their watchdog. The host's rate is the pty's output speed (:meth:`DynamixelBus.line_baud_rate`:
the two ends of a pty share their termios on Linux; ``tcgetattr`` on the bus's end, and on
Linux ``TCGETS2`` for a rate without a ``B`` constant such as 4.5 Mbit/s), read when the bus
takes the bytes; when it cannot be read, every servo hears. A pty opens at 38400 bit/s, a rate
no X servo has: the host must set its rate, as the SDK's ``PortHandler`` does.

Dispatch, as real hardware on one half-duplex bus (among the servos that hear the line):

* a unicast instruction is answered by the servo of that ID (if its Status Return Level allows:
  0 only PING, 1 PING and READ, 2 everything); an ID no servo has gets no answer;
* SYNC_READ: each listed servo answers with its own status packet, in the listed order;
* SYNC_WRITE, and WRITE or REBOOT to the broadcast ID: no answer;
* broadcast PING: every servo answers, in ID order;
* a packet with a bad CRC is answered with CRC Error by the servo it names (unicast only).

**Bus Watchdog feeding** (``watchdog_feed``). The e-manual counts "all the Instruction Packet
in the DYNAMIXEL Protocol" as communication, without saying whether packets for other IDs
count. Both readings are offered; with either, a packet with a bad CRC or at another baud rate
feeds no servo:

* ``addressed`` (default, the stricter): a servo is fed by packets with its ID, by plain
  broadcasts (PING, WRITE, REBOOT, ... to ID 254), and by sync and bulk packets (SYNC_READ,
  SYNC_WRITE, FAST_SYNC_READ, BULK_READ, BULK_WRITE, FAST_BULK_READ) that list its ID;
* ``any``: every instruction packet on the bus feeds every servo.

Fault injection (thread-safe, all off by default): :attr:`DynamixelBus.crc_error_ids`,
:attr:`DynamixelBus.silent_ids`, :attr:`DynamixelBus.status_delay_s` and
:meth:`DynamixelBus.hardware_error`. Each status packet is also held back by its servo's Return
Delay Time (address 9; 500 us by default, as on real servos).
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import os
import re
import select
import struct
import sys
import termios
import threading
import time
import tty
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass

from dam_sim_bridge.dynamixel_packets import (
    STATUS_INSTRUCTION,
    CorruptPacket,
    ErrorCode,
    Instruction,
    Packet,
    PacketParser,
    build_status,
    from_le,
)
from dam_sim_bridge.dynamixel_servo import DynamixelServo, Status

#: The reader loop wakes at least this often to look at its stop flag [s].
POLL_S = 0.02
#: An incomplete packet is dropped when no byte came for this long [s].
PARTIAL_TIMEOUT_S = 0.1
#: A status packet that cannot be written within this long is dropped [s].
WRITE_TIMEOUT_S = 0.2
_READ_CHUNK = 4096
#: ``watchdog_feed``: packets with a servo's ID, plain broadcasts, sync and bulk packets that
#: list its ID feed its Bus Watchdog.
WATCHDOG_FEED_ADDRESSED = 'addressed'
#: ``watchdog_feed``: every instruction packet feeds every servo's Bus Watchdog.
WATCHDOG_FEED_ANY = 'any'
#: The values of ``watchdog_feed``.
WATCHDOG_FEEDS = (WATCHDOG_FEED_ADDRESSED, WATCHDOG_FEED_ANY)
#: A servo hears a host whose rate is off its Baud Rate by at most this fraction (e-manual:
#: "less than 3% of the baud rate error margin will not affect UART communication").
BAUD_RATE_TOLERANCE = 0.03

# Instructions that list IDs but are not emulated (Protocol 2.0).
_BULK_READ, _BULK_WRITE, _FAST_BULK_READ = 0x92, 0x93, 0x9A
# termios speed constants (B9600, ...) to bit/s.
_TERMIOS_RATES = {getattr(termios, name): int(name[1:]) for name in dir(termios)
                  if re.fullmatch(r'B\d+', name)}
_BOTHER = 0o010000  # Linux: the rate is in termios2's c_ispeed/c_ospeed
# Linux TCGETS2 = _IOR('T', 0x2A, struct termios2), struct termios2 of 44 bytes, where the
# ioctl numbers are asm-generic's.
_TCGETS2 = 0x802C542A
_TERMIOS2 = struct.Struct('=4I20x2I')  # flags, c_line + c_cc[19], c_ispeed, c_ospeed
_TCGETS2_MACHINES = ('x86_64', 'i386', 'i686', 'aarch64', 'armv7l', 'armv6l', 'riscv64')

_Answer = tuple[int, DynamixelServo, Status]  # (ID at the time of the instruction, servo, status)


@dataclass
class BusStats:
    """Counters of a bus (and of the stand-in that owns it)."""

    packets: int = 0  #: instruction packets received with a good CRC
    crc_errors: int = 0  #: packets received with a bad CRC
    garbage_bytes: int = 0  #: bytes skipped outside packets
    ignored: int = 0  #: good packets no servo acts on (unknown ID, status packets, ...)
    status_sent: int = 0  #: status packets written
    status_dropped: int = 0  #: status packets that could not be written (no reader)
    cycles: int = 0  #: physics cycles (counted by the stand-in)
    missed_deadlines: int = 0  #: real-time cycles started more than a period late


class DynamixelBus:
    """Servos behind a pseudo-terminal.

    Parameters
    ----------
    servos
        The servos on the bus (their IDs are read from their tables at every packet, so a
        written ID takes effect at once).
    link_path
        If given, a symlink to the pty created here and removed by :meth:`close` (an existing
        symlink there is replaced).
    clock
        Device clock [s], for the Bus Watchdog and Realtime Tick.
    lock
        Guards the servos' tables; the bus holds it while it handles a packet (never while it
        writes or waits). A new RLock by default.
    before_dispatch
        Called with every packet (good CRC) that a servo hears, before it is handled, with
        ``lock`` held (the stand-in steps its world here in lockstep).
    watchdog_feed
        Which packets feed a servo's Bus Watchdog: ``'addressed'`` or ``'any'`` (module
        docstring).

    Raises
    ------
    ValueError
        ``watchdog_feed`` is not one of :data:`WATCHDOG_FEEDS`.
    OSError
        The pty cannot be opened or the link cannot be created.
    FileExistsError
        ``link_path`` exists and is not a symlink.
    """

    def __init__(self, servos: Sequence[DynamixelServo], *, link_path: str | None = None,
                 clock: Callable[[], float] = time.monotonic,
                 lock: threading.RLock | None = None,
                 before_dispatch: Callable[[Packet], None] | None = None,
                 watchdog_feed: str = WATCHDOG_FEED_ADDRESSED) -> None:
        if watchdog_feed not in WATCHDOG_FEEDS:
            raise ValueError(f'watchdog_feed {watchdog_feed!r} is not one of {WATCHDOG_FEEDS}')
        self._watchdog_feed = watchdog_feed
        self.servos: tuple[DynamixelServo, ...] = tuple(servos)
        self.lock = lock if lock is not None else threading.RLock()
        self.stats = BusStats()
        self._clock = clock
        self._before_dispatch = before_dispatch
        self._parser = PacketParser()
        self._last_rx_s = time.monotonic()
        self._faults = threading.Lock()
        self._crc_error_ids: frozenset[int] = frozenset()
        self._silent_ids: frozenset[int] = frozenset()
        self._status_delay_s = 0.0
        self._stop = threading.Event()
        self._serving = threading.Lock()
        self._closed = False
        self._master, self._slave = os.openpty()
        try:
            tty.setraw(self._slave)
            os.set_blocking(self._master, False)
            self.port_path: str = os.ttyname(self._slave)
            self.link_path: str | None = None
            if link_path:
                self._make_link(str(link_path))
        except BaseException:
            os.close(self._master)
            os.close(self._slave)
            raise

    def _make_link(self, path: str) -> None:
        if os.path.lexists(path):
            if not os.path.islink(path):
                raise FileExistsError(errno.EEXIST, 'not a symlink, not replaced', path)
            os.unlink(path)
        os.symlink(self.port_path, path)
        self.link_path = path

    @property
    def watchdog_feed(self) -> str:
        """``'addressed'`` or ``'any'``: which packets feed a servo's Bus Watchdog."""
        return self._watchdog_feed

    def line_baud_rate(self) -> int | None:
        """The rate the host set on the pty [bit/s] (0: hung up), ``None`` if unknown.

        The termios output speed of the bus's end of the pty, which Linux shares with the
        host's end.
        """
        try:
            speed = termios.tcgetattr(self._slave)[5]
        except (termios.error, OSError, ValueError):
            return None
        if speed == _BOTHER and sys.platform.startswith('linux'):
            return _termios2_output_speed(self._slave)
        return _TERMIOS_RATES.get(speed, speed)  # else a C library whose speeds are bit/s

    def _hearing(self) -> tuple[DynamixelServo, ...]:
        """The servos whose Baud Rate matches the host's (all if the host's is unknown)."""
        rate = self.line_baud_rate()
        if rate is None:
            return self.servos
        return tuple(s for s in self.servos
                     if abs(rate - s.baud_rate_bps) <= BAUD_RATE_TOLERANCE * s.baud_rate_bps)

    # ---------------------------------------------------------------------------------------
    # Fault injection

    @property
    def crc_error_ids(self) -> frozenset[int]:
        """IDs whose status packets go out with a corrupted CRC."""
        return self._crc_error_ids

    @crc_error_ids.setter
    def crc_error_ids(self, ids: Iterable[int]) -> None:
        with self._faults:
            self._crc_error_ids = frozenset(int(i) for i in ids)

    @property
    def silent_ids(self) -> frozenset[int]:
        """IDs that never answer (they still act on what they receive: a broken TX line)."""
        return self._silent_ids

    @silent_ids.setter
    def silent_ids(self, ids: Iterable[int]) -> None:
        with self._faults:
            self._silent_ids = frozenset(int(i) for i in ids)

    @property
    def status_delay_s(self) -> float:
        """Every status packet is written this much later than it would be [s]."""
        return self._status_delay_s

    @status_delay_s.setter
    def status_delay_s(self, delay_s: float) -> None:
        delay = float(delay_s)
        if not 0.0 <= delay < 60.0:
            raise ValueError(f'status delay {delay_s!r} s must be in [0, 60) s')
        with self._faults:
            self._status_delay_s = delay

    def servo(self, servo_id: int) -> DynamixelServo | None:
        """The servo that has ``servo_id`` now, or ``None`` (whatever its baud rate)."""
        return _with_id(self.servos, servo_id)

    def hardware_error(self, servo_id: int, bits: int) -> None:
        """Set Hardware Error Status ``bits`` on a servo, with their consequences (torque off
        when Shutdown enables one, Alert bit in every status packet until a REBOOT).

        Parameters
        ----------
        servo_id
            The servo's current ID.
        bits
            Bits of address 70: 0x01 input voltage, 0x04 overheating, 0x08 motor encoder,
            0x10 electrical shock, 0x20 overload.

        Raises
        ------
        KeyError
            No servo has this ID.
        ValueError
            ``bits`` is not a byte.
        """
        with self.lock:
            s = self.servo(servo_id)
            if s is None:
                raise KeyError(f'no servo with ID {servo_id} on the bus')
            s.set_hardware_error(bits)

    # ---------------------------------------------------------------------------------------
    # Dispatch

    def handle(self, packet: Packet | CorruptPacket) -> list[_Answer]:
        """Act on one packet; the status packets due, in the order they go on the bus.

        Parameters
        ----------
        packet
            A parsed instruction packet, or one whose CRC failed.

        Returns
        -------
        list
            ``(id, servo, status)`` per answer (``id``: the servo's ID when the instruction
            arrived).
        """
        with self.lock:
            hearing = self._hearing()
            if isinstance(packet, CorruptPacket):
                self.stats.crc_errors += 1
                s = _with_id(hearing, packet.packet_id)
                if s is None or not _answers(s, packet.instruction):
                    return []
                return [(s.servo_id, s, s.status(ErrorCode.CRC))]
            if packet.instruction == STATUS_INSTRUCTION:
                self.stats.ignored += 1
                return []
            self.stats.packets += 1
            if self._before_dispatch is not None and hearing:
                self._before_dispatch(packet)
            now = self._clock()
            for s in self.servos:
                s.check_watchdog(now)
            for s in self._fed(packet, hearing):
                s.heard(now)
            if packet.is_broadcast:
                return self._broadcast(packet, hearing, now)
            s = _with_id(hearing, packet.packet_id)
            if s is None:
                self.stats.ignored += 1
                return []
            sid = s.servo_id
            status = self._unicast(s, packet, now)
            return [(sid, s, status)] if _answers(s, packet.instruction) else []

    def _fed(self, packet: Packet, hearing: tuple[DynamixelServo, ...]
             ) -> tuple[DynamixelServo, ...]:
        """The servos whose Bus Watchdog ``packet`` feeds (of those that hear it)."""
        if self._watchdog_feed == WATCHDOG_FEED_ANY:
            return hearing
        if not packet.is_broadcast:
            s = _with_id(hearing, packet.packet_id)
            return () if s is None else (s,)
        listed = _listed_ids(packet)
        if listed is None:  # a plain broadcast
            return hearing
        return tuple(s for s in hearing if s.servo_id in listed)

    def _unicast(self, s: DynamixelServo, packet: Packet, now: float) -> Status:
        p, inst = packet.params, packet.instruction
        if inst == Instruction.PING:
            return s.ping()
        if inst == Instruction.READ:
            if len(p) != 4:
                return s.status(ErrorCode.DATA_LENGTH)
            return s.read(from_le(p[0:2]), from_le(p[2:4]), now)
        if inst == Instruction.WRITE:
            if len(p) < 3:
                return s.status(ErrorCode.DATA_LENGTH)
            return s.write(from_le(p[0:2]), p[2:])
        if inst == Instruction.REBOOT:
            return s.reboot()
        return s.status(ErrorCode.INSTRUCTION)

    def _broadcast(self, packet: Packet, hearing: tuple[DynamixelServo, ...], now: float
                   ) -> list[_Answer]:
        p, inst = packet.params, packet.instruction
        if inst == Instruction.PING:
            ordered = sorted(hearing, key=lambda s: s.servo_id)
            return [(s.servo_id, s, s.ping()) for s in ordered]
        if inst == Instruction.WRITE and len(p) >= 3:
            for s in hearing:
                s.write(from_le(p[0:2]), p[2:])
            return []
        if inst == Instruction.REBOOT:
            for s in hearing:
                s.reboot()
            return []
        if inst == Instruction.SYNC_READ and len(p) >= 4:
            address, length = from_le(p[0:2]), from_le(p[2:4])
            answers = []
            for sid in p[4:]:
                s = _with_id(hearing, sid)
                if s is not None and s.status_return_level >= 1:
                    answers.append((sid, s, s.read(address, length, now)))
            return answers
        if inst == Instruction.SYNC_WRITE and len(p) >= 4:
            address, length = from_le(p[0:2]), from_le(p[2:4])
            block = length + 1
            if length < 1 or (len(p) - 4) % block:
                self.stats.ignored += 1
                return []
            for k in range(4, len(p), block):
                s = _with_id(hearing, p[k])
                if s is not None:
                    s.write(address, p[k + 1:k + block])
            return []
        self.stats.ignored += 1  # e.g. READ to broadcast, FAST_SYNC_READ (not emulated)
        return []

    # ---------------------------------------------------------------------------------------
    # The line

    def _write_all(self, data: bytes) -> bool:
        """Write ``data`` to the master; ``False`` if it could not go out in time."""
        view = memoryview(data)
        deadline = time.monotonic() + WRITE_TIMEOUT_S
        while view:
            try:
                n = os.write(self._master, view)
                view = view[n:]
                continue
            except (BlockingIOError, InterruptedError):
                pass
            except OSError:  # EIO: nobody on the other end; any other: drop the packet
                return False
            left = deadline - time.monotonic()
            if left <= 0.0:
                return False
            try:
                select.select([], [self._master], [], left)
            except (OSError, ValueError):
                return False
        return True

    def _send(self, answers: list[_Answer], t0: float) -> None:
        """Write the status packets of one instruction, each held back by the injected delay
        and its servo's Return Delay Time after ``t0`` [s, time.monotonic]."""
        with self._faults:
            crc_ids, silent, delay = (self._crc_error_ids, self._silent_ids,
                                      self._status_delay_s)
        for sid, servo, status in answers:
            if sid in silent:
                continue
            data = build_status(sid, status.error, status.params)
            if sid in crc_ids:
                data = data[:-2] + bytes((data[-2] ^ 0xFF, data[-1] ^ 0x5A))
            wait = t0 + delay + servo.return_delay_s - time.monotonic()
            if wait > 0.0:
                time.sleep(wait)
            if self._write_all(data):
                self.stats.status_sent += 1
            else:
                self.stats.status_dropped += 1

    def feed(self, data: bytes) -> None:
        """Handle ``data`` as if it came from the line (parse, dispatch, answer).

        Parameters
        ----------
        data
            Bytes from the host.
        """
        now = time.monotonic()
        if self._parser.pending and now - self._last_rx_s > PARTIAL_TIMEOUT_S:
            self._parser.discard_partial()
        self._last_rx_s = now
        for packet in self._parser.feed(data):
            answers = self.handle(packet)
            if answers:
                self._send(answers, time.monotonic())
        self.stats.garbage_bytes = self._parser.garbage_bytes

    def poll(self, timeout_s: float = POLL_S) -> bool:
        """Wait up to ``timeout_s`` [s] for bytes from the host and handle them.

        Returns
        -------
        bool
            ``True`` if bytes came.
        """
        try:
            ready, _, _ = select.select([self._master], [], [], timeout_s)
        except (OSError, ValueError):  # closed meanwhile
            return False
        if not ready:
            return False
        try:
            data = os.read(self._master, _READ_CHUNK)
        except (BlockingIOError, InterruptedError):
            return False
        except OSError:  # EIO while no slave is open
            time.sleep(timeout_s)
            return False
        if not data:
            return False
        self.feed(data)
        return True

    def serve(self, stop: threading.Event | None = None) -> None:
        """Handle the host's packets until :meth:`stop`, :meth:`close` or ``stop`` is set."""
        with self._serving:
            while not (self._stop.is_set() or (stop is not None and stop.is_set())):
                self.poll(POLL_S)

    def stop(self) -> None:
        """Ask :meth:`serve` to return (within :data:`POLL_S`)."""
        self._stop.set()

    def close(self) -> None:
        """Stop serving, close the pty and remove the link (idempotent)."""
        self._stop.set()
        if self._closed:
            return
        acquired = self._serving.acquire(timeout=1.0)  # let serve() leave its select
        try:
            self._closed = True
            for fd in (self._master, self._slave):
                with contextlib.suppress(OSError):
                    os.close(fd)
            if self.link_path is not None:
                with contextlib.suppress(OSError):
                    if os.path.islink(self.link_path):
                        os.unlink(self.link_path)
        finally:
            if acquired:
                self._serving.release()

    def __enter__(self) -> DynamixelBus:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _with_id(servos: Iterable[DynamixelServo], servo_id: int) -> DynamixelServo | None:
    """The servo of ``servos`` that has ``servo_id`` now, or ``None``."""
    for s in servos:
        if s.servo_id == servo_id:
            return s
    return None


def _listed_ids(packet: Packet) -> frozenset[int] | None:
    """The IDs a broadcast sync or bulk packet lists (empty if it is malformed); ``None`` for
    a plain broadcast (another instruction)."""
    p, inst = packet.params, packet.instruction
    if inst in (Instruction.SYNC_READ, Instruction.FAST_SYNC_READ):
        return frozenset(p[4:]) if len(p) >= 4 else frozenset()
    if inst == Instruction.SYNC_WRITE:
        length = from_le(p[2:4]) if len(p) >= 4 else 0
        if length < 1 or (len(p) - 4) % (length + 1):
            return frozenset()
        return frozenset(p[4::length + 1])
    if inst in (_BULK_READ, _FAST_BULK_READ):  # per servo: ID, address (2), length (2)
        return frozenset(p[0::5]) if len(p) % 5 == 0 else frozenset()
    if inst == _BULK_WRITE:  # per servo: ID, address (2), length (2), data
        ids, k = set(), 0
        while k + 5 <= len(p):
            ids.add(p[k])
            k += 5 + from_le(p[k + 3:k + 5])
        return frozenset(ids) if k == len(p) else frozenset()
    return None


def _termios2_output_speed(fd: int) -> int | None:
    """The output speed of ``fd`` from Linux's ``TCGETS2`` [bit/s], ``None`` where this
    machine's ioctl numbers are not known here or the call fails."""
    if os.uname().machine not in _TCGETS2_MACHINES:
        return None
    try:
        raw = fcntl.ioctl(fd, _TCGETS2, bytes(_TERMIOS2.size))
    except OSError:
        return None
    return int(_TERMIOS2.unpack(raw)[5])


def _answers(servo: DynamixelServo, instruction: int) -> bool:
    """Whether ``servo``'s Status Return Level lets it answer a unicast ``instruction``."""
    level = servo.status_return_level
    if instruction == Instruction.PING:
        return True
    if instruction == Instruction.READ:
        return level >= 1
    return level >= 2
