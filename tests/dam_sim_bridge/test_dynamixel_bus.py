"""Tests of the emulated bus on a real pty, with the dynamixel_sdk as the host (no physics).

The servos are set to 4 Mbit/s (Baud Rate 6), the hosts open the line at that rate, as a hand
set up as docs/dynamixel.md says.
"""

from __future__ import annotations

import os
import sys
import termios
import threading
import time
import tty
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

import pytest
from dynamixel_testing import fast_gil_handoff

from dam_sim_bridge.dynamixel_bus import WATCHDOG_FEEDS, DynamixelBus
from dam_sim_bridge.dynamixel_packets import (
    BROADCAST_ID,
    Instruction,
    Packet,
    build_instruction,
)
from dam_sim_bridge.dynamixel_servo import HW_OVERHEATING, DynamixelServo

sdk = pytest.importorskip('dynamixel_sdk')

IDS = tuple(range(1, 10))
MODEL = {i: ('XC330-M288' if i % 3 == 2 else 'XM430-W350') for i in IDS}
NUMBER = {'XM430-W350': 1020, 'XC330-M288': 1240}
#: The line rate of the tests [bit/s] and its Baud Rate value (e-manual: 6 = 4 Mbit/s).
LINE_BPS, BAUD_4M = 4_000_000, 6


def _servo(servo_id: int, model: str) -> DynamixelServo:
    """A servo set to 4 Mbit/s (a servo from the factory has 57600 bit/s)."""
    servo = DynamixelServo(servo_id, model)
    servo.set('baud_rate', BAUD_4M)
    return servo


def _open_raw(path: str, bps: int = LINE_BPS) -> int:
    """The pty opened as a raw serial line at ``bps`` (a termios ``B`` constant's rate)."""
    fd = os.open(path, os.O_RDWR | os.O_NOCTTY)
    tty.setraw(fd)
    attrs = termios.tcgetattr(fd)
    attrs[4] = attrs[5] = getattr(termios, f'B{bps}')
    termios.tcsetattr(fd, termios.TCSANOW, attrs)
    return fd



@pytest.fixture(autouse=True)
def _fast_gil_handoff() -> Iterator[None]:
    with fast_gil_handoff():
        yield

class _Host:
    """The SDK's side of the line."""

    def __init__(self, path: str, bps: int = LINE_BPS) -> None:
        self.port = sdk.PortHandler(path)
        self.packet = sdk.PacketHandler(2.0)
        assert self.port.openPort()
        assert self.port.setBaudRate(bps)

    def close(self) -> None:
        if self.port.is_open:
            self.port.closePort()


@contextmanager
def _serving(**options: object) -> Iterator[DynamixelBus]:
    servos = [_servo(i, MODEL[i]) for i in IDS]
    with DynamixelBus(servos, **options) as b:
        thread = threading.Thread(target=b.serve, daemon=True)
        thread.start()
        yield b
        b.stop()
        thread.join(2.0)
        assert not thread.is_alive()


@pytest.fixture
def bus() -> Iterator[DynamixelBus]:
    with _serving() as b:
        yield b


@pytest.fixture
def host(bus: DynamixelBus) -> Iterator[_Host]:
    h = _Host(bus.port_path)
    yield h
    h.close()


def test_ping_every_servo_and_unknown_id(host: _Host) -> None:
    for i in IDS:
        model, result, error = host.packet.ping(host.port, i)
        assert (result, error) == (sdk.COMM_SUCCESS, 0), i
        assert model == NUMBER[MODEL[i]]
        number, result, _ = host.packet.read2ByteTxRx(host.port, i, 0)
        assert (number, result) == (NUMBER[MODEL[i]], sdk.COMM_SUCCESS)
    assert host.packet.ping(host.port, 42)[1] == sdk.COMM_RX_TIMEOUT


def test_broadcast_ping_answers_all(host: _Host) -> None:
    found, result = host.packet.broadcastPing(host.port)
    assert result == sdk.COMM_SUCCESS
    assert sorted(found) == list(IDS)
    assert all(found[i][0] == NUMBER[MODEL[i]] for i in IDS)


