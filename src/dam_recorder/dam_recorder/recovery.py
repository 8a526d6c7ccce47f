"""Making a bag whole again: after its recorder died without closing it (SIGKILL, power cut),
or after its files or its ``metadata.yaml`` were damaged.

What a killed recorder leaves: every MCAP chunk it wrote out before it died, possibly a
partial chunk after them, and no summary or footer, so index-based readers refuse the last
file; ``metadata.yaml`` as written when the file or the last topic was added (counts stale). A
sqlite3 file holds every transaction committed and possibly a hot journal. Other damage: bytes
changed inside a chunk (the file's summary still reads, the chunk does not), a file cut short,
a ``metadata.yaml`` cut, edited or no YAML at all.

:func:`recover_bag` trusts the data files over ``metadata.yaml``: an MCAP file carries its own
schemas (the type names and definitions) and channels (topics, offered QoS). Each MCAP file is
read record by record (:mod:`dam_recorder.mcap_salvage`), every chunk decompressed and checked;
a file that is whole, with its summary and every chunk readable, is left as it is; any other is
rewritten with what could be read (the same writer the recorder uses), a chunk that cannot be
read skipped whole. A sqlite3 file is opened once (which rolls a hot journal back) and checked
whole (``PRAGMA integrity_check``): recovery stops at a damaged one, naming it. Then
``metadata.yaml`` is written anew from what the files hold: files, counts, times, and each
topic's type and offered QoS from the files, its type hash computed from the stored definition
(else kept from the old metadata when its type is the files' type); the old ``custom_data`` is
kept and ``dam_recorder.recovered_files`` names the rebuilt files. The report names, per file
and for the metadata, what was lost or corrected and why.

An episode its recorder left open (``..._recording``, :mod:`dam_recorder.episode_recovery`) is
then judged from what the recovered bag holds: ``dam_episode.summary``, ``dam_episode.complete``
and ``dam_episode.missing`` are written into ``metadata.yaml`` (never complete: an item of kind
``killed`` says what a kill loses) and the directory is renamed
``<stem>_<outcome>_incomplete`` (:attr:`RecoveryReport.episode`, :attr:`RecoveryReport.path`).
"""

from __future__ import annotations

import os
import re
import sqlite3
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader
from rosbags.rosbag2.metadata import parse_qos
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from dam_common.words import counted
from dam_recorder.bag_writer import (
    STORAGE_SUFFIXES,
    add_connection,
    make_connection,
    open_storage,
)
from dam_recorder.episode_recovery import (
    EpisodeVerdict,
    is_open_episode,
    judge_open_episode,
    relabel,
)
from dam_recorder.errors import RecoveryError
from dam_recorder.mcap_salvage import MCAP_MAGIC, Salvage, salvage_mcap
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

RECOVERED_KEY = 'dam_recorder.recovered_files'


@dataclass
class FileReport:
    """What recovery found in one storage file.

    Attributes
    ----------
    path : str
        File name in the bag directory.
    rebuilt : bool
        Whether the file was rewritten (it lacked its summary, or part of it was unreadable).
    message_count : int
        Messages the file holds now.
    dropped_bytes : int
        Bytes at the end of the damaged file that could not be read [bytes]: a partly written
        chunk (its messages are lost) or message index (nothing is lost with it).
    problems : list of str
        What was lost in this file and why, one sentence each (empty when nothing was).
    """

    path: str
    rebuilt: bool
    message_count: int
    dropped_bytes: int = 0
    problems: list[str] = field(default_factory=list)


@dataclass
class RecoveryReport:
    """The result of :func:`recover_bag`: one :class:`FileReport` per file, the topics, and
    what was wrong with ``metadata.yaml`` (``metadata_problems``, one sentence each); for an
    episode left open, the verdict on it (``episode``) and the directory's new path
    (``path``; else ``bag_dir``)."""

    bag_dir: Path
    files: list[FileReport] = field(default_factory=list)
    topics: list[TopicInfo] = field(default_factory=list)
    metadata_problems: list[str] = field(default_factory=list)
    episode: EpisodeVerdict | None = None
    path: Path | None = None

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


