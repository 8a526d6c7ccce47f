"""Dynamixel Protocol 2.0 packets: CRC, byte stuffing, a streaming parser and a status builder.

Pure byte handling, no I/O. The layout of a Protocol 2.0 packet (ROBOTIS e-manual, "Protocol
2.0"):

====================  =====  ==================================================================
field                 bytes  meaning
====================  =====  ==================================================================
header                3      ``FF FF FD``
reserved              1      ``00``
packet ID             1      0..252 a servo, 254 (``0xFE``) broadcast
length                2      little endian: bytes after this field (instruction, parameters,
                             CRC), counted after byte stuffing
instruction           1      :class:`Instruction`; ``0x55`` in a status packet
(error)               1      status packets only: :class:`ErrorCode` with the Alert bit
parameters            n      instruction-specific, multi-byte values little endian
CRC                   2      little endian CRC-16 of everything from the first header byte
                             through the last parameter byte (after stuffing)
====================  =====  ==================================================================

Byte stuffing keeps the header unique: wherever ``FF FF FD`` occurs from the instruction byte to
the last parameter, an extra ``FD`` follows it on the wire.

The CRC is the CRC-16 with polynomial ``0x8005``, initial value 0, no reflection of input or
output and no final XOR (the parameters catalogued as CRC-16/BUYPASS, check value ``0xFEE8``).
"""

from __future__ import annotations

import enum
from collections.abc import Iterator
from dataclasses import dataclass

#: The three header bytes that start every packet.
HEADER = b'\xff\xff\xfd'
#: Reserved byte after the header.
RESERVED = 0x00
#: Packet ID addressing every servo.
BROADCAST_ID = 0xFE
#: Largest servo ID.
MAX_ID = 252
#: Instruction byte of a status packet.
STATUS_INSTRUCTION = 0x55
#: Alert bit of the status error byte: the servo has a hardware error (Hardware Error Status).
ALERT_BIT = 0x80
#: Largest length field the parser accepts (longer claims are treated as garbage) [bytes].
MAX_LENGTH_FIELD = 1024
#: Bytes of header, reserved, ID and length: the fixed part before the instruction.
PREFIX_SIZE = 7
#: Smallest value of the length field: instruction and CRC.
MIN_LENGTH_FIELD = 3

_POLYNOMIAL = 0x8005
_STUFF_PATTERN = b'\xff\xff\xfd'
_STUFF_BYTE = 0xFD


class Instruction(enum.IntEnum):
    """Instruction bytes of Protocol 2.0 that the emulated servos understand."""

    PING = 0x01
    READ = 0x02
    WRITE = 0x03
    REBOOT = 0x08
    SYNC_READ = 0x82
    SYNC_WRITE = 0x83
    FAST_SYNC_READ = 0x8A


class ErrorCode(enum.IntEnum):
    """Error numbers of the status packet's error byte (its low 7 bits)."""

    NONE = 0
    RESULT_FAIL = 1
    INSTRUCTION = 2
    CRC = 3
    DATA_RANGE = 4
    DATA_LENGTH = 5
    DATA_LIMIT = 6
    ACCESS = 7


def _crc_table() -> tuple[int, ...]:
    table = []
    for byte in range(256):
        crc = byte << 8
        for _ in range(8):
            crc = ((crc << 1) ^ _POLYNOMIAL) if crc & 0x8000 else (crc << 1)
            crc &= 0xFFFF
        table.append(crc)
    return tuple(table)


_CRC_TABLE = _crc_table()


def crc16(data: bytes | bytearray | memoryview, crc: int = 0) -> int:
    """CRC-16 of Protocol 2.0 (polynomial 0x8005, MSB first, no reflection, no final XOR).

    Parameters
    ----------
    data
        The bytes to check.
    crc
        The CRC of the bytes before ``data`` (0 to start), to compute it in pieces.

    Returns
    -------
    int
        The CRC, 0..0xFFFF.
    """
    table = _CRC_TABLE
    for byte in bytes(data):
        crc = ((crc << 8) & 0xFFFF) ^ table[((crc >> 8) ^ byte) & 0xFF]
    return crc


