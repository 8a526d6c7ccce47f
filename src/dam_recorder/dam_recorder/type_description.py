"""Message types as ROS 2 Jazzy describes them: fields, message definition text and type hash.

Every interface package built by rosidl on Jazzy installs, next to ``msg/Name.msg``, a type
description ``msg/Name.json`` (REP 2011): the fields of the type and of every type it refers
to, with the RIHS01 type hash of each. For an action ``action/Name.json`` also describes the
types derived from it (``Name_FeedbackMessage``, ``Name_Goal``, ...), which have no file of their
own. This module reads those files (pure data, no rclpy) and gives

- the message definition in the ``ros2msg`` form a bag stores (the fields of the type, then
  one ``MSG: pkg/Name`` section per referenced type, separated by a line of 80 ``=``), which
  MCAP readers such as ``mcap-ros2-support`` decode with and ``rosbags`` parses;
- the type hash (``RIHS01_...``) that ``metadata.yaml`` stores as ``type_description_hash``;
- the field layout that :mod:`dam_recorder.cdr_end` walks.

Constants and comments are not part of a type description; the definition text has the fields
only, which is all a decoder needs.
"""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dam_recorder.errors import TypeDescriptionError

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
#: The line that separates the sections of a ``ros2msg`` definition.
SECTION_SEPARATOR = '=' * 80


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
    """

    name: str
    type_hash: str
    fields: Mapping[str, tuple[Field, ...]]

    def definition(self) -> str:
        """The ``ros2msg`` message definition: this type's fields, then one section per
        referenced type (depth first, in order of first use)."""
        sections = [_fields_text(self.fields[self.name])]
        for name in self.referenced_types():
            sections.append(f'{SECTION_SEPARATOR}\nMSG: {short_name(name)}\n'
                            f'{_fields_text(self.fields[name])}')
        return '\n'.join(sections) + '\n'

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


def short_name(type_name: str) -> str:
    """How a definition spells a nested type: ``'pkg/msg/Name'`` -> ``'pkg/Name'`` (as a
    ``.msg`` file does); a type derived from an action or a service keeps its full name
    (``'pkg/action/Name_Feedback'``), because a reader takes ``pkg/Name`` for
    ``pkg/msg/Name`` and would compute another type hash than the one stored."""
    parts = type_name.split('/')
    if len(parts) == 3 and parts[1] != 'msg':
        return type_name
    return f'{parts[0]}/{parts[-1]}'


def field_type_text(field_type: FieldType) -> str:
    """The ``.msg`` spelling of a field type, e.g. ``'float64[]'``, ``'string<=8[3]'``.

    Raises
    ------
    TypeDescriptionError
        For a type that has no ``.msg`` spelling or CDR layout supported here (wstring,
        long double, wchar, fixed-size strings), naming it.
    """
    element = field_type.element_id
    if element == NESTED:
        base = short_name(field_type.nested_type_name)
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


def _fields_text(fields: Sequence[Field]) -> str:
    return '\n'.join(f'{field_type_text(f.type)} {f.name}' for f in fields)


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
            return message_type_from_description(document, type_name)
    package = type_name.split('/')[0]
    raise TypeDescriptionError(
        f'no type description of {type_name!r} installed (looked for share/{package}/.../*.json'
        f' under {len(prefixes)} prefix(es) of AMENT_PREFIX_PATH)')