def test_sync_write_and_sync_read_round_trip(bus: DynamixelBus, host: _Host) -> None:
    ph, port = host.packet, host.port
    for i in IDS:
        assert ph.write1ByteTxRx(port, i, 11, 0 if i % 2 else 5) == (sdk.COMM_SUCCESS, 0)
    currents = {i: (-1) ** i * 10 * i for i in IDS}
    write = sdk.GroupSyncWrite(port, ph, 102, 2)
    for i in IDS:
        assert write.addParam(i, list((currents[i] & 0xFFFF).to_bytes(2, 'little')))
    assert write.txPacket() == sdk.COMM_SUCCESS
    positions = {i: 1000 + 100 * i for i in IDS}
    write = sdk.GroupSyncWrite(port, ph, 116, 4)
    for i in IDS:
        assert write.addParam(i, list(positions[i].to_bytes(4, 'little')))
    assert write.txPacket() == sdk.COMM_SUCCESS
    for i in IDS:  # the present values the physics would set
        bus.servo(i).set_present(-7 * i, 3 * i, -2 * i)
    read = sdk.GroupSyncRead(port, ph, 100, 36)  # Goal PWM .. Present Position
    for i in IDS:
        assert read.addParam(i)
    assert read.txRxPacket() == sdk.COMM_SUCCESS
    for i in IDS:
        assert read.isAvailable(i, 102, 2)
        assert _signed(read.getData(i, 102, 2), 16) == currents[i]
        assert read.getData(i, 116, 4) == positions[i]
        assert _signed(read.getData(i, 132, 4), 32) == -7 * i
        assert _signed(read.getData(i, 128, 4), 32) == 3 * i
        assert _signed(read.getData(i, 126, 2), 16) == -2 * i
    state = sdk.GroupSyncRead(port, ph, 120, 16)
    for i in IDS:
        state.addParam(i)
    assert state.txRxPacket() == sdk.COMM_SUCCESS
    assert all(state.isAvailable(i, 120, 16) for i in IDS)
    assert bus.stats.status_sent >= 18


def _signed(value: int, bits: int) -> int:
    return value - (1 << bits) if value >= 1 << (bits - 1) else value


def test_sync_read_answers_in_listed_order(bus: DynamixelBus) -> None:
    fd = _open_raw(bus.port_path)
    try:
        os.write(fd, build_instruction(BROADCAST_ID, Instruction.SYNC_READ,
                                       bytes((7, 0, 1, 0, 9, 2, 5))))
        data = _read_for(fd, 0.3)
    finally:
        os.close(fd)
    ids = [data[k + 4] for k in range(len(data) - 3) if data[k:k + 4] == b'\xff\xff\xfd\x00']
    assert ids == [9, 2, 5]


def _read_for(fd: int, seconds: float) -> bytes:
    os.set_blocking(fd, False)
    out = b''
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        try:
            out += os.read(fd, 1024)
        except BlockingIOError:
            time.sleep(0.005)
    return out


def test_eeprom_write_refused_with_torque_on(host: _Host) -> None:
    ph, port = host.packet, host.port
    assert ph.write1ByteTxRx(port, 4, 64, 1) == (sdk.COMM_SUCCESS, 0)
    result, error = ph.write1ByteTxRx(port, 4, 11, 0)
    assert result == sdk.COMM_SUCCESS
    assert error == 7  # Access Error
    assert 'not available' in ph.getRxPacketError(error)
    assert ph.read1ByteTxRx(port, 4, 11)[0] == 3
    assert ph.write2ByteTxRx(port, 4, 102, 2000)[1] == 6  # beyond Current Limit: Data Limit


def test_hardware_error_alert_and_reboot(bus: DynamixelBus, host: _Host) -> None:
    ph, port = host.packet, host.port
    assert ph.write1ByteTxRx(port, 2, 64, 1) == (sdk.COMM_SUCCESS, 0)
    bus.hardware_error(2, HW_OVERHEATING)
    value, result, error = ph.read1ByteTxRx(port, 2, 70)
    assert (value, result) == (HW_OVERHEATING, sdk.COMM_SUCCESS)
    assert error & sdk.ERRBIT_ALERT
    assert 'Hardware error' in ph.getRxPacketError(error)
    assert ph.read1ByteTxRx(port, 2, 64)[0] == 0  # torque went off
    assert ph.write1ByteTxRx(port, 2, 64, 1)[1] == sdk.ERRBIT_ALERT | 1  # Result Fail
    assert ph.ping(port, 3)[2] == 0  # the others are fine
    assert ph.reboot(port, 2) == (sdk.COMM_SUCCESS, sdk.ERRBIT_ALERT)  # sent before reboot
    value, result, error = ph.read1ByteTxRx(port, 2, 70)
    assert (value, result, error) == (0, sdk.COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 2, 64, 1) == (sdk.COMM_SUCCESS, 0)
    with pytest.raises(KeyError):
        bus.hardware_error(77, 1)


