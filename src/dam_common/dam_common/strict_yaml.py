"""YAML parsing that refuses duplicate mapping keys.

``yaml.safe_load`` keeps the last of two equal keys in a mapping without a word: a
configuration with ``friction_angle_deg`` written twice under ``contact:``, or a second
``contact:`` section appended to the file, silently takes the later value.
:func:`safe_load_unique` parses like ``yaml.safe_load`` but raises
:class:`~dam_common.errors.ConfigError` naming the dotted key path, the file and both lines.

Keys are compared as the values they construct to (so ``1`` and ``1.0`` are the same key, as
they are in the resulting dict). The keys a merge (``<<: *anchor``) brings in may be
overridden by explicit keys, as YAML intends; duplicates among explicit keys are refused.

This module is pure Python (PyYAML); it does not import rclpy.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Any

import yaml

from dam_common.errors import ConfigError

_MERGE_TAG = 'tag:yaml.org,2002:merge'


def safe_load_unique(text: str, source: str) -> Any:
    """Parse one YAML document like ``yaml.safe_load``, refusing duplicate mapping keys.

    Parameters
    ----------
    text
        The YAML text.
    source
        Where the text came from (a file name), for error messages.

    Returns
    -------
    Any
        The parsed document (``None`` for an empty one).

    Raises
    ------
    ConfigError
        A mapping at any depth holds the same key twice; the message gives the key path
        (``contact.friction_angle_deg``, ``hand.fingers[1].name``), the file and both lines.
    yaml.YAMLError
        The text is not valid YAML.
    """
    loader = yaml.SafeLoader(text)
    try:
        node = loader.get_single_node()
        if node is None:
            return None
        _check_unique_keys(loader, node, '', source, set())
        return loader.construct_document(node)
    finally:
        loader.dispose()


def _check_unique_keys(loader: yaml.SafeLoader, node: yaml.Node, path: str, source: str,
                       visited: set[int]) -> None:
    """Walk the node graph below ``node`` (at key path ``path``) and raise on a duplicate."""
    if id(node) in visited:  # an alias of a node already checked (or a recursive one)
        return
    visited.add(id(node))
    if isinstance(node, yaml.SequenceNode):
        for i, item in enumerate(node.value):
            _check_unique_keys(loader, item, f'{path}[{i}]', source, visited)
        return
    if not isinstance(node, yaml.MappingNode):
        return
    first_line: dict[Hashable, int] = {}
    for key_node, value_node in node.value:
        if key_node.tag == _MERGE_TAG:
            continue
        if not isinstance(key_node, yaml.ScalarNode):  # the constructor refuses these itself
            continue
        key = loader.construct_object(key_node)
        if not isinstance(key, Hashable):
            continue
        key_path = f'{path}.{key}' if path else str(key)
        line = key_node.start_mark.line + 1
        if key in first_line:
            raise ConfigError(f'{key_path}: duplicate key, first on line {first_line[key]}, '
                              f'again on line {line} (in {source})')
        first_line[key] = line
        _check_unique_keys(loader, value_node, key_path, source, visited)
