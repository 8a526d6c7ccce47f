"""Tests of the Protocol 2.0 codec (CRC, stuffing, parser, builders), against hand-computed
values, the e-manual's worked examples and the dynamixel_sdk's own CRC and stuffing."""

from __future__ import annotations

import pytest

from dam_sim_bridge.dynamixel_packets import (
    ALERT_BIT,
    BROADCAST_ID,
    CorruptPacket,
    ErrorCode,
    Instruction,
    Packet,
    PacketParser,
    build_instruction,
    build_status,
    crc16,
    stuff,
    unstuff,
)

sdk = pytest.importorskip('dynamixel_sdk')


def _crc_bitwise(data: bytes) -> int:
    """The CRC-16 of the definition, one bit at a time (poly 0x8005, init 0, MSB first)."""
    crc = 0
    for byte in data:
        for bit in range(7, -1, -1):
            top = (crc >> 15) & 1
            crc = (crc << 1) & 0xFFFF
            if top ^ ((byte >> bit) & 1):
                crc ^= 0x8005
    return crc


def test_crc_check_value() -> None:
    # The catalogue's check value of CRC-16/BUYPASS (poly 0x8005, init 0, no reflection).
    assert crc16(b'123456789') == 0xFEE8
    assert _crc_bitwise(b'123456789') == 0xFEE8
    assert crc16(b'') == 0


def test_crc_matches_bitwise_and_sdk_and_pieces() -> None:
    handler = sdk.Protocol2PacketHandler()
    for data in (b'\x00', b'\xff\xff\xfd\x00\x01', bytes(range(256)), b'DAM hand' * 9):
        assert crc16(data) == _crc_bitwise(data)
        assert crc16(data) == handler.updateCRC(0, list(data), len(data))
        assert crc16(data[5:], crc16(data[:5])) == crc16(data)


def test_emanual_ping_example() -> None:
    # e-manual, Protocol 2.0, Ping example: instruction to ID 1 and the answer of a servo of
    # model number 1030 (0x0406), firmware 0x26.
    assert build_instruction(1, Instruction.PING) == bytes.fromhex('FFFFFD0001030001194E')
    assert build_status(1, 0, bytes((0x06, 0x04, 0x26))) == bytes.fromhex(
        'FFFFFD000107005500060426655D')


def test_emanual_read_and_write_examples() -> None:
    # READ Present Position (132, 4 bytes) of ID 1; WRITE Goal Position (116) = 512.
    assert build_instruction(1, Instruction.READ, bytes((0x84, 0, 4, 0))) == bytes.fromhex(
        'FFFFFD0001070002840004001D15')
    assert build_instruction(1, Instruction.WRITE, bytes((0x74, 0, 0, 2, 0, 0))) == \
        bytes.fromhex('FFFFFD0001090003740000020000CA89')


def test_length_field_counts_params_plus_three() -> None:
    packet = build_instruction(7, Instruction.WRITE, bytes(10))
    assert packet[4] == 7
    assert packet[5] | packet[6] << 8 == 10 + 3
    assert len(packet) == 7 + 10 + 3


def test_stuffing_round_trip_and_sdk_agrees() -> None:
    payload = bytes((0x03, 0xFF, 0xFF, 0xFD, 0x01, 0xFF, 0xFF, 0xFD, 0xFD, 0xFF, 0xFF, 0xFD))
    stuffed = stuff(payload)
    assert stuffed == bytes((0x03, 0xFF, 0xFF, 0xFD, 0xFD, 0x01, 0xFF, 0xFF, 0xFD, 0xFD, 0xFD,
                             0xFF, 0xFF, 0xFD, 0xFD))
    assert unstuff(stuffed) == payload
    for data in (b'', b'\xff\xff\xfd', b'\xff\xff\xff\xfd', b'\xfd\xfd\xff\xff\xfd\xfd'):
        assert unstuff(stuff(data)) == data
    # The SDK stuffs a packet it sends; ours must be byte for byte the same.
    params = [0x80, 0x00, 0x04, 0x00, 0xFF, 0xFF, 0xFD, 0x10]
    ours = build_instruction(3, Instruction.WRITE, bytes(params))
    tx = [0] * 7 + [Instruction.WRITE] + params + [0, 0]
    tx[4] = 3
    tx[5], tx[6] = (len(params) + 3) & 0xFF, (len(params) + 3) >> 8
    handler = sdk.Protocol2PacketHandler()
    tx = handler.addStuffing(tx)  # (it returns a new list when it stuffed)
    tx[0:4] = [0xFF, 0xFF, 0xFD, 0x00]
    total = (tx[5] | tx[6] << 8) + 7
    crc = handler.updateCRC(0, tx, total - 2)
    tx[total - 2:total] = [crc & 0xFF, crc >> 8]
    assert ours == bytes(tx[:total])
    assert ours[5] == len(params) + 1 + 3  # the stuffed byte is counted


