"""dam_common.echo: a quoted value is short however long the value, and a short one is whole."""

from __future__ import annotations

import array
import time

import numpy as np

from dam_common.echo import ECHO_LIMIT, TEXT_LIMIT, brief_repr, brief_text


def test_a_short_value_is_quoted_whole_as_repr_quotes_it() -> None:
    assert brief_repr(1.5) == '1.5'
    assert brief_repr('left_compliant_joint') == "'left_compliant_joint'"
    assert brief_repr([0.5, 0.25]) == '[0.5, 0.25]'
    assert brief_repr((1, 2)) == '(1, 2)'
    assert brief_repr(b'\x01') == "b'\\x01'"
    assert brief_repr(None) == 'None'


def test_arrays_are_quoted_as_the_list_of_their_numbers() -> None:
    assert brief_repr(np.array([1.0, 2.0])) == '[1.0, 2.0]'
    assert brief_repr(array.array('d', [3.0])) == '[3.0]'
    assert brief_repr(np.float64(2.0)) == repr(np.float64(2.0))  # a scalar as repr has it


def test_a_million_values_are_cut_with_the_count_and_quickly() -> None:
    values = [1.0] * 1_000_000
    for value in (values, tuple(values), np.array(values), array.array('d', values)):
        t0 = time.perf_counter()
        text = brief_repr(value)
        assert time.perf_counter() - t0 < 0.05, type(value)
        assert len(text) < ECHO_LIMIT + 40, text
        assert text.startswith('[1.0, 1.0') or text.startswith('(1.0, 1.0'), text
        assert text.endswith('... (1000000 values)'), text


def test_a_long_string_and_bytes_say_their_length() -> None:
    text = brief_repr('x' * 70_000)
    assert text.startswith("'xxx") and text.endswith('... (70000 characters)')
    assert len(text) < ECHO_LIMIT + 40
    assert brief_repr(b'\0' * 5000).endswith('... (5000 bytes)')


def test_another_object_with_a_long_repr_is_cut_at_the_limit() -> None:
    class Wordy:
        def __repr__(self) -> str:
            return 'w' * 1000

    assert brief_repr(Wordy()) == 'w' * ECHO_LIMIT + '... (1000 characters)'
    assert brief_repr({'k': 'v' * 1000}, limit=10) == "{'k': 'vvv... (1009 characters)"


def test_brief_text_keeps_a_message_and_cuts_a_huge_one() -> None:
    assert brief_text('k_theta: stiffness must be positive') == \
        'k_theta: stiffness must be positive'
    huge = 'y' * (TEXT_LIMIT + 1)
    assert brief_text(huge) == 'y' * TEXT_LIMIT + f'... ({TEXT_LIMIT + 1} characters)'
