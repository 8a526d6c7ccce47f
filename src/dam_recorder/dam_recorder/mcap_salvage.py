"""Reading every record an MCAP file still holds, and saying what it lost and why.

A bag file may be damaged in three ways: cut short (the recorder killed while writing, a disk
full), bytes changed inside it (a bad sector, a bad copy), or its summary lost. The file carries
everything needed to read it in its data section: schemas, channels and messages, in records
framed by an opcode and a length. :func:`salvage_mcap` walks those records one by one:

- a chunk is decompressed and checked (its stated uncompressed size, its CRC when the writer
  set one, every record in it complete, and its messages against the message index that follows
  it): a chunk that fails is skipped whole, and the messages its index lists are counted as
  lost, per channel; the walk goes on with the next record, whose place the chunk's length
  gives;
- a record cut short, or a length that runs past the end of the file, ends the walk: what
  follows is lost (a partly written chunk: its message count is not in the file);
- schemas and channels are taken from the data section and, when it is readable, from the
  summary too (a channel whose record was in a lost chunk survives there).

The caller writes what was saved into a new file (:mod:`dam_recorder.recovery`).
"""

from __future__ import annotations

import io
import zlib
from dataclasses import dataclass, field
from pathlib import Path

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, MessageIndex, ReadDataStream, Schema

#: The 8 bytes that begin and end a complete MCAP file.
MCAP_MAGIC = b'\x89MCAP0\r\n'
OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE, OP_CHUNK, OP_MESSAGE_INDEX = 2, 3, 4, 5, 6, 7
OP_DATA_END = 0x0F
_RECORD_HEAD = 9  # opcode (1 byte) and length (8 bytes)


class ChunkError(ValueError):
    """A chunk cannot be read; the message says why."""


@dataclass
class LostChunk:
    """A chunk that could not be read.

    Attributes
    ----------
    offset : int
        Where its record starts in the file [bytes].
    reason : str
        Why it could not be read.
    lost : dict[int, int]
        Messages it held, per channel id, as its message index lists them (empty when the
        index is lost too).
    """

    offset: int
    reason: str
    lost: dict[int, int] = field(default_factory=dict)


@dataclass
class Salvage:
    """What :func:`salvage_mcap` read from one file.

    Attributes
    ----------
    schemas, channels : dict
        By id, from the data section and the summary.
    messages : list of mcap Message
        Every message that could be read, in file order.
    lost_chunks : list of LostChunk
        Chunks skipped, with why and what they held.
    size, read_to : int
        File size and where the readable records end [bytes]; ``read_to < size`` when the
        file was cut short or its end could not be read.
    cut_reason : str
        Why the walk stopped before the end of the file (``''`` when it did not).
    summary_ok : bool
        Whether the file ends in a footer with a summary the ``mcap`` reader reads.
    """

    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    lost_chunks: list[LostChunk] = field(default_factory=list)
    size: int = 0
    read_to: int = 0
    cut_reason: str = ''
    summary_ok: bool = False

    @property
    def intact(self) -> bool:
        """Whether the file needs no rebuilding: whole, with its summary, every chunk read."""
        return self.summary_ok and not self.lost_chunks and not self.cut_reason


def _decompress(compression: str, data: bytes, size: int) -> bytes:
    if compression == '':
        return data
    if compression == 'zstd':
        import zstandard

        try:
            return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
        except zstandard.ZstdError as exc:
            raise ChunkError(f'zstd: {exc}') from None
    if compression == 'lz4':
        import lz4.frame

        try:
            return lz4.frame.decompress(data)
        except RuntimeError as exc:
            raise ChunkError(f'lz4: {exc}') from None
    raise ChunkError(f'unknown compression {compression!r}')


def read_chunk(body: bytes) -> tuple[list[Schema | Channel | Message],
                                     dict[int, tuple[int, int]]]:
    """The records of a chunk record's content, checked whole, and where each message lies in
    the decompressed data (offset -> channel id and log time, as a message index lists them).

    Raises
    ------
    ChunkError
        If the chunk does not decompress to its stated size, fails its CRC, or a record in it
        is cut short or malformed (the message says which).
    """
    try:
        stream = ReadDataStream(io.BytesIO(body))
        stream.read8()  # message start time
        stream.read8()  # message end time
        size = stream.read8()
        crc = stream.read4()
        compression = stream.read(stream.read4()).decode('utf-8')
        data = stream.read(stream.read8())
    except (McapError, EOFError, UnicodeDecodeError, ValueError) as exc:
        raise ChunkError(f'malformed chunk header: {exc}') from None
    raw = _decompress(compression, data, size)
    if len(raw) != size:
        raise ChunkError(f'decompressed to {len(raw)} bytes, the chunk says {size}')
    if crc and zlib.crc32(raw) != crc:
        raise ChunkError(f'CRC mismatch ({zlib.crc32(raw):#010x}, the chunk says {crc:#010x})')
    records: list[Schema | Channel | Message] = []
    offsets: dict[int, tuple[int, int]] = {}
    pos = 0
    while pos < len(raw):
        if pos + _RECORD_HEAD > len(raw):
            raise ChunkError(f'a record cut short at byte {pos} of {len(raw)}')
        opcode = raw[pos]
        length = int.from_bytes(raw[pos + 1:pos + _RECORD_HEAD], 'little')
        end = pos + _RECORD_HEAD + length
        if end > len(raw):
            raise ChunkError(f'a record of {length} bytes at byte {pos} runs past the chunk')
        stream = ReadDataStream(io.BytesIO(raw[pos + _RECORD_HEAD:end]))
        try:
            if opcode == OP_SCHEMA:
                records.append(Schema.read(stream))
            elif opcode == OP_CHANNEL:
                records.append(Channel.read(stream))
            elif opcode == OP_MESSAGE:
                message = Message.read(stream, length)
                records.append(message)
                offsets[pos] = (message.channel_id, message.log_time)
        except (McapError, EOFError, UnicodeDecodeError, ValueError) as exc:
            raise ChunkError(f'malformed record (opcode {opcode:#x}) at byte {pos}: {exc}'
                             ) from None
        pos = end
    return records, offsets


