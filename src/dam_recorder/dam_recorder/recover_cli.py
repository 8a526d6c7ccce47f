"""``recover``: make a bag whole again after its recorder was killed (no rclpy).

``ros2 run dam_recorder recover DIR`` rebuilds the summary and index of every MCAP file of the
bag that lacks them, from the chunks that were written completely, and writes ``metadata.yaml``
anew (:mod:`dam_recorder.recovery`). Exit status 0 on success, 1 when ``DIR`` holds no bag that
can be recovered.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence

from dam_recorder.errors import RecoveryError
from dam_recorder.recovery import recover_bag


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of ``recover``."""
    parser = argparse.ArgumentParser(
        prog='recover',
        description='Make a bag whose recorder was killed readable again: rebuild the summary '
                    'and index of damaged MCAP files from their complete chunks, and '
                    'metadata.yaml from what the files hold. Messages of the chunk that was '
                    'being written when the recorder died are lost (at most chunk_interval, '
                    '1 s by default).')
    parser.add_argument('bag', metavar='DIR', help='the bag directory')
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(sys.argv[1:] if argv is None else list(argv))
    try:
        report = recover_bag(args.bag)
    except RecoveryError as exc:
        print(f'recover: {exc}', file=sys.stderr)
        return 1
    for file in report.files:
        state = (f'rebuilt, {file.dropped_bytes} unreadable bytes at the end dropped'
                 if file.rebuilt else 'intact')
        print(f'{file.path}: {file.message_count} messages ({state})')
    for topic in report.topics:
        print(f'  {topic.name}: {topic.message_count} ({topic.type})')
    print(f'{report.bag_dir}: {report.message_count} messages; metadata.yaml written')
    return 0


if __name__ == '__main__':
    sys.exit(main())
