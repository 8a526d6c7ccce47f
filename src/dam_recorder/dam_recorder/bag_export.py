"""``bag export``: a bag's signals as CSV files, one per topic (no rclpy).

Each file has a header row and one row per message, in receive order:

- ``time_s``: receive time [s since the bag's first message];
- ``time_ns``: receive time [ns since the epoch];
- then every field of the message, flattened: nested messages with dotted names
  (``header.stamp.sec``), arrays one column per element (``status.0.name``,
  ``compliant_torque.1``). In a message with a string array ``name`` (``JointState``,
  ``HandCommand``) or ``finger_names`` (``DamStatus``), the arrays as long as it are named by
  its entries instead (``position.finger1_compliant_joint``) and it has no columns of its own.
  A ``unique_identifier_msgs/UUID`` is one column of 32 hex digits (``goal_id.uuid``).

Values: integers as they are, floats in the shortest text that reads back to the same float
(``nan``, ``inf``, ``-inf`` for non-finite ones), booleans ``true``/``false``, strings as they
are (the ``csv`` module quotes them where needed). A column a message lacks (another joint set,
a shorter array) is left empty in its row. Files are named after the topic with ``/`` as
``-`` and no leading one (``/sim/object_pose`` -> ``sim-object_pose.csv``) and are written
over when they exist.
"""

from __future__ import annotations

import csv
import dataclasses
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dam_recorder.bag_reading import BagReader, check_topics, read_bag_metadata
from dam_recorder.bag_selection import Selection
from dam_recorder.errors import ExportError

TIME_COLUMNS: tuple[str, str] = ('time_s', 'time_ns')
#: String-array fields whose entries name the elements of equally long arrays beside them.
NAME_FIELDS: tuple[str, ...] = ('name', 'finger_names')
UUID_TYPE = 'unique_identifier_msgs/msg/UUID'


@dataclass(frozen=True)
class ExportedTopic:
    """One CSV file written.

    Attributes
    ----------
    topic : str
        The topic.
    path : Path
        The file.
    rows : int
        Messages written (rows below the header).
    columns : list of str
        The header.
    """

    topic: str
    path: Path
    rows: int
    columns: list[str]


def csv_name(topic: str) -> str:
    """File name of ``topic``'s CSV file (``/dam/status`` -> ``dam-status.csv``)."""
    return topic.strip('/').replace('/', '-') + '.csv'


def format_value(value: Any) -> str:
    """One scalar as CSV text (see the module)."""
    if isinstance(value, (bool, np.bool_)):
        return 'true' if value else 'false'
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return repr(float(value))
    if isinstance(value, bytes):
        return value.hex()
    return str(value)


def _is_message(value: Any) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def _sequence(value: Any) -> Sequence[Any] | None:
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (list, tuple)):
        return value
    return None


def _element_names(message: Any) -> tuple[str | None, list[str] | None]:
    """The field naming the elements of ``message``'s arrays, and its entries."""
    for name in NAME_FIELDS:
        entries = getattr(message, name, None)
        if isinstance(entries, list) and entries and all(isinstance(e, str) for e in entries) \
                and len(set(entries)) == len(entries):
            return name, entries
    return None, None


def message_fields(message: Any) -> tuple[str, ...]:
    """The fields of a ``rosbags`` message by its dataclass (``__msgtype__`` and constants,
    upper-case names, left out); :meth:`BagReader.field_names` asks the type store instead."""
    return tuple(f.name for f in dataclasses.fields(message)
                 if not f.name.startswith('_') and not f.name.isupper())


def flatten(message: Any, prefix: str = '', out: dict[str, str] | None = None,
            fields_of: Callable[[str], Sequence[str]] | None = None) -> dict[str, str]:
    """The fields of a deserialized message as ``{column: text}`` (see the module).

    Parameters
    ----------
    message : rosbags message
        The message.
    prefix : str
        Put before every column name (``'header.'`` for a nested message).
    out : dict, optional
        Filled and returned (a new one by default).
    fields_of : callable, optional
        Type name -> its field names; default :func:`message_fields`.
    """
    out = {} if out is None else out
    if getattr(message, '__msgtype__', None) == UUID_TYPE:
        out[prefix + 'uuid'] = bytes(np.asarray(message.uuid, dtype=np.uint8)).hex()
        return out
    key_field, keys = _element_names(message)
    keyed = False
    msgtype = getattr(message, '__msgtype__', None)
    fields = fields_of(msgtype) if fields_of and msgtype else message_fields(message)
    for name in fields:
        if name == key_field:
            continue
        value = getattr(message, name)
        column = prefix + name
        items = _sequence(value)
        if items is None:
            if _is_message(value):
                flatten(value, column + '.', out, fields_of)
            else:
                out[column] = format_value(value)
            continue
        named = keys is not None and len(items) == len(keys) and not any(
            _is_message(v) for v in items)
        keyed = keyed or named
        for i, item in enumerate(items):
            element = f'{column}.{keys[i] if named and keys else i}'
            if _is_message(item):
                flatten(item, element + '.', out, fields_of)
            else:
                out[element] = format_value(item)
    if key_field is not None and not keyed and keys is not None:
        for i, entry in enumerate(keys):
            out[f'{prefix}{key_field}.{i}'] = entry
    return out


