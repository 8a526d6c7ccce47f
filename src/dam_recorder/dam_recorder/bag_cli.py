"""``bag``: look into recorded bags (no rclpy).

::

    ros2 run dam_recorder bag info BAG [--json]      # topics, rates, gaps, losses, episode
    ros2 run dam_recorder bag info EPISODES_DIR      # one row per episode bag, totals
    ros2 run dam_recorder bag plot BAG [-o grasp.png] [--episode N | --start S --end S]
    ros2 run dam_recorder bag export BAG [-o DIR] [--topics /joint_states /dam/status]
                                         [--episode N | --start S --end S]

Exit status 0 on success, 1 when a bag cannot be read or an output cannot be written (one line
on standard error naming the path and the cause), 2 for a malformed command line.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
from collections.abc import Sequence
from pathlib import Path

from dam_common.closed_output import quiet_when_output_closed
from dam_common.command_line import CommandLineParser
from dam_common.picture import picture_path
from dam_common.progress import Progress
from dam_common.words import counted
from dam_recorder.errors import DamRecorderError

PROG = 'bag'


def _topics(text: str) -> list[str]:
    names = [t for t in text.split(',') if t]
    for name in names:
        if not name.startswith('/'):
            raise argparse.ArgumentTypeError(f'{name!r} is not a topic name (it starts with /)')
    return names


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``bag`` and its subcommands."""
    parser = CommandLineParser(
        prog=PROG,
        description='Look into bags the recorder wrote: describe them (info), draw a grasp '
                    '(plot), write their signals as CSV (export). BAG is a bag directory '
                    '(it holds metadata.yaml); info also takes a directory of episode bags.')
    sub = parser.add_subparsers(dest='command', metavar='{info,plot,export}', required=True)

    info = sub.add_parser(
        'info', help='topics, counts, rates, gaps, losses and episodes of a bag',
        description='For one bag: each topic with its type, message count, mean rate [Hz], '
                    'the largest gap between consecutive messages and when it began '
                    '[s from the bag start], the messages the recorder counted lost, '
                    'dropped, paused and trimmed, its backlog, the episode metadata (outcome, '
                    'k_theta, delta_theta_p, check_lift margins), whether the episode is '
                    'complete and what it lacks, and the grasps /dam/status shows. For a '
                    'directory of episode bags: one row per episode (start, durations, '
                    'outcome, complete, k_theta, delta_theta_p, lift guaranteed), what the '
                    'incomplete ones lack and the totals per outcome (every episode by its '
                    'outcome, and how many of them are INCOMPLETE).')
    info.add_argument('bag', metavar='BAG', help='a bag directory or a directory of bags')
    info.add_argument('--json', action='store_true',
                      help='print JSON instead of text (non-finite numbers as "nan", "inf")')

    plot = sub.add_parser(
        'plot', help='draw a grasp: joint angles and torques, phases, object rise, margins',
        description='Draw the grasp recorded in BAG: per finger the compliant and position '
                    'joint angles [deg] and torques [N*m] (/joint_states), the controller '
                    'phases (/dam/status) as shaded spans, the object rise [mm] '
                    '(/sim/object_pose) with the stretches off the table and the lift-off '
                    '(/sim/object_table_contact: the stand-in\'s ground truth) and the '
                    'controller\'s estimated rise (/dam/episode), and the check_lift margins '
                    '(episode metadata, or the action feedback). What the bag lacks is listed '
                    'in the picture.')
    plot.add_argument('bag', metavar='BAG', help='the bag directory')
    plot.add_argument('-o', '--output', metavar='FILE', type=picture_path,
                      help='picture to write; the suffix picks the format (.png, .pdf, .svg, '
                           '.jpg, ...; another is refused); '
                           'default <bag name>.png in the current directory')
    plot.add_argument('--dpi', type=int, default=110, help='resolution of a PNG (default 110)')
    _selection_options(plot, 'the only one; of several, the last (the others are named)')

    export = sub.add_parser(
        'export', help='write the signals as CSV, one file per topic',
        description='Write one CSV file per topic: time_s [s from the bag start], time_ns '
                    '[ns since the epoch], then every field flattened (header.stamp.sec, '
                    'position.finger1_compliant_joint, status.0.name). Existing files of '
                    'the same name are written over.')
    export.add_argument('bag', metavar='BAG', help='the bag directory')
    export.add_argument('-o', '--output', metavar='DIR', type=Path,
                        help='output directory (created); default <bag name>_csv in the '
                             'current directory')
    export.add_argument('-t', '--topics', metavar='TOPIC', nargs='+', type=_topics,
                        help='topics to export (names, or one comma-separated list); '
                             'default every topic')
    _selection_options(export, 'the whole bag')
    return parser


