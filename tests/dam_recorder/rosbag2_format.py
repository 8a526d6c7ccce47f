"""What ROS 2 Jazzy's rosbag2 (0.26) requires of ``metadata.yaml`` version 9, written down from
its YAML decoder (``rosbag2_storage/yaml.hpp`` and ``qos.cpp``), independently of the recorder:
every key it reads with ``node[key].as<T>()`` must be there with a value of that type, else
``ros2 bag info`` and ``ros2 bag play`` stop with "bad conversion".
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import yaml

HISTORY = {'keep_last', 'keep_all', 'system_default', 'unknown'}
RELIABILITY = {'reliable', 'best_effort', 'system_default', 'best_available', 'unknown'}
DURABILITY = {'volatile', 'transient_local', 'system_default', 'best_available', 'unknown'}
LIVELINESS = {'automatic', 'manual_by_topic', 'system_default', 'best_available', 'unknown'}


def _unsigned(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value >= 0


def _time(value: Any) -> bool:
    return isinstance(value, dict) and _unsigned(value.get('sec')) \
        and _unsigned(value.get('nsec'))


def _problems_of_qos(where: str, qos: Any) -> list[str]:
    if not isinstance(qos, dict):
        return [f'{where}: not a mapping']
    problems = []
    history = qos.get('history')
    if not (isinstance(history, int) or history in HISTORY):
        problems.append(f'{where}.history: {history!r}')
    if not _unsigned(qos.get('depth')):
        problems.append(f'{where}.depth: {qos.get("depth")!r}')
    for key, allowed in (('reliability', RELIABILITY), ('durability', DURABILITY),
                         ('liveliness', LIVELINESS)):
        if qos.get(key) not in allowed:
            problems.append(f'{where}.{key}: {qos.get(key)!r}')
    for key in ('deadline', 'lifespan', 'liveliness_lease_duration'):
        if not _time(qos.get(key)):
            problems.append(f'{where}.{key}: {qos.get(key)!r}')
    if not isinstance(qos.get('avoid_ros_namespace_conventions'), bool):
        problems.append(f'{where}.avoid_ros_namespace_conventions')
    return problems


def metadata_problems(bag_dir: str | Path) -> list[str]:
    """Everything in ``bag_dir/metadata.yaml`` that rosbag2 (Jazzy) would refuse, and every
    inconsistency between it and the files (empty when the bag is fine)."""
    bag_dir = Path(bag_dir)
    data = yaml.safe_load((bag_dir / 'metadata.yaml').read_text())
    info = data.get('rosbag2_bagfile_information') if isinstance(data, dict) else None
    if not isinstance(info, dict):
        return ['no rosbag2_bagfile_information']
    problems = []
    if info.get('version') != 9:
        problems.append(f'version: {info.get("version")!r} (Jazzy writes 9)')
    if info.get('storage_identifier') not in ('mcap', 'sqlite3'):
        problems.append(f'storage_identifier: {info.get("storage_identifier")!r}')
    for key, sub in (('duration', 'nanoseconds'), ('starting_time', 'nanoseconds_since_epoch')):
        if not (isinstance(info.get(key), dict) and _unsigned(info[key].get(sub))):
            problems.append(f'{key}.{sub}: {info.get(key)!r}')
    if not _unsigned(info.get('message_count')):
        problems.append(f'message_count: {info.get("message_count")!r}')
    for key in ('compression_format', 'compression_mode', 'ros_distro'):
        if not isinstance(info.get(key), str):
            problems.append(f'{key}: {info.get(key)!r}')
    custom = info.get('custom_data')
    if not (custom is None or (isinstance(custom, dict) and all(
            isinstance(k, str) and isinstance(v, str) for k, v in custom.items()))):
        problems.append(f'custom_data: {custom!r} (string to string)')
    topics = info.get('topics_with_message_count')
    if not isinstance(topics, list):
        return [*problems, 'topics_with_message_count: not a list']
    for n, entry in enumerate(topics):
        meta = entry.get('topic_metadata', {}) if isinstance(entry, dict) else {}
        where = f'topics_with_message_count[{n}]'
        for key in ('name', 'type', 'serialization_format', 'type_description_hash'):
            if not isinstance(meta.get(key), str):
                problems.append(f'{where}.topic_metadata.{key}: {meta.get(key)!r}')
        profiles = meta.get('offered_qos_profiles')
        if not isinstance(profiles, list):
            problems.append(f'{where}.offered_qos_profiles: {profiles!r} (a list in version 9)')
        else:
            for k, qos in enumerate(profiles):
                problems += _problems_of_qos(f'{where}.offered_qos_profiles[{k}]', qos)
        if not _unsigned(entry.get('message_count') if isinstance(entry, dict) else None):
            problems.append(f'{where}.message_count')
    paths = info.get('relative_file_paths')
    files = info.get('files')
    if not (isinstance(paths, list) and all(isinstance(p, str) for p in paths)):
        return [*problems, f'relative_file_paths: {paths!r}']
    if not isinstance(files, list):
        return [*problems, 'files: not a list']
    for n, file in enumerate(files):
        if not (isinstance(file, dict) and isinstance(file.get('path'), str)
                and _unsigned(file.get('message_count'))
                and _unsigned((file.get('duration') or {}).get('nanoseconds'))
                and _unsigned((file.get('starting_time') or {}).get('nanoseconds_since_epoch'))):
            problems.append(f'files[{n}]: {file!r}')
    if problems:
        return problems
    if [f['path'] for f in files] != paths:
        problems.append('relative_file_paths and files disagree')
    problems += [f'{p} is missing' for p in paths if not (bag_dir / p).is_file()]
    total = info['message_count']
    if sum(f['message_count'] for f in files) != total:
        problems.append('the files\' message counts do not add up to message_count')
    if sum(t['message_count'] for t in topics) != total:
        problems.append('the topics\' message counts do not add up to message_count')
    return problems


# -- message definitions ---------------------------------------------------------------------

#: rosbag2's (Jazzy, ``local_message_definition_source.cpp``) rules, restated: a field's type is
#: the first word of a line followed by whitespace (arrays' brackets aside), a type without
#: ``/`` belongs to the package of the file, primitives have no section.
_FIELD_TYPE = re.compile(r'(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+')
_PRIMITIVES = {'bool', 'byte', 'char', 'float32', 'float64', 'int8', 'uint8', 'int16', 'uint16',
               'int32', 'uint32', 'int64', 'uint64', 'string'}


def rosbag2_msg_definition(type_name: str, prefixes: list[str]) -> str:
    """The definition Jazzy's rosbag2 writes for the message type ``type_name``
    (``pkg/msg/Name``), from the installed ``.msg`` files: the type's text, then per
    dependency (sorted names, depth first, each once) a newline, 80 ``=``, ``MSG: pkg/Name``
    and its text."""
    def text_of(name: str) -> str:
        package, _, short = name.partition('/')
        short = short.removeprefix('msg/')
        for prefix in prefixes:
            path = Path(prefix) / 'share' / package / 'msg' / f'{short}.msg'
            if path.is_file():
                return path.read_text(encoding='utf-8')
        raise FileNotFoundError(f'no {package}/msg/{short}.msg under the prefixes')

    seen: set[str] = set()

    def append(name: str) -> str:
        text = text_of(name)
        package = name.split('/')[0]
        deps = set()
        for match in _FIELD_TYPE.finditer(text):
            dep = match.group(1)
            if dep not in _PRIMITIVES:
                deps.add(dep if '/' in dep else f'{package}/{dep}')
        for dep in sorted(deps):
            if dep not in seen:
                seen.add(dep)
                text += '\n' + '=' * 80 + f'\nMSG: {dep}\n' + append(dep)
        return text

    return append(type_name)