def test_crc_fault(bus: DynamixelBus, host: _Host) -> None:
    bus.crc_error_ids = {5}
    assert host.packet.ping(host.port, 5)[1] == sdk.COMM_RX_CORRUPT
    assert host.packet.ping(host.port, 6)[1] == sdk.COMM_SUCCESS
    bus.crc_error_ids = ()
    assert host.packet.ping(host.port, 5)[1] == sdk.COMM_SUCCESS


def test_crc_error_received_is_answered(bus: DynamixelBus) -> None:
    fd = _open_raw(bus.port_path)
    try:
        packet = bytearray(build_instruction(3, Instruction.READ, bytes((132, 0, 4, 0))))
        packet[-2] ^= 0x10
        os.write(fd, bytes(packet))
        data = _read_for(fd, 0.2)
    finally:
        os.close(fd)
    assert data[4] == 3 and data[7] == 0x55 and data[8] == 3  # CRC Error
    assert bus.stats.crc_errors == 1


def test_silent_servo_times_out(bus: DynamixelBus, host: _Host) -> None:
    bus.silent_ids = [8]
    assert host.packet.ping(host.port, 8)[1] == sdk.COMM_RX_TIMEOUT
    assert host.packet.ping(host.port, 7)[1] == sdk.COMM_SUCCESS
    read = sdk.GroupSyncRead(host.port, host.packet, 132, 4)
    for i in IDS:
        read.addParam(i)
    assert read.txRxPacket() == sdk.COMM_RX_TIMEOUT
    # it still acts on what it hears
    assert host.packet.write1ByteTxRx(host.port, 8, 65, 1)[0] == sdk.COMM_RX_TIMEOUT
    assert bus.servo(8).table[65] == 1


def test_status_delay(bus: DynamixelBus, host: _Host) -> None:
    t0 = time.monotonic()
    assert host.packet.ping(host.port, 1)[1] == sdk.COMM_SUCCESS
    fast = time.monotonic() - t0
    bus.status_delay_s = 0.015
    t0 = time.monotonic()
    assert host.packet.ping(host.port, 1)[1] == sdk.COMM_SUCCESS
    assert time.monotonic() - t0 >= 0.015 > fast
    bus.status_delay_s = 0.12  # beyond the SDK's ~34 ms packet timeout
    assert host.packet.ping(host.port, 1)[1] == sdk.COMM_RX_TIMEOUT
    time.sleep(0.15)
    with pytest.raises(ValueError):
        bus.status_delay_s = -1.0


def test_status_return_level(host: _Host) -> None:
    ph, port = host.packet, host.port
    # the new level already governs the answer to the write that sets it
    assert ph.write1ByteTxRx(port, 1, 68, 0)[0] == sdk.COMM_RX_TIMEOUT
    assert ph.read1ByteTxRx(port, 1, 68)[1] == sdk.COMM_RX_TIMEOUT
    assert ph.ping(port, 1)[1] == sdk.COMM_SUCCESS
    ph.write1ByteTxOnly(port, 1, 68, 1)
    time.sleep(0.01)
    assert ph.read1ByteTxRx(port, 1, 68) == (1, sdk.COMM_SUCCESS, 0)
    assert ph.write1ByteTxRx(port, 1, 65, 1)[0] == sdk.COMM_RX_TIMEOUT


def test_client_closes_and_reopens(bus: DynamixelBus) -> None:
    first = _Host(bus.port_path)
    assert first.packet.ping(first.port, 1)[1] == sdk.COMM_SUCCESS
    first.packet.ping(first.port, 2)  # and close while nothing is read
    first.close()
    fd = os.open(bus.port_path, os.O_RDWR | os.O_NOCTTY)  # a client that never reads
    os.write(fd, build_instruction(BROADCAST_ID, Instruction.PING) * 50)
    os.close(fd)
    time.sleep(0.1)
    second = _Host(bus.port_path)
    try:
        assert second.packet.ping(second.port, 8)[0] == 1240
    finally:
        second.close()


def test_link_path_created_and_removed(tmp_path: Path) -> None:
    link = tmp_path / 'ttyDXL'
    bus = DynamixelBus([_servo(1, 'XM430-W350')], link_path=str(link))
    try:
        assert link.is_symlink() and os.path.realpath(link) == os.path.realpath(bus.port_path)
        thread = threading.Thread(target=bus.serve, daemon=True)
        thread.start()
        h = _Host(str(link))
        assert h.packet.ping(h.port, 1)[0] == 1020
        h.close()
    finally:
        bus.close()
    assert not link.exists() and not link.is_symlink()
    (tmp_path / 'file').write_text('x')
    with pytest.raises(FileExistsError):
        DynamixelBus([DynamixelServo(1, 'XM430-W350')], link_path=str(tmp_path / 'file'))


