"""Two independent readers of a recorded bag, for the tests.

- :func:`read_with_rosbags`: ``rosbags``' rosbag2 reader (it follows ``metadata.yaml``) and its
  CDR deserializer, with the types registered from the message definitions stored in the bag;
- :func:`read_with_mcap`: the ``mcap`` library's indexed reader with ``mcap-ros2-support``'s
  decoder, file by file (MCAP bags only).

Both return ``{topic: [Record(timestamp_ns, values, data), ...]}`` in file and time order,
``values`` being plain Python (dicts, lists, numbers, strings) so that the two can be compared
with each other and with ``recorder_samples``, and ``data`` the serialized message as stored.

``mcap-ros2-support`` (0.6) refuses the *name* of a schema whose type name has an underscore
other than before ``_Goal``, ``_Result``, ``_Feedback``, ``_Request``, ``_Response`` (its copy of
rosidl's rule ``^[A-Z][A-Za-z0-9]*$``): ``DamGrasp_FeedbackMessage``, ``Name_Event``, whatever
the definition says. For those the reader hands it the schema under the name without its
underscores (:func:`decodable_schema`) and the stored definition *unchanged*, so that every
section and every field type of the definition is read as stored.
"""

from __future__ import annotations

import dataclasses
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
    if dataclasses.is_dataclass(value):  # fields only: no constants (upper case names)
        return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)
                if not f.name.startswith('_') and not f.name.isupper()}
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
    """Every message of the bag, deserialized by ``rosbags`` (which must find the type hash of
    each stored definition equal to the one ``metadata.yaml`` stores, as its ``AnyReader``
    requires)."""
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.EMPTY)
    out: dict[str, list[Record]] = {}
    with Reader(bag_dir) as reader:
        defined = any(c.msgdef.data for c in reader.connections)
    if defined:  # (without any definition AnyReader wants a type store of its own)
        with AnyReader([Path(bag_dir)]):
            pass  # it refuses a bag whose definitions and hashes disagree
    with Reader(bag_dir) as reader:
        for connection in reader.connections:
            store.register(get_types_from_msg(connection.msgdef.data, connection.msgtype))
            out.setdefault(connection.topic, [])
        for connection in reader.connections:  # what rosbags' AnyReader checks
            if connection.digest and connection.msgdef.data:
                assert store.hash_rihs01(connection.msgtype) == connection.digest, \
                    f'{connection.topic}: the definition stored gives another type hash'
        for connection, timestamp, data in reader.messages():
            message = store.deserialize_cdr(data, connection.msgtype)
            out[connection.topic].append(Record(timestamp, plain(message), bytes(data)))
    return out


_MESSAGE_NAME = re.compile(r'^[A-Z][A-Za-z0-9]*(_Goal|_Result|_Feedback|_Request|_Response)?$')


def decodable_schema(schema: Any) -> Any:
    """``schema`` as ``mcap-ros2-support`` accepts it: under a name without underscores when its
    name rule refuses the type's name (``pkg/action/Name_FeedbackMessage`` ->
    ``pkg/action/NameFeedbackMessage``); the definition is never touched."""
    from mcap.records import Schema

    package, _, name = schema.name.rpartition('/')
    if _MESSAGE_NAME.match(name):
        return schema
    return Schema(id=schema.id, name=f'{package}/{name.replace("_", "")}',
                  encoding=schema.encoding, data=schema.data)


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
                    decoders[schema.id] = factory.decoder_for(channel.message_encoding,
                                                              decodable_schema(schema))
                decoder = decoders[schema.id]
                values = plain(decoder(message.data)) if decoder is not None else None
                out.setdefault(channel.topic, []).append(
                    Record(message.log_time, values, bytes(message.data)))
    return out
