"""Writing a rosbag2 bag, split into files, with the storage writers of ``rosbags``.

A bag is a directory holding ``metadata.yaml`` (:mod:`dam_recorder.metadata`) and one or more
storage files ``<bag name>_<index>.mcap`` (or ``.db3``), as ``ros2 bag record`` lays it out.
``rosbags``' :class:`~rosbags.rosbag2.Writer` writes a bag of one file only, so this module
drives its storage writers (the MCAP and sqlite3 plugins) itself, one per file, and writes the
metadata of the whole bag.

MCAP files are chunked: messages collect in a chunk (zstd-compressed by default) that is
written out with its message index when it exceeds 1 MiB or when :meth:`BagWriter.flush` is
called (the recorder calls it every ``chunk_interval``), and the file is flushed to the
operating system right then. A file is finished with its summary (schemas, channels, chunk
index, statistics) and footer only when it is closed; if the process dies before, every chunk
written so far stays readable and :mod:`dam_recorder.recovery` adds the summary. sqlite3 files
commit on every flush.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from rosbags.interfaces import (
    Connection,
    ConnectionExtRosbag2,
    MessageDefinition,
    MessageDefinitionFormat,
    Qos,
)
from rosbags.rosbag2.enums import CompressionMode
from rosbags.rosbag2.storage_mcap import McapWriter
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer

from dam_recorder.errors import BagError, ConfigurationError
from dam_recorder.metadata import (
    METADATA_VERSION,
    TOP_KEY,
    FileInfo,
    TopicInfo,
    bag_metadata,
    dump_metadata,
    write_metadata,
)
from dam_recorder.qos import metadata_profiles

#: Storage plugins: identifier -> file suffix.
STORAGE_SUFFIXES: dict[str, str] = {'mcap': '.mcap', 'sqlite3': '.db3'}
#: Compression of MCAP chunks.
COMPRESSIONS: tuple[str, ...] = ('zstd', 'none')
#: The smallest size limit of a file [bytes] (``-b``), the one rosbag2's sqlite3 storage
#: requires: below it a file would close after every few messages.
MIN_SPLIT_BYTES = 86_016
#: The range of the recorder's chunk interval [s]: the longest a message waits in memory.
CHUNK_INTERVAL_RANGE_S = (0.01, 60.0)


#: A message stamped this much before the newest of its file is a clock that jumped back
#: (receive stamps of different topics may be out of order by a sweep of the taker) [ns].
CLOCK_JUMP_BACK_NS = 1_000_000_000

class _FileTarget:
    """Stands in for the bag directory that ``rosbags``' storage writers take: they open
    ``<directory>/<directory name>.<suffix>``; this names the file of a split bag instead."""

    def __init__(self, file: Path) -> None:
        self.file = file
        self.name = file.stem

    def __truediv__(self, _name: str) -> Path:
        return self.file


def storage_file_name(stem: str, index: int, storage: str) -> str:
    """Name of the ``index``-th storage file of a bag whose files are named after ``stem``
    (``stem_0.mcap``, ``stem_1.mcap``; ``ros2 bag record`` takes the bag directory's name)."""
    return f'{stem}_{index}{STORAGE_SUFFIXES[storage]}'


def qos_text(profiles: Sequence[Qos]) -> str:
    """Offered profiles as the YAML text that MCAP channel metadata and the sqlite3 ``topics``
    table carry (the same list as ``metadata.yaml``)."""
    return yaml.safe_dump(metadata_profiles(profiles), sort_keys=False,
                          default_flow_style=False).strip()


@dataclass(frozen=True)
class _Topic:
    connection: Connection
    info: TopicInfo


def open_storage(file: Path, storage: str, compression: str) -> Any:
    """A ``rosbags`` storage writer for a new ``file`` (MCAP chunks compressed with zstd when
    ``compression`` is ``'zstd'``)."""
    if storage == 'mcap':
        mode = CompressionMode.STORAGE if compression == 'zstd' else CompressionMode.NONE
        return McapWriter(_FileTarget(file), mode)  # type: ignore[arg-type]
    return Sqlite3Writer(_FileTarget(file), CompressionMode.NONE)  # type: ignore[arg-type]


def add_connection(writer: Any, connection: Connection, new_type: bool) -> None:
    """Register ``connection`` (and its type, when ``new_type``) with a storage writer."""
    if new_type:
        writer.add_msgtype(connection)
    writer.add_connection(connection, qos_text(connection.ext.offered_qos_profiles))


def make_connection(connection_id: int, info: TopicInfo, definition: str) -> Connection:
    """The ``rosbags`` connection of a topic."""
    return Connection(
        id=connection_id, topic=info.name, msgtype=info.type,
        msgdef=MessageDefinition(MessageDefinitionFormat.MSG, definition),
        digest=info.type_hash, msgcount=0,
        ext=ConnectionExtRosbag2(serialization_format=info.serialization_format,
                                 offered_qos_profiles=list(info.offered_qos)),
        owner=None)


class BagWriter:
    """A rosbag2 bag being written.

    Parameters
    ----------
    bag_dir : path
        The bag directory; it must not exist (it is created, with its parents).
    storage : str
        ``'mcap'`` (default) or ``'sqlite3'``.
    compression : str
        ``'zstd'`` (MCAP chunk compression, the default for MCAP) or ``'none'``; sqlite3 takes
        ``'none'`` only.
    max_file_bytes : int
        Start a new file once the current one holds this many bytes [bytes]; 0: no limit.
    max_file_duration_ns : int
        Start a new file before a message stamped this long [ns] after the file's first one,
        or more than :data:`CLOCK_JUMP_BACK_NS` before its newest (the clock jumped back: a
        simulation started again); 0: no limit.
    ros_distro : str
        Written as ``ros_distro``.
    custom_data : callable, optional
        Returns the ``custom_data`` entries (strings) each time the metadata is written.
    file_stem : str, optional
        Storage files are named ``<file_stem>_<index>.<suffix>``; default: the directory's name.
        (A bag whose directory is renamed after it is closed keeps its files' names: the
        metadata names them relative to the directory.)

    Raises
    ------
    ConfigurationError
        For an unknown storage or compression, or a negative limit (the value is named).
    BagError
        If ``bag_dir`` exists or cannot be created.
    """

    def __init__(self, bag_dir: str | os.PathLike[str], *, storage: str = 'mcap',
                 compression: str = 'zstd', max_file_bytes: int = 0,
                 max_file_duration_ns: int = 0, ros_distro: str = 'jazzy',
                 custom_data: Callable[[], Mapping[str, str]] | None = None,
                 file_stem: str | None = None) -> None:
        if storage not in STORAGE_SUFFIXES:
            raise ConfigurationError(
                f'storage must be one of {", ".join(STORAGE_SUFFIXES)}, got {storage!r}')
        if compression not in COMPRESSIONS:
            raise ConfigurationError(
                f'compression must be one of {", ".join(COMPRESSIONS)}, got {compression!r}')
        if storage == 'sqlite3' and compression != 'none':
            raise ConfigurationError(
                f'compression {compression!r} is for MCAP chunks; sqlite3 takes none')
        if max_file_bytes < 0 or max_file_duration_ns < 0:
            raise ConfigurationError(
                'split limits must be 0 (off) or positive, got max_file_bytes='
                f'{max_file_bytes!r}, max_file_duration_ns={max_file_duration_ns!r}')
        if 0 < max_file_bytes < MIN_SPLIT_BYTES:
            raise ConfigurationError(
                f'max_file_bytes {max_file_bytes!r} is below the smallest split size, '
                f'{MIN_SPLIT_BYTES} bytes (0: no limit)')
        self.bag_dir = Path(bag_dir)
        self.storage = storage
        self.compression = compression
        self.max_file_bytes = int(max_file_bytes)
        self.max_file_duration_ns = int(max_file_duration_ns)
        #: Times the clock of the messages went back by more than CLOCK_JUMP_BACK_NS while
        #: a duration limit was set (each started a new file).
        self.clock_jumps_back = 0
        self.ros_distro = ros_distro
        self._custom_data = custom_data
        self.file_stem = file_stem or self.bag_dir.name
        if self.bag_dir.exists():
            raise BagError(f'{self.bag_dir} exists already; a bag is never written over')
        try:
            self.bag_dir.mkdir(parents=True)
        except OSError as exc:
            raise BagError(f'cannot create the bag directory {self.bag_dir}: {exc}') from None
        self.files: list[FileInfo] = []
        self._topics: list[_Topic] = []
        self._writer: Any = None
        self._file_data_bytes = 0
        #: Bytes of the MCAP chunks written out so far, uncompressed and as stored.
        self._chunk_bytes = [0, 0]
        self._open_file()

    # -- files -------------------------------------------------------------------------------

    @property
    def topics(self) -> list[TopicInfo]:
        """The topics added so far, with their message counts."""
        return [t.info for t in self._topics]

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` ran."""
        return self._writer is None

    @property
    def current_file(self) -> Path:
        """The storage file being written."""
        return self.bag_dir / self.files[-1].path

    def _open_file(self) -> None:
        name = storage_file_name(self.file_stem, len(self.files), self.storage)
        try:
            self._writer = open_storage(self.bag_dir / name, self.storage, self.compression)
        except OSError as exc:
            raise BagError(f'cannot open {self.bag_dir / name}: {exc}') from None
        self.files.append(FileInfo(name))
        self._file_data_bytes = 0
        seen: set[str] = set()
        for topic in self._topics:
            add_connection(self._writer, topic.connection, topic.info.type not in seen)
            seen.add(topic.info.type)
        self.write_metadata()

    def metadata(self) -> dict[str, Any]:
        """The bag's ``metadata.yaml`` content as of now."""
        return bag_metadata(
            storage_identifier=self.storage, files=self.files, topics=self.topics,
            custom_data=self._custom_data() if self._custom_data else None,
            ros_distro=self.ros_distro)

    def write_metadata(self) -> None:
        """Write ``metadata.yaml`` as of now (done on every new file, topic and close)."""
        write_metadata(self.bag_dir, self.metadata())

    def _close_file(self) -> None:
        if self.storage == 'mcap':
            self._write_chunk()
        writer, self._writer = self._writer, None
        text = dump_metadata(self.metadata()[TOP_KEY]).strip()
        writer.close(METADATA_VERSION, text)

    # -- topics and messages -----------------------------------------------------------------

    def add_topic(self, name: str, type_name: str, definition: str, type_hash: str,
                  offered_qos: Sequence[Qos]) -> int:
        """Add a topic; return the id to :meth:`write` its messages with.

        Parameters
        ----------
        name, type_name : str
            Topic name and full type name.
        definition : str
            ``ros2msg`` message definition (:meth:`MessageType.definition`).
        type_hash : str
            RIHS01 type hash.
        offered_qos : sequence of rosbags Qos
            The profiles the topic's publishers offer.

        Raises
        ------
        BagError
            If the bag is closed or ``name`` was added before.
        """
        self._check_open()
        if any(t.info.name == name for t in self._topics):
            raise BagError(f'topic {name!r} is in the bag already')
        info = TopicInfo(name, type_name, type_hash, list(offered_qos))
        connection = make_connection(len(self._topics) + 1, info, definition)
        new_type = all(t.info.type != type_name for t in self._topics)
        add_connection(self._writer, connection, new_type)
        self._topics.append(_Topic(connection, info))
        self.write_metadata()
        return connection.id

    def write(self, topic_id: int, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Write one serialized message of topic ``topic_id`` received at ``timestamp_ns``
        [ns since the epoch], starting a new file first or after when a limit says so."""
        self._check_open()
        topic = self._topics[topic_id - 1]
        file = self.files[-1]
        if (self.max_file_duration_ns and file.message_count
                and (timestamp_ns - file.start_ns >= self.max_file_duration_ns
                     or timestamp_ns < file.end_ns - CLOCK_JUMP_BACK_NS)):
            # The duration of a file is that of one clock run: a clock that jumps back (a
            # simulation started again) starts a new file, as the duration limit would.
            if timestamp_ns < file.end_ns - CLOCK_JUMP_BACK_NS:
                self.clock_jumps_back += 1
            self.split()
            file = self.files[-1]
        writer = self._writer
        if self.storage == 'mcap':
            before = (writer.chunk.bio.tell(), writer.bio.tell())
        writer.write(topic.connection, timestamp_ns, data)
        file.add(timestamp_ns)
        topic.info.message_count += 1
        self._file_data_bytes += len(data)
        if self.storage == 'mcap' and writer.chunk.bio.tell() == 0:
            # The writer just wrote out a full chunk (this message's record included).
            self._count_chunk(before[0] + len(data), writer.bio.tell() - before[1])
            writer.bio.flush()
        if self.max_file_bytes and self.file_bytes() >= self.max_file_bytes:
            self.split()

    def _write_chunk(self) -> None:
        """Write out the pending MCAP chunk, if any, and count its sizes."""
        writer = self._writer
        if writer.chunk.msgs:
            before = (writer.chunk.bio.tell(), writer.bio.tell())
            writer.close_chunk()
            self._count_chunk(before[0], writer.bio.tell() - before[1])

    def _count_chunk(self, raw_bytes: int, stored_bytes: int) -> None:
        self._chunk_bytes[0] += raw_bytes
        self._chunk_bytes[1] += stored_bytes

    def file_bytes(self) -> int:
        """Size of the current file [bytes]: for MCAP what is written, plus the pending chunk
        and its message index, at the ratio of stored to raw bytes of the chunks written out
        so far (compression and index included; before the first, the raw bytes and 16 bytes
        of index a message); for sqlite3 the message data. The summary written when the file
        closes (schemas, channels, chunk index, statistics: a few hundred bytes) is not
        counted."""
        if self.storage == 'mcap':
            writer = self._writer
            raw, stored = self._chunk_bytes
            if raw > 0:  # stored bytes per raw byte, message index included
                return int(writer.bio.tell() + stored / raw * writer.chunk.bio.tell())
            pending = sum(len(m) for m in writer.chunk.msgs.values())
            return writer.bio.tell() + writer.chunk.bio.tell() + 16 * pending
        return self._file_data_bytes

    def flush(self) -> None:
        """Make every message written so far readable after a crash: write out the pending
        MCAP chunk and flush the file to the operating system (sqlite3: commit)."""
        self._check_open()
        if self.storage == 'mcap':
            self._write_chunk()
            self._writer.bio.flush()
        else:
            self._writer.conn.commit()

    def split(self) -> Path:
        """Finish the current file and continue in a new one; return the new file's path."""
        self._check_open()
        self._close_file()
        self._open_file()
        return self.current_file

    def close(self) -> None:
        """Finish the current file (summary and footer) and write ``metadata.yaml``; a second
        call does nothing."""
        if self._writer is None:
            return
        self._close_file()
        self.write_metadata()

    def _check_open(self) -> None:
        if self._writer is None:
            raise BagError(f'the bag {self.bag_dir} is closed')
