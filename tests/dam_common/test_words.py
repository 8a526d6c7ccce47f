"""Counts with their nouns: "1 trial", never "1 trials" (issue 34)."""

from __future__ import annotations

import pytest

from dam_common.words import counted


@pytest.mark.parametrize(('count', 'noun', 'plural', 'text'), [
    (1, 'trial', None, '1 trial'),
    (0, 'trial', None, '0 trials'),
    (2, 'friction angle', None, '2 friction angles'),
    (1, 'repeat', None, '1 repeat'),
    (3, 'k_theta', None, '3 k_theta'),
    (2, 'body', 'bodies', '2 bodies'),
])
def test_a_count_takes_the_plural_unless_it_is_one(count, noun, plural, text) -> None:
    assert counted(count, noun, plural) == text


def test_a_count_keeps_its_number_format() -> None:
    assert counted(1024, 'message', spec=',') == '1,024 messages'
