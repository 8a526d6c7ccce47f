"""The recorder's command line: options that become the node's parameters (no rclpy).

``ros2 run dam_recorder recorder -o DIR [topics...]``: an option given on the command line
overrides the parameter of the same meaning (also one from ``--params-file``); an option left
out leaves the parameter as it is. ROS arguments (``--ros-args ...``) are removed before.
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from typing import Any

from dam_common.command_line import CommandLineParser
from dam_recorder.bag_writer import (
    CHUNK_INTERVAL_RANGE_S,
    COMPRESSIONS,
    MIN_SPLIT_BYTES,
    STORAGE_SUFFIXES,
)
from dam_recorder.selection import DEFAULT_TOPICS

EPILOG = f"""\
Without topics and without --regex the default set is recorded:
  {' '.join(DEFAULT_TOPICS)}
A topic is recorded when it is named or matches --regex (anywhere in the name), and does not
match --exclude. Topics that appear later are picked up. The subscription asks for the QoS the
publishers offer (reliable or best effort; transient local for latched topics).

With --episodes, each /dam_grasp goal becomes one bag in the directory -o (which may exist):
from --pre-roll seconds before the goal starts to --post-roll seconds after it ends, named by
start time and outcome (2026_11_29-18_05_12_success), with the goal, the /check_lift answer, the
outcome, the controller's configuration and the software version in its metadata.

Services while recording (std_srvs/srv/Trigger): ~/pause, ~/resume, ~/split.
SIGINT or SIGTERM closes the bag (exit status 0): what was received is written for at most
--stop-write-time seconds, the rest is counted per topic (metadata and the closing line), and
an episode that lacks it is INCOMPLETE. Log times: a message's header stamp when it starts
with a std_msgs/Header, else its receive time (on the simulated clock with use_sim_time).
A write error (a full or read-only file
system, the bag directory removed) is logged once, the bag closed with what is on disk and the
recorder exits with status 74. After a SIGKILL run `ros2 run dam_recorder recover DIR`.
Every option is also a parameter of the node (see docs/recording.md, "Use")."""


def _number(kind: type, *, low: float = 0.0, high: float = math.inf, off: bool = False,
            low_reason: str = '') -> Any:
    """An argparse type: a number in ``[low, high]``, or 0 if ``off`` (no limit)."""
    def parse(text: str) -> Any:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f'{text!r} is not a finite number')
        if off and value == 0:
            return value
        if value < 0:
            raise argparse.ArgumentTypeError(
                f'{text!r} is negative' + (' (0 turns the limit off)' if off else ''))
        if value < low:
            raise argparse.ArgumentTypeError(
                f'{text!r} is below {low:g}{low_reason}' + (' (0 turns the limit off)'
                                                            if off else ''))
        if value > high:
            raise argparse.ArgumentTypeError(f'{text!r} is above {high:g}')
        return value
    return parse


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``recorder``."""
    parser = CommandLineParser(
        prog='recorder', formatter_class=argparse.RawDescriptionHelpFormatter,
        description='Record topics into a rosbag2 bag (MCAP or sqlite3) that ros2 bag info '
                    'and ros2 bag play read.', epilog=EPILOG)
    parser.add_argument('topics', nargs='*', metavar='TOPIC',
                        help='topics to record (default: the set listed below)')
    parser.add_argument('-o', '--output', metavar='DIR',
                        help='bag directory to create (must not exist; default: '
                             'rosbag2_<date>-<time> in the current directory); with '
                             '--episodes the directory of the episode bags')
    parser.add_argument('-s', '--storage', choices=sorted(STORAGE_SUFFIXES),
                        help='storage format (default: mcap)')
    parser.add_argument('--compression', choices=COMPRESSIONS,
                        help='MCAP chunk compression (default: zstd for mcap, none for sqlite3)')
    parser.add_argument('-e', '--regex', metavar='REGEX',
                        help='also record every topic this regular expression matches')
    parser.add_argument('-x', '--exclude', metavar='REGEX',
                        help='never record a topic this regular expression matches')
    parser.add_argument('-b', '--max-bag-size', type=_number(int, low=MIN_SPLIT_BYTES, off=True,
                                     low_reason=', the smallest split size'),
                        metavar='BYTES',
                        help='no file is larger than this once closed: a new file starts '
                             'before a message that could take the current one over; at '
                             f'least {MIN_SPLIT_BYTES} (default: 0, no limit)')
    parser.add_argument('-d', '--max-bag-duration', type=_number(float, off=True), metavar='S',
                        help='start a new file when the current one spans this many seconds '
                             '(default: 0, no limit)')
    parser.add_argument('--chunk-interval', metavar='S',
                        type=_number(float, low=CHUNK_INTERVAL_RANGE_S[0],
                                     high=CHUNK_INTERVAL_RANGE_S[1]),
                        help='write the pending chunk out at least this often: the most that '
                             f'a SIGKILL can lose (default: 1.0; {CHUNK_INTERVAL_RANGE_S[0]:g} '
                             f'to {CHUNK_INTERVAL_RANGE_S[1]:g})')
    parser.add_argument('--max-backlog-bytes', type=_number(int, low=10_000), metavar='B',
                        help='most memory the messages waiting to be written may take; a '
                             'recorder that falls further behind drops (and counts) what '
                             'arrives, never the goal events (default: 268435456, 256 MiB)')
    parser.add_argument('--stop-write-time', type=_number(float, high=60.0), metavar='S',
                        help='after SIGINT or SIGTERM, write what was received for at most '
                             'this long, then count the rest as not written and close '
                             '(default: 2.0)')
    parser.add_argument('--episodes', action='store_true', default=None,
                        help='one bag per /dam_grasp goal, in the directory -o')
    parser.add_argument('--pre-roll', type=_number(float), metavar='S',
                        help='episodes: seconds kept before a goal starts (default: 3.0)')
    parser.add_argument('--post-roll', type=_number(float), metavar='S',
                        help='episodes: seconds recorded after a goal ends (default: 2.0)')
    return parser


def parameter_overrides(argv: Sequence[str]) -> dict[str, Any]:
    """The node parameters the command line ``argv`` (without the program name and without
    ROS arguments) sets. Exits with status 2 and a usage message on a bad command line."""
    args = build_parser().parse_args(list(argv))
    overrides: dict[str, Any] = {}
    if args.topics:
        overrides['topics'] = list(args.topics)
    elif args.regex:
        # --regex alone records what it matches, not the default set; [''] selects no name
        # (an override of a string array parameter cannot be empty).
        overrides['topics'] = ['']
    for option in ('output', 'storage', 'compression', 'regex', 'exclude', 'max_bag_size',
                   'max_bag_duration', 'chunk_interval', 'max_backlog_bytes',
                   'stop_write_time', 'episodes', 'pre_roll', 'post_roll'):
        value = getattr(args, option)
        if value is not None:
            overrides[option] = value
    return overrides
