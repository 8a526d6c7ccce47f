"""Making a bag whole again after its recorder died without closing it (SIGKILL, power cut).

What such a bag holds: every MCAP chunk the recorder wrote out before it died (it writes the
pending chunk out every ``chunk_interval`` and whenever a chunk reaches 1 MiB), possibly a
partial chunk after them, and no summary or footer, so index-based readers refuse the last
file. ``metadata.yaml`` is the one written when the file or the last topic was added: its file
list and topics are right, its counts are not. A sqlite3 file holds every transaction committed
(one per ``chunk_interval``) and possibly a hot journal.

:func:`recover_bag` reads each MCAP file that has no valid footer from the start with the
``mcap`` library's stream reader, keeps every schema, channel and message up to the first record
it cannot read (the partial chunk, whose messages are lost), and writes them into a new file
with a summary (the same writer the recorder uses), which replaces the damaged one. A file that
has a valid summary is left as it is. A sqlite3 file is opened once (which rolls a hot journal
back). Then ``metadata.yaml`` is written anew from what the files hold, keeping the type hashes
and ``custom_data`` of the old one, with ``dam_recorder.recovered_files`` naming the rebuilt
files.
"""

from __future__ import annotations

import os
import re
import sqlite3
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, BinaryIO

from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
from rosbags.rosbag2.metadata import parse_qos

from dam_recorder.bag_writer import (
    STORAGE_SUFFIXES,
    add_connection,
    make_connection,
    open_storage,
)
from dam_recorder.errors import RecoveryError
from dam_recorder.metadata import (
    METADATA_VERSION,
    TOP_KEY,
    FileInfo,
    TopicInfo,
    bag_metadata,
    dump_metadata,
    read_metadata,
    write_metadata,
)

#: The 8 bytes that begin and end a complete MCAP file.
MCAP_MAGIC = b'\x89MCAP0\r\n'
RECOVERED_KEY = 'dam_recorder.recovered_files'


@dataclass
class FileReport:
    """What recovery found in one storage file.

    Attributes
    ----------
    path : str
        File name in the bag directory.
    rebuilt : bool
        Whether the file was rewritten (it had no valid summary).
    message_count : int
        Messages the file holds now.
    dropped_bytes : int
        Bytes at the end of the damaged file that could not be read [bytes]: a partly written
        chunk (its messages are lost) or message index (nothing is lost with it).
    """

    path: str
    rebuilt: bool
    message_count: int
    dropped_bytes: int = 0


@dataclass
class RecoveryReport:
    """The result of :func:`recover_bag`: one :class:`FileReport` per file and the topics."""

    bag_dir: Path
    files: list[FileReport] = field(default_factory=list)
    topics: list[TopicInfo] = field(default_factory=list)

    @property
    def message_count(self) -> int:
        """Messages in the recovered bag."""
        return sum(f.message_count for f in self.files)


def _file_index(path: Path) -> tuple[int, str]:
    match = re.search(r'_(\d+)$', path.stem)
    return (int(match.group(1)) if match else -1, path.name)


def storage_files(bag_dir: Path) -> tuple[str, list[Path]]:
    """The storage identifier and the storage files of ``bag_dir``, in file order.

    Raises
    ------
    RecoveryError
        If ``bag_dir`` is not a directory, holds no storage file, or holds both kinds.
    """
    if not bag_dir.is_dir():
        raise RecoveryError(f'{bag_dir} is not a bag directory')
    found = {storage: sorted((p for p in bag_dir.iterdir()
                              if p.suffix == suffix and p.is_file()), key=_file_index)
             for storage, suffix in STORAGE_SUFFIXES.items()}
    kinds = [s for s, paths in found.items() if paths]
    if not kinds:
        raise RecoveryError(f'{bag_dir} holds no .mcap or .db3 file')
    if len(kinds) > 1:
        raise RecoveryError(f'{bag_dir} holds both .mcap and .db3 files; recover them apart')
    return kinds[0], found[kinds[0]]


def mcap_is_complete(path: Path) -> bool:
    """Whether the MCAP file ends with its magic and has a readable summary."""
    try:
        with open(path, 'rb') as stream:
            stream.seek(0, os.SEEK_END)
            if stream.tell() < 2 * len(MCAP_MAGIC):
                return False
            stream.seek(-len(MCAP_MAGIC), os.SEEK_END)
            if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
                return False
            stream.seek(0)
            return make_reader(stream).get_summary() is not None
    except (McapError, OSError, ValueError, EOFError):
        return False


class _Topics:
    """Topics collected over the files, by name, with the hashes of the old metadata."""

    def __init__(self, old: dict[str, Any] | None) -> None:
        self.by_name: dict[str, TopicInfo] = {}
        self.hashes: dict[str, str] = {}
        for entry in (old or {}).get('topics_with_message_count', []) or []:
            meta = entry.get('topic_metadata', {})
            if meta.get('name'):
                self.hashes[meta['name']] = str(meta.get('type_description_hash', ''))
                self.by_name[meta['name']] = TopicInfo(
                    meta['name'], str(meta.get('type', '')), self.hashes[meta['name']],
                    parse_qos(meta.get('offered_qos_profiles') or []))

    def add(self, name: str, type_name: str, qos_text: str, count: int) -> TopicInfo:
        info = self.by_name.get(name)
        if info is None or not info.type:
            info = TopicInfo(name, type_name, self.hashes.get(name, ''), parse_qos(qos_text))
            self.by_name[name] = info
        info.message_count += count
        return info


