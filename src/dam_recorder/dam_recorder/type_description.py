"""Message types as ROS 2 Jazzy describes them: fields, message definition text and type hash.

Every interface package built by rosidl on Jazzy installs, next to ``msg/Name.msg``, a type
description ``msg/Name.json`` (REP 2011): the fields of the type and of every type it refers
to, with the RIHS01 type hash of each. For an action ``action/Name.json`` also describes the
types derived from it (``Name_FeedbackMessage``, ``Name_Goal``, ...), which have no file of their
own. This module reads those files (pure data, no rclpy) and gives

- the message definition in the ``ros2msg`` form rosbag2 stores (the installed ``.msg`` text
  of the type, then one ``MSG: pkg/Name`` section per referenced type, separated by a line of
  80 ``=``: :mod:`dam_recorder.msg_definition`), which MCAP readers such as
  ``mcap-ros2-support`` decode with and ``rosbags`` parses;
- the type hash (``RIHS01_...``) that ``metadata.yaml`` stores as ``type_description_hash``;
- the field layout that :mod:`dam_recorder.cdr_end` walks.

Constants and comments are not part of a type description: :func:`load_message_type` reads
them from the installed ``.msg`` files, for the definition text. A type without one (derived
from an action or a service) is described by its fields.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dam_common.words import counted
from dam_recorder.errors import TypeDescriptionError
from dam_recorder.msg_definition import field_type_name, header_name, ros2msg_definition

#: ``type_description_interfaces/FieldType`` ids of the single (non-array) field types.
NESTED = 1
PRIMITIVE_NAMES: dict[int, str] = {
    2: 'int8', 3: 'uint8', 4: 'int16', 5: 'uint16', 6: 'int32', 7: 'uint32', 8: 'int64',
    9: 'uint64', 10: 'float32', 11: 'float64', 13: 'char', 15: 'bool', 16: 'byte',
}
#: Serialized size [bytes] of each primitive (also its CDR alignment).
PRIMITIVE_SIZES: dict[int, int] = {
    2: 1, 3: 1, 4: 2, 5: 2, 6: 4, 7: 4, 8: 8, 9: 8, 10: 4, 11: 8, 13: 1, 15: 1, 16: 1,
}
STRING = 17
BOUNDED_STRING = 21
#: Field types a bag cannot carry here (no ``.msg`` spelling, or no agreed CDR layout).
UNSUPPORTED_NAMES: dict[int, str] = {
    12: 'long double', 14: 'wchar', 18: 'wstring', 19: 'fixed string', 20: 'fixed wstring',
    22: 'bounded wstring',
}
#: Offsets added to a single type's id for its containers.
ARRAY_OFFSET = 48
BOUNDED_SEQUENCE_OFFSET = 96
UNBOUNDED_SEQUENCE_OFFSET = 144


@dataclass(frozen=True)
class FieldType:
    """The type of one field (``type_description_interfaces/FieldType``)."""

    type_id: int
    capacity: int = 0
    string_capacity: int = 0
    nested_type_name: str = ''

    @property
    def container(self) -> str:
        """``'single'``, ``'array'`` (fixed size ``capacity``), ``'bounded'`` (sequence of at
        most ``capacity``) or ``'sequence'`` (unbounded)."""
        return ('single', 'array', 'bounded', 'sequence')[(self.type_id - 1) // ARRAY_OFFSET]

    @property
    def element_id(self) -> int:
        """Id of the element type (the single type of an array or sequence)."""
        return self.type_id - ARRAY_OFFSET * ((self.type_id - 1) // ARRAY_OFFSET)


@dataclass(frozen=True)
class Field:
    """One field of a message type."""

    name: str
    type: FieldType


@dataclass(frozen=True)
class MessageType:
    """A message type with every type it refers to.

    Attributes
    ----------
    name : str
        Full type name, e.g. ``'sensor_msgs/msg/JointState'`` or
        ``'dam_interfaces/action/DamGrasp_FeedbackMessage'``.
    type_hash : str
        RIHS01 hash of the type (``'RIHS01_<64 hex digits>'``).
    fields : dict[str, tuple[Field, ...]]
        Fields of this type and of each type it refers to (directly or not), by full name.
    texts : dict[str, str]
        The installed ``.msg`` text of those types that have one, by full name (the
        definition takes it as it is; types without one are described by their fields).
    """

    name: str
    type_hash: str
    fields: Mapping[str, tuple[Field, ...]]
    texts: Mapping[str, str] = dataclasses.field(default_factory=dict)

    def definition(self) -> str:
        """The ``ros2msg`` message definition, as rosbag2 writes it into a bag: this type's
        text, then one section per referenced type (:mod:`dam_recorder.msg_definition`)."""
        nested = {name: [f.type.nested_type_name for f in fields if f.type.nested_type_name]
                  for name, fields in self.fields.items()}
        return ros2msg_definition(self.name, nested, self.own_text)

    def own_text(self, type_name: str) -> str:
        """The text of ``type_name`` alone: its ``.msg`` file, else its fields (one line each,
        nested types spelt as :func:`~dam_recorder.msg_definition.field_type_name` says)."""
        if type_name in self.texts:
            return self.texts[type_name]
        return ''.join(f'{field_type_text(f.type, type_name)} {f.name}\n'
                       for f in self.fields[type_name])

    def referenced_types(self) -> list[str]:
        """Full names of the types this type refers to, depth first, each once."""
        seen: list[str] = []

        def visit(name: str) -> None:
            for field in self.fields[name]:
                nested = field.type.nested_type_name
                if nested and nested not in seen:
                    seen.append(nested)
                    visit(nested)

        visit(self.name)
        return seen


def field_type_text(field_type: FieldType, owner: str = '') -> str:
    """The ``.msg`` spelling of a field type of the type ``owner``, e.g. ``'float64[]'``,
    ``'string<=8[3]'``, ``'std_msgs/Header'``, ``'DamGrasp_Feedback'``.

    Raises
    ------
    TypeDescriptionError
        For a type that has no ``.msg`` spelling or CDR layout supported here (wstring,
        long double, wchar, fixed-size strings), naming it.
    """
    element = field_type.element_id
    if element == NESTED:
        nested = field_type.nested_type_name
        base = field_type_name(nested, owner) if owner else header_name(nested)
    elif element in PRIMITIVE_NAMES:
        base = PRIMITIVE_NAMES[element]
    elif element == STRING:
        base = 'string'
    elif element == BOUNDED_STRING:
        base = f'string<={field_type.string_capacity}'
    else:
        what = UNSUPPORTED_NAMES.get(element, f'type id {field_type.type_id}')
        raise TypeDescriptionError(f'field type {what!r} is not supported')
    container = field_type.container
    if container == 'array':
        return f'{base}[{field_type.capacity}]'
    if container == 'bounded':
        return f'{base}[<={field_type.capacity}]'
    if container == 'sequence':
        return f'{base}[]'
    return base


def _parse_fields(description: Mapping[str, Any]) -> tuple[str, tuple[Field, ...]]:
    fields = []
    for item in description['fields']:
        t = item['type']
        fields.append(Field(item['name'], FieldType(
            int(t['type_id']), int(t.get('capacity', 0)), int(t.get('string_capacity', 0)),
            str(t.get('nested_type_name', '')))))
    return str(description['type_name']), tuple(fields)


def message_type_from_description(document: Mapping[str, Any], type_name: str) -> MessageType:
    """The :class:`MessageType` ``type_name`` out of a type description document (the content
    of an installed ``.json`` file).

    Raises
    ------
    TypeDescriptionError
        If the document does not describe ``type_name`` or a type it refers to, or a field has
        a type not supported here (the message names the type and the field).
    """
    try:
        msg = document['type_description_msg']
        described = dict(_parse_fields(d) for d in
                         [msg['type_description'], *msg['referenced_type_descriptions']])
        hashes = {h['type_name']: h['hash_string'] for h in document['type_hashes']}
    except (KeyError, TypeError, ValueError) as exc:
        raise TypeDescriptionError(
            f'malformed type description for {type_name!r}: missing or bad {exc}') from None
    if type_name not in described:
        raise TypeDescriptionError(f'the type description does not describe {type_name!r}')
    fields: dict[str, tuple[Field, ...]] = {}
    pending = [type_name]
    while pending:
        name = pending.pop()
        if name in fields:
            continue
        if name not in described:
            raise TypeDescriptionError(
                f'the type description of {type_name!r} lacks the referenced type {name!r}')
        fields[name] = described[name]
        for field in described[name]:
            try:
                field_type_text(field.type)
            except TypeDescriptionError as exc:
                raise TypeDescriptionError(
                    f'{type_name}: field {name}.{field.name}: {exc}') from None
            if field.type.nested_type_name:
                pending.append(field.type.nested_type_name)
    return MessageType(type_name, hashes.get(type_name, ''), fields)


def description_file_candidates(type_name: str, prefixes: Iterable[str | os.PathLike[str]]
                                ) -> list[Path]:
    """Where an install puts the type description of ``type_name``, most specific first.

    ``pkg/msg/Name`` is described in ``<prefix>/share/pkg/msg/Name.json``; a type derived from
    an action or a service (``pkg/action/Name_FeedbackMessage``) in the file of the interface
    whose name it starts with (``action/Name.json``).
    """
    try:
        package, kind, name = type_name.split('/')
    except ValueError:
        raise TypeDescriptionError(
            f'type name {type_name!r} is not of the form package/kind/Name') from None
    stems = [name] + [name[:i] for i in range(len(name) - 1, 0, -1) if name[i] == '_']
    return [Path(prefix) / 'share' / package / kind / f'{stem}.json'
            for stem in stems for prefix in prefixes]


def install_prefix_of(module_file: str | os.PathLike[str], package: str) -> Path | None:
    """The install prefix that holds ``share/<package>`` above a file of the package's Python
    code (``<prefix>/lib/python3.X/site-packages/<package>/__init__.py``), or ``None``.

    The PyPI wheels of ROS 2 do not put their prefix on ``AMENT_PREFIX_PATH``; the place the
    message module was imported from finds their ``share`` directory all the same.
    """
    for parent in Path(module_file).resolve().parents:
        if (parent / 'share' / package).is_dir():
            return parent
    return None


def load_message_type(type_name: str, prefixes: Iterable[str | os.PathLike[str]]
                      ) -> MessageType:
    """Find and read the installed type description of ``type_name`` under ``prefixes`` (the
    entries of ``AMENT_PREFIX_PATH``).

    Raises
    ------
    TypeDescriptionError
        If no installed file describes ``type_name`` (the message names the type and the
        places looked at), or the description cannot be used.
    """
    prefixes = list(prefixes)
    candidates = description_file_candidates(type_name, prefixes)
    for path in candidates:
        if not path.is_file():
            continue
        try:
            document = json.loads(path.read_text(encoding='utf-8'))
        except (OSError, ValueError) as exc:
            raise TypeDescriptionError(f'cannot read {path}: {exc}') from None
        names = {h.get('type_name') for h in document.get('type_hashes', [])}
        if type_name in names:
            message_type = message_type_from_description(document, type_name)
            texts = installed_msg_texts(message_type.fields, prefixes)
            return dataclasses.replace(message_type, texts=texts)
    package = type_name.split('/')[0]
    raise TypeDescriptionError(
        f'no type description of {type_name!r} installed (looked for share/{package}/.../*.json'
        f' under {counted(len(prefixes), "prefix", "prefixes")} of AMENT_PREFIX_PATH)')


def installed_msg_texts(type_names: Iterable[str], prefixes: Sequence[str | os.PathLike[str]]
                        ) -> dict[str, str]:
    """The installed ``.msg`` file text (``<prefix>/share/pkg/msg/Name.msg``, the first prefix
    that has it) of each message type of ``type_names`` that has one, by full name.

    Raises
    ------
    TypeDescriptionError
        If a ``.msg`` file is there but cannot be read (the message names it).
    """
    texts = {}
    for type_name in type_names:
        package, kind, name = type_name.split('/')
        if kind != 'msg':
            continue
        for prefix in prefixes:
            path = Path(prefix) / 'share' / package / 'msg' / f'{name}.msg'
            if path.is_file():
                try:
                    texts[type_name] = path.read_text(encoding='utf-8')
                except (OSError, ValueError) as exc:
                    raise TypeDescriptionError(f'cannot read {path}: {exc}') from None
                break
    return texts