def read_old_metadata(bag_dir: Path) -> tuple[dict[str, Any] | None, list[str]]:
    """The ``rosbag2_bagfile_information`` of ``bag_dir/metadata.yaml`` as far as it can be
    used, and what is wrong with it (one sentence each)."""
    path = bag_dir / METADATA_FILE
    try:
        text = path.read_text(encoding='utf-8')
    except FileNotFoundError:
        return None, [f'{METADATA_FILE} is missing']
    except (OSError, ValueError) as exc:
        return None, [f'{METADATA_FILE} cannot be read: {exc}']
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        where = getattr(exc, 'problem_mark', None)
        line = f' (line {where.line + 1})' if where is not None else ''
        return None, [f'{METADATA_FILE} is not valid YAML{line}: its content is ignored']
    info = data.get(TOP_KEY) if isinstance(data, dict) else None
    if not isinstance(info, dict):
        return None, [f'{METADATA_FILE} has no {TOP_KEY} mapping: its content is ignored']
    return info, []


_TYPE_NAME = re.compile(r'^[A-Za-z][A-Za-z0-9_]*/(msg|srv|action)/[A-Za-z][A-Za-z0-9_]*$')


def definition_hash(type_name: str, definition: str) -> str:
    """The RIHS01 hash of ``type_name`` computed from its stored ``ros2msg`` definition, or
    ``''`` when the definition does not describe it."""
    try:
        store = get_typestore(Stores.EMPTY)
        store.register(get_types_from_msg(definition, type_name))
        return store.hash_rihs01(type_name)
    except Exception:  # noqa: BLE001 - any failure: no hash from the definition
        return ''


class _Topics:
    """Topics collected over the files, by name; the old metadata fills in what the files do
    not say (a topic without messages, a hash), and is corrected where they disagree."""

    def __init__(self, old: dict[str, Any] | None, problems: list[str]) -> None:
        self.by_name: dict[str, TopicInfo] = {}
        self.old: dict[str, TopicInfo] = {}
        self.old_counts: dict[str, Any] = {}
        self.from_files: set[str] = set()
        self.problems = problems
        entries = (old or {}).get('topics_with_message_count')
        for entry in entries if isinstance(entries, list) else []:
            meta = entry.get('topic_metadata') if isinstance(entry, dict) else None
            if not isinstance(meta, dict) or not isinstance(meta.get('name'), str):
                problems.append(f'{METADATA_FILE}: a topic entry without a name: {entry!r}')
                continue
            try:
                qos = parse_qos(meta.get('offered_qos_profiles') or [])
            except Exception:  # noqa: BLE001 - malformed profiles: none
                qos = []
            info = TopicInfo(meta['name'], str(meta.get('type', '')),
                             str(meta.get('type_description_hash', '') or ''), qos)
            self.old[info.name] = info
            self.old_counts[info.name] = entry.get('message_count')

    def add(self, name: str, type_name: str, qos_text: str, count: int,
            definition: str = '', type_hash: str = '') -> TopicInfo:
        """Account for ``count`` messages of topic ``name`` as a data file describes it."""
        info = self.by_name.get(name)
        if info is None:
            old = self.old.get(name)
            try:
                qos = parse_qos(qos_text) if qos_text else []
            except Exception:  # noqa: BLE001 - malformed profiles in the file: the old ones
                qos = []
            if not qos and old is not None:
                qos = old.offered_qos
            if not type_hash and definition:
                type_hash = definition_hash(type_name, definition)
            if not type_hash and old is not None and old.type == type_name:
                type_hash = old.type_hash
            if old is None:
                self.problems.append(f'{METADATA_FILE}: topic {name} ({type_name}) was missing')
            elif old.type != type_name:
                self.problems.append(f'{METADATA_FILE}: topic {name} had type {old.type!r}, '
                                     f'the data files say {type_name!r}')
            info = TopicInfo(name, type_name, type_hash, qos)
            self.by_name[name] = info
            self.from_files.add(name)
        info.message_count += count
        return info

    def finish(self) -> list[TopicInfo]:
        """Every topic: those of the files, then those the old metadata alone names (a topic
        subscribed to whose messages never reached a file) when its type is a type name."""
        for name, old in self.old.items():
            if name in self.by_name:
                count = self.old_counts.get(name)
                if count != self.by_name[name].message_count:
                    self.problems.append(
                        f'{METADATA_FILE}: topic {name}: message count {count!r}, the data '
                        f'files hold {self.by_name[name].message_count}')
            elif _TYPE_NAME.match(old.type):
                self.by_name[name] = TopicInfo(name, old.type, old.type_hash, old.offered_qos)
            else:
                self.problems.append(
                    f'{METADATA_FILE}: topic {name} has no messages in the data files and a '
                    f'malformed type {old.type!r}: left out')
        return list(self.by_name.values())