def stuff(payload: bytes | bytearray) -> bytes:
    """Insert ``FD`` after every ``FF FF FD`` of ``payload`` (instruction through parameters).

    Parameters
    ----------
    payload
        Instruction byte (status: and error byte) and parameters, unstuffed.

    Returns
    -------
    bytes
        The bytes as sent on the wire.
    """
    out = bytearray()
    for byte in payload:
        out.append(byte)
        if byte == _STUFF_BYTE and out[-3:] == _STUFF_PATTERN:
            out.append(_STUFF_BYTE)
    return bytes(out)


def unstuff(payload: bytes | bytearray) -> bytes:
    """Remove the ``FD`` that :func:`stuff` inserted after every ``FF FF FD``.

    Parameters
    ----------
    payload
        Stuffed bytes from the instruction through the last parameter.

    Returns
    -------
    bytes
        The original bytes.
    """
    out = bytearray()
    skip = False
    for byte in payload:
        if skip:
            skip = False
            if byte == _STUFF_BYTE:
                continue
        out.append(byte)
        if byte == _STUFF_BYTE and out[-3:] == _STUFF_PATTERN:
            skip = True
    return bytes(out)


def build_packet(packet_id: int, payload: bytes | bytearray) -> bytes:
    """A complete packet: header, ID, length, stuffed ``payload``, CRC.

    Parameters
    ----------
    packet_id
        0..252 or :data:`BROADCAST_ID`.
    payload
        Instruction byte (for a status packet ``0x55`` and the error byte) and parameters,
        unstuffed.

    Returns
    -------
    bytes
        The packet as it goes on the wire.

    Raises
    ------
    ValueError
        ``packet_id`` is not a byte, or the payload is empty or too long.
    """
    if not 0 <= packet_id <= 0xFF:
        raise ValueError(f'packet ID {packet_id!r} is not a byte')
    if not payload:
        raise ValueError('a packet needs at least an instruction byte')
    body = stuff(payload)
    length = len(body) + 2
    if length > 0xFFFF:
        raise ValueError(f'payload of {len(payload)} bytes does not fit a packet')
    head = HEADER + bytes((RESERVED, packet_id, length & 0xFF, length >> 8))
    crc = crc16(head + body)
    return head + body + bytes((crc & 0xFF, crc >> 8))


def build_instruction(packet_id: int, instruction: int, params: bytes | bytearray = b''
                      ) -> bytes:
    """An instruction packet (what a host sends).

    Parameters
    ----------
    packet_id
        Target servo ID or :data:`BROADCAST_ID`.
    instruction
        The instruction byte (:class:`Instruction`).
    params
        Its parameters, unstuffed.

    Returns
    -------
    bytes
        The packet on the wire.

    Raises
    ------
    ValueError
        As :func:`build_packet`.
    """
    return build_packet(packet_id, bytes((instruction & 0xFF,)) + bytes(params))


def build_status(servo_id: int, error: int, params: bytes | bytearray = b'') -> bytes:
    """A status packet (a servo's answer): instruction ``0x55``, the error byte, parameters.

    Parameters
    ----------
    servo_id
        The answering servo's ID, 0..252.
    error
        Error byte: an :class:`ErrorCode` in the low 7 bits, :data:`ALERT_BIT` when the servo
        has a hardware error.
    params
        Parameters (e.g. the data read), unstuffed.

    Returns
    -------
    bytes
        The packet on the wire.

    Raises
    ------
    ValueError
        The ID is not 0..252, or the error is not a byte.
    """
    if not 0 <= servo_id <= MAX_ID:
        raise ValueError(f'status packet from ID {servo_id!r}: not a servo ID (0..{MAX_ID})')
    if not 0 <= error <= 0xFF:
        raise ValueError(f'error byte {error!r} is not a byte')
    return build_packet(servo_id, bytes((STATUS_INSTRUCTION, error)) + bytes(params))


@dataclass(frozen=True)
class Packet:
    """A packet whose CRC matched.

    Attributes
    ----------
    packet_id
        The ID byte.
    instruction
        The instruction byte (``0x55`` for a status packet).
    params
        Parameters, unstuffed (for a status packet the error byte comes first).
    """

    packet_id: int
    instruction: int
    params: bytes

    @property
    def is_broadcast(self) -> bool:
        """``True`` when addressed to :data:`BROADCAST_ID`."""
        return self.packet_id == BROADCAST_ID


