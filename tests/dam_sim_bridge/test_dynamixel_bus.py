"""Tests of the emulated bus on a real pty, with the dynamixel_sdk as the host (no physics)."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from dynamixel_testing import fast_gil_handoff

from dam_sim_bridge.dynamixel_bus import DynamixelBus
from dam_sim_bridge.dynamixel_packets import BROADCAST_ID, Instruction, build_instruction
from dam_sim_bridge.dynamixel_servo import HW_OVERHEATING, DynamixelServo

sdk = pytest.importorskip('dynamixel_sdk')

IDS = tuple(range(1, 10))
MODEL = {i: ('XC330-M288' if i % 3 == 2 else 'XM430-W350') for i in IDS}
NUMBER = {'XM430-W350': 1020, 'XC330-M288': 1240}



@pytest.fixture(autouse=True)
def _fast_gil_handoff() -> Iterator[None]:
    with fast_gil_handoff():
        yield

class _Host:
    """The SDK's side of the line."""

    def __init__(self, path: str) -> None:
        self.port = sdk.PortHandler(path)
        self.packet = sdk.PacketHandler(2.0)
        assert self.port.openPort()
        assert self.port.setBaudRate(4_000_000)

    def close(self) -> None:
        if self.port.is_open:
            self.port.closePort()


@pytest.fixture
def bus() -> Iterator[DynamixelBus]:
    servos = [DynamixelServo(i, MODEL[i]) for i in IDS]
    with DynamixelBus(servos) as b:
        thread = threading.Thread(target=b.serve, daemon=True)
        thread.start()
        yield b
        b.stop()
        thread.join(2.0)
        assert not thread.is_alive()


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
    fd = os.open(bus.port_path, os.O_RDWR | os.O_NOCTTY)
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
    fd = os.open(bus.port_path, os.O_RDWR | os.O_NOCTTY)
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
    bus = DynamixelBus([DynamixelServo(1, 'XM430-W350')], link_path=str(link))
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
