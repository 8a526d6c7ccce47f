"""Dynamixel Protocol 2.0 servos on one serial bus as a :class:`HandDevice` (no rclpy).

Through the official ``dynamixel-sdk``: one Group Sync Read of Realtime Tick .. Present
Position (addresses 120-135) of all servos per bus cycle, one Group Sync Write of Goal Current
.. Goal Position (102-119). A second sync read, of Torque Enable .. Goal Position (64-119:
Hardware Error Status, Bus Watchdog and the goals the servos hold), checks the servos every
:data:`CHECK_EVERY` cycles, and at once when a status packet carries the Alert bit. The host
is the bus master: :meth:`receive` paces the cycles at ``dynamixel.rate_hz``. See
``docs/dynamixel.md`` for wiring and configuration and :mod:`dam_hand_driver.dynamixel_goals`
for the control law.

Start-up: the port is opened exclusively (:mod:`dam_hand_driver.dynamixel_port`); every
configured servo must answer a ping with its configured model number, else the device is
refused naming the servo by ID and joint. Torque off, then Operating Mode and Current Limit
written (EEPROM: only while torque is off), Bus Watchdog cleared. Torque comes on only in
:meth:`arm` (the driver is ACTIVE): every servo holds its posture with torque on, and only then
one Sync Write sets the Bus Watchdog of all of them, so that no watchdog runs while the others
are armed, and servos whose host stops sending stop by themselves. A tripped watchdog (address
98 reads 255: the servo refuses its goals), a servo whose goals are not the ones written, a
hardware error and a port that fails (an adapter unplugged) are faults: the driver goes to
ERROR naming them, and :meth:`disarm` switches torque off.
"""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Callable, Sequence

import numpy as np

from dam_common.config import DamConfig
from dam_common.device_protocol import JointMode
from dam_hand_driver.device import CommandItemLike, HandDevice, JointSample
from dam_hand_driver.dynamixel_check import CheckRead, ServoCheck
from dam_hand_driver.dynamixel_goals import (
    ServoTable,
    goals_raw,
    mode_error,
    signed,
    state_si,
    update_hold,
)
from dam_hand_driver.dynamixel_port import (
    PORT_ERRORS,
    PortLost,
    checked_sync_read,
    close_port,
    latency_timer_fix,
    open_port,
    usb_latency_timer_ms,
)
from dam_hand_driver.dynamixel_table import (
    ADDR_BUS_WATCHDOG,
    ADDR_CURRENT_LIMIT,
    ADDR_GOAL_CURRENT,
    ADDR_GOAL_POSITION,
    ADDR_HARDWARE_ERROR,
    ADDR_OPERATING_MODE,
    ADDR_PRESENT_CURRENT,
    ADDR_PRESENT_POSITION,
    ADDR_PRESENT_VELOCITY,
    ADDR_REALTIME_TICK,
    ADDR_RETURN_DELAY_TIME,
    ADDR_TORQUE_ENABLE,
    ALERT_BIT,
    CHECK_LENGTH,
    CHECK_START,
    DRAIN_LIMIT,
    GOAL_LENGTH,
    GOAL_START,
    QUIET_MS,
    STATE_LENGTH,
    STATE_START,
    TRANSACTION_TRIES,
    hardware_error_names,
    stale_error_bits,
)
from dam_hand_driver.errors import HandDriverError

try:  # imported here, not at start-up: a stop request may come at any moment of that
    import dynamixel_sdk as sdk
    _SDK_IMPORT_ERROR = ''
except ImportError as _exc:  # the driver still serves the UDP link without it
    sdk = None
    _SDK_IMPORT_ERROR = str(_exc)

