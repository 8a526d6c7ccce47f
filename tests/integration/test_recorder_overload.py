"""A recorder starved of CPU time stops within its bound and accounts for every message.

Real processes over DDS: the recorder in episode mode at ``nice 19`` beside six CPU burners, a
2000 Hz joint-state stream (with its publisher's count on ``/diagnostics``) and the goal
events on ``/dam/episode`` published here as the controller does. The recorder falls behind
(its backlog grows); SIGINT must close its episode within 10 s of the recorder seeing the
request (the bound it promises: ``stop_write_time``, 2 s of writing, then closing; the signal
reaches the starved process up to seconds late) and end the process, with the episode closed
on disk, labelled by what its bag proves, every message it did not write counted per topic
in the bag's metadata and in the closing line, and the goal events (never dropped) in the
bag.
"""

from __future__ import annotations

import json
import re
import signal
import sys
import time
import uuid
from pathlib import Path

import pytest
import yaml
from recorder_testing import episode_recording

from ros_testing import cpu_burners

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'dam_recorder'))
from bag_readers import read_with_mcap, read_with_rosbags  # noqa: E402

pytestmark = pytest.mark.integration

TOPICS = ('/joint_states', '/diagnostics', '/dam/episode')
#: What the recorder promises: stop_write_time (2 s) of writing, then closing.
STOP_BOUND_S = 10.0


def _episode_closed(out: Path) -> bool:
    names = [p.name for p in out.iterdir()] if out.is_dir() else []
    return bool(names) and not any(n.endswith('_recording') for n in names)


def _counts(custom: dict[str, str], key: str) -> dict[str, int]:
    return json.loads(custom.get(key, '{}'))


@pytest.mark.exclusive  # six burners: never beside another test's grasp (scripts/test.sh)
def test_a_starved_recorder_stops_within_its_bound_and_counts_what_it_did_not_write(
        tmp_path: Path) -> None:
    out = tmp_path / 'grasps'
    goal = uuid.uuid4().hex
    with episode_recording(out, TOPICS, '1', '5', [('--joint-states', '--rate', '2000')],
                           prefix=('nice', '-n', '19'),
                           ros_args=('--ros-args', '-p', 'max_backlog_bytes:=3000000'),
                           start_timeout_s=120.0, match_timeout_s=60.0
                           ) as (recorder, _streams, client, events):
        with cpu_burners(6):
            client.spin_until(lambda: False, 1.5)
            events.send(goal, 0)
            client.spin_until(lambda: False, 8.0)
            events.send(goal, 1)
            client.spin_until(lambda: False, 1.0)
            recorder.process.send_signal(signal.SIGINT)
            asked = time.monotonic()
            closed_after = None
            while recorder.alive() and time.monotonic() - asked < 60.0:
                if closed_after is None and _episode_closed(out):
                    closed_after = time.monotonic() - asked
                time.sleep(0.02)
            status = recorder.process.poll()
            took = time.monotonic() - asked
            if closed_after is None and _episode_closed(out):
                closed_after = took
        log = recorder.output()
    assert status == 0, log
    # The recorder closes its episode within the bound from the moment it sees the stop
    # request (its own account, in its log). The request itself reaches a process that gets
    # about 1 % of a core seconds late (the signal handler runs when its main thread next runs
    # Python: up to 6 s measured), so from SIGINT the episode is on disk within twice the
    # bound; the process ends soon after (each of its threads waits for the CPU to exit: no
    # fixed bound, but never a hang).
    closed_line = re.search(r'the bags are closed ([0-9.]+) s after the stop request', log)
    if closed_line:
        assert float(closed_line.group(1)) <= STOP_BOUND_S, closed_line.group(0)
    assert closed_after is not None and closed_after <= 2 * STOP_BOUND_S, \
        f'episode closed {closed_after} s after SIGINT (exit {took:.1f} s):\n{log[-3000:]}'
    assert status is not None, f'still running {took:.1f} s after SIGINT:\n{log[-3000:]}'

    [bag] = list(out.iterdir())
    assert not bag.name.endswith('_recording'), bag.name
    # Goal events are never dropped by the recorder: an ENDED event that reached it labels
    # the episode (a starved middleware may not deliver it before the stop).
    meta = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    custom = meta['custom_data']
    in_bag = {t['topic_metadata']['name']: t['message_count']
              for t in meta['topics_with_message_count']}
    missing = json.loads(custom['dam_episode.missing'])
    shed = _counts(custom, 'dam_recorder.backlog_dropped_messages')
    not_written = _counts(custom, 'dam_recorder.stop_unwritten_messages')
    dropped = _counts(custom, 'dam_recorder.dropped_messages')

    # Both independent readers read what metadata.yaml counts; both goal events are there.
    for read in (read_with_rosbags, read_with_mcap):
        topics = read(bag)
        assert {t: len(rs) for t, rs in topics.items() if rs} == \
            {t: c for t, c in in_bag.items() if c}
        events_in_bag = [r.values['event'] for r in topics['/dam/episode']]
        assert events_in_bag == ([0, 1] if '_success' in bag.name else [0]), bag.name

    # Every loss counted is named in the episode's verdict, with the same count.
    assert '/dam/episode' not in shed and '/dam/episode' not in not_written
    by_kind = {(m['kind'], m['topic']): m for m in missing}
    for topic, count in shed.items():
        assert by_kind[('backlog_dropped', topic)]['short'] == count
    for topic, count in not_written.items():
        assert by_kind[('not_written', topic)]['short'] == count
    for topic, count in dropped.items():
        assert by_kind[('dropped', topic)]['short'] >= count
    lost_any = bool(shed or not_written or dropped)
    assert bag.name.endswith('_incomplete') == bool(missing)
    assert lost_any <= bool(missing)
    # The closing line counts the whole recording (the episode's counts and those before it).
    line = [x for x in log.splitlines()
            if re.search(r'\b(1 episode|\d+ episodes) recorded in ', x)][-1]
    for label, counts in (('not written at the stop', not_written),
                          ('dropped from the full backlog', shed)):
        total = int(re.search(rf'{label} (\d+)', line).group(1))
        assert total >= sum(counts.values()), line
    assert 'topics not recorded 0' in line, line
    assert float(re.search(r'backlog max ([0-9.]+) s', line).group(1)) > 0.0