def seconds_text(duration_ns: int) -> str:
    """A duration [ns] as seconds with nine decimals, exactly (``1500000`` -> ``0.001500000``)."""
    sign = '-' if duration_ns < 0 else ''
    whole, part = divmod(abs(int(duration_ns)), 1_000_000_000)
    return f'{sign}{whole}.{part:09d}'


def default_output(bag_dir: str | os.PathLike[str]) -> Path:
    """``<bag name>_csv`` in the current directory."""
    return Path(f'{Path(bag_dir).resolve().name}_csv')


def export_bag(bag_dir: str | os.PathLike[str], out_dir: str | os.PathLike[str] | None = None,
               topics: Sequence[str] | None = None,
               selection: Selection | None = None) -> list[ExportedTopic]:
    """Write the CSV file of each topic of ``bag_dir`` (or of ``topics``) into ``out_dir``.

    Parameters
    ----------
    bag_dir : path
        The bag directory.
    out_dir : path, optional
        Where the files go (created with its parents); default :func:`default_output`.
    topics : sequence of str, optional
        Topic names to export; default every topic of the bag.
    selection : Selection, optional
        Only the messages received within it (one grasp or a time window,
        :mod:`dam_recorder.bag_selection`); default the whole bag. ``time_s`` still counts
        from the bag's first message.

    Returns
    -------
    list of ExportedTopic
        One per file, in topic order.

    Raises
    ------
    BagReadError
        If the bag cannot be read or lacks a requested topic (naming it).
    ExportError
        If the output directory or a file cannot be written.
    """
    meta = read_bag_metadata(bag_dir)
    target = Path(out_dir) if out_dir is not None else default_output(meta.path)
    with BagReader(meta.path) as bag:
        available = dict(bag.topics)
        for name, type_name in meta.topics.items():
            available.setdefault(name, type_name)
        chosen = sorted(available) if not topics else list(dict.fromkeys(topics))
        check_topics(chosen, available, meta.path)
        times = bag.receive_times()
        firsts = [int(v[0]) for v in times.values() if v.size]
        start_ns = min(firsts) if firsts else meta.start_ns
        # First pass: the columns, which depend on the joints and array lengths each message
        # has; second pass: the rows.
        columns: dict[str, dict[str, None]] = {t: {} for t in chosen}
        for item in bag.messages([t for t in chosen if t in bag.topics]):
            if selection is not None and not selection.contains(item.time_ns):
                continue
            columns[item.topic].update(dict.fromkeys(
                flatten(item.message, fields_of=bag.field_names)))
        try:
            target.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise ExportError(f'{target}: cannot create the output directory: '
                              f'{exc.strerror or exc}') from None
        files: dict[str, Any] = {}
        writers: dict[str, Any] = {}
        counts = dict.fromkeys(chosen, 0)
        try:
            for topic in chosen:
                path = target / csv_name(topic)
                try:
                    files[topic] = open(path, 'w', encoding='utf-8', newline='')  # noqa: SIM115
                except OSError as exc:
                    raise ExportError(f'{path}: cannot write: {exc.strerror or exc}') from None
                writers[topic] = csv.writer(files[topic])
                writers[topic].writerow([*TIME_COLUMNS, *columns[topic]])
            for item in bag.messages([t for t in chosen if t in bag.topics]):
                if selection is not None and not selection.contains(item.time_ns):
                    continue
                values = flatten(item.message, fields_of=bag.field_names)
                writers[item.topic].writerow(
                    [seconds_text(item.time_ns - start_ns), str(item.time_ns),
                     *(values.get(c, '') for c in columns[item.topic])])
                counts[item.topic] += 1
        finally:
            for stream in files.values():
                stream.close()
    return [ExportedTopic(t, target / csv_name(t), counts[t], [*TIME_COLUMNS, *columns[t]])
            for t in chosen]
