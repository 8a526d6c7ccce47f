"""Two independent readers of a recorded bag, for the tests.

- :func:`read_with_rosbags`: ``rosbags``' rosbag2 reader (it follows ``metadata.yaml``) and its
  CDR deserializer, with the types registered from the message definitions stored in the bag;
- :func:`read_with_mcap`: the ``mcap`` library's indexed reader with ``mcap-ros2-support``'s
  decoder, file by file (MCAP bags only).

Both return ``{topic: [Record(timestamp_ns, values, data), ...]}`` in file and time order,
``values`` being plain Python (dicts, lists, numbers, strings) so that the two can be compared
with each other and with ``recorder_samples``, and ``data`` the serialized message as stored.

``mcap-ros2-support`` (0.6) refuses to build a decoder for a type whose name has an underscore
(its copy of rosidl's name rule ``^[A-Z][A-Za-z0-9]*$``), which every type derived from an
action has (``DamGrasp_FeedbackMessage``); for those the reader hands it the schema with the
underscores taken out of the derived names (:func:`without_underscores`): the same layout.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any, NamedTuple

import yaml


class Record(NamedTuple):
    """One message as a reader returns it."""

    timestamp: int
    values: Any
    data: bytes


def plain(value: Any) -> Any:
    """A decoded message (either reader's) as plain Python values."""
    if hasattr(value, '__dataclass_fields__'):
        return {k: plain(getattr(value, k)) for k in value.__dataclass_fields__
                if not k.startswith('_')}
    if hasattr(value, '__slots__') and not isinstance(value, (str, bytes)):
        return {k: plain(getattr(value, k)) for k in value.__slots__}
    if hasattr(value, 'tolist'):
        return plain(value.tolist())
    if isinstance(value, (bytes, bytearray)):
        return list(value)
    if isinstance(value, (list, tuple)):
        return [plain(v) for v in value]
    return value


def bag_files(bag_dir: str | os.PathLike[str]) -> list[Path]:
    """The storage files ``metadata.yaml`` lists, in its order."""
    info = yaml.safe_load((Path(bag_dir) / 'metadata.yaml').read_text())
    return [Path(bag_dir) / p for p in info['rosbag2_bagfile_information']['relative_file_paths']]


def read_with_rosbags(bag_dir: str | os.PathLike[str]) -> dict[str, list[Record]]:
    """Every message of the bag, deserialized by ``rosbags``."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    out: dict[str, list[Record]] = {}
    with Reader(bag_dir) as reader:
        for connection in reader.connections:
            store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
            out.setdefault(connection.topic, [])
        for connection, timestamp, data in reader.messages():
            message = store.deserialize_cdr(data, connection.msgtype)
            out[connection.topic].append(Record(timestamp, plain(message), bytes(data)))
    return out


_DERIVED_TYPE = re.compile(r'\b([a-z][a-z0-9_]*)/(?:action|srv)/([A-Za-z][A-Za-z0-9_]*)')


def without_underscores(schema: Any) -> Any:
    """``schema`` with every type derived from an action or a service renamed without its
    underscores (``pkg/action/Name_Feedback`` -> ``pkg/NameFeedback``), in its name and its
    definition: ``mcap-ros2-support`` refuses such names, the layout is unchanged."""
    from mcap.records import Schema

    def rename(match: re.Match[str]) -> str:
        return f'{match.group(1)}/{match.group(2).replace("_", "")}'
    name = _DERIVED_TYPE.sub(rename, schema.name)
    package, _, type_name = name.partition('/')
    data = _DERIVED_TYPE.sub(rename, schema.data.decode())
    return Schema(id=schema.id, name=f'{package}/msg/{type_name}', encoding=schema.encoding,
                  data=data.encode())


def read_with_mcap(bag_dir: str | os.PathLike[str]) -> dict[str, list[Record]]:
    """Every message of an MCAP bag, decoded by ``mcap-ros2-support``."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    factory = DecoderFactory()
    decoders: dict[int, Any] = {}
    out: dict[str, list[Record]] = {}
    for path in bag_files(bag_dir):
        decoders.clear()
        with open(path, 'rb') as stream:
            reader = make_reader(stream)
            for schema, channel, message in reader.iter_messages(log_time_order=True):
                if schema.id not in decoders:
                    if _DERIVED_TYPE.search(schema.name + schema.data.decode()):
                        schema = without_underscores(schema)
                    decoders[schema.id] = factory.decoder_for(channel.message_encoding,
                                                              schema)
                decoder = decoders[schema.id]
                values = plain(decoder(message.data)) if decoder is not None else None
                out.setdefault(channel.topic, []).append(
                    Record(message.log_time, values, bytes(message.data)))
    return out
