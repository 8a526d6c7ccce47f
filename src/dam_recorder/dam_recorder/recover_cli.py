"""``recover``: make a bag whole again after its recorder was killed (no rclpy).

``ros2 run dam_recorder recover DIR`` rewrites every MCAP file of the bag that lacks its
summary or holds records that cannot be read, from every record that can, and writes
``metadata.yaml`` anew from the data files (:mod:`dam_recorder.recovery`). It prints what it
corrected in ``metadata.yaml``, per file what was lost and why, and per topic the messages
kept. An episode its recorder left open (``..._recording``) is then judged by what the bag
holds and renamed ``<start>_<outcome>_incomplete`` (:mod:`dam_recorder.episode_recovery`):
it prints the outcome, what the bag lacks and the new path. Exit status 0 on success, 1 when
``DIR`` holds no bag that can be recovered.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from dam_common.closed_output import quiet_when_output_closed
from dam_common.command_line import CommandLineParser
from dam_common.words import counted
from dam_recorder.completeness import describe
from dam_recorder.errors import RecoveryError
from dam_recorder.recovery import recover_bag


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``recover``."""
    parser = CommandLineParser(
        prog='recover',
        description='Make a bag whose recorder was killed, or whose files were damaged, '
                    'readable again: rewrite damaged MCAP files from every record that can be '
                    'read (a chunk that cannot is skipped and its messages counted as lost), '
                    'and metadata.yaml from what the files hold (the files win where the old '
                    'metadata disagrees). Messages of the chunk that was being written when '
                    'the recorder died are lost (at most chunk_interval, 1 s by default). An '
                    'episode the recorder left open (DIR named ..._recording) is then labelled '
                    'by what its bag proves: the outcome from the goal\'s ENDED event in the '
                    'bag (else UNKNOWN), always INCOMPLETE (the kill lost up to '
                    'chunk_interval, and while the goal runs up to 3 s more that an episode '
                    'holds back), with what else it lacks; metadata.yaml says so '
                    '(dam_episode.summary, complete, missing) and '
                    'DIR is renamed <start>_<outcome>_incomplete. It prints the verdict and '
                    'the new path.')
    parser.add_argument('bag', metavar='DIR', help='the bag directory')
    return parser


@quiet_when_output_closed  # `| head`: status 141, no traceback
def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(sys.argv[1:] if argv is None else list(argv))
    try:
        report = recover_bag(args.bag)
    except RecoveryError as exc:
        print(f'recover: {exc}', file=sys.stderr)
        return 1
    for problem in report.metadata_problems:
        print(f'{problem}: corrected from the data files')
    for file in report.files:
        if not file.rebuilt:
            state = 'intact'
        elif file.problems:
            lost = [p for p in file.problems if 'lost' in p and 'nothing lost' not in p]
            state = 'rebuilt, with losses' if lost else 'rebuilt'
        else:
            state = 'rebuilt'
        print(f'{file.path}: {counted(file.message_count, "message")} ({state})')
        for problem in file.problems:
            print(f'  {file.path}: {problem}')
    for topic in report.topics:
        print(f'  {topic.name}: {topic.message_count} ({topic.type})')
    print(f'{report.bag_dir}: {counted(report.message_count, "message")}; metadata.yaml '
          'written')
    verdict, path = report.episode, report.path or report.bag_dir
    if verdict is not None:
        # 'episode OUTCOME: PATH' alone on its line, as the recorder logs a closed episode.
        print(f'episode {verdict.outcome}: {path}')
        goal = verdict.goal_id[:8] or 'unknown: no STARTED event in the bag'
        source = ("from the goal's ENDED event" if verdict.got_result
                  else 'no ENDED event of the goal in the bag')
        print(f'{path.name} is INCOMPLETE (goal {goal}; outcome {source}), the bag '
              'lacks:')
        for line in describe(verdict.missing):
            print(f'  {line}')
        for topic, count in sorted(verdict.undecodable.items()):
            print(f'  ({counted(count, "message")} of {topic} could not be decoded: not counted)')
        if path == report.bag_dir:
            print(f'(not named as an open episode: {path.name} keeps its name)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
