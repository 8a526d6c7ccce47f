"""The YAML reader that refuses duplicate keys, on small documents."""

from __future__ import annotations

import pytest
import yaml

from dam_common.errors import ConfigError
from dam_common.strict_yaml import safe_load_unique


def test_it_reads_what_safe_load_reads() -> None:
    text = 'a: 1\nb: [1, {c: 2, d: [x, y]}]\ne: {f: null}\n'
    assert safe_load_unique(text, 'doc.yaml') == yaml.safe_load(text)
    assert safe_load_unique('', 'empty.yaml') is None
    assert safe_load_unique('42\n', 'scalar.yaml') == 42


@pytest.mark.parametrize(('text', 'expected'), [
    ('a: 1\na: 2\n', r'^a: duplicate key, first on line 1, again on line 2 \(in doc\.yaml\)$'),
    ('a:\n  b: 1\n  c: 2\n  b: 3\n', r'^a\.b: duplicate key, first on line 2, again on line 4'),
    ('l:\n  - {x: 1}\n  - x: 1\n    x: 2\n', r'^l\[1\]\.x: .* line 3, again on line 4'),
    ('1: a\n1.0: b\n', r'^1\.0: duplicate key, first on line 1, again on line 2'),
])
def test_duplicates_are_refused_with_path_and_lines(text: str, expected: str) -> None:
    with pytest.raises(ConfigError, match=expected):
        safe_load_unique(text, 'doc.yaml')


def test_merged_keys_may_be_overridden_and_aliases_are_checked_once() -> None:
    text = 'base: &b {x: 1, y: 2}\nother:\n  <<: *b\n  x: 3\nthird: *b\n'
    assert safe_load_unique(text, 'doc.yaml') == {
        'base': {'x': 1, 'y': 2}, 'other': {'x': 3, 'y': 2}, 'third': {'x': 1, 'y': 2}}


def test_invalid_yaml_still_raises_a_yaml_error() -> None:
    with pytest.raises(yaml.YAMLError):
        safe_load_unique('a: [unclosed\n', 'doc.yaml')
