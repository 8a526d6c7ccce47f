"""``metadata.yaml`` of a rosbag2 bag, in the format version ROS 2 Jazzy writes (9).

Jazzy's rosbag2 (0.26) writes and requires, under ``rosbag2_bagfile_information``:
``version``, ``storage_identifier`` (``mcap`` or ``sqlite3``), ``duration.nanoseconds``,
``starting_time.nanoseconds_since_epoch``, ``message_count``, ``topics_with_message_count``
(each a ``topic_metadata`` with ``name``, ``type``, ``serialization_format``,
``offered_qos_profiles`` and ``type_description_hash``, and a ``message_count``),
``compression_format``, ``compression_mode``, ``relative_file_paths``, ``files`` (each with
``path``, ``starting_time``, ``duration`` and ``message_count``), ``custom_data`` (string to
string) and ``ros_distro``. From version 9 on, ``offered_qos_profiles`` is a YAML list of
profiles (before: one string holding YAML), see :mod:`dam_recorder.qos`.

The recorder keeps its own figures in ``custom_data`` under keys starting with
``dam_recorder.`` (values are strings, as the format requires).
"""

from __future__ import annotations

import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml
from rosbags.interfaces import Qos

from dam_recorder.qos import metadata_profiles

#: The rosbag2 metadata format version of ROS 2 Jazzy.
METADATA_VERSION = 9
METADATA_FILE = 'metadata.yaml'
TOP_KEY = 'rosbag2_bagfile_information'


@dataclass
class FileInfo:
    """One storage file of a bag.

    Attributes
    ----------
    path : str
        File name, relative to the bag directory.
    start_ns, end_ns : int
        Time stamps of the first and the last message [ns since the epoch]; meaningless while
        ``message_count`` is 0.
    message_count : int
        Messages in the file.
    """

    path: str
    start_ns: int = 0
    end_ns: int = 0
    message_count: int = 0

    def add(self, timestamp_ns: int, count: int = 1) -> None:
        """Account for ``count`` messages at ``timestamp_ns`` [ns]."""
        if self.message_count == 0:
            self.start_ns = self.end_ns = timestamp_ns
        else:
            self.start_ns = min(self.start_ns, timestamp_ns)
            self.end_ns = max(self.end_ns, timestamp_ns)
        self.message_count += count


@dataclass
class TopicInfo:
    """One topic of a bag.

    Attributes
    ----------
    name, type : str
        Topic name and full type name (``sensor_msgs/msg/JointState``).
    type_hash : str
        RIHS01 type hash (``''`` where unknown).
    offered_qos : list of rosbags Qos
        The profiles the topic's publishers offered.
    message_count : int
        Messages recorded on the topic (all files).
    serialization_format : str
        ``cdr``.
    """

    name: str
    type: str
    type_hash: str = ''
    offered_qos: list[Qos] = field(default_factory=list)
    message_count: int = 0
    serialization_format: str = 'cdr'


def _duration(ns: int) -> dict[str, int]:
    return {'nanoseconds': int(ns)}


def _start(ns: int) -> dict[str, int]:
    return {'nanoseconds_since_epoch': int(ns)}


def bag_metadata(*, storage_identifier: str, files: Sequence[FileInfo],
                 topics: Sequence[TopicInfo], compression_format: str = '',
                 compression_mode: str = '', custom_data: Mapping[str, str] | None = None,
                 ros_distro: str = 'jazzy') -> dict[str, Any]:
    """The content of ``metadata.yaml`` (version 9) for a bag of ``files`` and ``topics``.

    The bag's start is the earliest first message of any file and its duration reaches the
    latest last message [ns]; both are 0 for a bag without messages.
    """
    filled = [f for f in files if f.message_count]
    start = min((f.start_ns for f in filled), default=0)
    end = max((f.end_ns for f in filled), default=0)
    info = {
        'version': METADATA_VERSION,
        'storage_identifier': storage_identifier,
        'duration': _duration(end - start),
        'starting_time': _start(start),
        'message_count': sum(f.message_count for f in files),
        'topics_with_message_count': [
            {
                'topic_metadata': {
                    'name': t.name,
                    'type': t.type,
                    'serialization_format': t.serialization_format,
                    'offered_qos_profiles': metadata_profiles(t.offered_qos),
                    'type_description_hash': t.type_hash,
                },
                'message_count': t.message_count,
            }
            for t in topics
        ],
        'compression_format': compression_format,
        'compression_mode': compression_mode,
        'relative_file_paths': [f.path for f in files],
        'files': [
            {
                'path': f.path,
                'starting_time': _start(f.start_ns if f.message_count else 0),
                'duration': _duration(f.end_ns - f.start_ns if f.message_count else 0),
                'message_count': f.message_count,
            }
            for f in files
        ],
        'custom_data': {str(k): str(v) for k, v in (custom_data or {}).items()},
        'ros_distro': ros_distro,
    }
    return {TOP_KEY: info}


def dump_metadata(metadata: Mapping[str, Any]) -> str:
    """``metadata`` as YAML text (keys in the order rosbag2 writes them)."""
    return yaml.safe_dump(dict(metadata), sort_keys=False, default_flow_style=False)


def write_metadata(bag_dir: str | os.PathLike[str], metadata: Mapping[str, Any]) -> Path:
    """Write ``metadata`` to ``bag_dir/metadata.yaml`` atomically (a reader sees the old file
    or the new one, never half of one); return the path."""
    path = Path(bag_dir) / METADATA_FILE
    tmp = path.with_name(METADATA_FILE + '.tmp')
    with open(tmp, 'w', encoding='utf-8') as out:
        out.write(dump_metadata(metadata))
        out.flush()
        os.fsync(out.fileno())
    os.replace(tmp, path)
    return path


def read_metadata(bag_dir: str | os.PathLike[str]) -> dict[str, Any] | None:
    """The ``rosbag2_bagfile_information`` of ``bag_dir/metadata.yaml``, or ``None`` when the
    file is missing or unreadable."""
    try:
        text = (Path(bag_dir) / METADATA_FILE).read_text(encoding='utf-8')
        data = yaml.safe_load(text)
    except (OSError, yaml.YAMLError):
        return None
    info = data.get(TOP_KEY) if isinstance(data, dict) else None
    return info if isinstance(info, dict) else None
