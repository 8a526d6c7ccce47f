"""A recorder in episode mode killed (SIGKILL) with an episode open, from real processes over
DDS: the joint states with their publisher's count on /diagnostics
(tests/fixtures/stream_publisher.py) and the goal events on /dam/episode, published here as the
controller publishes them. ``bag info`` says the episode is open and to run ``recover``;
``recover`` labels it by what the bag proves (the outcome from the ENDED event, INCOMPLETE
with the kill) and renames it; ``bag info`` then shows that, never RECORDING."""

from __future__ import annotations

import json
import signal
import subprocess
import uuid
from pathlib import Path

import pytest
import yaml
from recorder_testing import episode_recording

from dam_recorder.mcap_salvage import salvage_mcap
from ros_testing import installed_executable

pytestmark = pytest.mark.integration

TOPICS = ('/joint_states', '/diagnostics', '/dam/episode')


def _events_on_disk(out: Path) -> int:
    """The /dam/episode messages in the chunks the open episode's file holds so far."""
    files = list(out.glob('*_recording/*.mcap')) if out.is_dir() else []
    if not files:
        return 0
    salvage = salvage_mcap(files[0])
    ids = {i for i, c in salvage.channels.items() if c.topic == '/dam/episode'}
    return sum(m.channel_id in ids for m in salvage.messages)


def test_a_killed_episode_is_open_until_recover_labels_it_by_what_it_holds(
        tmp_path: Path) -> None:
    out = tmp_path / 'grasps'
    goal = uuid.uuid4().hex
    # A long post-roll: the episode is still open when the recorder is killed after the end.
    with episode_recording(out, TOPICS, '1.0', '30', [('--joint-states', '--rate', '200')]
                           ) as (recorder, _streams, client, events):
        client.spin_until(lambda: False, 1.5)
        events.send(goal, 0)
        client.spin_until(lambda: False, 2.0)
        events.send(goal, 1)
        # The end releases what the episode held back; a chunk is written out every
        # second (chunk_interval): kill it once the ENDED event is on disk.
        assert client.spin_until(lambda: _events_on_disk(out) >= 2, 60.0), \
            recorder.output()
        recorder.process.send_signal(signal.SIGKILL)
        recorder.process.wait(timeout=10.0)
    [opened] = list(out.iterdir())
    assert opened.name.endswith('_recording'), opened.name

    bag = str(installed_executable('dam_recorder', 'bag'))
    table = subprocess.run([bag, 'info', str(out)], capture_output=True, text=True, timeout=60)
    assert table.returncode == 0, table.stderr
    [row] = [line.split() for line in table.stdout.splitlines()
             if line.startswith(opened.name)]
    assert row[row.index('OPEN') + 1] == 'NO', table.stdout
    assert 'ros2 run dam_recorder recover DIR' in table.stdout

    recover = str(installed_executable('dam_recorder', 'recover'))
    done = subprocess.run([recover, str(opened)], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    [closed] = list(out.iterdir())
    assert closed.name == opened.name.replace('_recording', '_success_incomplete')
    assert f'episode SUCCESS: {closed}\n' in done.stdout
    custom = yaml.safe_load((closed / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']['custom_data']
    assert custom['dam_episode.complete'] == 'false'
    kinds = [m['kind'] for m in json.loads(custom['dam_episode.missing'])]
    # The goal's result and both events are in the bag; the kill is named last.
    assert kinds[-1] == 'killed' and not {'result', 'start_event', 'end_event', 'open'} & \
        set(kinds), kinds
    summary = json.loads(custom['dam_episode.summary'])
    assert (summary['goal_id'], summary['outcome_name']) == (goal, 'SUCCESS')

    one = subprocess.run([bag, 'info', str(closed)], capture_output=True, text=True,
                         timeout=60)
    assert one.returncode == 0, one.stderr
    assert 'episode:    SUCCESS (fixture grasp done)' in one.stdout
    assert 'complete:   NO, INCOMPLETE: the bag lacks' in one.stdout
    assert 'the recorder was killed with the episode open' in one.stdout
    assert 'RECORDING' not in one.stdout
