"""Upper bounds of a storage file's size once it is closed, for the size limit (no rclpy).

The size limit (``-b``, ``max_bag_size``) is met for both storages: the recorder starts a new
file before a message that could take the current one, closed, above the limit. "Closed"
counts what the file gets when it is finished:

- MCAP: the pending chunk (its compressed size at most ``zstd``'s bound of its raw size, or
  the raw size without compression) with its message index, then the data end, the
  ``rosbag2`` metadata record (``metadata.yaml``'s text), the summary (every schema and channel
  again, one chunk index per chunk, the statistics, the summary offsets) and the footer.
  Everything else is the bytes written so far, known exactly;
- sqlite3: the pages the database holds (``PRAGMA page_count``, which counts the open
  transaction), each new row at most its data and :data:`SQLITE_ROW_OVERHEAD` bytes,
  :data:`SQLITE_SLACK_PAGES` pages for the B-tree pages an insert may add at once (a new
  leaf of the table and of the timestamp index, their parents), and the row of the
  ``metadata`` table that closing adds.

The closing metadata text grows while a file is written (counts in ``custom_data``, an
episode's summary); it is measured at every chunk or commit and reserved with
:data:`METADATA_MARGIN` of its size and :data:`METADATA_SLACK` bytes more.
"""

from __future__ import annotations

from io import BytesIO
from typing import Any

from rosbags.rosbag2.storage_mcap import write_channel, write_schema

#: Bytes of an MCAP record's opcode and length.
MCAP_RECORD = 9
#: An MCAP message record without its data: channel id, sequence, log and publish time.
MCAP_MESSAGE = MCAP_RECORD + 2 + 4 + 8 + 8
#: A message index entry (time, offset) and a message index record without entries.
MCAP_INDEX_ENTRY = 16
MCAP_INDEX_RECORD = MCAP_RECORD + 2 + 4
#: A chunk record without its compression name and data.
MCAP_CHUNK = MCAP_RECORD + 8 + 8 + 8 + 4 + 4 + 8
#: A chunk index record without its compression name and its per-channel offsets.
MCAP_CHUNK_INDEX = MCAP_RECORD + 8 + 8 + 8 + 8 + 4 + 8 + 4 + 8 + 8
#: Data end, metadata index, statistics without per-channel counts, five summary offsets,
#: footer and closing magic.
MCAP_CLOSING = ((MCAP_RECORD + 4) + (MCAP_RECORD + 8 + 8 + 4 + len('rosbag2'))
                + (MCAP_RECORD + 8 + 2 + 4 + 4 + 4 + 4 + 8 + 8 + 4)
                + 5 * (MCAP_RECORD + 1 + 8 + 8) + (MCAP_RECORD + 8 + 8 + 4) + 8)
#: The metadata record without the text: name ``rosbag2``, map length, key, text length.
MCAP_METADATA = MCAP_RECORD + 4 + len('rosbag2') + 4 + 4 + len('serialized_metadata') + 4
#: Bytes a sqlite3 row may take besides its data: row id, record header, the three integer
#: columns, the cell pointer, and its timestamp index entry.
SQLITE_ROW_OVERHEAD = 96
#: Pages one insert may add besides its own cells (a new leaf and a new parent, table and
#: index).
SQLITE_SLACK_PAGES = 4
#: Reserve for the closing metadata text: this share of its size measured last, plus bytes.
METADATA_MARGIN = 0.25
METADATA_SLACK = 1024


def metadata_reserve(text_bytes: int) -> int:
    """Bytes reserved for a closing metadata text last measured at ``text_bytes``."""
    return int(text_bytes * (1.0 + METADATA_MARGIN)) + METADATA_SLACK


def compressed_bound(raw: int, compression: str) -> int:
    """The most ``raw`` bytes take once compressed (``zstd``'s ``ZSTD_COMPRESSBOUND`` with
    room to spare; ``none``: ``raw``)."""
    if compression == 'none':
        return raw
    return raw + (raw >> 7) + 512


def mcap_definitions_bytes(writer: Any) -> int:
    """Bytes of every schema and channel record of a ``rosbags`` MCAP writer, as its summary
    repeats them."""
    out = BytesIO()
    for schema in writer.schemas:
        write_schema(out, schema)
    for channel in writer.channels:
        write_channel(out, channel, writer.schemas)
    return out.tell()


def mcap_pending_bytes(raw: int, messages: int, channels: int, compression: str) -> int:
    """The most a pending chunk of ``raw`` bytes with ``messages`` messages of ``channels``
    channels takes once written out, with its message index."""
    name = 0 if compression == 'none' else len(compression)
    return (MCAP_CHUNK + name + compressed_bound(raw, compression)
            + channels * MCAP_INDEX_RECORD + messages * MCAP_INDEX_ENTRY)


def mcap_closing_bytes(definitions: int, chunks: int, channels: int, metadata_text: int,
                       compression: str) -> int:
    """The most an MCAP file grows by when it is closed after its last chunk: the metadata
    record (a text last measured at ``metadata_text`` bytes), the summary with
    ``definitions`` bytes of schemas and channels and ``chunks`` chunk indexes, the footer."""
    name = 0 if compression == 'none' else len(compression)
    return (MCAP_METADATA + metadata_reserve(metadata_text) + definitions
            + chunks * (MCAP_CHUNK_INDEX + name + 10 * channels) + MCAP_CLOSING + 10 * channels)


def sqlite_row_bytes(data: int, page_size: int) -> int:
    """The most a row of ``data`` bytes adds to a sqlite3 file (cells, an overflow chain's
    last page partly empty)."""
    overflow = page_size if data > page_size // 4 else 0
    return data + SQLITE_ROW_OVERHEAD + overflow


def sqlite_closing_bytes(metadata_text: int, page_size: int) -> int:
    """The most a sqlite3 file grows by when it is closed (the ``metadata`` row of a text
    last measured at ``metadata_text`` bytes, its pages and overflow) plus the slack pages of
    one insert."""
    return (metadata_reserve(metadata_text) + SQLITE_ROW_OVERHEAD
            + (SQLITE_SLACK_PAGES + 1) * page_size)