# -------------------------------------------------------------------------------------------
# The baud rate on the line


def test_a_host_at_another_baud_rate_gets_no_answer(bus: DynamixelBus) -> None:
    """Servos at 4 Mbit/s do not understand a host at 57600 or 1M bit/s: no answer, nothing
    done; at 4 Mbit/s they answer."""
    for bps in (57600, 1_000_000):
        host = _Host(bus.port_path, bps)
        try:
            assert bus.line_baud_rate() == bps
            assert host.packet.ping(host.port, 1)[1] == sdk.COMM_RX_TIMEOUT
            assert host.packet.broadcastPing(host.port)[1] == sdk.COMM_RX_TIMEOUT
            assert host.packet.write1ByteTxRx(host.port, 4, 65, 1)[0] == sdk.COMM_RX_TIMEOUT
            assert bus.servo(4).table[65] == 0  # the LED write was not understood
        finally:
            host.close()
    host = _Host(bus.port_path, LINE_BPS)
    try:
        assert bus.line_baud_rate() == LINE_BPS
        assert host.packet.ping(host.port, 1)[:2] == (1020, sdk.COMM_SUCCESS)
        assert host.packet.write1ByteTxRx(host.port, 4, 65, 1) == (sdk.COMM_SUCCESS, 0)
    finally:
        host.close()


def test_a_baud_rate_scan_finds_each_servo_at_its_rate(bus: DynamixelBus, host: _Host) -> None:
    """Servo 3 is set to 1 Mbit/s (Baud Rate 3) by a write at 4 Mbit/s; from then on only a
    host at 1 Mbit/s reaches it, and a broadcast ping at each rate finds the servos set to it."""
    ph, port = host.packet, host.port
    ph.write1ByteTxRx(port, 3, 8, 3)
    assert bus.servo(3).baud_rate_bps == 1_000_000
    assert ph.ping(port, 3)[1] == sdk.COMM_RX_TIMEOUT
    found = {}
    for bps in (57600, 1_000_000, LINE_BPS):
        assert port.setBaudRate(bps)
        answers, _ = ph.broadcastPing(port)
        found[bps] = sorted(answers)
    assert found == {57600: [], 1_000_000: [3], LINE_BPS: [i for i in IDS if i != 3]}
    assert port.setBaudRate(1_000_000)
    assert ph.ping(port, 3)[:2] == (1020, sdk.COMM_SUCCESS)


@pytest.mark.skipif(not sys.platform.startswith('linux'), reason='TCSETS2 is Linux')
def test_a_rate_without_a_termios_constant(bus: DynamixelBus) -> None:
    """4.5 Mbit/s (Baud Rate 7 of the XM430-W350) has no B constant: pyserial sets it with
    TCSETS2, and the bus reads it back so."""
    serial = pytest.importorskip('serial')
    bus.servo(1).set('baud_rate', 7)
    line = serial.Serial(bus.port_path, baudrate=4_500_000, timeout=0.3)
    try:
        assert bus.line_baud_rate() == 4_500_000
        line.write(build_instruction(1, Instruction.PING))
        answer = line.read(14)
        assert len(answer) == 14 and answer[4] == 1 and answer[8] == 0  # ID 1, no error
        assert answer[9:11] == (1020).to_bytes(2, 'little')
        line.write(build_instruction(2, Instruction.PING))  # servo 2 is at 4 Mbit/s
        assert line.read(14) == b''
    finally:
        line.close()


# -------------------------------------------------------------------------------------------
# What feeds the Bus Watchdog


class _Clock:
    """A device clock the test advances [s]."""

    def __init__(self) -> None:
        self.now_s = 100.0

    def __call__(self) -> float:
        return self.now_s


def _arm(host: _Host, ids: tuple[int, ...], watchdog: int) -> None:
    for i in ids:
        assert host.packet.write1ByteTxRx(host.port, i, 98, watchdog) == (sdk.COMM_SUCCESS, 0)
        assert host.packet.write1ByteTxRx(host.port, i, 64, 1) == (sdk.COMM_SUCCESS, 0)


def _watchdogs(host: _Host, ids: tuple[int, ...]) -> dict[int, int]:
    out = {}
    for i in ids:
        value, result, _ = host.packet.read1ByteTxRx(host.port, i, 98)
        assert result == sdk.COMM_SUCCESS
        out[i] = value
    return out


