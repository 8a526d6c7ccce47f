"""Dynamixel Protocol 2.0 servos on one serial bus as a :class:`HandDevice` (no rclpy).

Through the official ``dynamixel-sdk``: one Group Sync Read of Realtime Tick .. Present
Position (addresses 120-135) of all servos per bus cycle, one Group Sync Write of Goal Current
.. Goal Position (102-119); Hardware Error Status (70) read by a second sync read every
:data:`HARDWARE_ERROR_EVERY` cycles. The host is the bus master: :meth:`receive` paces the
cycles at ``dynamixel.rate_hz``. See ``docs/dynamixel.md`` for wiring and configuration and
:mod:`dam_hand_driver.dynamixel_goals` for the control law.

Start-up: every configured servo must answer a ping with its configured model number, else
the device is refused naming the servo by ID and joint. Torque off, then Operating Mode and
Current Limit written (EEPROM: only while torque is off), Bus Watchdog cleared. Torque comes on
only in :meth:`arm` (the driver is ACTIVE), with the Bus Watchdog set, so that servos whose
host stops sending stop by themselves; :meth:`disarm` (driver ERROR) switches torque off.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from dam_common.config import DamConfig
from dam_common.device_protocol import JointMode
from dam_hand_driver.device import CommandItemLike, HandDevice, JointSample
from dam_hand_driver.dynamixel_goals import (
    ServoTable,
    goals_raw,
    mode_error,
    signed,
    state_si,
    update_hold,
)
from dam_hand_driver.errors import HandDriverError

try:  # imported here, not at start-up: a stop request may come at any moment of that
    import dynamixel_sdk as sdk
    _SDK_IMPORT_ERROR = ''
except ImportError as _exc:  # the driver still serves the UDP link without it
    sdk = None
    _SDK_IMPORT_ERROR = str(_exc)

# Control table addresses (X series, shared by the supported models).
ADDR_MODEL_NUMBER = 0
ADDR_RETURN_DELAY_TIME = 9
ADDR_OPERATING_MODE = 11
ADDR_CURRENT_LIMIT = 38
ADDR_TORQUE_ENABLE = 64
ADDR_HARDWARE_ERROR = 70
ADDR_BUS_WATCHDOG = 98
ADDR_GOAL_CURRENT = 102
ADDR_GOAL_POSITION = 116
ADDR_REALTIME_TICK = 120
ADDR_PRESENT_CURRENT = 126
ADDR_PRESENT_VELOCITY = 128
ADDR_PRESENT_POSITION = 132
#: The block one sync read takes per cycle: Realtime Tick .. Present Position.
STATE_START, STATE_LENGTH = ADDR_REALTIME_TICK, 16
#: The block one sync write gives per cycle: Goal Current .. Goal Position.
GOAL_START, GOAL_LENGTH = ADDR_GOAL_CURRENT, 18
#: Torque Enable .. Hardware Error Status (64-70) is read once every this many cycles.
HARDWARE_ERROR_EVERY = 25
CHECK_START, CHECK_LENGTH = ADDR_TORQUE_ENABLE, ADDR_HARDWARE_ERROR - ADDR_TORQUE_ENABLE + 1
#: Hardware Error Status bits (ROBOTIS e-manual, X series).
HARDWARE_ERROR_BITS = {0: 'input voltage error', 2: 'overheating error',
                       3: 'motor encoder error', 4: 'electrical shock error',
                       5: 'overload error'}
#: The errors a reboot clears and ``~/reset`` reboots for.
REBOOT_BITS = (1 << 2) | (1 << 5)
#: Tries of one start-up, arming or recovery transaction before a servo counts as silent.
_TRANSACTION_TRIES = 3
#: The emulated bus on simulated time steps the world at each state read and answers when
#: its Python process gets the CPU: on a loaded machine later than the SDK's packet timeout
#: (34 ms). A read the host gave up on would advance the simulated clock unseen, so its
#: timeouts get this much more [ms] (a simulated clock does not care how long a read takes).
_EMULATED_PACKET_MARGIN_MS = 1000.0
#: The SDK's packet timeout without the transfer time [ms]: twice its USB latency timer
#: (16 ms) plus 2 ms. After a failed transaction the input is drained until the line has
#: been quiet this long (plus the margin): an answer later than the SDK waited must not be
#: taken for the next transaction's (the SDK matches status packets by ID only).
_QUIET_MS = 2.0 * 16.0 + 2.0
#: A drain ends after this many quiet times even if bytes keep coming.
_DRAIN_LIMIT = 8
#: Reads of a Hardware Error Status in :meth:`DynamixelDevice.recover` before a servo that
#: answers only with stale answers counts as not answering.
_STATUS_READ_TRIES = 3
_KNOWN_BITS = sum(1 << b for b in HARDWARE_ERROR_BITS)
_TICK_WRAP_MS = 32768
#: Failed reads in a row after which the compliant (current) joints get zero current.
LIMP_AFTER_FAILED_READS = 3
_REBOOT_WAIT_S = 2.0


def _stale_error_bits(bits: int | np.ndarray) -> int | np.ndarray:
    """Bits that no Hardware Error Status has: an answer of an earlier transaction, which the
    SDK took for this one (it matches status packets by ID only)."""
    return bits & ~_KNOWN_BITS


def hardware_error_names(bits: int) -> str:
    """``overload error, overheating error`` for Hardware Error Status ``bits``."""
    names = [name for bit, name in HARDWARE_ERROR_BITS.items() if bits & (1 << bit)]
    unknown = bits & ~sum(1 << b for b in HARDWARE_ERROR_BITS)
    if unknown:
        names.append(f'unknown bits 0x{unknown:02x}')
    return ', '.join(names) if names else 'none'


def _port_handler(sdk_module: object, port: str, margin_ms: float) -> object:
    """The SDK's port handler, its packet timeouts longer by ``margin_ms`` [ms]."""
    base = sdk_module.PortHandler  # type: ignore[attr-defined]
    if margin_ms <= 0.0:
        return base(port)

    class _Patient(base):  # type: ignore[misc, valid-type]
        def setPacketTimeout(self, packet_length: int) -> None:  # noqa: N802 - the SDK's
            super().setPacketTimeout(packet_length)
            self.packet_timeout += margin_ms

    return _Patient(port)