def _lost_text(salvage: Salvage, lost: dict[int, int]) -> str:
    if not lost:
        return 'its messages are lost (their number is not in the file: its index is lost too)'
    parts = []
    for channel_id, count in sorted(lost.items()):
        channel = salvage.channels.get(channel_id)
        parts.append(f'{count} of {channel.topic if channel else f"channel {channel_id}"}')
    return f'{counted(sum(lost.values()), "message")} lost ({", ".join(parts)})'


def _file_problems(salvage: Salvage) -> list[str]:
    problems = [f'chunk at byte {chunk.offset} cannot be read ({chunk.reason}): '
                f'{_lost_text(salvage, chunk.lost)}' for chunk in salvage.lost_chunks]
    if salvage.cut_reason:
        problems.append(
            f'{salvage.cut_reason}: the last {salvage.size - salvage.read_to} bytes cannot be '
            'read (a chunk written in part loses its messages, their number is not in the '
            'file; a message index or summary loses nothing)')
    elif not salvage.summary_ok:
        problems.append('no summary (index, statistics): rebuilt from the records, nothing '
                        'lost')
    return problems


def _recover_mcap(path: Path, topics: _Topics) -> tuple[FileReport, FileInfo]:
    """Read every record ``path`` still holds; rewrite the file unless it is intact."""
    salvage = salvage_mcap(path)
    info = FileInfo(path.name)
    problems = _file_problems(salvage)
    channels: dict[int, tuple[TopicInfo, Any]] = {}
    for channel_id, channel in sorted(salvage.channels.items()):
        schema = salvage.schemas.get(channel.schema_id)
        if schema is None:
            problems.append(f'channel {channel.topic}: its schema (id {channel.schema_id}) is '
                            'lost: its messages cannot be decoded and are left out')
            continue
        topic = topics.add(channel.topic, schema.name,
                           channel.metadata.get('offered_qos_profiles', ''), 0,
                           definition=schema.data.decode('utf-8', 'replace'))
        channels[channel_id] = (topic, schema)
    counts: dict[str, int] = {}
    orphans = 0
    for message in salvage.messages:
        if message.channel_id not in channels:
            orphans += 1
            continue
        topic = channels[message.channel_id][0]
        counts[topic.name] = counts.get(topic.name, 0) + 1
        info.add(message.log_time)
    if orphans:
        problems.append(f'{counted(orphans, "message")} of channels whose record is lost are '
                        'left out')
    for topic, _ in channels.values():
        topic.message_count += counts.get(topic.name, 0)
    if salvage.intact and not problems:
        return FileReport(path.name, False, info.message_count), info
    _write_mcap(path, salvage, channels, counts, info)
    return FileReport(path.name, True, info.message_count,
                      max(0, salvage.size - salvage.read_to), problems), info


def _write_mcap(path: Path, salvage: Salvage, channels: dict[int, tuple[TopicInfo, Any]],
                counts: dict[str, int], info: FileInfo) -> None:
    """Write what was saved into a new file with a summary, and put it in place of ``path``."""
    tmp = path.with_name(path.name + '.recovering')
    tmp.unlink(missing_ok=True)
    writer = open_storage(tmp, 'mcap', 'zstd')
    connections: dict[int, Any] = {}
    types: set[str] = set()
    for channel_id, (topic, schema) in channels.items():
        connection = make_connection(len(connections) + 1, topic,
                                     schema.data.decode('utf-8', 'replace'))
        add_connection(writer, connection, topic.type not in types)
        types.add(topic.type)
        connections[channel_id] = connection
    for message in sorted((m for m in salvage.messages if m.channel_id in connections),
                          key=lambda m: m.log_time):
        writer.write(connections[message.channel_id], message.log_time, message.data)
    file_topics = [TopicInfo(t.name, t.type, t.type_hash, t.offered_qos, counts.get(t.name, 0))
                   for t, _ in channels.values()]
    own = bag_metadata(storage_identifier='mcap', files=[info], topics=file_topics)
    writer.close(METADATA_VERSION, dump_metadata(own[TOP_KEY]).strip())
    os.replace(tmp, path)


