"""Where a serialized (CDR) ROS 2 message ends, found without deserializing it.

Why a recorder needs this: Fast DDS's ``rmw_serialize`` (what
``rclpy.serialization.serialize_message`` and ``rclcpp::Serialization`` call) sizes the buffer
with the type support's *estimated* serialized size, an upper bound that counts alignment
padding the message does not need (4 bytes more for a ``sensor_msgs/JointState`` whose float64
arrays happen to be aligned, 8 with empty arrays), and sets ``buffer_length`` to that estimate,
not to the number of bytes written. The bytes between the end of the message and the estimate
are uninitialized memory. A node that publishes such a buffer (a relay, a player, any
``publish(serialized)``) puts them on the wire, and a raw subscription hands them on. The MCAP
ROS 2 decoder ignores trailing bytes; ``rosbags``' ``deserialize_cdr`` accepts at most 3 (final
alignment) and rejects the message ("CDR message size mismatch"). So the recorder cuts every
message at its real end.

:class:`CdrEnd` is compiled once per type from its field layout (:mod:`type_description`) and
walks only lengths: fixed-size fields are skipped, strings and sequences read one ``uint32``
each. Layout (classic CDR, XCDR1, as ROS 2 uses it): a 4-byte encapsulation header (byte 1:
0 big endian, 1 little endian), then the fields; every primitive is aligned to its size
relative to the end of the header; strings and sequences start with a ``uint32`` length
(strings count their terminating NUL); the elements of an empty sequence are not aligned.
"""

from __future__ import annotations

import struct
from collections.abc import Callable

from dam_recorder.errors import CdrError
from dam_recorder.type_description import (
    BOUNDED_STRING,
    NESTED,
    PRIMITIVE_SIZES,
    STRING,
    FieldType,
    MessageType,
)

#: Size [bytes] of the encapsulation header in front of the CDR data.
HEADER_SIZE = 4
_UINT32 = {0: struct.Struct('>I').unpack_from, 1: struct.Struct('<I').unpack_from}

#: A compiled step: (buffer, position after the header, unpack_uint32) -> new position.
Step = Callable[[bytes | memoryview, int, Callable[..., tuple[int]]], int]


def _align(pos: int, size: int) -> int:
    return (pos + size - 1) & -size


def _fixed(size: int, count: int) -> Step:
    total = size * count

    def step(buf, pos, u32):  # noqa: ANN001, ANN202 - hot path, typed by Step
        return _align(pos, size) + total
    return step


def _read_length(buf: bytes | memoryview, pos: int, u32: Callable[..., tuple[int]]
                 ) -> tuple[int, int]:
    pos = _align(pos, 4)
    return u32(buf, HEADER_SIZE + pos)[0], pos + 4


def _string(buf, pos, u32):  # noqa: ANN001, ANN202 - hot path, typed by Step
    length, pos = _read_length(buf, pos, u32)
    return pos + length


def _primitive_sequence(size: int) -> Step:
    def step(buf, pos, u32):  # noqa: ANN001, ANN202
        count, pos = _read_length(buf, pos, u32)
        return _align(pos, size) + size * count if count else pos
    return step


def _repeat(element: Step, fixed_count: int | None) -> Step:
    """``element`` ``fixed_count`` times, or as many times as a leading ``uint32`` says."""
    def step(buf, pos, u32):  # noqa: ANN001, ANN202
        if fixed_count is None:
            count, pos = _read_length(buf, pos, u32)
        else:
            count = fixed_count
        for _ in range(count):
            pos = element(buf, pos, u32)
        return pos
    return step


def _sequence_of_steps(steps: list[Step]) -> Step:
    if len(steps) == 1:
        return steps[0]

    def step(buf, pos, u32):  # noqa: ANN001, ANN202
        for s in steps:
            pos = s(buf, pos, u32)
        return pos
    return step


class CdrEnd:
    """The end of a CDR-serialized message of one type.

    Parameters
    ----------
    message_type : MessageType
        The type, with the fields of every type it refers to.
    """

    def __init__(self, message_type: MessageType) -> None:
        self.type_name = message_type.name
        self._compiled: dict[str, Step] = {}
        self._fields = message_type.fields
        self._step = self._compile(message_type.name)

    def _compile(self, name: str) -> Step:
        if name in self._compiled:
            return self._compiled[name]
        steps = [self._field_step(f.type) for f in self._fields[name]]
        # An empty struct still takes one byte on the wire.
        step = _sequence_of_steps(steps) if steps else _fixed(1, 1)
        self._compiled[name] = step
        return step

    def _field_step(self, field_type: FieldType) -> Step:
        element = field_type.element_id
        container = field_type.container
        if element in PRIMITIVE_SIZES:
            size = PRIMITIVE_SIZES[element]
            if container == 'single':
                return _fixed(size, 1)
            if container == 'array':
                return _fixed(size, field_type.capacity)
            return _primitive_sequence(size)
        if element in (STRING, BOUNDED_STRING):
            single: Step = _string
        elif element == NESTED:
            single = self._compile(field_type.nested_type_name)
        else:  # refused by type_description already
            raise CdrError(f'{self.type_name}: no CDR layout for type id {field_type.type_id}')
        if container == 'single':
            return single
        return _repeat(single, field_type.capacity if container == 'array' else None)

    def end(self, data: bytes | memoryview) -> int:
        """Length [bytes] of the message in ``data``, encapsulation header included.

        Raises
        ------
        CdrError
            If ``data`` is shorter than its header and lengths say (truncated or not a message
            of this type), or its header names an encoding other than plain CDR.
        """
        if len(data) < HEADER_SIZE:
            raise CdrError(f'{self.type_name}: {len(data)} bytes is shorter than the CDR header')
        if data[0] != 0 or data[1] not in _UINT32:
            raise CdrError(f'{self.type_name}: encapsulation {bytes(data[:2]).hex()} is not '
                           'plain CDR (0000 or 0001)')
        try:
            end = HEADER_SIZE + self._step(data, 0, _UINT32[data[1]])
        except struct.error:
            end = len(data) + 1
        if end > len(data):
            raise CdrError(f'{self.type_name}: the message needs more than the {len(data)} '
                           'bytes received (truncated or of another type)')
        return end

    def trim(self, data: bytes) -> bytes:
        """``data`` without the bytes after the message's end (``data`` itself when there are
        none)."""
        end = self.end(data)
        return data if end == len(data) else data[:end]
