"""Reading rosbag2 bags for the bag tools (no rclpy): where the bags are, their metadata, and
their messages, read with ``rosbags``' rosbag2 reader and decoded with a type store built from
the definitions stored in the bag (:func:`typestore_of`, as ``rosbags.highlevel.AnyReader``
builds its own, but tolerant of a stored type hash that differs from the computed one).

A path given to the tools is either one bag directory (it holds ``metadata.yaml``) or a
directory of episode bags (it holds no ``metadata.yaml`` but bag directories).
:func:`locate` tells the two apart. The message types are taken from the definitions stored
in the bag (every bag the recorder writes has them, the DAM interfaces included), so no ROS
installation is needed to read one; Jazzy's standard types stand in for a bag without them.

Every problem (no bag, a malformed ``metadata.yaml``, a storage file or a message that cannot
be read) is raised as :class:`~dam_recorder.errors.BagReadError` with a one-line message that
names the path.
"""

from __future__ import annotations

import json
import os
from collections.abc import Collection, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from dam_common.progress import current as current_progress
from dam_recorder.backlog import BACKLOG_KEY
from dam_recorder.completeness import Completeness, completeness_from_custom_data
from dam_recorder.episode import Episode, episode_from_custom_data
from dam_recorder.errors import BagReadError, EpisodeError
from dam_recorder.metadata import METADATA_FILE, TOP_KEY

#: ``custom_data`` keys holding per-topic message counts (JSON ``{topic: count}``).
LOST_KEY = 'dam_recorder.lost_messages'
PAUSED_KEY = 'dam_recorder.paused_messages'
TRIMMED_KEY = 'dam_recorder.trimmed_messages'
DROPPED_KEY = 'dam_recorder.dropped_messages'
#: ... dropped by the recorder from its full backlog, not written when its stop time ran out.
SHED_KEY = 'dam_recorder.backlog_dropped_messages'
STOP_UNWRITTEN_KEY = 'dam_recorder.stop_unwritten_messages'
#: JSON ``{topic: reason}``: topics selected for the recording that it does not hold.
NOT_RECORDED_KEY = 'dam_recorder.not_recorded_topics'


def one_line(text: str) -> str:
    """``text`` with every run of white space (new lines included) made one space."""
    return ' '.join(str(text).split())


@dataclass(frozen=True)
class BagMetadata:
    """What ``metadata.yaml`` says about a bag.

    Attributes
    ----------
    path : Path
        The bag directory.
    storage : str
        Storage identifier (``mcap``, ``sqlite3``).
    start_ns : int
        Receive time of the first message [ns since the epoch] (0 without messages).
    duration_ns : int
        From the first to the last message [ns].
    message_count : int
        Messages in the bag.
    topics : dict
        Topic name -> type name, in the order of ``metadata.yaml``.
    topic_counts : dict
        Topic name -> message count as ``metadata.yaml`` states it.
    files : list of str
        Storage files, relative to the bag directory.
    custom_data : dict
        ``custom_data`` (string -> string).
    """

    path: Path
    storage: str
    start_ns: int
    duration_ns: int
    message_count: int
    topics: dict[str, str]
    topic_counts: dict[str, int]
    files: list[str]
    custom_data: dict[str, str] = field(default_factory=dict)

    def counts(self, key: str) -> dict[str, int]:
        """A per-topic count stored as JSON in ``custom_data[key]`` (empty when absent).

        Raises
        ------
        BagReadError
            If the value is not a JSON object of non-negative integers.
        """
        return topic_counts(self.custom_data, key, self.path)

    def episode(self) -> Episode | None:
        """The episode metadata (:mod:`dam_recorder.episode`), ``None`` when there is none.

        Raises
        ------
        BagReadError
            If it is malformed (the message names the bag, the key and the value).
        """
        try:
            return episode_from_custom_data(self.custom_data)
        except EpisodeError as exc:
            raise BagReadError(f'{self.path}: {exc}') from None

    def completeness(self) -> Completeness | None:
        """Whether the episode bag holds its whole episode (:mod:`dam_recorder.completeness`),
        ``None`` when the metadata does not say.

        Raises
        ------
        BagReadError
            If it is malformed (the message names the bag, the key and the value).
        """
        try:
            return completeness_from_custom_data(self.custom_data)
        except EpisodeError as exc:
            raise BagReadError(f'{self.path}: {exc}') from None

    def backlog(self) -> dict[str, float] | None:
        """The recorder's backlog (``dam_recorder.backlog``: ``max_s``, ``mean_s``,
        ``messages``), ``None`` when absent or not such a JSON object."""
        try:
            data = json.loads(self.custom_data[BACKLOG_KEY])
        except (KeyError, TypeError, ValueError):
            return None
        if not isinstance(data, dict) or not all(
                isinstance(data.get(k), (int, float)) for k in ('max_s', 'mean_s', 'messages')):
            return None
        return {k: data[k] for k in ('max_s', 'mean_s', 'messages')}


