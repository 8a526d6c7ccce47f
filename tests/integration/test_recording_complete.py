"""The recorder loses nothing: for a minute of back-to-back DAM grasps, with ``/joint_states`` at
500 Hz from the real driver and stand-in, every joint state the driver published is in the bag.

The driver reports on ``/diagnostics`` how many joint states it has published and the header
stamp of the last one, in one reading. Between two such readings that are in the bag, the bag
must hold exactly the joint states stamped after the first and up to the second: the
difference of the two counts. Stamps are the driver's, counts are the driver's: the check does
not depend on the recorder's own view.
"""

from __future__ import annotations

import json
import signal
import sys
import time
from pathlib import Path

import pytest
import yaml
from std_srvs.srv import Trigger

from ros_testing import RosClient, config_with_free_ports, installed_executable, node_process

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'dam_recorder'))
from rosbag2_format import metadata_problems  # noqa: E402

# The driver's /joint_states publisher keeps a second of history (STREAM_HISTORY_DEPTH): with
# the usual 10 messages, a recorder that the kernel stopped when the real-time budget ran out
# (several times a minute beside the stack on two cores) lost about 500 joint states a minute.
pytestmark = pytest.mark.integration

#: How long the grasps are recorded [s] (the issue asks for a minute at 500 Hz).
RECORD_S = 60.0
TOPICS = ('/joint_states', '/diagnostics', '/hand/command', '/dam/status', '/dam/episode')


def _wait_for(proc, text: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while text not in proc.output():
        assert proc.alive(), f'exited before printing {text!r}:\n{proc.output()}'
        assert time.monotonic() < deadline, f'no {text!r} within {timeout} s:\n{proc.output()}'
        time.sleep(0.05)


def _grasp_cycles(client: RosClient, until: float) -> list[str]:
    """Grasp, let go, reset the world; again until ``until`` (monotonic) [s]. The outcomes."""
    from rclpy.action import ActionClient

    from dam_interfaces.action import DamGrasp

    action = ActionClient(client.node, DamGrasp, '/dam_grasp')
    outcomes = []
    try:
        assert action.wait_for_server(timeout_sec=30.0)
        while time.monotonic() < until:
            goal = action.send_goal_async(DamGrasp.Goal())  # the configured pair
            assert client.wait_future(goal, 10.0)
            result = goal.result().get_result_async()
            assert client.wait_future(result, 40.0)
            outcomes.append(result.result().result.outcome_name)
            client.spin_until(lambda: False, 0.5)
            client.call(Trigger, '/spcm_controller/release', Trigger.Request(), timeout=30.0)
            client.call(Trigger, '/hand_driver_sim/reset', Trigger.Request(), timeout=30.0)
            client.spin_until(lambda: False, 0.3)
            client.call(Trigger, '/hand_driver/reset', Trigger.Request(), timeout=30.0)
    finally:
        action.destroy()
    return outcomes


def _published_readings(messages) -> list[tuple[int, int]]:
    """(joint states published, stamp of the last [ns]) from each /diagnostics message."""
    readings = []
    for msg in messages:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if 'joint_states_published' in values:
                readings.append((int(values['joint_states_published']),
                                 int(values['joint_states_last_stamp_ns'])))
    return readings


def test_a_minute_of_grasps_at_500_hz_loses_no_joint_state(tmp_path: Path) -> None:
    from rosbags.highlevel import AnyReader

    config = config_with_free_ports(tmp_path)
    env = {'DAM_CONFIG': str(config)}
    bag = tmp_path / 'minute'
    rate_hz = yaml.safe_load(config.read_text())['device']['rate_hz']
    assert rate_hz == 500.0
    with node_process([installed_executable('dam_recorder', 'recorder'), '-o', str(bag),
                       *TOPICS], env=env) as recorder, \
            node_process([installed_executable('dam_hand_driver', 'hand_driver'),
                          '--ros-args', '-p', 'backend:=sim'], env=env) as driver, \
            node_process([installed_executable('dam_analysis', 'check_lift_server')],
                         env=env), \
            node_process([installed_executable('dam_spcm_controller', 'spcm_controller')],
                         env=env):
        _wait_for(recorder, 'recording /joint_states')
        _wait_for(recorder, 'recording /diagnostics')
        client = RosClient()
        try:
            outcomes = _grasp_cycles(client, time.monotonic() + RECORD_S)
        finally:
            client.close()
        time.sleep(1.2)  # one more /diagnostics reading after the last grasp
        recorder.process.send_signal(signal.SIGINT)
        assert recorder.process.wait(timeout=20.0) == 0, recorder.output()
        assert driver.alive(), driver.output()
    assert len(outcomes) >= 3, outcomes
    assert metadata_problems(bag) == []
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert json.loads(info['custom_data']['dam_recorder.lost_messages']).get(
        '/joint_states', 0) == 0

    with AnyReader([bag]) as reader:
        by_topic = {c.topic: c for c in reader.connections}
        stamps = [
            (m := reader.deserialize(raw, c.msgtype)).header.stamp.sec * 1_000_000_000
            + m.header.stamp.nanosec
            for c, _t, raw in reader.messages(connections=[by_topic['/joint_states']])]
        readings = _published_readings(
            reader.deserialize(raw, c.msgtype)
            for c, _t, raw in reader.messages(connections=[by_topic['/diagnostics']]))
    readings = [r for r in readings if r[0] > 0 and stamps and r[1] >= stamps[0]]
    assert len(readings) >= 2, readings
    (count_a, stamp_a), (count_b, stamp_b) = readings[0], readings[-1]
    span_s = (stamp_b - stamp_a) / 1e9
    assert span_s > 0.9 * RECORD_S, span_s
    published = count_b - count_a
    # A real 500 Hz stream (world resets pause it for a moment)...
    assert published > 0.8 * rate_hz * span_s, (published, span_s)
    # ...and every message of it is in the bag.
    in_bag = sum(1 for s in stamps if stamp_a < s <= stamp_b)
    assert in_bag == published, f'{published - in_bag} of {published} joint states missing'
    assert len(set(stamps)) == len(stamps), 'a joint state is in the bag twice'
