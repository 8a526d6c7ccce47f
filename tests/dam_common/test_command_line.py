"""Negative values on every command line are values, judged by their own option (issue: a
negative value was taken for an option: ``expected at least one argument``)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from dam_common.command_line import CommandLineParser

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from ros_testing import installed_executable  # noqa: E402


def _parser() -> CommandLineParser:
    parser = CommandLineParser(prog='t')
    parser.add_argument('--many', '--much', nargs='+', default=[])
    parser.add_argument('--one')
    parser.add_argument('--each', action='append', default=[])
    parser.add_argument('-q', action='count', default=0)
    parser.add_argument('-v', '--verbose', action='store_true')
    sub = parser.add_subparsers(dest='command')
    plot = sub.add_parser('plot')
    plot.add_argument('--start')
    return parser


@pytest.mark.parametrize('word', ['-1', '-0.5', '-.5', '-1deg', '-1mm', '-5:12:3', '-1e-3',
                                  '-2rad:3rad'])
def test_a_word_of_a_minus_and_a_digit_is_a_value(word: str) -> None:
    options = _parser().parse_args(['--one', word, '--many', '3', word, '-v'])
    assert options.one == word and options.many == ['3', word] and options.verbose


def test_subcommands_read_negative_values_too() -> None:
    options = _parser().parse_args(['plot', '--start', '-3s'])
    assert (options.command, options.start) == ('plot', '-3s')


def test_options_are_still_options() -> None:
    options = _parser().parse_args(['--one', 'x', '--verbose'])
    assert options.verbose and options.one == 'x'
    with pytest.raises(SystemExit):
        _parser().parse_args(['--one', '--verbose'])  # --verbose is no value


def test_an_option_that_looks_like_a_negative_value_is_refused() -> None:
    with pytest.raises(ValueError, match="'-1' looks like a negative value"):
        CommandLineParser().add_argument('-1')


@pytest.mark.parametrize(('words', 'error'), [
    (['--one', 'a', '--one', 'b'], '--one given twice: give it once'),
    (['--one=a', '--one', 'b'], '--one given twice: give it once'),
    (['--many', '1', '2', '--much', '3'], '--much given twice (as --many): give it once'),
    (['-v', '--one', 'a', '--verbose'], '--verbose given twice (as -v): give it once'),
    (['--one', 'a', '--on', 'b'], '--on given twice (as --one): give it once'),
    (['plot', '--start', '1', '--start', '2'], '--start given twice: give it once'),
])
def test_an_option_given_twice_is_refused_not_replaced(
        words: list[str], error: str, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as stopped:
        _parser().parse_args(words)
    assert stopped.value.code == 2
    assert f't{" plot" if words[0] == "plot" else ""}: error: {error}' in capsys.readouterr().err


def test_options_made_to_repeat_and_words_for_others_may_repeat() -> None:
    parser = CommandLineParser(prog='t')
    parser.add_argument('--one')
    parser.add_argument('--each', action='append', default=[])
    parser.add_argument('-q', action='count', default=0)
    options, rest = parser.parse_known_args(
        ['--each', 'a', '-q', '--each', 'b', '-q', '--one', 'x', '--ros-args', '-p', 'a:=1',
         '-p', 'b:=2'])
    assert options.each == ['a', 'b'] and options.q == 2 and options.one == 'x'
    assert rest == ['--ros-args', '-p', 'a:=1', '-p', 'b:=2']


def test_a_sweep_told_two_object_lists_runs_neither() -> None:
    result = _run('dam_experiments', 'sweep', '--object', 'hex_bar', '--objects', 'cylinder',
                  '--k-theta', '3', '--delta-theta-p', '10deg', '--out', '/nonexistent/never')
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert 'sweep: error: --objects given twice (as --object): give it once' in result.stderr


def _run(package: str, executable: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([str(installed_executable(package, executable)), *args],
                          capture_output=True, text=True, timeout=60)


#: (package, executable, arguments, what the error says): each negative value reaches its
#: option, which refuses it by name (before: "expected (at least) one argument").
REFUSED = [
    ('dam_analysis', 'check_lift', ['--friction-angle', '-1deg'],
     "argument --friction-angle: '-1deg': -1 deg must be at least 0 deg (leave the option out"),
    ('dam_analysis', 'plan_lift', ['--position-tolerance', '-1mm'],
     "argument --position-tolerance: '-1mm': -1 mm must be at least 0 mm (leave"),
    ('dam_analysis', 'plan_lift', ['--mass', '-0.03:0.05'],
     "argument --mass: '-0.03:0.05': -30 g must be above 0 g (leave"),
    ('dam_analysis', 'plan_lift', ['--delta-theta-p', '-5deg:10deg'],
     "argument --delta-theta-p: '-5deg:10deg': -5 deg must be at least 0 deg"),
    ('dam_analysis', 'scale_map', ['--radius-range', '-5mm:12mm:3', '--delta-theta-p', '5deg'],
     "argument --radius-range: '-5mm:12mm:3': -5 mm must be above 0 mm"),
    ('dam_spcm_controller', 'dam_grasp', ['--delta-theta-p', '-10deg'],
     "argument --delta-theta-p: '-10deg': -10 deg must be above 0 deg"),
    ('dam_recorder', 'recorder', ['-o', 'x', '--max-bag-duration', '-1.5e1'],
     "argument -d/--max-bag-duration: '-1.5e1' is negative"),
    ('dam_analysis', 'check_lift', ['--delta-theta-p', '-1deg'],
     "argument --delta-theta-p: '-1deg': -1 deg must be above 0 deg"),
]

#: Values the server or the controller would refuse, refused by the command line before it
#: waits for anything (a fresh user's review: they were sent, and the user waited).
OUT_OF_RANGE = [
    ('dam_analysis', 'check_lift', ['--k-theta', '0'], "'0' must be greater than 0 N*m/rad"),
    ('dam_analysis', 'check_lift', ['--k-theta', 'nan'], "'nan' is not a finite number"),
    ('dam_analysis', 'check_lift', ['--delta-theta-p', '95deg'], '95 deg must be at most 90'),
    ('dam_analysis', 'check_lift', ['--friction-angle', '95deg'], '95 deg must be below 90'),
    ('dam_analysis', 'check_lift', ['--timeout', 'nan'], "'nan' is not a finite number"),
    ('dam_analysis', 'plan_lift', ['--friction-angle', '90deg'], '90 deg must be below 90'),
    ('dam_analysis', 'plan_lift', ['--mass', '0'], '0 g must be above 0 g'),
    ('dam_analysis', 'plan_lift', ['--k-theta-max', '0'], "'0' must be greater than 0 N*m/rad"),
    ('dam_analysis', 'plan_lift', ['--timeout', 'inf'], "'inf' is not a finite number"),
    ('dam_spcm_controller', 'dam_grasp', ['--delta-theta-p', '95deg'],
     '95 deg must be at most 90 deg'),
    ('dam_experiments', 'dam_experiment', ['--alpha', '100deg'],
     '--alpha: 100 deg must be in [0, 90) deg'),
    ('dam_experiments', 'dam_experiment', ['--delta-theta-p', '80deg'],
     '--delta-theta-p: 80 deg must be in (0, 65] deg'),
    ('dam_experiments', 'dam_experiment', ['--config', '/nonexistent/dam.yaml'],
     'dam_experiment: '),
    ('dam_analysis', 'check_lift', ['--ros-args', '-p', 'bad'],
     'check_lift: invalid ROS arguments: '),
    ('dam_analysis', 'plan_lift', ['--ros-args', '--params-file', '/nonexistent.yaml'],
     'plan_lift: invalid ROS arguments: '),
    ('dam_recorder', 'recorder', ['-o', 'x', '--ros-args', '-p', 'bad'],
     'recorder: invalid ROS arguments: '),
]


@pytest.mark.parametrize(('package', 'executable', 'args', 'error'), REFUSED,
                         ids=[f'{c[1]}{c[2][0]}' for c in REFUSED])
def test_negative_values_are_refused_by_their_option(package: str, executable: str,
                                                     args: list[str], error: str) -> None:
    result = _run(package, executable, *args)
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert error in result.stderr, result.stderr
    assert 'expected' not in result.stderr, result.stderr


@pytest.mark.parametrize(('package', 'executable', 'args', 'error'), OUT_OF_RANGE,
                         ids=[f'{c[1]}{" ".join(c[2])}' for c in OUT_OF_RANGE])
def test_values_the_other_end_would_refuse_are_refused_at_once(package: str, executable: str,
                                                               args: list[str],
                                                               error: str) -> None:
    result = _run(package, executable, *args)
    assert result.returncode == 2, (result.stdout, result.stderr)
    assert error in result.stderr, result.stderr
    assert 'Traceback' not in result.stderr, result.stderr


def test_dam_grasp_takes_ros_arguments_as_ros2_run_passes_them() -> None:
    result = _run('dam_spcm_controller', 'dam_grasp', '--ros-args', '-p', 'x:=1', '--',
                  '--help')
    assert result.returncode == 0 and 'usage: dam_grasp' in result.stdout, result.stderr
