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


def test_the_commands_print_one_of_a_thing_in_the_singular() -> None:
    """Every count printed beside its noun goes through :func:`counted` in the modules that
    print counts (a count of one printed "1 trials", "1 friction angles", "1 repeats"): no
    f-string there puts a bare count before a plural noun."""
    import re
    from pathlib import Path

    root = Path(__file__).resolve().parents[2] / 'src'
    nouns = ('trials', 'friction angles', 'repeats', 'rows', 'grasps', 'messages', 'topics',
             'cells', 'lines', 'bags')
    bare = re.compile(r"\{[^{}]*\} (?:" + '|'.join(nouns) + r")\b")
    modules = ['dam_experiments/dam_experiments/sweep_cli.py',
               'dam_experiments/dam_experiments/sweep_plot.py',
               'dam_experiments/dam_experiments/sweep_report_cli.py',
               'dam_experiments/dam_experiments/experiment.py',
               'dam_experiments/dam_experiments/calibrate_csm.py',
               'dam_recorder/dam_recorder/recover_cli.py',
               'dam_recorder/dam_recorder/recovery.py',
               'dam_recorder/dam_recorder/bag_info_text.py',
               'dam_recorder/dam_recorder/bag_selection.py']
    found = [f'{name}:{n}: {line.strip()}' for name in modules
             for n, line in enumerate((root / name).read_text(encoding='utf-8').splitlines(), 1)
             if bare.search(line) and 'counted(' not in line
             and not line.lstrip().startswith('#')]
    assert not found, '\n'.join(found)