def usb_latency_timer_ms(port: str) -> int | None:
    """The USB serial adapter's latency timer [ms] (``None``: not a USB serial adapter, or it
    cannot be read)."""
    name = Path(os.path.realpath(port)).name
    try:
        return int(Path(f'/sys/bus/usb-serial/devices/{name}/latency_timer').read_text())
    except (OSError, ValueError):
        return None


class DynamixelDevice(HandDevice):
    """The hand's nine Dynamixel servos.

    Parameters
    ----------
    config
        ``dynamixel`` (port, baud rate, rate, servos), ``device.torque_limit_nm``.
    port
        The serial port; ``None``: ``dynamixel.port``.
    clock_hint_ns
        The node's clock now [ns]: fixes the 32.768 s ambiguity of the servos' Realtime Tick
        when the first sample's stamp is taken (simulated time on the emulated bus).
    simulated
        The bus is the emulated one (its samples say so).
    sim_time
        ... on simulated time: the packet timeouts are :data:`_EMULATED_PACKET_MARGIN_MS`
        longer.

    Raises
    ------
    HandDriverError
        No ``dynamixel:`` section or no port; the SDK is missing; the port cannot be opened;
        a servo does not answer its ping or is of another model; a setting cannot be written.
    """

    kind = 'dynamixel'

    def __init__(self, config: DamConfig, port: str | None = None, *,
                 clock_hint_ns: Callable[[], int] | None = None,
                 simulated: bool = False, sim_time: bool = False) -> None:
        dxl = config.dynamixel
        if dxl is None:
            raise HandDriverError(f'backend dynamixel needs the dynamixel: section in the '
                                  f'configuration ({config.source}); see docs/dynamixel.md')
        port = port or dxl.port
        if not port:
            raise HandDriverError('backend dynamixel: no serial port (dynamixel.port is empty '
                                  'and no port parameter was given)')
        if sdk is None:
            raise HandDriverError(f'backend dynamixel needs the dynamixel-sdk package '
                                  f'(pip install dynamixel-sdk): {_SDK_IMPORT_ERROR}')
        self._sdk = sdk
        self.config = dxl
        self.port = port
        self.table = ServoTable.from_config(dxl)
        self.n = len(self.table.ids)
        self.period_s = 1.0 / dxl.rate_hz
        self.hardware_id = f'{port}@{dxl.baud_rate}'
        self.torque_limit_nm = float(config.device.torque_limit_nm)
        self.hold_stiffness = float(dxl.hold_stiffness_nm_per_rad)
        self.hold_damping = float(dxl.hold_damping_nms_per_rad)
        self.simulated = bool(simulated)
        self._clock_hint_ns = clock_hint_ns
        self._lock = threading.Lock()  # one transaction on the bus at a time
        margin_ms = _EMULATED_PACKET_MARGIN_MS if sim_time else 0.0
        self._port = _port_handler(sdk, port, margin_ms)
        self._quiet_s = (_QUIET_MS + margin_ms) / 1000.0
        try:
            opened = self._port.openPort() and self._port.setBaudRate(dxl.baud_rate)
        except Exception as exc:  # noqa: BLE001 - pyserial raises SerialException, OSError
            raise HandDriverError(f'cannot open the Dynamixel port {port!r}: {exc}') from exc
        if not opened:
            raise HandDriverError(f'cannot open the Dynamixel port {port!r} at '
                                  f'{dxl.baud_rate} bit/s')
        self._ph = sdk.PacketHandler(2.0)
        try:
            self._check_servos()
            self._configure()
            self.rate_report = self._rate_report()
        except BaseException:
            self._port.closePort()
            raise
        self._reader = sdk.GroupSyncRead(self._port, self._ph, STATE_START, STATE_LENGTH)
        self._error_reader = sdk.GroupSyncRead(self._port, self._ph, CHECK_START, CHECK_LENGTH)
        self._writer = sdk.GroupSyncWrite(self._port, self._ph, GOAL_START, GOAL_LENGTH)
        for servo_id in self.table.ids:
            self._reader.addParam(servo_id)
            self._error_reader.addParam(servo_id)
        self.samples_received = 0
        self.last_sample_time: float | None = None
        self.read_failures = 0  #: sync reads that failed or came back incomplete
        self.last_read_failure = ''
        self.write_failures = 0
        self.commands_sent = 0
        self.hardware_errors = np.zeros(self.n, dtype=np.int64)  #: Hardware Error Status
        self._error_candidates = np.zeros(self.n, dtype=np.int64)
        #: Servos found with torque off while armed (restarted).
        self.torque_lost = np.zeros(self.n, dtype=bool)
        self._torque_off_candidates = np.zeros(self.n, dtype=bool)
        self.armed = False
        self._seq = 0
        self._cycles = 0
        self._next_deadline: float | None = None
        self._tick_ms: int | None = None
        self._time_ms = 0
        self._modes = np.full(self.n, int(JointMode.HOLD), dtype=np.int64)
        self._hold = np.zeros(self.n)
        self._failed_in_a_row = 0
        self._goal_current = np.zeros(self.n, dtype=np.int64)
        self._goal_position = np.zeros(self.n, dtype=np.int64)
        self._closed = False

    # ---------------------------------------------------------------------------------------
    # Start-up

    def _result(self, what: str, j: int, result: int, error: int) -> None:
        if result != self._sdk.COMM_SUCCESS:
            raise HandDriverError(f'{what} of servo {self.table.label(j)} on {self.port}: '
                                  f'{self._ph.getTxRxResult(result)}')
        if error & 0x7F:
            raise HandDriverError(f'{what} of servo {self.table.label(j)} on {self.port}: '
                                  f'{self._ph.getRxPacketError(error)}')

    def _check_servos(self) -> None:
        """Ping every servo; refuse the bus naming each one missing or of another model."""
        problems = []
        for j, servo in enumerate(self.config.servos):
            for _ in range(_TRANSACTION_TRIES):
                model, result, _error = self._ph.ping(self._port, servo.servo_id)
                if result == self._sdk.COMM_SUCCESS:
                    break
                self._clear_input()
            if result != self._sdk.COMM_SUCCESS:
                problems.append(f'servo {self.table.label(j)} does not answer the ping '
                                f'({self._ph.getTxRxResult(result)})')
            elif model != servo.spec.model_number:
                problems.append(f'servo {self.table.label(j)} is model number {model}, the '
                                f'configuration says {servo.model} '
                                f'({servo.spec.model_number})')
        if problems:
            raise HandDriverError(
                f'the Dynamixel bus on {self.port} at {self.config.baud_rate} bit/s does not '
                f'match dynamixel.servos: ' + '; '.join(problems))

    def _write(self, j: int, address: int, size: int, value: int, what: str) -> None:
        write = {1: self._ph.write1ByteTxRx, 2: self._ph.write2ByteTxRx,
                 4: self._ph.write4ByteTxRx}[size]
        raw = int(value) % (1 << 8 * size)
        for _ in range(_TRANSACTION_TRIES):  # a late answer is not yet a missing servo
            result, error = write(self._port, self.table.ids[j], address, raw)
            if result == self._sdk.COMM_SUCCESS:
                break
            self._clear_input()
        self._result(f'writing {what}', j, result, error)

    def _read(self, j: int, address: int, size: int, what: str) -> int:
        read = {1: self._ph.read1ByteTxRx, 2: self._ph.read2ByteTxRx,
                4: self._ph.read4ByteTxRx}[size]
        for _ in range(_TRANSACTION_TRIES):
            value, result, error = read(self._port, self.table.ids[j], address)
            if result == self._sdk.COMM_SUCCESS:
                break
            self._clear_input()
        self._result(f'reading {what}', j, result, error)
        return int(value)

    def _configure(self) -> None:
        """Torque off, then the EEPROM settings; Bus Watchdog cleared."""
        modes = self.table.operating_modes
        for j, servo in enumerate(self.config.servos):
            self._write(j, ADDR_TORQUE_ENABLE, 1, 0, 'Torque Enable')
            self._write(j, ADDR_BUS_WATCHDOG, 1, 0, 'Bus Watchdog')
            if self._read(j, ADDR_OPERATING_MODE, 1, 'Operating Mode') != modes[j]:
                self._write(j, ADDR_OPERATING_MODE, 1, int(modes[j]), 'Operating Mode')
            self._write(j, ADDR_CURRENT_LIMIT, 2, servo.current_limit_raw, 'Current Limit')

    def _rate_report(self) -> list[str]:
        """The settings that cap the bus rate below ``dynamixel.rate_hz``, each with its fix."""
        report = []
        delays = [self._read(j, ADDR_RETURN_DELAY_TIME, 1, 'Return Delay Time')
                  for j in range(self.n)]
        slow = [f'{self.table.label(j)}: {2 * d} us' for j, d in enumerate(delays) if d]
        # Each servo answers a sync read after its Return Delay Time (2 us units).
        delay_s = sum(2e-6 * d for d in delays)
        if slow:
            report.append(
                f'Return Delay Time is not 0 ({", ".join(slow)}): every sync read waits '
                f'{delay_s * 1e3:.2f} ms for it; fix: write 0 to address 9 of each servo with '
                f'torque off (Dynamixel Wizard 2.0, or the SDK\'s write1ByteTxRx)')
        latency = usb_latency_timer_ms(self.port)
        if latency is not None and latency > 1:
            report.append(
                f'the USB serial adapter\'s latency timer is {latency} ms: each bus '
                f'transaction may wait that long, capping the rate near {500.0 / latency:.0f} '
                f'Hz; fix: echo 1 | sudo tee /sys/bus/usb-serial/devices/'
                f'{Path(os.path.realpath(self.port)).name}/latency_timer (or a udev rule '
                f'setting ATTR{{latency_timer}}="1")')
        bytes_per_cycle = (14 + self.n) + self.n * (11 + STATE_LENGTH) \
            + (14 + self.n * (1 + GOAL_LENGTH))
        wire_s = bytes_per_cycle * 10.0 / self.config.baud_rate + delay_s
        if wire_s > self.period_s:
            report.append(
                f'{bytes_per_cycle} bytes per cycle take {wire_s * 1e3:.2f} ms at '
                f'{self.config.baud_rate} bit/s, longer than the {self.period_s * 1e3:.2f} ms '
                f'of dynamixel.rate_hz {self.config.rate_hz:g}: raise the baud rate (all '
                f'servos and dynamixel.baud_rate) or lower the rate')
        return report

    # ---------------------------------------------------------------------------------------
    # The bus cycle

    def receive(self, timeout_s: float) -> JointSample | None:
        now = time.monotonic()
        if self._next_deadline is None:
            self._next_deadline = now
        wait = self._next_deadline - now
        if wait > timeout_s:
            time.sleep(max(timeout_s, 0.0))
            return None
        if wait > 0.0:
            time.sleep(wait)
        # The next cycle one period on; a late cycle is not caught up.
        self._next_deadline = max(self._next_deadline + self.period_s,
                                  time.monotonic() - self.period_s)
        with self._lock:
            if self._closed:
                return None
            try:
                sample = self._read_state()
            except Exception as exc:  # noqa: BLE001 - whatever the bus sends, no sample
                sample = self._read_failed(f'sync read: {exc!r}')
        return sample

    def _read_failed(self, why: str) -> None:
        """Count a failed or incomplete read; let answers still under way arrive and drop
        them, so that they are not taken for the next transaction's (the SDK matches status
        packets by ID only)."""
        self.read_failures += 1
        self.last_read_failure = why
        self._failed_in_a_row += 1
        self._clear_input()
        if self._failed_in_a_row == LIMP_AFTER_FAILED_READS and self.armed:
            # The host law has no state to run on: a current held from an old state would
            # keep pushing (to a joint limit). The compliant joints go limp, the position
            # servos keep their goal; the next good read takes over again.
            current = np.where(self.table.current_mode, 0, self._goal_current)
            self._write_goals(current, self._goal_position)

    def _clear_input(self) -> None:
        """Drop what the port receives until the line has been quiet for one packet timeout
        (at most :data:`_DRAIN_LIMIT` of them): answers later than the SDK waited arrive
        during the drain, not in the next transaction. Nothing if the port is gone (the
        reads say so)."""
        now = time.monotonic()
        quiet_until = now + self._quiet_s
        give_up = now + _DRAIN_LIMIT * self._quiet_s
        try:
            while now < quiet_until and now < give_up:
                waiting = self._port.getBytesAvailable()
                if waiting:
                    self._port.readPort(waiting)
                    quiet_until = time.monotonic() + self._quiet_s
                else:
                    time.sleep(0.001)
                now = time.monotonic()
        except Exception:  # noqa: BLE001 - termios.error, OSError: a port that went away
            pass

    def _complete(self, reader: object, length: int) -> str | None:
        """Which servo's data is missing or of the wrong length (``None``: all there)."""
        data = getattr(reader, 'data_dict', {})
        for j, servo_id in enumerate(self.table.ids):
            if len(data.get(servo_id) or ()) != length:
                return f'no complete data from {self.table.label(j)}'
        return None

    def _read_state(self) -> JointSample | None:
        sdk = self._sdk
        result = self._reader.txRxPacket()
        missing = self._complete(self._reader, STATE_LENGTH)
        if result != sdk.COMM_SUCCESS:
            return self._read_failed(f'sync read: {missing or "failed"} '
                                     f'({self._ph.getTxRxResult(result)})')
        if missing is not None:
            return self._read_failed(f'sync read: {missing}')
        raw = np.zeros((self.n, 4), dtype=np.int64)
        for j, servo_id in enumerate(self.table.ids):
            raw[j] = (self._reader.getData(servo_id, ADDR_REALTIME_TICK, 2),
                      self._reader.getData(servo_id, ADDR_PRESENT_CURRENT, 2),
                      self._reader.getData(servo_id, ADDR_PRESENT_VELOCITY, 4),
                      self._reader.getData(servo_id, ADDR_PRESENT_POSITION, 4))
        q, dq, tau = state_si(self.table, signed(raw[:, 1], 16), signed(raw[:, 2], 32),
                              signed(raw[:, 3], 32))
        self._cycles += 1
        if self._cycles % HARDWARE_ERROR_EVERY in (1, 2):
            self._read_hardware_errors()
        self._seq = (self._seq + 1) % 2**32
        self._failed_in_a_row = 0
        self.samples_received += 1
        self.last_sample_time = time.monotonic()
        return JointSample(seq=self._seq, stamp_ns=self._stamp_ns(int(raw[0, 0])), position=q,
                           velocity=dq, effort=tau, simulated=self.simulated,
                           fault=self._fault())

    def _stamp_ns(self, tick_ms: int) -> int:
        """The servos' Realtime Tick [ms, wraps at 32768] unwrapped to a clock [ns]."""
        if self._tick_ms is None:
            hint_ms = self._clock_hint_ns() // 1_000_000 if self._clock_hint_ns else 0
            # The time that shows this tick, nearest to the node's clock.
            base = hint_ms - (hint_ms - tick_ms) % _TICK_WRAP_MS
            if hint_ms - base > _TICK_WRAP_MS // 2:
                base += _TICK_WRAP_MS
            self._time_ms = max(base, 0)
        else:
            self._time_ms += (tick_ms - self._tick_ms) % _TICK_WRAP_MS
        self._tick_ms = tick_ms
        return self._time_ms * 1_000_000

    def _read_hardware_errors(self) -> None:
        result = self._error_reader.txRxPacket()
        if result != self._sdk.COMM_SUCCESS or self._complete(self._error_reader, CHECK_LENGTH):
            self._clear_input()  # the state reads count the bus's failures
            return
        bits = np.array([self._error_reader.getData(servo_id, ADDR_HARDWARE_ERROR, 1)
                         for servo_id in self.table.ids], dtype=np.int64)
        torque = np.array([self._error_reader.getData(servo_id, ADDR_TORQUE_ENABLE, 1)
                           for servo_id in self.table.ids], dtype=np.int64)
        if np.any(_stale_error_bits(bits)) or np.any(torque > 1):
            # Not a Hardware Error Status: an answer of an earlier transaction (the SDK
            # matches by ID only). Dropped, like the rest of the input.
            self.read_failures += 1
            self.last_read_failure = 'hardware error read: a stale answer'
            self._clear_input()
            return
        # A bit counts when two reads in a row show it.
        self.hardware_errors = bits & self._error_candidates
        self._error_candidates = bits
        # Torque off while armed, without a hardware error: the servo restarted (a power dip,
        # a reboot by someone else). Also two reads in a row.
        off = (torque == 0) & (bits == 0)
        self.torque_lost = (off & self._torque_off_candidates) if self.armed \
            else np.zeros_like(off)
        self._torque_off_candidates = off

    def _fault(self) -> str:
        bad = np.flatnonzero(self.hardware_errors)
        faults = [f'servo {self.table.label(j)}: hardware error '
                  f'{hardware_error_names(int(self.hardware_errors[j]))}' for j in bad]
        faults += [f'servo {self.table.label(j)}: torque went off (the servo restarted: power '
                   f'dip or reboot)' for j in np.flatnonzero(self.torque_lost)]
        return '; '.join(faults)

    def needs_rearm(self) -> str:
        """Why the armed hand must be armed again (empty: it need not): a servo whose torque
        is off (read now, from the executor's thread)."""
        if not self.armed:
            return ''
        off = []
        with self._lock:
            for j, servo_id in enumerate(self.table.ids):
                value, result, _ = self._ph.read1ByteTxRx(self._port, servo_id,
                                                          ADDR_TORQUE_ENABLE)
                if result == self._sdk.COMM_SUCCESS and value == 0:
                    off.append(self.table.label(j))
        return f'torque off on servo {", ".join(off)}' if off else ''

    def send(self, sample: JointSample, modes: np.ndarray, setpoints: np.ndarray,
             stiffness: np.ndarray, damping: np.ndarray) -> None:
        m = np.asarray(modes, dtype=np.int64)
        self._hold = update_hold(self._hold, self._modes, m, sample.position)
        self._modes = m.copy()
        current, position, _tau = goals_raw(
            self.table, sample.position, sample.velocity, m, setpoints, stiffness, damping,
            self._hold, self.torque_limit_nm, self.hold_stiffness, self.hold_damping)
        with self._lock:
            if self._closed:
                return
            self._write_goals(current, position)

    def _write_goals(self, current: np.ndarray, position: np.ndarray) -> None:
        self._goal_current, self._goal_position = current, position
        self._writer.clearParam()
        for j, servo_id in enumerate(self.table.ids):
            block = (int(current[j]) % (1 << 16)).to_bytes(2, 'little') + bytes(12) \
                + (int(position[j]) % (1 << 32)).to_bytes(4, 'little')
            self._writer.addParam(servo_id, list(block))
        if self._writer.txPacket() == self._sdk.COMM_SUCCESS:
            self.commands_sent += 1
        else:
            self.write_failures += 1

    def command_error(self, items: Sequence[CommandItemLike]) -> str | None:
        for item in items:
            why = mode_error(self.table, int(item.joint), int(item.mode))
            if why is not None:
                return why
        return None

    # ---------------------------------------------------------------------------------------
    # Torque on and off, recovery

    def arm(self, sample: JointSample) -> None:
        """Hold the present posture, then torque on and the Bus Watchdog set.

        Raises
        ------
        HandDriverError
            A servo refused a write (named).
        """
        self._modes[:] = int(JointMode.HOLD)
        self._hold = np.asarray(sample.position, dtype=np.float64).copy()
        zeros = np.zeros(self.n)
        current, position, _ = goals_raw(
            self.table, sample.position, zeros, self._modes, zeros, zeros, zeros, self._hold,
            self.torque_limit_nm, self.hold_stiffness, self.hold_damping)
        current = np.where(self.table.current_mode, 0, current)  # no step at switch-on
        with self._lock:
            for j in range(self.n):
                self._write(j, ADDR_BUS_WATCHDOG, 1, 0, 'Bus Watchdog')  # clear a trip
                self._write(j, ADDR_GOAL_CURRENT, 2, int(current[j]), 'Goal Current')
                self._write(j, ADDR_GOAL_POSITION, 4, int(position[j]), 'Goal Position')
                self._write(j, ADDR_TORQUE_ENABLE, 1, 1, 'Torque Enable')
                self._write(j, ADDR_BUS_WATCHDOG, 1, self.config.bus_watchdog_raw,
                            'Bus Watchdog')
            self._goal_current, self._goal_position = current, position
            self.armed = True
            self.torque_lost[:] = False
            self._torque_off_candidates[:] = False

    def disarm(self) -> None:
        """Torque off and Bus Watchdog cleared on every servo that answers (best effort: the
        Bus Watchdog stops the others once the host stops writing)."""
        with self._lock:
            if self._closed:
                return
            for servo_id in self.table.ids:
                self._ph.write1ByteTxRx(self._port, servo_id, ADDR_TORQUE_ENABLE, 0)
                # A host that stops now would trip the watchdog of a servo already off.
                self._ph.write1ByteTxRx(self._port, servo_id, ADDR_BUS_WATCHDOG, 0)
            self.armed = False

    def _read_error_status(self, servo_id: int) -> int | None:
        """The Hardware Error Status of one servo; ``None`` when it does not answer, or only
        with answers of earlier transactions (bits no error has: the SDK matches an answer
        by ID only), :data:`_STATUS_READ_TRIES` times with the input drained in between."""
        for _ in range(_STATUS_READ_TRIES):
            bits, result, _ = self._ph.read1ByteTxRx(self._port, servo_id, ADDR_HARDWARE_ERROR)
            if result != self._sdk.COMM_SUCCESS:
                return None
            if not _stale_error_bits(bits):
                return int(bits)
            self.read_failures += 1
            self.last_read_failure = 'hardware error read: a stale answer'
            self._clear_input()
        return None

    def recover(self) -> str:
        """Reboot the servos in an overload or overheating error, wait for them, write their
        settings again (torque stays off until :meth:`arm`). Returns what was done."""
        done = []
        with self._lock:
            for j, servo_id in enumerate(self.table.ids):
                bits = self._read_error_status(servo_id)
                if bits is None:
                    done.append(f'servo {self.table.label(j)} does not answer')
                    continue
                self.hardware_errors[j] = bits
                if bits & REBOOT_BITS:
                    self._ph.reboot(self._port, servo_id)
                    deadline = time.monotonic() + _REBOOT_WAIT_S
                    while time.monotonic() < deadline:
                        _, result, _ = self._ph.ping(self._port, servo_id)
                        if result == self._sdk.COMM_SUCCESS:
                            break
                        time.sleep(0.05)
                    done.append(f'rebooted servo {self.table.label(j)} '
                                f'({hardware_error_names(int(bits))})')
                    self.hardware_errors[j] = 0
                elif bits:
                    done.append(f'servo {self.table.label(j)} keeps '
                                f'{hardware_error_names(int(bits))} (a reboot does not clear '
                                f'it: check the supply and the wiring)')
            try:
                self._configure()
            except HandDriverError as exc:
                done.append(str(exc))
            self.armed = False
            # Torque is off until arm() on purpose: a loss seen before this recovery (a read
            # of the state thread between two of its transactions) is no fault of the hand
            # that is about to be armed.
            self.torque_lost[:] = False
            self._torque_off_candidates[:] = False
            self._next_deadline = None
        return '; '.join(done)

    # ---------------------------------------------------------------------------------------

    def diagnostics(self) -> dict[str, str]:
        values = {
            'bus': self.hardware_id,
            'bus_rate_target_hz': f'{self.config.rate_hz:g}',
            'bus_read_failures': str(self.read_failures),
            'bus_last_read_failure': self.last_read_failure,
            'bus_write_failures': str(self.write_failures),
            'commands_sent': str(self.commands_sent),
            'torque_enabled': str(self.armed),
            'rate_caps': ' | '.join(self.rate_report) if self.rate_report else 'none',
        }
        for j in range(self.n):
            bits = int(self.hardware_errors[j])
            values[f'hardware_error_id{self.table.ids[j]}'] = (
                f'{bits} ({hardware_error_names(bits)})' if bits else '0')
        return values

    def close(self) -> None:
        """Torque off where the bus still answers, then close the port (idempotent)."""
        if self._closed:
            return
        if self.armed:
            try:
                self.disarm()
            except Exception:  # noqa: BLE001 - closing: the port may be gone
                pass
        with self._lock:
            self._closed = True
            try:
                self._port.closePort()
            except Exception:  # noqa: BLE001 - the device may have disappeared
                pass

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def last_failure(self) -> str:
        return self.last_read_failure
