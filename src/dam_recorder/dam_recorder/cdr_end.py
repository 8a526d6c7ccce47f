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

:class:`CdrEnd` compiles the field layout of a type (:mod:`type_description`) once into a
Python function that walks only lengths: fixed-size fields are skipped by arithmetic, strings
and sequences read one ``uint32`` each (about 5 us for a 9-joint ``JointState``, a fifteenth of
a deserialization).

Layout (classic CDR, XCDR1, as ROS 2 uses it): a 4-byte encapsulation header (byte 1: 0 big
endian, 1 little endian), then the fields; every primitive is aligned to its size relative to
the end of the header; strings and sequences start with a ``uint32`` length
(strings count their terminating NUL); the elements of an empty sequence are not aligned.
"""

from __future__ import annotations

import struct

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


class _Source:
    """Python source of a walker function, built line by line."""

    def __init__(self) -> None:
        self.lines: list[str] = []
        self.depth = 0  # loop nesting, for unique loop variable names

    def add(self, indent: int, line: str) -> None:
        self.lines.append('    ' * indent + line)

    def align(self, indent: int, size: int) -> None:
        if size > 1:
            self.add(indent, f'pos = (pos + {size - 1}) & -{size}')

    def read_count(self, indent: int) -> str:
        """Read a uint32 length into a fresh variable (checked against the data left, since
        every element takes at least one byte); return the variable's name."""
        name = f'n{self.depth}'
        self.align(indent, 4)
        self.add(indent, f'{name} = u32(buf, {HEADER_SIZE} + pos)[0]')
        self.add(indent, 'pos += 4')
        self.add(indent, f'if {name} > size - pos:')
        self.add(indent + 1, 'raise _Overrun')
        return name


class _Overrun(Exception):
    """A length that points past the end of the data."""


class CdrEnd:
    """The end of a CDR-serialized message of one type.

    The layout is compiled once into a Python function with one statement per fixed-size field
    and one loop per sequence (a few microseconds per message, no objects made).

    Parameters
    ----------
    message_type : MessageType
        The type, with the fields of every type it refers to.
    """

    def __init__(self, message_type: MessageType) -> None:
        self.type_name = message_type.name
        self._fields = message_type.fields
        source = _Source()
        source.add(0, 'def walk(buf, u32, size):')
        source.add(1, 'pos = 0')
        self._emit_struct(source, 1, message_type.name)
        source.add(1, 'return pos')
        namespace: dict[str, object] = {'_Overrun': _Overrun}
        exec(compile('\n'.join(source.lines), f'<cdr_end {self.type_name}>', 'exec'),
             namespace)
        self._walk = namespace['walk']
        self.source = '\n'.join(source.lines)

    def _emit_struct(self, source: _Source, indent: int, name: str) -> None:
        fields = self._fields[name]
        if not fields:  # an empty struct still takes one byte on the wire
            source.add(indent, 'pos += 1')
        for field in fields:
            self._emit_field(source, indent, field.type)

    def _emit_single(self, source: _Source, indent: int, field_type: FieldType) -> None:
        element = field_type.element_id
        if element in PRIMITIVE_SIZES:
            size = PRIMITIVE_SIZES[element]
            source.align(indent, size)
            source.add(indent, f'pos += {size}')
        elif element in (STRING, BOUNDED_STRING):
            source.align(indent, 4)
            source.add(indent, f'pos += 4 + u32(buf, {HEADER_SIZE} + pos)[0]')
        elif element == NESTED:
            self._emit_struct(source, indent, field_type.nested_type_name)
        else:  # refused by type_description already
            raise CdrError(f'{self.type_name}: no CDR layout for type id {field_type.type_id}')

    def _emit_field(self, source: _Source, indent: int, field_type: FieldType) -> None:
        container = field_type.container
        element = field_type.element_id
        if container == 'single':
            self._emit_single(source, indent, field_type)
            return
        if element in PRIMITIVE_SIZES:  # arrays of primitives: one step
            size = PRIMITIVE_SIZES[element]
            if container == 'array':
                source.align(indent, size)
                source.add(indent, f'pos += {size * field_type.capacity}')
                return
            count = source.read_count(indent)
            source.add(indent, f'if {count}:')
            source.align(indent + 1, size)
            source.add(indent + 1, f'pos += {size} * {count}')
            return
        if container == 'array':
            count = str(field_type.capacity)
        else:
            count = source.read_count(indent)
        source.add(indent, f'for _ in range({count}):')
        source.depth += 1
        self._emit_single(source, indent + 1, field_type)
        source.depth -= 1

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
            end = HEADER_SIZE + self._walk(data, _UINT32[data[1]], len(data) - HEADER_SIZE)
        except (struct.error, _Overrun):
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