#: The servo check (:mod:`dam_hand_driver.dynamixel_check`) reads its block every this many
#: cycles (twice in a row, as a fault counts when two reads show it), and at once after a
#: status packet with the Alert bit.
CHECK_EVERY = 25
#: The emulated bus on simulated time steps the world at each state read and answers when
#: its Python process gets the CPU: on a loaded machine later than the SDK's packet timeout
#: (34 ms). A read the host gave up on would advance the simulated clock unseen, so its
#: timeouts get this much more [ms] (a simulated clock does not care how long a read takes).
_EMULATED_PACKET_MARGIN_MS = 1000.0
#: Reads of a Hardware Error Status in :meth:`DynamixelDevice.recover` before a servo that
#: answers only with stale answers counts as not answering.
_STATUS_READ_TRIES = 3
_TICK_WRAP_MS = 32768
#: Failed reads in a row after which the compliant (current) joints get zero current.
LIMP_AFTER_FAILED_READS = 3
_REBOOT_WAIT_S = 2.0


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
    PortBusyError
        Another program holds the port (:mod:`dam_hand_driver.dynamixel_port`).
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
        self._margin_ms = _EMULATED_PACKET_MARGIN_MS if sim_time else 0.0
        self._quiet_s = (QUIET_MS + self._margin_ms) / 1000.0
        self._ph = sdk.PacketHandler(2.0)
        #: Status packets with the Alert bit, and whether they ask for a check of the servos.
        self.alerts = 0
        self._alert_pending = False
        self._port = self._open()
        try:
            self.rate_report = self._rate_report()
        except BaseException:
            close_port(self._port)
            raise
        self.samples_received = 0
        self.last_sample_time: float | None = None
        self.read_failures = 0  #: sync reads that failed or came back incomplete
        self.last_read_failure = ''
        self.write_failures = 0
        self.commands_sent = 0
        #: What the servo check found (hardware errors, torque lost, tripped watchdogs,
        #: refused goals).
        self.check = ServoCheck(self.table, dxl.bus_watchdog_s)
        #: Why the port failed (empty: it works): a fault until ``recover`` opens it again.
        self.port_lost = ''
        #: Sync writes of goals since :meth:`arm` (the check compares the goals read back
        #: only once one has reached the servos).
        self._writes_since_arm = 0
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

    def _open(self) -> object:
        """Open the port exclusively, check the servos and write their settings; the groups
        of the bus cycle use it.

        Raises
        ------
        HandDriverError
            As the constructor.
        """
        port = open_port(self._sdk, self.port, self.config.baud_rate, margin_ms=self._margin_ms)
        self._port = port
        try:
            self._check_servos()
            self._configure()
        except BaseException:
            close_port(port)
            raise
        sdk = self._sdk
        self._reader = checked_sync_read(sdk)(port, self._ph, STATE_START, STATE_LENGTH)
        self._check_reader = checked_sync_read(sdk)(port, self._ph, CHECK_START,
                                                      CHECK_LENGTH)
        self._writer = sdk.GroupSyncWrite(port, self._ph, GOAL_START, GOAL_LENGTH)
        self._watchdog_writer = sdk.GroupSyncWrite(port, self._ph, ADDR_BUS_WATCHDOG, 1)
        for servo_id in self.table.ids:
            self._reader.addParam(servo_id)
            self._check_reader.addParam(servo_id)
        return port

    def _note_alert(self, error: int) -> None:
        """A status packet's error byte: the Alert bit starts a check of the servos at once."""
        if error & ALERT_BIT:
            self.alerts += 1
            self._alert_pending = True

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
        silent = []
        for j, servo in enumerate(self.config.servos):
            model, result, _error = self._transact(
                lambda sid=servo.servo_id: self._ph.ping(self._port, sid))
            if result != self._sdk.COMM_SUCCESS:
                silent.append(j)
                problems.append(f'servo {self.table.label(j)} does not answer the ping '
                                f'({self._ph.getTxRxResult(result)})')
            elif model != servo.spec.model_number:
                problems.append(f'servo {self.table.label(j)} is model number {model}, the '
                                f'configuration says {servo.model} '
                                f'({servo.spec.model_number})')
        if len(silent) == self.n:
            raise HandDriverError(
                f'no servo answers on {self.port} at {self.config.baud_rate} bit/s: the servos '
                f'at another baud rate, without power, or another adapter? (`dynamixel_setup '
                f'scan --port {self.port}` tries every rate)')
        if problems:
            raise HandDriverError(
                f'the Dynamixel bus on {self.port} at {self.config.baud_rate} bit/s does not '
                f'match dynamixel.servos: ' + '; '.join(problems))

    def _write(self, j: int, address: int, size: int, value: int, what: str) -> None:
        write = {1: self._ph.write1ByteTxRx, 2: self._ph.write2ByteTxRx,
                 4: self._ph.write4ByteTxRx}[size]
        raw = int(value) % (1 << 8 * size)
        servo_id = self.table.ids[j]
        # A late answer is not yet a missing servo.
        result, error = self._transact(lambda: write(self._port, servo_id, address, raw))
        self._result(f'writing {what}', j, result, error)

    def _read(self, j: int, address: int, size: int, what: str) -> int:
        read = {1: self._ph.read1ByteTxRx, 2: self._ph.read2ByteTxRx,
                4: self._ph.read4ByteTxRx}[size]
        servo_id = self.table.ids[j]
        value, result, error = self._transact(lambda: read(self._port, servo_id, address))
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
                f'Hz; fix: {latency_timer_fix(self.port)}')
        bytes_per_cycle = (14 + self.n) + self.n * (11 + STATE_LENGTH) \
            + (14 + self.n * (1 + GOAL_LENGTH))
        wire_s = bytes_per_cycle * 10.0 / self.config.baud_rate
        if wire_s + delay_s > self.period_s:
            # Name what takes the time: the wire (the baud rate) or the servos' waits.
            fix = ('raise the baud rate (all servos and dynamixel.baud_rate) or lower the rate'
                   if wire_s > self.period_s else
                   'write 0 to Return Delay Time (address 9, torque off) as above')
            report.append(
                f'one cycle takes {(wire_s + delay_s) * 1e3:.2f} ms ({bytes_per_cycle} bytes '
                f'in {wire_s * 1e3:.2f} ms at {self.config.baud_rate} bit/s, plus '
                f'{delay_s * 1e3:.2f} ms of Return Delay Time), longer than the '
                f'{self.period_s * 1e3:.2f} ms of dynamixel.rate_hz {self.config.rate_hz:g}: '
                f'{fix}')
        return report

    # ---------------------------------------------------------------------------------------
    # The bus cycle

    def receive(self, timeout_s: float) -> JointSample | None:
        if self.port_lost:  # nothing to read until recover() opens the port again
            time.sleep(max(timeout_s, 0.0))
            return None
        now = time.monotonic()
        # One read of the deadline: recover() (another thread) may reset it meanwhile.
        deadline = self._next_deadline
        if deadline is None:
            deadline = now
        wait = deadline - now
        if wait > timeout_s:
            time.sleep(max(timeout_s, 0.0))
            return None
        if wait > 0.0:
            time.sleep(wait)
        # The next cycle one period on; a late cycle is not caught up.
        self._next_deadline = max(deadline + self.period_s, time.monotonic() - self.period_s)
        with self._lock:
            if self._closed or self.port_lost:
                return None
            try:
                sample = self._read_state()
            except PORT_ERRORS as exc:  # the port failed
                sample = self._lose_port(exc)
            except Exception as exc:  # noqa: BLE001 - whatever the bus sends, no sample
                sample = self._read_failed(f'sync read: {exc!r}')
        return sample

    def _lose_port(self, exc: BaseException) -> None:
        """The port failed: a fault named by the port until :meth:`recover` reopens it."""
        self._port.is_using = False  # the SDK's flag stays set when a transaction raises
        gone = '' if os.path.exists(self.port) else ' (the device is gone: adapter unplugged?)'
        self.port_lost = (f'the Dynamixel port {self.port!r} failed{gone}: '
                          f'{type(exc).__name__}: {exc}')
        self.read_failures += 1
        self.last_read_failure = self.port_lost
        self._failed_in_a_row += 1

    @property
    def link_lost(self) -> str:
        return self.port_lost

    @property
    def failing_reads(self) -> int:
        return self._failed_in_a_row

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
        (at most :data:`DRAIN_LIMIT` of them): answers later than the SDK waited arrive
        during the drain, not in the next transaction. Nothing if the port is gone (the
        reads say so)."""
        now = time.monotonic()
        quiet_until = now + self._quiet_s
        give_up = now + DRAIN_LIMIT * self._quiet_s
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
        stale = getattr(reader, 'stale', None)
        if stale is not None:
            return (f'a status packet of another length from ID {stale} (an answer of an '
                    f'earlier transaction)')
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
        refused = self._status_errors(self._reader)
        if refused:
            return self._read_failed(f'sync read: {refused}')
        raw = np.zeros((self.n, 4), dtype=np.int64)
        for j, servo_id in enumerate(self.table.ids):
            raw[j] = (self._reader.getData(servo_id, ADDR_REALTIME_TICK, 2),
                      self._reader.getData(servo_id, ADDR_PRESENT_CURRENT, 2),
                      self._reader.getData(servo_id, ADDR_PRESENT_VELOCITY, 4),
                      self._reader.getData(servo_id, ADDR_PRESENT_POSITION, 4))
        q, dq, tau = state_si(self.table, signed(raw[:, 1], 16), signed(raw[:, 2], 32),
                              signed(raw[:, 3], 32))
        self._cycles += 1
        if self._cycles % CHECK_EVERY in (1, 2) or self._alert_pending:
            self._check()
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

    def _status_errors(self, reader: object) -> str:
        """The servos whose status packets in ``reader`` carry an error (the Alert bit
        noted), named; empty: none."""
        errors = getattr(reader, 'errors', {})
        bad = []
        for j, servo_id in enumerate(self.table.ids):
            error = errors.get(servo_id, 0)
            self._note_alert(error)
            if error & 0x7F:
                bad.append(f'{self.table.label(j)} answered {self._ph.getRxPacketError(error)}')
        return '; '.join(bad)

    def _check(self) -> None:
        """Read Torque Enable .. Goal Position of every servo: hardware errors, a torque that
        went off, a tripped Bus Watchdog and goals other than the ones written, each a fault
        when two reads in a row show it."""
        self._alert_pending = False
        reader = self._check_reader
        result = reader.txRxPacket()
        if result != self._sdk.COMM_SUCCESS or self._complete(reader, CHECK_LENGTH):
            self._clear_input()  # the state reads count the bus's failures
            self._alert_pending = True  # check again next cycle
            return
        self._status_errors(reader)
        self._alert_pending = False  # the Alert bit of this very read asks for nothing more

        def column(address: int, size: int) -> np.ndarray:
            return np.array([reader.getData(servo_id, address, size)
                             for servo_id in self.table.ids], dtype=np.int64)

        bits = column(ADDR_HARDWARE_ERROR, 1)
        torque = column(ADDR_TORQUE_ENABLE, 1)
        if np.any(stale_error_bits(bits)) or np.any(torque > 1):
            # Not a Hardware Error Status: an answer of an earlier transaction (the SDK
            # matches by ID only). Dropped, like the rest of the input.
            self.read_failures += 1
            self.last_read_failure = 'servo check: a stale answer'
            self._clear_input()
            return
        read = CheckRead(torque_enable=torque, hardware_error=bits,
                         bus_watchdog=column(ADDR_BUS_WATCHDOG, 1),
                         goal_current=signed(column(ADDR_GOAL_CURRENT, 2), 16),
                         goal_position=signed(column(ADDR_GOAL_POSITION, 4), 32))
        written = (self._goal_current, self._goal_position) if self._writes_since_arm \
            else None
        self.check.update(read, self.armed, written)

    def _fault(self) -> str:
        return self.check.fault()

    def needs_rearm(self) -> str:
        """Why the armed hand must be armed again (empty: it need not): a servo whose torque
        is off (read now, from the executor's thread)."""
        if not self.armed:
            return ''
        off = []
        with self._lock:
            if self.port_lost:
                return self.port_lost
            try:
                for j, servo_id in enumerate(self.table.ids):
                    value, result, _ = self._ph.read1ByteTxRx(self._port, servo_id,
                                                              ADDR_TORQUE_ENABLE)
                    if result == self._sdk.COMM_SUCCESS and value == 0:
                        off.append(self.table.label(j))
            except PORT_ERRORS as exc:
                self._lose_port(exc)
                return self.port_lost
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
            if self._closed or self.port_lost:
                return
            self._write_goals(current, position)

    def _write_goals(self, current: np.ndarray, position: np.ndarray) -> None:
        self._goal_current, self._goal_position = current, position
        self._writer.clearParam()
        for j, servo_id in enumerate(self.table.ids):
            block = (int(current[j]) % (1 << 16)).to_bytes(2, 'little') + bytes(12) \
                + (int(position[j]) % (1 << 32)).to_bytes(4, 'little')
            self._writer.addParam(servo_id, list(block))
        try:
            result = self._writer.txPacket()
        except PORT_ERRORS as exc:
            self._lose_port(exc)
            return
        if result == self._sdk.COMM_SUCCESS:
            self.commands_sent += 1
            self._writes_since_arm += 1
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
        """Hold the present posture with torque on, then the Bus Watchdog of every servo in
        one Sync Write.

        Each servo gets its watchdog cleared (a trip too), its goals (the posture) and
        Torque Enable, all with no watchdog running; only then does one Sync Write set the
        watchdog of all of them at once. The next bus cycle (a read and a write to every
        servo) follows at once, so no watchdog runs out while others are armed, whichever
        packets feed it: its own only, or any on the bus.

        Raises
        ------
        HandDriverError
            A servo refused a write (named), or the port failed.
        """
        self._modes[:] = int(JointMode.HOLD)
        self._hold = np.asarray(sample.position, dtype=np.float64).copy()
        zeros = np.zeros(self.n)
        current, position, _ = goals_raw(
            self.table, sample.position, zeros, self._modes, zeros, zeros, zeros, self._hold,
            self.torque_limit_nm, self.hold_stiffness, self.hold_damping)
        current = np.where(self.table.current_mode, 0, current)  # no step at switch-on
        with self._lock:
            self._raise_if_port_lost()
            try:
                for j in range(self.n):
                    self._write(j, ADDR_BUS_WATCHDOG, 1, 0, 'Bus Watchdog')  # clear a trip
                    self._write(j, ADDR_GOAL_CURRENT, 2, int(current[j]), 'Goal Current')
                    self._write(j, ADDR_GOAL_POSITION, 4, int(position[j]), 'Goal Position')
                    self._write(j, ADDR_TORQUE_ENABLE, 1, 1, 'Torque Enable')
                self._goal_current, self._goal_position = current, position
                self._watchdog_writer.clearParam()
                for servo_id in self.table.ids:
                    self._watchdog_writer.addParam(servo_id, [self.config.bus_watchdog_raw])
                if self._watchdog_writer.txPacket() != self._sdk.COMM_SUCCESS:
                    raise HandDriverError(f'the Sync Write of Bus Watchdog on {self.port} '
                                          f'failed')
            except PORT_ERRORS as exc:
                self._lose_port(exc)
                raise PortLost(self.port_lost) from exc
            self.armed = True
            self._writes_since_arm = 0
            self.check.clear()

    def _raise_if_port_lost(self) -> None:
        if self.port_lost:
            raise PortLost(self.port_lost)

    def disarm(self) -> None:
        """Torque off and Bus Watchdog cleared on every servo that answers (best effort: the
        Bus Watchdog stops the others once the host stops writing)."""
        with self._lock:
            self.armed = False
            if self._closed or self.port_lost:
                return
            try:
                for servo_id in self.table.ids:
                    self._ph.write1ByteTxRx(self._port, servo_id, ADDR_TORQUE_ENABLE, 0)
                    # A host that stops now would trip the watchdog of a servo already off.
                    self._ph.write1ByteTxRx(self._port, servo_id, ADDR_BUS_WATCHDOG, 0)
            except PORT_ERRORS as exc:
                self._lose_port(exc)

    def _transact(self, call: Callable[[], tuple], tries: int = TRANSACTION_TRIES) -> tuple:
        """``call()`` (an SDK transaction returning ``(..., result, error)``) until it
        succeeds, at most ``tries`` times with the input drained in between."""
        for _ in range(tries):
            answer = call()
            self._note_alert(int(answer[-1]))
            if answer[-2] == self._sdk.COMM_SUCCESS:
                return answer
            self._clear_input()
        return answer

    def _read_error_status(self, servo_id: int) -> int | None:
        """The Hardware Error Status of one servo; ``None`` when it does not answer, or only
        with answers of earlier transactions (bits no error has: the SDK matches an answer
        by ID only), :data:`_STATUS_READ_TRIES` times with the input drained in between."""
        for _ in range(_STATUS_READ_TRIES):
            bits, result, _ = self._transact(
                lambda: self._ph.read1ByteTxRx(self._port, servo_id, ADDR_HARDWARE_ERROR))
            if result != self._sdk.COMM_SUCCESS:
                return None
            if not stale_error_bits(bits):
                return int(bits)
            self.read_failures += 1
            self.last_read_failure = 'hardware error read: a stale answer'
            self._clear_input()
        return None

    def recover(self) -> str:
        """Prepare ``~/reset``: open the port again if it failed, reboot every servo in a
        hardware error (only a reboot clears one), wait for it and read its status again,
        write the settings again (torque
        stays off until :meth:`arm`). Every transaction is tried
        :data:`TRANSACTION_TRIES` times.

        Returns
        -------
        str
            What was done (empty: nothing was needed).

        Raises
        ------
        HandDriverError
            The hand cannot be armed: the port is still missing or busy, a servo does not
            answer, shows its hardware error again after the reboot, or refuses its settings
            (each named). The driver stays in ERROR with this reason.
        """
        done: list[str] = []
        problems: list[str] = []
        with self._lock:
            self.armed = False
            self._next_deadline = None
            if self.port_lost:
                close_port(self._port)
                try:
                    self._open()
                except HandDriverError as exc:
                    raise HandDriverError(f'{self.port_lost}; reopening it: {exc}') from exc
                done.append(f'opened {self.port} again')
                self.port_lost = ''
                self._failed_in_a_row = 0
            try:
                for j, servo_id in enumerate(self.table.ids):
                    bits = self._read_error_status(servo_id)
                    if bits is None:
                        problems.append(f'servo {self.table.label(j)} does not answer')
                        continue
                    self.check.hardware_errors[j] = bits
                    if not bits:
                        continue
                    # Only a reboot clears Hardware Error Status, whatever the error; one
                    # whose cause is still there (a supply still too low) is set again.
                    self._reboot(j)
                    done.append(f'rebooted servo {self.table.label(j)} '
                                f'({hardware_error_names(int(bits))})')
                    after = self._read_error_status(servo_id)
                    self.check.hardware_errors[j] = after or 0
                    if after is None:
                        problems.append(f'servo {self.table.label(j)} does not answer after '
                                        f'its reboot')
                    elif after:
                        problems.append(f'servo {self.table.label(j)} keeps '
                                        f'{hardware_error_names(int(after))} after a reboot '
                                        f'(its cause is still there: check the supply, the '
                                        f'wiring and the load)')
                if not problems:
                    self._configure()
            except PORT_ERRORS as exc:
                self._lose_port(exc)
                problems.append(self.port_lost)
            except HandDriverError as exc:
                problems.append(str(exc))
            # Torque is off until arm() on purpose: a loss seen before this recovery (a read
            # of the state thread between two of its transactions) is no fault of the hand
            # that is about to be armed.
            self.check.clear()
        if problems:
            raise HandDriverError('; '.join(done + problems))
        return '; '.join(done)

    def _reboot(self, j: int) -> None:
        """Reboot servo ``j`` and wait until it answers a ping again (at most
        :data:`_REBOOT_WAIT_S`)."""
        servo_id = self.table.ids[j]
        self._transact(lambda: self._ph.reboot(self._port, servo_id))
        deadline = time.monotonic() + _REBOOT_WAIT_S
        while time.monotonic() < deadline:
            _, result, _ = self._ph.ping(self._port, servo_id)
            if result == self._sdk.COMM_SUCCESS:
                return
            time.sleep(0.05)

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
            'port_lost': self.port_lost or 'no',
            'bus_watchdog_s': f'{self.config.bus_watchdog_s:g}',
            'bus_watchdog_trips': str(int(self.check.watchdog_trips.sum())),
            'status_alerts': str(self.alerts),
            # Present Current of these models is the supply (input) current, not the motor's:
            # their efforts are no torque estimate (docs/dynamixel.md).
            'effort_not_a_torque': ', '.join(
                s.joint for s in self.config.servos if not s.spec.motor_current) or 'none',
        }
        for j in range(self.n):
            bits = int(self.check.hardware_errors[j])
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
            close_port(self._port)

    @property
    def closed(self) -> bool:
        return self._closed

    @property
    def last_failure(self) -> str:
        return self.last_read_failure
