"""Per-grasp episodes from real processes: the controller's /dam/episode events, through a
recorder in episode mode (``recorder --episodes``), to one bag per /dam_grasp goal.

The stack is the one a researcher runs: the PyBullet stand-in behind the driver, the /check_lift
server, the controller and the recorder with its defaults, as separate processes over DDS. Two
goals: a grasp run to its end and a grasp cancelled on its way. The test does not judge the
grasps (``test_dam_grasp.py`` does): whatever their outcome, each goal must be one bag named by
its outcome, marked complete, and holding the goal's result as the action returned it, the
/check_lift answer (compared with a call of our own), the configuration file's text, the
software version, the signals from the pre-roll before the goal to the post-roll after its
end, the hand's URDF and both events; both independent readers read it, and the installed
``bag plot`` draws it.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from std_srvs.srv import Trigger

from ros_testing import RosClient, config_with_free_ports, installed_executable, node_process

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'dam_recorder'))
from bag_readers import read_with_mcap, read_with_rosbags  # noqa: E402
from rosbag2_format import metadata_problems  # noqa: E402

# Real-time runs on a shared 2-core machine: a failure is run once more (R in the summary).
# Alone (exclusive): beside another worker's stack the driver's ~/reset, which waits 0.5 s of
# wall time for a device state, failed, and a release waited for joint states (two full runs).
pytestmark = [pytest.mark.integration, pytest.mark.exclusive, pytest.mark.flaky(reruns=1)]

DELTA_THETA_P = math.radians(10.0)
PRE_ROLL_S = 2.0
POST_ROLL_S = 1.0
FINGERS = ('finger1', 'finger2', 'finger3')


class _Goals:
    """An action client of /dam_grasp that keeps every goal as sent and its result."""

    def __init__(self, client: RosClient) -> None:
        from rclpy.action import ActionClient

        from dam_interfaces.action import DamGrasp

        self.client = client
        self.action = ActionClient(client.node, DamGrasp, '/dam_grasp')
        self.goal_type = DamGrasp.Goal
        self.sent: dict[str, dict[str, list[float]]] = {}  # goal id -> the goal as sent
        self.results: dict[str, object] = {}  # goal id -> DamGrasp.Result

    def send(self, k_theta: float):
        future = self.action.send_goal_async(
            self.goal_type(k_theta=[k_theta], delta_theta_p=[DELTA_THETA_P]))
        assert self.client.wait_future(future, 10.0), 'no answer to the goal'
        handle = future.result()
        assert handle.accepted
        goal_id = bytes(bytearray(handle.goal_id.uuid)).hex()
        self.sent[goal_id] = {'k_theta': [k_theta], 'delta_theta_p': [DELTA_THETA_P]}
        return handle

    def result(self, handle, timeout: float = 30.0):
        future = handle.get_result_async()
        assert self.client.wait_future(future, timeout), f'no result within {timeout} s'
        result = future.result().result
        self.results[bytes(bytearray(handle.goal_id.uuid)).hex()] = result
        return result


@pytest.fixture(scope='module')
def stack(tmp_path_factory: pytest.TempPathFactory) -> Iterator[tuple[_Goals, Path, Path, object]]:
    base = tmp_path_factory.mktemp('episodes')
    config_file = config_with_free_ports(base)
    episodes_dir = base / 'grasps'
    env = {'DAM_CONFIG': str(config_file)}
    with node_process([installed_executable('dam_recorder', 'recorder'), '--episodes',
                       '-o', str(episodes_dir), '--pre-roll', str(PRE_ROLL_S),
                       '--post-roll', str(POST_ROLL_S)], env=env) as recorder, \
            node_process([installed_executable('dam_hand_driver', 'hand_driver'),
                          '--ros-args', '-p', 'backend:=sim'], env=env) as driver, \
            node_process([installed_executable('dam_analysis', 'check_lift_server')],
                         env=env) as analysis, \
            node_process([installed_executable('dam_spcm_controller', 'spcm_controller')],
                         env=env) as controller, \
            node_process([installed_executable('dam_hand_driver', 'dam_state_publisher')],
                         env=env) as frames:
        client = RosClient()
        goals = _Goals(client)
        try:
            assert goals.action.wait_for_server(timeout_sec=30.0), controller.output()
            deadline = time.monotonic() + 30.0
            while not all(f'recording {t} ' in recorder.output()
                          for t in ('/joint_states', '/dam/episode', '/robot_description',
                                    '/tf', '/tf_static')):
                assert time.monotonic() < deadline, recorder.output()
                time.sleep(0.1)
            yield goals, episodes_dir, config_file, recorder
        finally:
            goals.action.destroy()
            client.close()
            for proc in (frames, controller, analysis, driver, recorder):
                assert proc.alive(), proc.output()


def _ready(client: RosClient) -> int:
    """Joint states flowing: a stand-in stalled by a reset or at start-up leaves the driver in
    ERROR, which its ~/reset ends (it answers 'already ACTIVE' otherwise). Returns the time
    [ns since the epoch] before the reset: a driver that was in ERROR published nothing until
    then (it publishes no joint states in ERROR), so a pre-roll holds nothing older."""
    before_ns = time.time_ns()
    assert client.call(Trigger, '/hand_driver/reset', Trigger.Request()).success
    # A second of signals before the goal: a pre-roll that is lost cannot pass for one that
    # starts at the reset (the check below allows 0.5 s).
    client.spin_until(lambda: False, 1.0)
    return before_ns


def _episode_bags(episodes_dir: Path, goal_ids: list[str], recorder) -> dict[str, Path]:
    """goal id -> its closed episode bag, waiting for the post-roll of the last goal."""
    deadline = time.monotonic() + 30.0
    while True:
        found = {}
        for bag in episodes_dir.iterdir():
            if bag.name.endswith('_recording') or not (bag / 'metadata.yaml').is_file():
                continue
            custom = yaml.safe_load((bag / 'metadata.yaml').read_text())[
                'rosbag2_bagfile_information']['custom_data']
            goal_id = json.loads(custom['dam_episode.summary'])['goal_id']
            assert goal_id not in found, (bag, found[goal_id])  # one bag per goal
            found[goal_id] = bag
        if all(goal_id in found for goal_id in goal_ids):
            return found
        assert time.monotonic() < deadline, (sorted(p.name for p in episodes_dir.iterdir()),
                                             recorder.output()[-3000:])
        time.sleep(0.2)


def test_each_goal_becomes_one_episode_bag_with_its_result_and_signals(stack) -> None:
    from dam_interfaces.srv import CheckLift

    goals, episodes_dir, config_file, recorder = stack
    client = goals.client
    streaming_ns: dict[str, int] = {}  # goal id -> joint states flowing since [ns]
    since_ns = _ready(client)
    handle = goals.send(10.0)
    streaming_ns[bytes(bytearray(handle.goal_id.uuid)).hex()] = since_ns
    finished = goals.result(handle)
    # Let go and put the world back, then a grasp cancelled on its way. (Where the device
    # stream stalled, the driver is in ERROR first: docs/simulation_grasp.md, "The CPU budget
    # of two cores".)
    _ready(client)
    released = client.call(Trigger, '/spcm_controller/release', Trigger.Request(), timeout=120.0)
    assert released.success, released.message
    assert client.call(Trigger, '/hand_driver_sim/reset', Trigger.Request()).success
    since_ns = _ready(client)
    handle = goals.send(0.5)
    streaming_ns[bytes(bytearray(handle.goal_id.uuid)).hex()] = since_ns
    client.spin_until(lambda: False, 1.0)
    cancel = handle.cancel_goal_async()
    assert client.wait_future(cancel, 10.0)
    cancelled = goals.result(handle)
    assert finished.outcome_name != '' and cancelled.outcome_name != ''

    # (this test's goals: a rerun finds the goals of the first try in the module's stack)
    bags = _episode_bags(episodes_dir, list(streaming_ns), recorder)
    checked = 0
    config_text = config_file.read_text(encoding='utf-8')
    for goal_id in streaming_ns:
        result = goals.results[goal_id]
        bag = bags[goal_id]
        custom = yaml.safe_load((bag / 'metadata.yaml').read_text())[
            'rosbag2_bagfile_information']['custom_data']
        summary = json.loads(custom['dam_episode.summary'])
        # Labelled by its outcome, and complete: no false INCOMPLETE for a whole episode.
        assert bag.name.endswith('_' + result.outcome_name.lower()), bag.name
        assert custom['dam_episode.complete'] == 'true', custom['dam_episode.missing']
        assert json.loads(custom['dam_episode.missing']) == []
        assert json.loads(custom['dam_recorder.dropped_messages']) == {}
        assert summary['outcome'] == result.outcome
        assert summary['message'] == result.message
        assert summary['duration_s'] == pytest.approx(result.duration)
        assert summary['goal'] == goals.sent[goal_id]
        assert custom['dam_episode.config'] == config_text
        assert custom['dam_episode.version'].startswith('dam_common ')
        assert metadata_problems(bag) == []
        # The /check_lift answer the controller got (none if the server did not answer within
        # the controller's check_lift_timeout: a first call may take longer), equal to ours.
        answer = summary['check_lift']
        if answer is not None:
            checked += 1
            k_theta = summary['k_theta'][0]
            expected = client.call(CheckLift, '/check_lift', CheckLift.Request(
                k_theta=[k_theta], delta_theta_p=[DELTA_THETA_P]))
            assert answer['lift_guaranteed'] == expected.lift_guaranteed
            assert answer['worst_case_margin'] == pytest.approx(expected.worst_case_margin)
            assert answer['csm_margin'] == pytest.approx(expected.csm_margin)
            assert summary['friction_angle'] == pytest.approx(expected.friction_angle)
            assert summary['delta_theta_p'] == pytest.approx([DELTA_THETA_P] * 3)
        topics = read_with_rosbags(bag)
        # Nothing outside the window from the pre-roll before the goal to the post-roll after
        # its end, by the times the messages arrived (what the recorder windows by; the events
        # are stamped by the controller); the pre-roll's ring buffer is there. (The latched
        # /robot_description is stamped at the pre-roll's start. How much of the post-roll
        # arrives depends on the machine: a starved recorder closes the episode on time. The
        # pre-roll starts with the signals at the later of its start and the driver's reset
        # before the goal: where the stand-in had stalled, the driver published nothing before.)
        stamps = [r.timestamp for t, rs in topics.items() for r in rs]
        firsts = [r[0].timestamp for t, r in topics.items()
                  if r and t not in ('/robot_description', '/tf_static')]
        pre, post = PRE_ROLL_S * 1e9, POST_ROLL_S * 1e9
        assert summary['accepted_ns'] - pre - 0.1e9 < min(stamps)
        late = {t: rs[-1].timestamp - summary['ended_ns'] for t, rs in topics.items()
                if rs and rs[-1].timestamp >= summary['ended_ns'] + post + 0.5e9}
        assert not late, late
        assert min(firsts) < max(summary['accepted_ns'] - pre, streaming_ns[goal_id]) + 0.5e9
        assert len(topics['/joint_states']) > 500
        [description] = topics['/robot_description']
        assert description.values['data'].startswith('<?xml')
        events = [r.values for r in topics['/dam/episode'] if r.values['goal_id'] == goal_id]
        assert [e['event'] for e in events] == [0, 1]  # STARTED, ENDED
        assert events[1]['outcome'] == result.outcome
        mcap_topics = read_with_mcap(bag)
        assert [r.data for r in mcap_topics['/dam/status']] == \
            [r.data for r in topics['/dam/status']]
        # What a 3D view needs, read back by both readers: every joint's frame and the
        # object's on /tf, and the latched fingertip frames on /tf_static in every episode.
        moving = {t['child_frame_id'] for r in topics['/tf'] for t in r.values['transforms']}
        assert moving == {f'{f}_{role}_link' for f in FINGERS
                          for role in ('compliant', 'locked', 'position')} | {'object'}
        assert {t['header']['frame_id'] for r in topics['/tf'] for t in r.values['transforms']
                if t['child_frame_id'] == 'object'} == {'hand_base'}
        [static] = topics['/tf_static']
        assert {t['child_frame_id'] for t in static.values['transforms']} == \
            {f'{f}_fingertip' for f in FINGERS}
        for topic in ('/tf', '/tf_static'):
            assert [r.data for r in mcap_topics[topic]] == [r.data for r in topics[topic]]
            assert [[t['child_frame_id'] for t in r.values['transforms']]
                    for r in mcap_topics[topic]] == \
                [[t['child_frame_id'] for t in r.values['transforms']] for r in topics[topic]]
    assert checked >= 1  # the second goal, at least, found the server warm
    # The picture of the finished grasp, drawn by the installed bag tool.
    bag = bags[next(g for g, r in goals.results.items() if r is finished)]
    picture = episodes_dir.parent / 'finished.png'
    drawn = subprocess.run([str(installed_executable('dam_recorder', 'bag')), 'plot', str(bag),
                            '-o', str(picture)], capture_output=True, text=True, timeout=120)
    assert drawn.returncode == 0, drawn.stderr
    assert '9 joints' in drawn.stdout, drawn.stdout
    assert ('missing: check_lift margins' in drawn.stdout) == (
        json.loads(yaml.safe_load((bag / 'metadata.yaml').read_text())[
            'rosbag2_bagfile_information']['custom_data']['dam_episode.summary'])['check_lift']
        is None)
    assert 'object rise' in drawn.stdout and picture.stat().st_size > 20_000