def _selection_options(parser: argparse.ArgumentParser, default: str) -> None:
    group = parser.add_argument_group(
        'which part of the bag', 'the grasps are found from /dam/status and numbered as bag '
        f'info BAG lists them (default: {default})')
    group.add_argument('--episode', type=_grasp_number, metavar='N',
                       help='the N-th grasp of the bag (1 is the first)')
    group.add_argument('--start', type=_seconds, metavar='S',
                       help='window start [s from the bag\'s first message]')
    group.add_argument('--end', type=_seconds, metavar='S',
                       help='window end [s from the bag\'s first message]')


def _grasp_number(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a grasp number (1, 2, ...)') from None
    if value < 1:
        raise argparse.ArgumentTypeError(f'{text!r}: grasps are numbered from 1')
    return value


def _seconds(text: str) -> float:
    try:
        value = float(text.removesuffix('s'))
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a time [s]') from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f'{text!r} is not a finite time')
    return value


def _one_bag(path: str) -> None:
    """Refuse a directory of episode bags where one bag is needed."""
    from dam_recorder.bag_reading import locate

    kind, bags = locate(path)
    if kind == 'episodes':
        raise DamRecorderError(
            f'{path}: a directory of {len(bags)} bags, not one bag; give one of them, '
            f'e.g. {bags[0]}')


def run_info(args: argparse.Namespace) -> int:
    from dam_recorder import bag_info as core
    from dam_recorder import bag_info_text as text
    from dam_recorder.bag_reading import locate

    kind, _bags = locate(args.bag)
    if kind == 'bag':
        info = core.bag_info(args.bag)
        print(json.dumps(text.bag_info_json(info), indent=1) if args.json
              else text.format_bag_info(info))
        return 0
    episodes = core.episodes_info(args.bag)
    print(json.dumps(text.episodes_json(episodes), indent=1) if args.json
          else text.format_episodes(episodes))
    for error in episodes.errors:
        print(f'{PROG} info: {error}', file=sys.stderr)
    return 1 if episodes.errors else 0


def run_plot(args: argparse.Namespace) -> int:
    from dam_recorder.bag_plot import plot_bag

    _one_bag(args.bag)
    if args.dpi <= 0:
        raise DamRecorderError(f'--dpi must be positive, got {args.dpi}')
    output = args.output or Path(f'{Path(args.bag).resolve().name}.png')
    with Progress(f'{PROG} plot', 'drawing'):  # a line every few seconds (stderr)
        result = plot_bag(args.bag, output, dpi=args.dpi, episode=args.episode,
                          start_s=args.start, end_s=args.end)
    data = result.data
    print(f'{output}: {data.title()}')
    chosen = data.selection
    if chosen is not None and (chosen.grasp_count > 1 or args.start is not None
                               or args.end is not None):
        print(f'  shown: {chosen.description}')
        for note in chosen.notes:
            print(f'  {note}')
    print(f'  {len(data.joints)} joints, {len(data.phases)} phase spans'
          + (', check_lift margins' if data.margins else ''))
    if data.object_truth is not None and (data.object_truth.rise_final_mm is not None
                                          or data.object_truth.contact_recorded):
        from dam_recorder.object_record import object_lines

        for line in object_lines(data.object_truth, data.object_estimate):
            print(f'  {line}')
    for item in data.missing:
        print(f'  missing: {item}')
    return 0


def run_export(args: argparse.Namespace) -> int:
    from dam_recorder.bag_export import export_bag

    _one_bag(args.bag)
    topics = [t for group in args.topics for t in group] if args.topics else None
    selection = None
    with Progress(f'{PROG} export', 'writing CSV'):  # a line every few seconds (stderr)
        if args.episode is not None or args.start is not None or args.end is not None:
            from dam_recorder.bag_plot import read_selection

            selection = read_selection(args.bag, episode=args.episode, start_s=args.start,
                                       end_s=args.end)
            print(f'{args.bag}: {selection.description}')
        for exported in export_bag(args.bag, args.output, topics, selection):
            print(f'{exported.path}: {counted(exported.rows, "row")}, '
                  f'{counted(len(exported.columns), "column")} ({exported.topic})')
    return 0


@quiet_when_output_closed  # `| head`: status 141, no traceback
def main(argv: Sequence[str] | None = None) -> int:
    """Run ``bag`` with ``argv`` (default: the process's arguments); return the exit status."""
    args = build_parser().parse_args(sys.argv[1:] if argv is None else list(argv))
    commands = {'info': run_info, 'plot': run_plot, 'export': run_export}
    try:
        return commands[args.command](args)
    except DamRecorderError as exc:
        print(f'{PROG} {args.command}: {exc}', file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # the reader of our output went away (| head)
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == '__main__':
    sys.exit(main())