@dataclass(frozen=True)
class BagMessage:
    """One deserialized message.

    Attributes
    ----------
    topic, type : str
        Topic and type name.
    time_ns : int
        Receive time [ns since the epoch].
    message : object
        The message as ``rosbags`` deserializes it (a dataclass; numeric arrays as numpy).
    """

    topic: str
    type: str
    time_ns: int
    message: Any


def topic_counts(custom_data: Mapping[str, str], key: str, path: Path) -> dict[str, int]:
    """Parse the JSON ``{topic: count}`` text stored in ``custom_data[key]`` (see
    :class:`BagMetadata.counts`)."""
    text = custom_data.get(key)
    if text is None:
        return {}
    try:
        data = json.loads(text)
    except (TypeError, ValueError):
        data = None
    if not isinstance(data, dict) or not all(
            isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in data.values()):
        raise BagReadError(f'{path}: custom_data {key}: expected JSON {{topic: count}}, got '
                           f'{one_line(repr(text))[:80]}')
    return {str(k): int(v) for k, v in data.items()}


def is_bag_dir(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is a directory holding ``metadata.yaml``."""
    return (Path(path) / METADATA_FILE).is_file()


def episode_bags(directory: str | os.PathLike[str]) -> list[Path]:
    """The bag directories directly inside ``directory``, sorted by name (episode bags are
    named by their start time, so this is their order in time)."""
    root = Path(directory)
    return sorted((p for p in root.iterdir() if p.is_dir() and is_bag_dir(p)),
                  key=lambda p: p.name)


def locate(path: str | os.PathLike[str]) -> tuple[str, list[Path]]:
    """Tell what ``path`` holds: ``('bag', [path])`` for a bag directory, ``('episodes',
    [bag, ...])`` for a directory of bag directories.

    Raises
    ------
    BagReadError
        If ``path`` does not exist, is not a directory, or holds neither.
    """
    root = Path(path)
    if not root.exists():
        raise BagReadError(f'{root}: no such file or directory')
    if not root.is_dir():
        raise BagReadError(f'{root}: not a bag (a bag is a directory with {METADATA_FILE})')
    if is_bag_dir(root):
        return 'bag', [root]
    try:
        bags = episode_bags(root)
    except OSError as exc:
        raise BagReadError(f'{root}: cannot list the directory: {exc.strerror}') from None
    if not bags:
        raise BagReadError(f'{root}: not a bag: no {METADATA_FILE} in it, and no bag '
                           'directories either')
    return 'episodes', bags


def _int_at(info: Mapping[str, Any], keys: tuple[str, ...], where: Path) -> int:
    value: Any = info
    for key in keys:
        if not isinstance(value, dict) or key not in value:
            raise BagReadError(f'{where}: missing key {".".join(keys)}')
        value = value[key]
    if isinstance(value, bool) or not isinstance(value, int):
        raise BagReadError(f'{where}: {".".join(keys)}: expected an integer, got {value!r}')
    return value


def read_bag_metadata(bag_dir: str | os.PathLike[str]) -> BagMetadata:
    """Read and check ``bag_dir/metadata.yaml``.

    Raises
    ------
    BagReadError
        If the file is missing, is not YAML, or lacks what a rosbag2 bag has (the message
        names the file and the key).
    """
    bag = Path(bag_dir)
    path = bag / METADATA_FILE
    if not bag.is_dir():
        raise BagReadError(f'{bag}: no such bag directory')
    try:
        text = path.read_text(encoding='utf-8')
    except FileNotFoundError:
        raise BagReadError(f'{bag}: not a bag: no {METADATA_FILE}') from None
    except (OSError, UnicodeDecodeError) as exc:
        raise BagReadError(f'{path}: cannot read: {one_line(str(exc))}') from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, 'problem_mark', None)
        where = f' (line {mark.line + 1})' if mark is not None else ''
        problem = getattr(exc, 'problem', None) or 'malformed'
        raise BagReadError(f'{path}: not valid YAML{where}: {one_line(problem)}') from None
    info = data.get(TOP_KEY) if isinstance(data, dict) else None
    if not isinstance(info, dict):
        raise BagReadError(f'{path}: no {TOP_KEY} mapping; not a rosbag2 metadata file')
    storage = info.get('storage_identifier')
    if not isinstance(storage, str) or not storage:
        raise BagReadError(f'{path}: storage_identifier: expected a name, got {storage!r}')
    topics: dict[str, str] = {}
    counts: dict[str, int] = {}
    entries = info.get('topics_with_message_count')
    if not isinstance(entries, list):
        raise BagReadError(f'{path}: topics_with_message_count: expected a list, got '
                           f'{one_line(repr(entries))[:80]}')
    for i, entry in enumerate(entries):
        meta = entry.get('topic_metadata') if isinstance(entry, dict) else None
        name = meta.get('name') if isinstance(meta, dict) else None
        type_name = meta.get('type') if isinstance(meta, dict) else None
        if not isinstance(name, str) or not isinstance(type_name, str):
            raise BagReadError(f'{path}: topics_with_message_count[{i}]: expected a '
                               'topic_metadata with name and type')
        topics[name] = type_name
        counts[name] = entry.get('message_count', 0) if isinstance(
            entry.get('message_count', 0), int) else 0
    files = info.get('relative_file_paths')
    if not isinstance(files, list) or not all(isinstance(f, str) for f in files):
        raise BagReadError(f'{path}: relative_file_paths: expected a list of file names, got '
                           f'{one_line(repr(files))[:80]}')
    custom = info.get('custom_data') or {}
    if not isinstance(custom, dict):
        raise BagReadError(f'{path}: custom_data: expected a mapping, got '
                           f'{one_line(repr(custom))[:80]}')
    return BagMetadata(
        path=bag, storage=storage,
        start_ns=_int_at(info, ('starting_time', 'nanoseconds_since_epoch'), path),
        duration_ns=_int_at(info, ('duration', 'nanoseconds'), path),
        message_count=_int_at(info, ('message_count',), path),
        topics=topics, topic_counts=counts, files=list(files),
        custom_data={str(k): str(v) if v is not None else '' for k, v in custom.items()})


def typestore_of(connections: Sequence[Any]) -> Any:
    """A ``rosbags`` type store of the types the bag's connections define (``ros2msg`` or
    ``ros2idl`` definitions stored in the bag), plus Jazzy's standard types for connections
    stored without one (or with an empty one).

    Unlike ``rosbags``' ``AnyReader``, which builds its store the same way, this does not
    refuse a type whose stored hash differs from the one computed from its definition: bags
    of other writers (and of this recorder before it spelt action-derived nested types in
    full) name such nested types ``pkg/Name_Feedback``, which the parser places in
    ``pkg/msg``; the layout, all that decoding needs, is right all the same.
    """
    from rosbags.interfaces import MessageDefinitionFormat
    from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

    types: dict[str, Any] = {}
    undefined = False
    for connection in connections:
        definition = connection.msgdef
        if not definition.data.strip():
            undefined = True
        elif definition.format == MessageDefinitionFormat.MSG:
            types.update(get_types_from_msg(definition.data, connection.msgtype))
        elif definition.format == MessageDefinitionFormat.IDL:
            sep = '=' * 80 + '\n'
            parts = definition.data.split(sep)[1:] if definition.data.startswith(
                sep + 'IDL: ') else [definition.data]
            for part in parts:
                types.update(get_types_from_idl(part.split('\n', 1)[1]
                                                if part.startswith('IDL: ') else part))
        else:
            undefined = True  # stored without a definition
    store = get_typestore(Stores.EMPTY)
    store.register(types)
    if undefined:
        standard = get_typestore(Stores.ROS2_JAZZY).fielddefs
        store.register({k: v for k, v in standard.items() if k not in store.fielddefs})
    return store


class BagReader:
    """A bag opened for reading its messages, with the types its definitions describe.

    Use as a context manager::

        with BagReader(bag_dir) as bag:
            for message in bag.messages(['/joint_states']):
                ...

    Parameters
    ----------
    bag_dir : path
        The bag directory.

    Raises
    ------
    BagReadError
        If the bag cannot be opened (the message names the path and the cause).
    """

    def __init__(self, bag_dir: str | os.PathLike[str]) -> None:
        self.path = Path(bag_dir)
        self.metadata = read_bag_metadata(self.path)
        self._reader: Any = None
        self._store: Any = None
        self._field_names: dict[str, tuple[str, ...]] = {}

    def __enter__(self) -> BagReader:
        from rosbags.rosbag2 import Reader

        try:
            reader = Reader(self.path)
            reader.open()
        except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds; all mean unreadable
            text = one_line(str(exc)) or type(exc).__name__
            if 'magic' in text.lower() or 'footer' in text.lower() or 'summary' in text.lower():
                text += ('; a file without its end (a recorder killed while writing?): '
                         '`recover` rebuilds it')
            raise BagReadError(f'{self.path}: cannot open the bag: {text}') from None
        self._reader = reader
        try:
            self._store = typestore_of(reader.connections)
        except Exception as exc:  # noqa: BLE001 - a definition the parser refuses
            self.__exit__()
            raise BagReadError(f'{self.path}: cannot read the message definitions: '
                               f'{one_line(str(exc)) or type(exc).__name__}') from None
        return self

    def __exit__(self, *_exc: object) -> None:
        reader, self._reader = self._reader, None
        if reader is not None:
            try:
                reader.close()
            except Exception:  # noqa: BLE001 - closing a broken file must not hide the cause
                pass

    @property
    def topics(self) -> dict[str, str]:
        """Topic -> type name, for every topic of the bag."""
        return {c.topic: c.msgtype for c in self._reader.connections}

    def field_names(self, msgtype: str) -> tuple[str, ...]:
        """The fields of ``msgtype`` in order (its constants, which ``rosbags`` also keeps as
        attributes of a message, left out)."""
        names = self._field_names.get(msgtype)
        if names is None:
            names = tuple(name for name, _kind in self._store.fielddefs[msgtype][1])
            self._field_names[msgtype] = names
        return names

    def _connections(self, topics: Collection[str] | None) -> list[Any]:
        connections = self._reader.connections
        if topics is None:
            return list(connections)
        return [c for c in connections if c.topic in set(topics)]

    def raw_messages(self, topics: Collection[str] | None = None
                     ) -> Iterator[tuple[str, int, bytes]]:
        """(topic, receive time [ns], serialized message) in time order, not deserialized."""
        connections = self._connections(topics)
        if not connections:
            return
        # a command's progress line (dam_common.progress) counts the messages read
        progress = current_progress()
        if progress is not None:
            progress.stage(f'reading messages of {self.path.name}',
                           total=sum(int(getattr(c, 'msgcount', 0) or 0) for c in connections))
        try:
            for connection, time_ns, data in self._reader.messages(connections=connections):
                if progress is not None:
                    progress.done += 1
                yield connection.topic, int(time_ns), data
            if progress is not None:
                progress.end_stage(f'read {progress.done:,} messages')
        except Exception as exc:  # noqa: BLE001 - a damaged file is raised as the reader's error
            raise BagReadError(f'{self.path}: cannot read the messages: '
                               f'{one_line(str(exc)) or type(exc).__name__}') from None

    def messages(self, topics: Collection[str] | None = None) -> Iterator[BagMessage]:
        """Deserialized messages of ``topics`` (default: all) in time order."""
        types = self.topics
        for topic, time_ns, data in self.raw_messages(topics):
            try:
                message = self._store.deserialize_cdr(data, types[topic])
            except Exception as exc:  # noqa: BLE001 - the reader raises several kinds
                raise BagReadError(
                    f'{self.path}: cannot decode the message of {topic} at {time_ns} ns: '
                    f'{one_line(str(exc)) or type(exc).__name__}') from None
            yield BagMessage(topic, types[topic], time_ns, message)

    def receive_times(self, topics: Collection[str] | None = None) -> dict[str, np.ndarray]:
        """Receive times [ns since the epoch, int64] of every message per topic, in time
        order; topics without messages map to empty arrays."""
        times: dict[str, list[int]] = {t: [] for t in self.topics
                                        if topics is None or t in topics}
        for topic, time_ns, _data in self.raw_messages(topics):
            times[topic].append(time_ns)
        return {t: np.asarray(v, dtype=np.int64) for t, v in times.items()}


def check_topics(requested: Collection[str], available: Collection[str], path: Path) -> None:
    """Raise :class:`BagReadError` naming every topic of ``requested`` the bag lacks."""
    missing = [t for t in requested if t not in available]
    if missing:
        raise BagReadError(f'{path}: no topic {", ".join(missing)} in the bag (it has: '
                           f'{", ".join(sorted(available)) or "no topics"})')