def test_parser_chunks_garbage_and_stuffing() -> None:
    a = build_instruction(1, Instruction.WRITE, bytes((0x74, 0, 0xFF, 0xFF, 0xFD, 0x00)))
    b = build_instruction(BROADCAST_ID, Instruction.PING)
    stream = b'\x00\xff\x12\xff\xff' + a + b'\xfd\xfd' + b
    parser = PacketParser()
    got: list[Packet | CorruptPacket] = []
    for i in range(len(stream)):  # one byte at a time: every split point
        got.extend(parser.feed(stream[i:i + 1]))
    assert got == [Packet(1, Instruction.WRITE, bytes((0x74, 0, 0xFF, 0xFF, 0xFD, 0x00))),
                   Packet(BROADCAST_ID, Instruction.PING, b'')]
    assert got[1].is_broadcast
    assert parser.garbage_bytes == 7
    assert parser.pending == 0


def test_parser_reports_crc_error_and_finds_next_packet() -> None:
    bad = bytearray(build_instruction(5, Instruction.READ, bytes((132, 0, 4, 0))))
    bad[-1] ^= 0x01
    good = build_instruction(6, Instruction.PING)
    got = PacketParser().feed(bytes(bad) + good)
    assert isinstance(got[0], CorruptPacket)
    assert (got[0].packet_id, got[0].instruction) == (5, Instruction.READ)
    assert got[0].received_crc != got[0].computed_crc
    assert got[1:] == [Packet(6, Instruction.PING, b'')]


def test_parser_corrupted_length_does_not_swallow_next_packet() -> None:
    bad = bytearray(build_instruction(5, Instruction.PING))
    bad[5] = 40  # claims 40 bytes: the next packet is inside its claimed body
    good = build_instruction(6, Instruction.PING)
    parser = PacketParser()
    got = parser.feed(bytes(bad) + good + bytes(40))
    assert isinstance(got[0], CorruptPacket)
    assert Packet(6, Instruction.PING, b'') in got


def test_parser_partial_packet_waits_and_discard() -> None:
    packet = build_instruction(2, Instruction.PING)
    parser = PacketParser()
    assert parser.feed(packet[:6]) == []
    assert parser.pending == 6
    assert parser.discard_partial() == 6
    assert parser.feed(packet) == [Packet(2, Instruction.PING, b'')]


def test_status_builder_and_sdk_reads_it() -> None:
    status = build_status(9, ALERT_BIT | ErrorCode.ACCESS, bytes((1, 2, 0xFF, 0xFF, 0xFD)))
    parsed = PacketParser().feed(status)
    assert parsed == [Packet(9, 0x55, bytes((0x87, 1, 2, 0xFF, 0xFF, 0xFD)))]
    # the SDK's unstuffing gives back the same parameters
    rx = sdk.Protocol2PacketHandler().removeStuffing(list(status))
    assert rx[8] == 0x87 and bytes(rx[9:14]) == bytes((1, 2, 0xFF, 0xFF, 0xFD))
    with pytest.raises(ValueError, match='not a servo ID'):
        build_status(BROADCAST_ID, 0)
