"""The configuration's YAML cursor: a value, its key path and its file, for messages.

:class:`ConfigNode` walks the parsed YAML of ``config/dam.yaml`` (or an overlay) and turns
every wrong value into a :class:`~dam_common.errors.ConfigError` that names the key's path,
the bad value and the file: ``hand.link_lengths_m[1]: expected a positive number, got -0.025
(in config/dam.yaml)``. The section parsers of :mod:`dam_common.config` and
:mod:`dam_common.dynamixel_config` take it. Pure Python; no rclpy.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from dam_common.errors import ConfigError


class ConfigNode:
    """A value of the parsed YAML with its key path (``hand.fingers[0].name``) and file."""

    def __init__(self, raw: Any, path: str, source: str) -> None:
        self.raw = raw
        self.path = path
        self.source = source

    def error(self, message: str) -> ConfigError:
        where = self.path or '<root>'
        return ConfigError(f'{where}: {message} (in {self.source})')

    def require_mapping(self) -> Mapping[str, Any]:
        if not isinstance(self.raw, Mapping):
            raise self.error(f'expected a mapping, got {self.raw!r}')
        return self.raw

    def only_keys(self, allowed: set[str]) -> None:
        mapping = self.require_mapping()
        unknown = sorted(str(k) for k in mapping if k not in allowed)
        if unknown:
            keys = 'key' if len(unknown) == 1 else 'keys'
            raise self.error(f'unknown {keys} {unknown} (allowed: {sorted(allowed)})')

    def child(self, key: str) -> ConfigNode:
        mapping = self.require_mapping()
        path = f'{self.path}.{key}' if self.path else key
        if key not in mapping:
            raise ConfigNode(None, path, self.source).error('missing key')
        return ConfigNode(mapping[key], path, self.source)

    def sequence(self, length: int | None = None) -> list[Any]:
        if isinstance(self.raw, (str, bytes)) or not isinstance(self.raw, Sequence):
            raise self.error(f'expected a list, got {self.raw!r}')
        if length is not None and len(self.raw) != length:
            raise self.error(f'expected {length} values, got {len(self.raw)}: {self.raw!r}')
        return list(self.raw)

    def item(self, index: int) -> ConfigNode:
        return ConfigNode(self.raw[index], f'{self.path}[{index}]', self.source)

    def number(self, positive: bool = False, nonnegative: bool = False) -> float:
        value = self.raw
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise self.error(f'expected a number, got {value!r}')
        value = float(value)
        if not math.isfinite(value):
            raise self.error(f'expected a finite number, got {value!r}')
        if positive and value <= 0.0:
            raise self.error(f'expected a positive number, got {value!r}')
        if nonnegative and value < 0.0:
            raise self.error(f'expected a non-negative number, got {value!r}')
        return value

    def integer(self, minimum: int | None = None, maximum: int | None = None) -> int:
        value = self.raw
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.error(f'expected an integer, got {value!r}')
        if minimum is not None and value < minimum:
            raise self.error(f'expected an integer >= {minimum}, got {value!r}')
        if maximum is not None and value > maximum:
            raise self.error(f'expected an integer <= {maximum}, got {value!r}')
        return value

    def vector(self, length: int, positive: bool = False) -> np.ndarray:
        items = self.sequence(length)
        return np.array([self.item(i).number(positive=positive) for i in range(len(items))],
                        dtype=np.float64)

    def boolean(self) -> bool:
        if not isinstance(self.raw, bool):
            raise self.error(f'expected true or false, got {self.raw!r}')
        return self.raw

    def string(self) -> str:
        if not isinstance(self.raw, str) or not self.raw:
            raise self.error(f'expected a non-empty string, got {self.raw!r}')
        return self.raw

    def identifier(self) -> str:
        value = self.string()
        if not value.isidentifier() or not value.isascii():
            raise self.error(f'expected a name of letters, digits and underscores, got {value!r}')
        return value
