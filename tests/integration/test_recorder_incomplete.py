"""Episodes labelled by what their bags prove, from real processes over DDS: a recorder in
episode mode, stream publishers that a test can kill (tests/fixtures/stream_publisher.py:
joint states with the driver's count on /diagnostics, the object pose) and the goal events
on /dam/episode published here, as the controller publishes them.

Three goals: one that runs to its end with every stream alive (complete, named by its
outcome); one whose joint-state publisher is killed (SIGKILL) mid-episode (incomplete: the
joint states stop, named with when and about how many are missing); one during which the
recorder is stopped (SIGINT: incomplete, no result and no end event). The names, the
metadata and ``bag info`` say so; both independent readers read the bags.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest
import yaml
from recorder_testing import episode_recording

from ros_testing import installed_executable

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'dam_recorder'))
from bag_readers import read_with_mcap, read_with_rosbags  # noqa: E402

pytestmark = pytest.mark.integration

PRE_ROLL_S = 1.5
POST_ROLL_S = 1.0
RATE_HZ = 200.0
TOPICS = ('/joint_states', '/diagnostics', '/dam/episode', '/sim/object_pose')


def _custom(bag: Path) -> dict[str, str]:
    return yaml.safe_load((bag / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']['custom_data']


def _closed(out: Path, count: int, timeout: float = 30.0) -> list[Path]:
    deadline = time.monotonic() + timeout
    while True:
        bags = sorted(p for p in out.iterdir() if not p.name.endswith('_recording')) \
            if out.is_dir() else []
        if len(bags) >= count:
            return bags
        assert time.monotonic() < deadline, sorted(p.name for p in out.iterdir())
        time.sleep(0.1)


def test_truncated_episodes_are_marked_incomplete_with_what_they_lack(tmp_path: Path) -> None:
    out = tmp_path / 'grasps'
    goals = [uuid.uuid4().hex for _ in range(3)]
    with episode_recording(out, TOPICS, str(PRE_ROLL_S), str(POST_ROLL_S), [
            ('--joint-states', '--rate', str(RATE_HZ)), ('--object-pose', '--rate', '100')]
            ) as (recorder, (joints, pose), client, events):
        client.spin_until(lambda: False, PRE_ROLL_S + 0.5)  # a whole pre-roll of streams
        # 1. Every stream alive to the end.
        events.send(goals[0], 0)
        client.spin_until(lambda: False, 2.0)
        events.send(goals[0], 1)
        # 2. The joint states' publisher (with its count) killed mid-episode.
        client.spin_until(lambda: False, POST_ROLL_S + 0.5)
        events.send(goals[1], 0)
        client.spin_until(lambda: False, 1.5)
        joints.process.send_signal(signal.SIGKILL)
        joints.process.wait(timeout=10.0)
        client.spin_until(lambda: False, 3.5)
        events.send(goals[1], 1)
        _closed(out, 2)
        # 3. The recorder stopped mid-grasp.
        events.send(goals[2], 0)
        client.spin_until(lambda: False, 1.0)
        recorder.process.send_signal(signal.SIGINT)
        assert recorder.process.wait(timeout=20.0) == 0, recorder.output()
        assert pose.alive()
        log = recorder.output()

    bags = {json.loads(_custom(b)['dam_episode.summary'])['goal_id']: b
            for b in _closed(out, 3)}
    assert sorted(bags) == sorted(goals) and len(list(out.iterdir())) == 3
    whole, killed, stopped = (bags[g] for g in goals)

    # 1. Complete: named by its outcome, and says so.
    assert whole.name.endswith('_success'), whole.name
    assert (_custom(whole)['dam_episode.complete'], _custom(whole)['dam_episode.missing']) == \
        ('true', '[]')

    # 2. The joint states stop where their publisher died; nothing else is missing.
    assert killed.name.endswith('_success_incomplete'), killed.name
    custom = _custom(killed)
    assert custom['dam_episode.complete'] == 'false'
    [missing] = json.loads(custom['dam_episode.missing'])
    assert (missing['kind'], missing['topic'], missing['basis']) == \
        ('stopped', '/joint_states', 'rate')
    for read in (read_with_rosbags, read_with_mcap):
        topics = read(killed)
        assert topics['/joint_states'][-1].timestamp == missing['until_ns']
        assert [r.values['event'] for r in topics['/dam/episode']] == [0, 1]
        first = min(rs[0].timestamp for rs in topics.values() if rs)
        end_ns = first + missing['end_s'] * 1e9
        assert topics['/sim/object_pose'][-1].timestamp > end_ns - 0.1e9  # alive to the end
    # About the rate times the silence: from the kill (3.5 s before the end event) to the
    # post-roll's end.
    silence_s = missing['end_s'] - missing['until_s']
    assert 3.5 + POST_ROLL_S - 0.5 < silence_s < 3.5 + POST_ROLL_S + 1.0, missing
    assert missing['short'] == pytest.approx(RATE_HZ * silence_s, rel=0.1)
    assert missing['expected'] == missing['recorded'] + missing['short']

    # 3. Stopped before the goal ended: no result, no end event.
    assert stopped.name.endswith('_unknown_incomplete'), stopped.name
    kinds = [m['kind'] for m in json.loads(_custom(stopped)['dam_episode.missing'])]
    assert kinds[:2] == ['result', 'end_event'], kinds
    assert _custom(stopped)['dam_episode.complete'] == 'false'

    # The recorder's log names them (run.sh reads the path from 'episode OUTCOME: PATH').
    assert f'episode SUCCESS: {killed}\n' in log
    assert f'{killed.name} is INCOMPLETE, the bag lacks: /joint_states: its publisher' in log
    # bag info: the table, the totals, and one bag.
    bag = str(installed_executable('dam_recorder', 'bag'))
    table = subprocess.run([bag, 'info', str(out)], capture_output=True, text=True, timeout=60)
    assert table.returncode == 0, table.stderr
    rows = {line.split()[0]: line.split() for line in table.stdout.splitlines()
            if line.startswith(tuple(b.name for b in bags.values()))}
    assert rows[whole.name][6:8] == ['SUCCESS', 'yes']
    assert rows[killed.name][6:8] == ['SUCCESS', 'NO']
    assert rows[stopped.name][6:8] == ['UNKNOWN', 'NO']
    assert ('  SUCCESS            2  (1 of them INCOMPLETE)\n'
            '  UNKNOWN            1  (it is INCOMPLETE)\n'
            '  INCOMPLETE         2  (counted above by their outcome)') in table.stdout
    one = subprocess.run([bag, 'info', str(killed)], capture_output=True, text=True,
                         timeout=60)
    assert one.returncode == 0, one.stderr
    lines = one.stdout.splitlines()
    at = lines.index('complete:   NO, INCOMPLETE: the bag lacks')
    assert lines[at + 1].startswith('  /joint_states: its publisher\'s count on /diagnostics '
                                    'stops at '), lines[at:]