def test_watchdog_feed_must_be_one_of_the_two() -> None:
    with pytest.raises(ValueError, match="'sometimes' is not one of"):
        DynamixelBus([_servo(1, 'XM430-W350')], watchdog_feed='sometimes')
    assert WATCHDOG_FEEDS == ('addressed', 'any')


@pytest.mark.parametrize(('feed', 'tripped'), [('addressed', True), ('any', False)])
def test_pings_to_another_servo_feed_its_watchdog_only_under_any(feed: str,
                                                                 tripped: bool) -> None:
    """Servo 1 armed with Bus Watchdog 5 (100 ms); 300 ms of device-clock time of pings to
    servo 2 only. Under addressed they are not for servo 1: it stops (255, -1)."""
    clock = _Clock()
    with _serving(clock=clock, watchdog_feed=feed) as bus:
        host = _Host(bus.port_path)
        try:
            assert bus.watchdog_feed == feed
            _arm(host, (1,), 5)
            for _ in range(30):
                clock.now_s += 0.010
                assert host.packet.ping(host.port, 2)[1] == sdk.COMM_SUCCESS
            assert _watchdogs(host, (1,)) == {1: 255 if tripped else 5}
            assert bus.servo(1).output_enabled is not tripped
        finally:
            host.close()


@pytest.mark.parametrize('feed', WATCHDOG_FEEDS)
def test_a_sync_read_feeds_the_servos_it_lists(feed: str) -> None:
    """A sync read listing all servos every 10 ms feeds all of them under both readings; one
    that leaves servo 1 out feeds it only under any."""
    clock = _Clock()
    with _serving(clock=clock, watchdog_feed=feed) as bus:
        host = _Host(bus.port_path)
        try:
            _arm(host, IDS, 5)
            for listed in (IDS, IDS[1:]):
                read = sdk.GroupSyncRead(host.port, host.packet, 132, 4)
                for i in listed:
                    read.addParam(i)
                for _ in range(30):
                    clock.now_s += 0.010
                    assert read.txRxPacket() == sdk.COMM_SUCCESS
                if listed == IDS:
                    assert _watchdogs(host, IDS) == dict.fromkeys(IDS, 5)
            expected = dict.fromkeys(IDS, 5)
            if feed == 'addressed':
                expected[1] = 255
            assert _watchdogs(host, IDS) == expected
        finally:
            host.close()


_BULK_READ, _BULK_WRITE = 0x92, 0x93  # Protocol 2.0 (not emulated, but they list IDs)


@pytest.mark.parametrize(('packet', 'fed'), [
    (Packet(BROADCAST_ID, Instruction.PING, b''), set(IDS)),
    (Packet(BROADCAST_ID, Instruction.WRITE, bytes((65, 0, 1))), set(IDS)),
    (Packet(BROADCAST_ID, Instruction.SYNC_WRITE, bytes((65, 0, 1, 0, 2, 1, 3, 1))), {2, 3}),
    (Packet(BROADCAST_ID, Instruction.SYNC_WRITE, bytes((65, 0, 1, 0, 2, 1, 3))), set()),
    (Packet(BROADCAST_ID, _BULK_READ, bytes((4, 132, 0, 4, 0, 5, 126, 0, 2, 0))), {4, 5}),
    (Packet(BROADCAST_ID, _BULK_WRITE, bytes((6, 65, 0, 1, 0, 1, 7, 116, 0, 4, 0)) + bytes(4)),
     {6, 7}),
    (Packet(8, Instruction.PING, b''), {8}),
    (Packet(42, Instruction.PING, b''), set()),
], ids=['ping', 'write', 'sync write', 'bad sync write', 'bulk read', 'bulk write',
        'unicast', 'unknown id'])
def test_which_packets_feed_under_addressed(packet: Packet, fed: set[int]) -> None:
    """Plain broadcasts feed every servo; sync and bulk packets the IDs they list (a malformed
    one none), a unicast packet its servo."""
    clock = _Clock()
    with DynamixelBus([_servo(i, MODEL[i]) for i in IDS], clock=clock) as bus:
        fd = _open_raw(bus.port_path)  # the line at 4 Mbit/s: every servo hears
        try:
            for s in bus.servos:
                assert s.write(98, b'\x05').error == 0 and s.write(64, b'\x01').error == 0
                s.heard(clock.now_s)
            clock.now_s += 0.060
            bus.handle(packet)
            clock.now_s += 0.060  # 120 ms since the last packet of a servo not fed
            for s in bus.servos:
                s.check_watchdog(clock.now_s)
            assert {s.servo_id for s in bus.servos if s.watchdog_tripped} == set(IDS) - fed
        finally:
            os.close(fd)