@dataclass(frozen=True)
class CorruptPacket:
    """A complete packet whose CRC did not match (a servo answers it with a CRC error).

    Attributes
    ----------
    packet_id
        The ID byte as received (it may itself be the corrupted byte).
    instruction
        The instruction byte as received.
    received_crc, computed_crc
        The CRC in the packet and the CRC of its bytes.
    """

    packet_id: int
    instruction: int
    received_crc: int
    computed_crc: int


class PacketParser:
    """Turns a byte stream into packets, chunk by chunk.

    Bytes before a header are skipped (counted in :attr:`garbage_bytes`); a packet split over
    several chunks is completed by the later ones. After a CRC failure only the header is
    dropped and the search goes on inside the bad packet, so a packet whose length field was
    corrupted does not swallow the packet behind it.
    """

    def __init__(self) -> None:
        self._buf = bytearray()
        #: Bytes skipped while looking for a header.
        self.garbage_bytes = 0

    @property
    def pending(self) -> int:
        """Bytes held for a packet not complete yet."""
        return len(self._buf)

    def discard_partial(self) -> int:
        """Drop the bytes of an incomplete packet (e.g. after a silence on the line).

        Returns
        -------
        int
            The number of bytes dropped (also added to :attr:`garbage_bytes`).
        """
        dropped = len(self._buf)
        self.garbage_bytes += dropped
        self._buf.clear()
        return dropped

    def _skip(self, n: int) -> None:
        del self._buf[:n]
        self.garbage_bytes += n

    def feed(self, data: bytes | bytearray) -> list[Packet | CorruptPacket]:
        """Add ``data`` and return every packet completed by it, oldest first.

        Parameters
        ----------
        data
            Any number of bytes from the line.

        Returns
        -------
        list[Packet | CorruptPacket]
            Packets with a good CRC, and the ID and instruction of those with a bad CRC.
        """
        self._buf.extend(data)
        return list(self._parse())

    def _parse(self) -> Iterator[Packet | CorruptPacket]:
        buf = self._buf
        while True:
            start = buf.find(HEADER)
            if start < 0:
                keep = 2 if buf[-2:] == HEADER[:2] else (1 if buf[-1:] == HEADER[:1] else 0)
                self._skip(len(buf) - keep)
                return
            if start:
                self._skip(start)
            if len(buf) < PREFIX_SIZE:
                return
            length = buf[5] | (buf[6] << 8)
            if (buf[3] != RESERVED or length < MIN_LENGTH_FIELD
                    or length > MAX_LENGTH_FIELD):
                self._skip(1)  # not a header (e.g. stuffed FF FF FD FD): search on
                continue
            total = PREFIX_SIZE + length
            if len(buf) < total:
                return
            received = buf[total - 2] | (buf[total - 1] << 8)
            computed = crc16(memoryview(buf)[:total - 2])
            if received != computed:
                yield CorruptPacket(buf[4], buf[7], received, computed)
                self._skip(len(HEADER))
                continue
            body = unstuff(buf[PREFIX_SIZE:total - 2])
            packet = Packet(buf[4], body[0], body[1:])
            del buf[:total]
            yield packet


def le_bytes(value: int, size: int) -> bytes:
    """``value`` as ``size`` little-endian bytes (negative values in two's complement).

    Parameters
    ----------
    value
        The integer.
    size
        1, 2 or 4 [bytes].

    Returns
    -------
    bytes
        The encoding.

    Raises
    ------
    OverflowError
        The value does not fit ``size`` bytes, signed or unsigned.
    """
    if value < 0:
        return int(value).to_bytes(size, 'little', signed=True)
    return int(value).to_bytes(size, 'little')


def from_le(data: bytes | bytearray, signed: bool = False) -> int:
    """The integer of little-endian ``data``.

    Parameters
    ----------
    data
        1, 2 or 4 bytes.
    signed
        Read as two's complement.

    Returns
    -------
    int
        The value.
    """
    return int.from_bytes(bytes(data), 'little', signed=signed)