def readable_records(stream: BinaryIO) -> Iterator[Any]:
    """The records of an MCAP stream (those inside chunks included) up to the first one that
    cannot be read: a record cut short, a chunk that does not decompress. A chunk is read whole
    before any record in it is yielded, so a partial chunk yields nothing."""
    records = StreamReader(stream).records
    while True:
        try:
            record = next(records)
        except StopIteration:
            return
        except Exception:  # noqa: BLE001 - any reading error ends the readable part
            return
        yield record


def _rebuild_mcap(path: Path, topics: _Topics) -> tuple[FileReport, FileInfo]:
    """Rewrite the readable part of a damaged MCAP file, with a summary, over it."""
    tmp = path.with_name(path.name + '.recovering')
    tmp.unlink(missing_ok=True)
    writer = open_storage(tmp, 'mcap', 'zstd')
    schemas: dict[int, Schema] = {}
    channels: dict[int, tuple[TopicInfo, Any]] = {}
    info = FileInfo(path.name)
    counts: dict[str, int] = {}
    read_to = 0
    with open(path, 'rb') as stream:
        for record in readable_records(stream):
            if isinstance(record, Schema):
                schemas[record.id] = record
            elif isinstance(record, Channel) and record.schema_id in schemas:
                schema = schemas[record.schema_id]
                topic = topics.add(record.topic, schema.name,
                                   record.metadata.get('offered_qos_profiles', ''), 0)
                connection = make_connection(len(channels) + 1, topic,
                                             schema.data.decode('utf-8'))
                new_type = all(t.type != schema.name for t, _ in channels.values())
                add_connection(writer, connection, new_type)
                channels[record.id] = (topic, connection)
            elif isinstance(record, Message) and record.channel_id in channels:
                topic, connection = channels[record.channel_id]
                writer.write(connection, record.log_time, record.data)
                info.add(record.log_time)
                counts[topic.name] = counts.get(topic.name, 0) + 1
            read_to = stream.tell()
        size = stream.seek(0, os.SEEK_END)
    file_topics = []
    for topic, _ in channels.values():
        topic.message_count += counts.get(topic.name, 0)
        file_topics.append(TopicInfo(topic.name, topic.type, topic.type_hash,
                                     topic.offered_qos, counts.get(topic.name, 0)))
    own = bag_metadata(storage_identifier='mcap', files=[info], topics=file_topics)
    writer.close(METADATA_VERSION, dump_metadata(own[TOP_KEY]).strip())
    os.replace(tmp, path)
    return FileReport(path.name, True, info.message_count, max(0, size - read_to)), info


def _read_complete_mcap(path: Path, topics: _Topics) -> tuple[FileReport, FileInfo]:
    with open(path, 'rb') as stream:
        summary = make_reader(stream).get_summary()
    info = FileInfo(path.name)
    stats = summary.statistics
    for channel_id, channel in summary.channels.items():
        schema = summary.schemas.get(channel.schema_id)
        count = stats.channel_message_counts.get(channel_id, 0) if stats else 0
        topics.add(channel.topic, schema.name if schema else '',
                   channel.metadata.get('offered_qos_profiles', ''), count)
    if stats and stats.message_count:
        info.start_ns, info.end_ns = stats.message_start_time, stats.message_end_time
        info.message_count = stats.message_count
    return FileReport(path.name, False, info.message_count), info


def _read_sqlite3(path: Path, topics: _Topics) -> tuple[FileReport, FileInfo]:
    info = FileInfo(path.name)
    try:
        conn = sqlite3.connect(path)  # read-write: rolls a hot journal back
        try:
            rows = conn.execute(
                'SELECT t.name, t.type, t.offered_qos_profiles, COUNT(m.id), MIN(m.timestamp), '
                'MAX(m.timestamp) FROM topics t LEFT JOIN messages m ON m.topic_id = t.id '
                'GROUP BY t.id ORDER BY t.id').fetchall()
        finally:
            conn.close()
    except sqlite3.Error as exc:
        raise RecoveryError(f'cannot read {path}: {exc}') from None
    for name, type_name, qos_text, count, first, last in rows:
        topics.add(name, type_name, qos_text or '', count)
        if count:
            info.add(first, 0)
            info.add(last, count)
    return FileReport(path.name, False, info.message_count), info


def recover_bag(bag_dir: str | os.PathLike[str]) -> RecoveryReport:
    """Make the bag in ``bag_dir`` readable by every reader again; return what was found.

    Run it only on a bag whose recorder has ended. A bag that is whole is left as it is
    (``metadata.yaml`` is rewritten with the same content).

    Raises
    ------
    RecoveryError
        If ``bag_dir`` holds no bag (see :func:`storage_files`) or a file cannot be read.
    """
    bag_dir = Path(bag_dir)
    storage, paths = storage_files(bag_dir)
    old = read_metadata(bag_dir)
    topics = _Topics(old)
    report = RecoveryReport(bag_dir)
    infos: list[FileInfo] = []
    for path in paths:
        if storage == 'sqlite3':
            file_report, info = _read_sqlite3(path, topics)
        elif mcap_is_complete(path):
            file_report, info = _read_complete_mcap(path, topics)
        else:
            file_report, info = _rebuild_mcap(path, topics)
        report.files.append(file_report)
        infos.append(info)
    custom = dict((old or {}).get('custom_data') or {})
    rebuilt = [f.path for f in report.files if f.rebuilt]
    if rebuilt:
        custom[RECOVERED_KEY] = ','.join(rebuilt)
    report.topics = list(topics.by_name.values())
    write_metadata(bag_dir, bag_metadata(
        storage_identifier=storage, files=infos, topics=report.topics, custom_data=custom,
        ros_distro=str((old or {}).get('ros_distro') or 'jazzy')))
    return report