def _index_of(body: bytes) -> MessageIndex | None:
    try:
        return MessageIndex.read(ReadDataStream(io.BytesIO(body)))
    except (McapError, EOFError, ValueError):
        return None


def _read_summary(path: Path, salvage: Salvage) -> None:
    try:
        with open(path, 'rb') as stream:
            summary = make_reader(stream).get_summary()
    except (McapError, OSError, ValueError, EOFError, KeyError, AssertionError):
        return
    if summary is None:
        return
    salvage.summary_ok = True
    for schema_id, schema in summary.schemas.items():
        salvage.schemas.setdefault(schema_id, schema)
    for channel_id, channel in summary.channels.items():
        salvage.channels.setdefault(channel_id, channel)


def salvage_mcap(path: str | Path) -> Salvage:
    """Every schema, channel and message the MCAP file ``path`` still holds (see the module).

    Raises
    ------
    OSError
        If the file cannot be read.
    """
    path = Path(path)
    data = path.read_bytes()
    salvage = Salvage(size=len(data))
    if len(data) >= len(MCAP_MAGIC) and data[-len(MCAP_MAGIC):] == MCAP_MAGIC:
        _read_summary(path, salvage)
    if data[:len(MCAP_MAGIC)] != MCAP_MAGIC:
        salvage.cut_reason = ('no MCAP magic at the start' if data
                              else 'the file is empty')
        salvage.summary_ok = False
        return salvage
    pos = len(MCAP_MAGIC)
    pending: LostChunk | None = None  # the last chunk, when lost: its index counts the loss
    checked: tuple[int, int, dict[int, tuple[int, int]]] | None = None  # the last good one
    indexed: dict[int, int] = {}  # messages per channel the last chunk's index lists
    while pos < len(data):
        if pos + _RECORD_HEAD > len(data):
            salvage.cut_reason = f'a record cut short at byte {pos} of {len(data)}'
            break
        opcode = data[pos]
        length = int.from_bytes(data[pos + 1:pos + _RECORD_HEAD], 'little')
        end = pos + _RECORD_HEAD + length
        if end > len(data):
            salvage.cut_reason = (f'a record (opcode {opcode:#x}) of {length} bytes at byte '
                                  f'{pos} runs past the end of the file ({len(data)} bytes)')
            break
        body = data[pos + _RECORD_HEAD:end]
        if opcode == OP_CHUNK:
            pending, checked, indexed = None, None, {}
            try:
                records, offsets = read_chunk(body)
            except ChunkError as exc:
                pending = LostChunk(pos, str(exc))
                salvage.lost_chunks.append(pending)
            else:
                checked = (pos, len(salvage.messages), offsets)
                for record in records:
                    if isinstance(record, Schema):
                        salvage.schemas[record.id] = record
                    elif isinstance(record, Channel):
                        salvage.channels[record.id] = record
                    else:
                        salvage.messages.append(record)
        elif opcode == OP_MESSAGE_INDEX:
            index = _index_of(body)
            if checked is not None and (index is None or any(
                    checked[2].get(offset) != (index.channel_id, log_time)
                    for log_time, offset in index.records)):
                # Decompressed, but not into what the writer indexed: garbage that parsed.
                chunk_at, first, _ = checked
                del salvage.messages[first:]
                pending = LostChunk(chunk_at, 'its messages disagree with its message index',
                                    dict(indexed))
                salvage.lost_chunks.append(pending)
                checked = None
            if index is not None:
                indexed[index.channel_id] = len(index.records)
                if pending is not None:
                    pending.lost[index.channel_id] = len(index.records)
        elif opcode in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
            try:
                stream = ReadDataStream(io.BytesIO(body))
                record = (Schema.read(stream) if opcode == OP_SCHEMA else
                          Channel.read(stream) if opcode == OP_CHANNEL else
                          Message.read(stream, length))
            except (McapError, EOFError, UnicodeDecodeError, ValueError) as exc:
                salvage.cut_reason = (f'a malformed record (opcode {opcode:#x}) at byte '
                                      f'{pos}: {exc}')
                break
            if isinstance(record, Schema):
                salvage.schemas[record.id] = record
            elif isinstance(record, Channel):
                salvage.channels[record.id] = record
            else:
                salvage.messages.append(record)
        elif opcode in (OP_DATA_END, OP_FOOTER):
            pos = end
            break
        pos = end
    else:
        pos = len(data)
    salvage.read_to = pos
    return salvage
