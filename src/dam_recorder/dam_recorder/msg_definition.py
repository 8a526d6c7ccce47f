"""The ``ros2msg`` message definition of a type, as rosbag2 writes it into a bag.

rosbag2's MCAP storage (Jazzy, ``LocalMessageDefinitionSource``) stores, per type, the text of
the type's installed ``.msg`` file followed, for each type it refers to (depth first; at each
level in the sorted order of the names as spelt, each type once), by a newline, a line of 80
``=``, a line ``MSG: pkg/Name`` and that type's own text, built the same way::

    std_msgs/Header header
    ...
    float64[] effort

    ================================================================================
    MSG: std_msgs/Header
    ...

The ``.msg`` text is kept as installed (comments and constants included). A reader
(``mcap-ros2-support``, ``rosbags``, Foxglove) splits the text at the separators and resolves
each field's type by its spelling: ``pkg/Name`` is ``pkg/msg/Name``, a bare ``Name`` belongs to
the package (``mcap-ros2-support``) or the interface (``rosbags``) of the type that uses it.

Types derived from an action or a service (``pkg/action/Name_FeedbackMessage`` on an action's
feedback topic, ``pkg/srv/Name_Event`` on a service's event topic, and the types they contain,
``Name_Feedback``, ``Name_Request``, ...) have no ``.msg`` file, and Jazzy's rosbag2 stores no
usable definition for them (its type name rule has no ``action/``: an empty schema of encoding
``unknown``). The recorder describes them so that every reader decodes them, in the grammar of
``.msg`` files: their fields (from the type description), a nested type derived from the same
interface spelt bare (``DamGrasp_Feedback feedback``: the ``ros2msg`` grammar has no
three-part names, and a bare name resolves to the right package for one reader and the right
interface for the other), and its section headed by its full name
(``MSG: dam_interfaces/action/DamGrasp_Feedback``), under which ``rosbags`` files it (the type
hash it computes then matches the stored one) and which ``mcap-ros2-support`` also files under
``pkg/Name``.

A plain message type whose ``.msg`` file is not installed (rosbag2 would fall back to the
``.idl`` file, encoding ``ros2idl``) is described by its fields too.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence

#: The line that separates the sections of a ``ros2msg`` definition.
SECTION_SEPARATOR = '=' * 80


def _parts(type_name: str) -> tuple[str, str, str]:
    package, kind, name = type_name.split('/')
    return package, kind, name


def header_name(type_name: str) -> str:
    """The name in a section's ``MSG:`` line: ``pkg/Name`` for ``pkg/msg/Name`` (as rosbag2
    writes it), the full name for a type derived from an action or a service."""
    package, kind, name = _parts(type_name)
    return f'{package}/{name}' if kind == 'msg' else type_name


def field_type_name(type_name: str, owner: str) -> str:
    """How a field of ``owner`` spells the nested type ``type_name``: ``pkg/Name`` for a message
    type, the bare ``Name`` for a type derived from the same interface as ``owner``, else the
    full name (a derived type of another interface: no reader resolves it by a shorter one)."""
    package, kind, name = _parts(type_name)
    if kind == 'msg':
        return f'{package}/{name}'
    owner_package, owner_kind, _ = _parts(owner)
    if (package, kind) == (owner_package, owner_kind):
        return name
    return type_name


def _sort_key(type_name: str) -> str:
    package, _, name = _parts(type_name)
    return f'{package}/{name}'


def ros2msg_definition(root: str, nested: Mapping[str, Sequence[str]],
                       own_text: Callable[[str], str]) -> str:
    """The whole ``ros2msg`` definition of ``root``.

    Parameters
    ----------
    root : str
        Full type name (``pkg/msg/Name``, ``pkg/action/Name_FeedbackMessage``).
    nested : mapping
        For every type involved (``root`` and each it refers to, directly or not), the full
        names of the types its fields refer to.
    own_text : callable
        The text of one type alone (its ``.msg`` file, or its fields), ending in a newline.
    """
    seen = {root}

    def section(type_name: str) -> str:
        text = own_text(type_name)
        for dep in sorted(set(nested[type_name]), key=_sort_key):
            if dep in seen:
                continue
            seen.add(dep)
            text += f'\n{SECTION_SEPARATOR}\nMSG: {header_name(dep)}\n{section(dep)}'
        return text

    return section(root)
