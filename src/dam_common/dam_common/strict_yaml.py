"""YAML parsing that refuses duplicate mapping keys.

``yaml.safe_load`` keeps the last of two equal keys in a mapping without a word: a
configuration with ``friction_angle_deg`` written twice under ``contact:``, or a second
``contact:`` section appended to the file, silently takes the later value.
:func:`safe_load_unique` parses like ``yaml.safe_load`` but raises
:class:`~dam_common.errors.ConfigError` naming the dotted key path, the file and both lines.

Keys are compared as the values they construct to (so ``1`` and ``1.0`` are the same key, as
they are in the resulting dict). The keys a merge (``<<: *anchor``) brings in may be
overridden by explicit keys, as YAML intends; duplicates among explicit keys are refused.

A configuration is small and shallow (the shipped one: 14 KB, 6 levels), so a text longer
than :data:`MAX_YAML_BYTES` or nested deeper than :data:`MAX_YAML_DEPTH` is refused at once
with one line naming the limit and the value: a 3.4 MB overlay of 100,000 vertices took
112 s to be refused, and a mapping nested 5,000 deep ended in a 202 KB ``RecursionError``
traceback (PyYAML composes recursively).

This module is pure Python (PyYAML); it does not import rclpy.
"""

from __future__ import annotations

from collections.abc import Hashable
from typing import Any

import yaml

from dam_common.errors import ConfigError

_MERGE_TAG = 'tag:yaml.org,2002:merge'
#: Longest YAML text a configuration (or an overlay) may be [bytes]: 256 KiB, 18 times the
#: shipped config/dam.yaml; one this long loads in about 0.3 s.
MAX_YAML_BYTES = 256 * 1024
#: Deepest nesting of mappings and lists a configuration may have (the shipped one: 6).
MAX_YAML_DEPTH = 32


def check_yaml_size(size: int, source: str) -> None:
    """Refuse a YAML text of ``size`` bytes beyond :data:`MAX_YAML_BYTES`.

    Raises
    ------
    ConfigError
        One line naming the file, its size and the limit.
    """
    if size > MAX_YAML_BYTES:
        raise ConfigError(f'{source!r} is {_kib(size)}: a configuration file may have at '
                          f'most {_kib(MAX_YAML_BYTES)} (a configuration is small)')


def _kib(size: int) -> str:
    return f'{size / 1024:.0f} KiB' if size < 1024 * 1024 else f'{size / 1024 ** 2:.1f} MiB'


class _DepthLimitedLoader(yaml.SafeLoader):
    """A SafeLoader that refuses nesting deeper than :data:`MAX_YAML_DEPTH` while it composes
    (before the recursion of composing, constructing or checking runs out of stack)."""

    def __init__(self, stream: str, source: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._source = source

    def compose_node(self, parent: yaml.Node | None, index: object) -> yaml.Node:
        if self._depth >= MAX_YAML_DEPTH and not self.check_event(yaml.ScalarEvent,
                                                                     yaml.AliasEvent):
            mark = self.peek_event().start_mark
            raise ConfigError(f'{self._source!r} nests mappings and lists more than '
                              f'{MAX_YAML_DEPTH} levels deep (level {self._depth + 1} on line '
                              f'{mark.line + 1}): a configuration may nest at most '
                              f'{MAX_YAML_DEPTH}')
        self._depth += 1
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1


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
        Or the text is longer than :data:`MAX_YAML_BYTES`, or nests deeper than
        :data:`MAX_YAML_DEPTH` (one line naming the limit and the value).
    yaml.YAMLError
        The text is not valid YAML.
    """
    check_yaml_size(len(text.encode('utf-8')), source)
    loader = _DepthLimitedLoader(text, source)
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
