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
commit on every flush and once a transaction holds 1 MiB of messages.

The size limit is met (:mod:`dam_recorder.file_size`): a new file starts before a message that
could take the current one, once closed, above it. With zstd the pending chunk is written out
early when its raw size alone would not fit (its compressed size is then known).

The first error writing the bag (:mod:`dam_recorder.write_failure`: a full or read-only file
system, the directory removed, an I/O error) ends the writing: the bag is cut back to what is
in its files (MCAP: up to the last chunk written out; sqlite3: the last commit), closed as far
as the file system allows (summary, ``metadata.yaml`` with the counts on disk), every message
not on disk is counted (``dam_recorder.unwritten_messages``) and
:class:`~dam_recorder.errors.BagWriteError` is raised once; from then on :meth:`BagWriter.write`
only counts.
"""

from __future__ import annotations

import json
import os
import sqlite3
from collections import defaultdict
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager, suppress
from dataclasses import dataclass, replace
from io import BytesIO
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
from rosbags.rosbag2.storage_mcap import McapWriter, PendingChunk
from rosbags.rosbag2.storage_sqlite3 import Sqlite3Writer

from dam_recorder.errors import BagError, BagWriteError, ConfigurationError
from dam_recorder.file_size import (
    MCAP_MESSAGE,
    mcap_closing_bytes,
    mcap_definitions_bytes,
    mcap_pending_bytes,
    sqlite_closing_bytes,
    sqlite_row_bytes,
)
from dam_recorder.metadata import (
    METADATA_FILE,
    METADATA_VERSION,
    TOP_KEY,
    FileInfo,
    TopicInfo,
    bag_metadata,
    dump_metadata,
    write_metadata,
)
from dam_recorder.qos import metadata_profiles
from dam_recorder.storage_stream import StorageStream
from dam_recorder.write_failure import WriteFailure, failure_from, vanished

#: Storage plugins: identifier -> file suffix.
STORAGE_SUFFIXES: dict[str, str] = {'mcap': '.mcap', 'sqlite3': '.db3'}
#: Compression of MCAP chunks.
COMPRESSIONS: tuple[str, ...] = ('zstd', 'none')
#: The smallest size limit of a file [bytes] (``-b``), the one rosbag2's sqlite3 storage
#: requires: below it a file would close after every few messages.
MIN_SPLIT_BYTES = 86_016
#: The range of the recorder's chunk interval [s]: the longest a message waits in memory.
CHUNK_INTERVAL_RANGE_S = (0.01, 60.0)
#: A sqlite3 transaction is committed once it holds this much message data [bytes], as an
#: MCAP chunk is written out (and at least every chunk interval): a write error rolls back
#: the open transaction whole.
SQLITE_COMMIT_BYTES = 1 << 20
#: ``custom_data`` key: messages per topic that could not be written (a write error).
UNWRITTEN_KEY = 'dam_recorder.unwritten_messages'
#: With zstd, a file whose room left after an early chunk is below this share of the limit is
#: finished (else its last bytes would fill with ever smaller chunks).
MIN_ROOM_SHARE = 0.125
#: The errors of writing a storage file or ``metadata.yaml``.
WRITE_ERRORS = (OSError, sqlite3.Error)


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
        writer = McapWriter(_FileTarget(file), mode)  # type: ignore[arg-type]
        writer.bio = StorageStream.replacing(writer.bio, file)
        return writer
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


@dataclass
class _Durable:
    """What the current file holds for sure: the state after its last chunk written out and
    flushed (MCAP) or its last commit (sqlite3)."""

    offset: int = 0
    chunks: int = 0
    channel_stats: dict[int, int] | None = None
    message_start_time: int = 2**63 - 1
    message_end_time: int = 0
    file: FileInfo | None = None
    file_index: int = 0
    topic_counts: tuple[int, ...] = ()


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
        No file exceeds this size once closed [bytes] (:mod:`dam_recorder.file_size`): a new
        file starts before a message that could take it over; a file holds at least one
        message (one that does not fit alone exceeds the limit). 0: no limit.
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
        If ``bag_dir`` exists or cannot be created (:class:`BagWriteError` when the file
        system refuses).

    Notes
    -----
    Every method that writes raises :class:`BagWriteError` on the first write error (after
    closing the bag with what is on disk, see the module); then :attr:`failure` says what
    failed and :attr:`unwritten` counts, per topic, the messages not on disk.
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
        #: The first write error (None while the bag is written).
        self.failure: WriteFailure | None = None
        #: Messages per topic that could not be written (after a write error).
        self.unwritten: dict[str, int] = {}
        #: Whether ``metadata.yaml`` says what the files hold (False after a write error
        #: when it could not be written).
        self.metadata_current = True
        self._final_metadata = False
        if self.bag_dir.exists():
            raise BagError(f'{self.bag_dir} exists already; a bag is never written over')
        try:
            self.bag_dir.mkdir(parents=True)
        except OSError as exc:
            failure = failure_from(exc, self.bag_dir, self.bag_dir)
            raise BagWriteError(f'cannot create the bag directory {self.bag_dir}: '
                                f'{failure.errno_name} ({exc})', failure) from None
        self.files: list[FileInfo] = []
        self._topics: list[_Topic] = []
        self._writer: Any = None
        self._durable = _Durable()
        self._definitions_bytes = 0  # MCAP: schema and channel records of the summary
        self._metadata_bytes = 0  # the closing metadata text, last measured
        self._sqlite_bytes = 0  # sqlite3: the file's size, an upper bound
        self._page_size = 4096
        self._pending = 0  # MCAP: messages in the pending chunk
        self._uncommitted = 0  # sqlite3: message bytes since the last commit
        with self._writing(self.bag_dir / storage_file_name(
                self.file_stem, 0, storage)):
            self._open_file()

    # -- files -------------------------------------------------------------------------------

    @property
    def topics(self) -> list[TopicInfo]:
        """The topics added so far, with their message counts."""
        return [t.info for t in self._topics]

    @property
    def closed(self) -> bool:
        """Whether :meth:`close` ran (or a write error closed the bag)."""
        return self._writer is None

    @property
    def current_file(self) -> Path:
        """The storage file being written."""
        return self.bag_dir / self.files[-1].path

    def _open_file(self) -> None:
        name = storage_file_name(self.file_stem, len(self.files), self.storage)
        self.files.append(FileInfo(name))
        self._writer = open_storage(self.bag_dir / name, self.storage, self.compression)
        self._pending = 0
        seen: set[str] = set()
        for topic in self._topics:
            add_connection(self._writer, topic.connection, topic.info.type not in seen)
            seen.add(topic.info.type)
        self._definitions_changed()
        if self.storage == 'mcap':
            self._writer.bio.flush()  # the header
            self._mark_durable()
        self.write_metadata()

    def _definitions_changed(self) -> None:
        """Topics were added: make them durable in sqlite3 (a commit), measure them for the
        size limit."""
        if self.storage == 'sqlite3':
            self._writer.conn.commit()
            self._mark_durable()
            self._page_size = self._writer.conn.execute('PRAGMA page_size').fetchone()[0]
            self._measure_sqlite()
        else:
            self._definitions_bytes = mcap_definitions_bytes(self._writer)

    def _measure_sqlite(self) -> int:
        pages = self._writer.conn.execute('PRAGMA page_count').fetchone()[0]
        self._sqlite_bytes = pages * self._page_size
        return self._sqlite_bytes

    def _mark_durable(self) -> None:
        """Everything written to the current file so far is in it."""
        writer = self._writer
        counts = tuple(t.info.message_count for t in self._topics)
        self._uncommitted = 0
        if self.storage == 'mcap':
            self._durable = _Durable(
                writer.bio.durable, len(writer.chunks), dict(writer.channel_stats),
                writer.message_start_time, writer.message_end_time, replace(self.files[-1]),
                len(self.files) - 1, counts)
        else:
            self._durable = _Durable(file=replace(self.files[-1]),
                                     file_index=len(self.files) - 1, topic_counts=counts)
        if self.max_file_bytes:
            self._metadata_bytes = len(self._metadata_text().encode())

    def metadata(self) -> dict[str, Any]:
        """The bag's ``metadata.yaml`` content as of now."""
        custom = dict(self._custom_data() if self._custom_data else {})
        if self.unwritten or self.failure is not None:
            custom[UNWRITTEN_KEY] = json.dumps(self.unwritten, sort_keys=True)
        return bag_metadata(
            storage_identifier=self.storage, files=self.files, topics=self.topics,
            custom_data=custom, ros_distro=self.ros_distro)

    def _metadata_text(self) -> str:
        return dump_metadata(self.metadata()[TOP_KEY]).strip()

    def write_metadata(self) -> None:
        """Write ``metadata.yaml`` as of now (done on every new file, topic and close)."""
        with self._writing(self.bag_dir / METADATA_FILE):
            write_metadata(self.bag_dir, self.metadata())

    def _close_file(self) -> None:
        if self.storage == 'mcap':
            self._write_chunk()
        writer, self._writer = self._writer, None
        writer.close(METADATA_VERSION, self._metadata_text())

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
        BagWriteError
            On the first write error (see the class).
        """
        if any(t.info.name == name for t in self._topics):
            raise BagError(f'topic {name!r} is in the bag already')
        info = TopicInfo(name, type_name, type_hash, list(offered_qos))
        connection = make_connection(len(self._topics) + 1, info, definition)
        if self.failure is not None:  # counted from now on, never written
            self._topics.append(_Topic(connection, info))
            return connection.id
        self._check_open()
        new_type = all(t.info.type != type_name for t in self._topics)
        self._topics.append(_Topic(connection, info))
        with self._writing(self.current_file):
            add_connection(self._writer, connection, new_type)
            self._definitions_changed()
        self.write_metadata()
        return connection.id

    def write(self, topic_id: int, timestamp_ns: int, data: bytes | memoryview) -> None:
        """Write one serialized message of topic ``topic_id`` received at ``timestamp_ns``
        [ns since the epoch], starting a new file first when a limit says so. After a write
        error the message is only counted (:attr:`unwritten`)."""
        topic = self._topics[topic_id - 1]
        if self.failure is not None:
            self._count_unwritten(topic.info.name, 1)
            return
        self._check_open()
        counted = False  # in the topic's count (then a write error counts it as unwritten)
        try:
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
            with self._writing(self.current_file):
                if self.max_file_bytes and file.message_count \
                        and not self._fits(topic.connection.id, len(data)):
                    self.split()
                    file = self.files[-1]
                file.add(timestamp_ns)
                topic.info.message_count += 1
                counted = True
                writer = self._writer
                writer.write(topic.connection, timestamp_ns, data)
                if self.storage == 'mcap':
                    self._pending += 1
                    if writer.chunk.bio.tell() == 0:  # the writer wrote out a full chunk
                        self._pending = 0
                        writer.bio.flush()
                        self._mark_durable()
                else:
                    self._sqlite_bytes += sqlite_row_bytes(len(data), self._page_size)
                    self._uncommitted += len(data)
                    if self._uncommitted >= SQLITE_COMMIT_BYTES:
                        writer.conn.commit()
                        self._mark_durable()
        except BagWriteError:
            if not counted:
                self._count_unwritten(topic.info.name, 1)
            raise

    def _fits(self, channel_id: int, size: int) -> bool:
        """Whether the current file, closed after a message of ``size`` bytes on channel
        ``channel_id``, stays within the size limit (with zstd the pending chunk may be
        written out first, to know its size)."""
        if self.storage == 'sqlite3':
            closing = sqlite_closing_bytes(self._metadata_bytes, self._page_size)
            row = sqlite_row_bytes(size, self._page_size)
            if self._sqlite_bytes + row + closing <= self.max_file_bytes:
                return True
            return self._measure_sqlite() + row + closing <= self.max_file_bytes
        bound = self._mcap_bound(channel_id, size)
        if bound <= self.max_file_bytes:
            return True
        if self.compression == 'none' or not self._writer.chunk.msgs:
            return False
        self.flush()  # the pending chunk's real size instead of its bound
        room = self.max_file_bytes - self._mcap_bound(channel_id, 0)
        return room >= size + MCAP_MESSAGE and room >= MIN_ROOM_SHARE * self.max_file_bytes

    def _mcap_bound(self, channel_id: int, size: int) -> int:
        """The most the current MCAP file takes once closed, with a message of ``size`` bytes
        on channel ``channel_id`` added to its pending chunk."""
        writer = self._writer
        chunk = writer.chunk
        channels = len(chunk.msgs) + (channel_id not in chunk.msgs)
        pending = mcap_pending_bytes(chunk.bio.tell() + MCAP_MESSAGE + size, self._pending + 1,
                                     channels, self.compression)
        closing = mcap_closing_bytes(self._definitions_bytes, len(writer.chunks) + 1,
                                     len(writer.channels), self._metadata_bytes,
                                     self.compression)
        return writer.bio.tell() + pending + closing

    def _write_chunk(self) -> None:
        """Write out the pending MCAP chunk, if any."""
        if self._writer.chunk.msgs:
            self._writer.close_chunk()
        self._pending = 0

    def flush(self) -> None:
        """Make every message written so far readable after a crash: write out the pending
        MCAP chunk and flush the file to the operating system (sqlite3: commit). A storage
        file removed meanwhile (with its directory) is a write error (``ENOENT``)."""
        if self.failure is not None:
            return
        self._check_open()
        with self._writing(self.current_file):
            if self.storage == 'mcap':
                self._write_chunk()
                self._writer.bio.flush()
            else:
                self._writer.conn.commit()
            self._mark_durable()
        gone = vanished(self.bag_dir, self.current_file)
        if gone is not None:
            self._fail(gone)

    def split(self) -> Path:
        """Finish the current file and continue in a new one; return the new file's path
        (after a write error: the last file, nothing is done)."""
        if self.failure is not None:
            return self.current_file
        self._check_open()
        with self._writing(self.current_file):
            self._close_file()
            self._mark_closed()
        with self._writing(self.bag_dir / storage_file_name(
                self.file_stem, len(self.files), self.storage)):
            self._open_file()
        return self.current_file

    def _mark_closed(self) -> None:
        """The file just closed holds everything written to it."""
        self._durable = _Durable(file=replace(self.files[-1]), file_index=len(self.files) - 1,
                                 topic_counts=tuple(t.info.message_count for t in self._topics))

    def close(self) -> None:
        """Finish the current file (summary and footer) and write ``metadata.yaml``; a second
        call does nothing. After a write error: write ``metadata.yaml`` once more with the
        final counts, where the file system allows (no error is raised)."""
        if self.failure is not None:
            if not self._final_metadata:
                self._final_metadata = True
                self._try_metadata()
            return
        if self._writer is None:
            return
        with self._writing(self.current_file):
            self._close_file()
            self._mark_closed()
        self.write_metadata()

    def _check_open(self) -> None:
        if self._writer is None:
            raise BagError(f'the bag {self.bag_dir} is closed')

    # -- write errors ------------------------------------------------------------------------

    @contextmanager
    def _writing(self, path: Path) -> Iterator[None]:
        """Turn the first write error inside into :meth:`_fail` (``path``: what is being
        written, where the error does not say)."""
        if self.failure is not None:
            yield
            return
        try:
            yield
        except WRITE_ERRORS as exc:
            if self.failure is not None:
                raise BagWriteError(self.failure.describe(), self.failure) from None
            self._fail(failure_from(exc, self.bag_dir, path))

    def _count_unwritten(self, name: str, count: int) -> None:
        if count > 0:
            self.unwritten[name] = self.unwritten.get(name, 0) + count

    def _fail(self, failure: WriteFailure) -> None:
        """Stop writing: cut the current file back to what is durable in it, close it as far
        as the file system allows, count what is not on disk, write ``metadata.yaml`` if
        possible; raise :class:`BagWriteError`."""
        self.failure = failure
        writer, self._writer = self._writer, None
        if writer is not None:
            self._salvage(writer)
        self._restore_counts()
        self._try_metadata()
        raise BagWriteError(failure.describe(), failure)

    def _salvage(self, writer: Any) -> None:
        """Close ``writer``'s file with what is durable in it (and, where the file system
        takes it, what was pending)."""
        if self.storage == 'sqlite3':
            # No second commit: after a failed one SQLite may have rolled the transaction back
            # already, and a commit without one "succeeds". What is on disk is the last commit.
            with suppress(*WRITE_ERRORS):
                writer.conn.rollback()
            self._restore_counts()
            try:
                writer.close(METADATA_VERSION, self._metadata_text())
            except WRITE_ERRORS:
                with suppress(*WRITE_ERRORS):
                    writer.conn.close()
            return
        self._writer = writer
        try:
            self._write_chunk()
            writer.bio.flush()
            self._mark_durable()
        except WRITE_ERRORS:
            pass
        self._writer = None
        durable = self._durable
        stream: StorageStream = writer.bio
        try:
            stream.rewind(durable.offset)
        except OSError:
            stream.release()  # (read-only: nothing can be cut or added)
            return
        writer.chunks = writer.chunks[:durable.chunks]
        writer.channel_stats = {cid: (durable.channel_stats or {}).get(cid, 0)
                                for cid in writer.channel_stats}
        writer.message_start_time = durable.message_start_time
        writer.message_end_time = durable.message_end_time
        writer.chunk = PendingChunk(2**63 - 1, 0, BytesIO(), defaultdict(list))
        self._restore_counts()
        try:
            writer.close(METADATA_VERSION, self._metadata_text())
        except WRITE_ERRORS:
            with suppress(OSError):
                stream.rewind(durable.offset)  # no summary: recover adds it
            stream.release()

    def _restore_counts(self) -> None:
        """Set the counts to what is durable (before the file's closing metadata)."""
        counts = self._durable.topic_counts
        for i, topic in enumerate(self._topics):
            on_disk = counts[i] if i < len(counts) else 0
            self._count_unwritten(topic.info.name, topic.info.message_count - on_disk)
            topic.info.message_count = on_disk
        durable = self._durable
        if durable.file is not None:
            self.files[durable.file_index] = replace(durable.file)
            for file in self.files[durable.file_index + 1:]:  # opened, nothing in it
                with suppress(OSError):
                    (self.bag_dir / file.path).unlink()
            del self.files[durable.file_index + 1:]

    def _try_metadata(self) -> None:
        """Write ``metadata.yaml`` after a write error, if the file system allows."""
        try:
            write_metadata(self.bag_dir, self.metadata())
            self.metadata_current = True
        except WRITE_ERRORS:
            self.metadata_current = False
            with suppress(OSError):
                (self.bag_dir / (METADATA_FILE + '.tmp')).unlink()