def _read_sqlite3(path: Path, topics: _Topics) -> tuple[FileReport, FileInfo]:
    info = FileInfo(path.name)
    try:
        conn = sqlite3.connect(path)  # read-write: rolls a hot journal back
        try:
            # Damage the queries below would not meet (a page of a table or an index they do
            # not read) would still stop every reader: the whole file is checked first.
            verdict = [row[0] for row in conn.execute('PRAGMA integrity_check(5)')]
            if verdict != ['ok']:
                raise RecoveryError(f'cannot read {path}: the SQLite integrity check fails: '
                                    f'{"; ".join(str(v) for v in verdict)}')
            columns = {row[1] for row in conn.execute('PRAGMA table_info(topics)')}
            hash_column = ('t.type_description_hash' if 'type_description_hash' in columns
                           else "''")
            rows = conn.execute(
                f'SELECT t.name, t.type, t.offered_qos_profiles, {hash_column}, COUNT(m.id), '
                'MIN(m.timestamp), MAX(m.timestamp) FROM topics t '
                'LEFT JOIN messages m ON m.topic_id = t.id GROUP BY t.id ORDER BY t.id'
            ).fetchall()
        finally:
            conn.close()
    except sqlite3.Error as exc:
        raise RecoveryError(f'cannot read {path}: {exc}') from None
    for name, type_name, qos_text, type_hash, count, first, last in rows:
        topics.add(name, type_name, qos_text or '', count, type_hash=type_hash or '')
        if count:
            info.add(first, 0)
            info.add(last, count)
    return FileReport(path.name, False, info.message_count), info


def recover_bag(bag_dir: str | os.PathLike[str]) -> RecoveryReport:
    """Make the bag in ``bag_dir`` readable by every reader again; return what was found.

    Run it only on a bag whose recorder has ended. A bag that is whole is left as it is
    (``metadata.yaml`` is rewritten with the same content). An episode left open is judged
    and renamed (see the module; :attr:`RecoveryReport.path` is where it is then). What was
    lost or corrected, and why, is in the report (:attr:`FileReport.problems`,
    :attr:`RecoveryReport.metadata_problems`).

    Raises
    ------
    RecoveryError
        If ``bag_dir`` holds no bag (see :func:`storage_files`) or a file cannot be read.
    """
    bag_dir = Path(bag_dir)
    storage, paths = storage_files(bag_dir)
    old, metadata_problems = read_old_metadata(bag_dir)
    topics = _Topics(old, metadata_problems)
    report = RecoveryReport(bag_dir, metadata_problems=metadata_problems)
    infos: list[FileInfo] = []
    for path in paths:
        if storage == 'sqlite3':
            file_report, info = _read_sqlite3(path, topics)
        else:
            try:
                file_report, info = _recover_mcap(path, topics)
            except OSError as exc:
                raise RecoveryError(f'cannot read or rewrite {path}: {exc}') from None
        report.files.append(file_report)
        infos.append(info)
    custom_data = (old or {}).get('custom_data')
    if custom_data is not None and not isinstance(custom_data, dict):
        metadata_problems.append(f'{METADATA_FILE}: custom_data is not a mapping: dropped')
        custom_data = {}
    custom = {str(k): str(v) for k, v in (custom_data or {}).items()}
    rebuilt = [f.path for f in report.files if f.rebuilt]
    if rebuilt:
        custom[RECOVERED_KEY] = ','.join(rebuilt)
    report.topics = topics.finish()
    distro = (old or {}).get('ros_distro')

    def write() -> None:
        write_metadata(bag_dir, bag_metadata(
            storage_identifier=storage, files=infos, topics=report.topics, custom_data=custom,
            ros_distro=distro if isinstance(distro, str) and distro else 'jazzy'))
    write()
    report.path = bag_dir
    if is_open_episode(bag_dir, custom):
        report.episode = judge_open_episode(
            bag_dir, custom, ((t.name, _latched(t.offered_qos)) for t in report.topics))
        custom.update(report.episode.custom_data)
        write()
        report.path = relabel(bag_dir, report.episode)
    return report


def _latched(profiles: list[Any]) -> bool:
    """Whether every publisher offered transient local durability (``rosbags`` QoS
    profiles): the recorder then records the topic as latched."""
    return bool(profiles) and all(
        getattr(getattr(q, 'durability', None), 'name', '') == 'TRANSIENT_LOCAL'
        for q in profiles)
