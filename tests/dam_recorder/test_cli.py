"""The recorder's command line: options become parameter overrides, --help documents them."""

from __future__ import annotations

import pytest

from dam_recorder.cli import build_parser, parameter_overrides
from dam_recorder.selection import DEFAULT_TOPICS


def test_options_become_parameters() -> None:
    assert parameter_overrides(['-o', 'out', '/a', 'b', '-s', 'sqlite3', '--compression',
                                'none', '-e', '^/dam', '-x', 'debug', '-b', '1000000', '-d',
                                '30', '--chunk-interval', '0.5']) == {
        'output': 'out', 'topics': ['/a', 'b'], 'storage': 'sqlite3', 'compression': 'none',
        'regex': '^/dam', 'exclude': 'debug', 'max_bag_size': 1_000_000,
        'max_bag_duration': 30.0, 'chunk_interval': 0.5}


def test_options_left_out_leave_the_parameters_alone() -> None:
    assert parameter_overrides([]) == {}
    assert parameter_overrides(['-o', 'x']) == {'output': 'x'}


def test_a_regex_alone_replaces_the_default_topics() -> None:
    assert parameter_overrides(['-e', 'status']) == {'topics': [''], 'regex': 'status'}
    assert parameter_overrides(['/a', '-e', 'status'])['topics'] == ['/a']


@pytest.mark.parametrize('argv, message', [
    (['-b', '-5'], "'-5' is negative"),
    (['-d', 'soon'], "'soon' is not a number"),
    (['-s', 'rosbag'], "invalid choice: 'rosbag'"),
    (['-b', '10'], "'10' is below 86016, the smallest split size (0 turns the limit off)"),
    (['--chunk-interval', '0'], "'0' is below 0.01"),
    (['--chunk-interval', '61'], "'61' is above 60"),
    (['--pre-roll', '-1'], "'-1' is negative"),
    (['-d', 'nan'], "'nan' is not a finite number"),
])
def test_bad_options_exit_2_naming_the_value(argv, message, capsys) -> None:
    with pytest.raises(SystemExit) as info:
        parameter_overrides(argv)
    assert info.value.code == 2
    err = capsys.readouterr().err
    assert message in err
    if '--pre-roll' in argv:  # a pre-roll is no limit that 0 turns off
        assert 'turns the limit off' not in err


def test_help_lists_the_options_the_default_topics_and_the_services(capsys) -> None:
    with pytest.raises(SystemExit) as info:
        build_parser().parse_args(['--help'])
    assert info.value.code == 0
    text = capsys.readouterr().out
    for word in ('--output', '--storage', '--regex', '--exclude', '--max-bag-size',
                 '--max-bag-duration', '--chunk-interval', '~/pause', '~/resume', '~/split',
                 'recover', *DEFAULT_TOPICS):
        assert word in text, word
