"""The recorder in real runs: real publisher and recorder processes over DDS, the bags read back
by two independent readers (``rosbags`` with deserialization, ``mcap`` with
``mcap-ros2-support``) and every field checked against what was published; SIGINT, SIGTERM,
SIGKILL with ``recover``, and the pause/resume/split services."""

from __future__ import annotations

import json
import random
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
import yaml

from dam_recorder.recorder_node import STARTUP_DISCOVERY_S
from ros_testing import (
    RosClient,
    cpu_burners,
    fixture_command,
    installed_executable,
    node_process,
)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'dam_recorder'))
import recorder_samples as samples  # noqa: E402
from bag_readers import read_with_mcap, read_with_rosbags  # noqa: E402
from rosbag2_format import metadata_problems  # noqa: E402

pytestmark = pytest.mark.integration

COUNT = 100
RECORDER = installed_executable('dam_recorder', 'recorder')
RECOVER = installed_executable('dam_recorder', 'recover')


def wait_for(proc, text: str, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while text not in proc.output():
        assert proc.alive(), f'exited before printing {text!r}:\n{proc.output()}'
        assert time.monotonic() < deadline, f'no {text!r} within {timeout} s:\n{proc.output()}'
        time.sleep(0.05)


def stop(proc, signum: int, timeout: float = 10.0) -> int:
    proc.process.send_signal(signum)
    return proc.process.wait(timeout=timeout)


def metadata(bag: Path) -> dict:
    return yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']


def indices(records: list, topic: str) -> list[int]:
    return [samples.index_of(topic, r.values) for r in records]


def check_values(topic: str, records: list) -> None:
    """Every decoded message equals the sample it was made from."""
    for record in records:
        if record.values is not None:
            assert record.values == samples.sample(topic, samples.index_of(topic, record.values))


def check_both_readers_agree(bag: Path) -> tuple[dict, dict]:
    by_rosbags, by_mcap = read_with_rosbags(bag), read_with_mcap(bag)
    assert by_rosbags.keys() == by_mcap.keys()
    for topic, records in by_rosbags.items():
        other = by_mcap[topic]
        assert [(r.timestamp, r.data) for r in records] == [(r.timestamp, r.data) for r in other]
        for mine, theirs in zip(records, other, strict=True):
            assert theirs.values == mine.values
        check_values(topic, records)
        check_values(topic, other)
    return by_rosbags, by_mcap


def test_sigint_closes_an_mcap_bag_both_readers_read_in_full(tmp_path: Path) -> None:
    bag = tmp_path / 'run'
    with node_process(fixture_command('recorder_publishers.py', '--count', str(COUNT))) as pub:
        wait_for(pub, 'waiting')  # the latched message is out before the recorder starts
        with node_process([RECORDER, '-o', str(bag)]) as rec:
            wait_for(pub, 'done')
            time.sleep(0.3)
            assert stop(rec, signal.SIGINT) == 0, rec.output()
            log = rec.output()
    assert 'Traceback' not in log and f'closed {bag}' in log
    assert metadata_problems(bag) == []
    topics, by_mcap = check_both_readers_agree(bag)
    reliable = [t for t in samples.TOPICS if t not in samples.BEST_EFFORT_TOPICS]
    for topic in [*reliable, samples.LATE_TOPIC]:
        assert indices(topics[topic], topic) == list(range(COUNT)), topic
    for topic in samples.BEST_EFFORT_TOPICS:  # best effort: what arrived, in order
        got = indices(topics[topic], topic)
        assert got and got == sorted(set(got)) and set(got) <= set(range(COUNT))
    assert [r.values for r in topics[samples.LATCHED_TOPIC]] == [{'data': samples.LATCHED_TEXT}]
    feedback = '/dam_grasp/_action/feedback'
    # mcap-ros2-support decodes the feedback (its type renamed, see bag_readers), and
    # rosbags' AnyReader, which checks each stored type hash against the definition, reads it.
    assert by_mcap[feedback][0].values['feedback']['phase'] == \
        topics[feedback][0].values['feedback']['phase']
    from rosbags.highlevel import AnyReader

    with AnyReader([bag]) as reader:
        [connection] = [c for c in reader.connections if c.topic == feedback]
        decoded = [reader.deserialize(raw, connection.msgtype)
                   for _c, _t, raw in reader.messages(connections=[connection])]
    assert [d.feedback.progress for d in decoded] == \
        [r.values['feedback']['progress'] for r in topics[feedback]]
    info = metadata(bag)
    qos = {t['topic_metadata']['name']: t['topic_metadata']['offered_qos_profiles'][0]
           for t in info['topics_with_message_count']}
    assert qos['/sim/object_pose']['reliability'] == 'best_effort'
    assert qos[samples.LATCHED_TOPIC]['durability'] == 'transient_local'
    assert qos['/joint_states']['reliability'] == 'reliable'
    assert qos['/joint_states']['durability'] == 'volatile'
    types = {t['topic_metadata']['name']: t['topic_metadata']['type']
             for t in info['topics_with_message_count']}
    assert types[feedback] == 'dam_interfaces/action/DamGrasp_FeedbackMessage'
    # The serialize_message buffers had trailing bytes: every one was cut.
    trimmed = json.loads(info['custom_data']['dam_recorder.trimmed_messages'])
    assert trimmed['/joint_states'] == COUNT and trimmed['/dam/status'] == COUNT
    assert json.loads(info['custom_data']['dam_recorder.lost_messages']) == {}


def test_sigterm_closes_a_sqlite3_bag_of_the_selected_topics(tmp_path: Path) -> None:
    bag = tmp_path / 'selected'
    selected = ['/joint_states', '/dam_grasp/_action/feedback']
    with node_process(fixture_command('recorder_publishers.py', '--count', str(COUNT),
                                      '--wait-for', *selected, '--no-late')) as pub:
        wait_for(pub, 'waiting')
        with node_process([RECORDER, '-o', str(bag), '-s', 'sqlite3',
                           '-e', '^/(joint_states|dam)', '-x', '^/dam/status$']) as rec:
            wait_for(pub, 'done')
            time.sleep(0.3)
            assert stop(rec, signal.SIGTERM) == 0, rec.output()
    assert metadata_problems(bag) == []
    assert metadata(bag)['storage_identifier'] == 'sqlite3'
    topics = read_with_rosbags(bag)
    assert sorted(topics) == sorted(selected)
    for topic in selected:
        assert indices(topics[topic], topic) == list(range(COUNT))
        check_values(topic, topics[topic])


def test_sigkill_then_recover_gives_back_every_flushed_message(tmp_path: Path) -> None:
    bag = tmp_path / 'killed'
    with node_process(fixture_command('recorder_publishers.py', '--count', str(COUNT))) as pub:
        wait_for(pub, 'waiting')
        with node_process([RECORDER, '-o', str(bag), '--chunk-interval', '0.2']) as rec:
            wait_for(pub, 'done')
            time.sleep(1.0)  # several chunk intervals: everything received is in the file
            assert stop(rec, signal.SIGKILL) == -signal.SIGKILL
    data = (bag / 'killed_0.mcap').read_bytes()
    assert not data.endswith(b'\x89MCAP0\r\n')  # no summary, no footer
    with pytest.raises(Exception):  # noqa: B017 - the index reader refuses it
        read_with_mcap(bag)
    done = subprocess.run([str(RECOVER), str(bag)], capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert 'killed_0.mcap' in done.stdout and 'rebuilt' in done.stdout
    assert metadata_problems(bag) == []
    topics, _ = check_both_readers_agree(bag)
    for topic in [*samples.TOPICS, samples.LATE_TOPIC]:
        if topic not in samples.BEST_EFFORT_TOPICS:
            assert indices(topics[topic], topic) == list(range(COUNT)), topic
    assert len(topics[samples.LATCHED_TOPIC]) == 1


def test_pause_resume_and_split_services(tmp_path: Path) -> None:
    from std_srvs.srv import Trigger

    bag = tmp_path / 'services'
    count = 400  # 4 s at 100 Hz
    with node_process(fixture_command('recorder_publishers.py', '--count', str(count),
                                      '--rate', '100', '--no-late')) as pub:
        wait_for(pub, 'waiting')
        with node_process([RECORDER, '-o', str(bag)]) as rec:
            client = RosClient()
            try:
                wait_for(pub, 'publishing')
                time.sleep(0.5)
                split = client.call(Trigger, '/recorder/split', Trigger.Request())
                assert split.success and split.message == 'now writing services_1.mcap'
                assert client.call(Trigger, '/recorder/pause', Trigger.Request()).success
                again = client.call(Trigger, '/recorder/pause', Trigger.Request())
                assert again.success and again.message == 'was paused already'
                time.sleep(0.8)
                assert client.call(Trigger, '/recorder/resume', Trigger.Request()).message \
                    == 'resumed'
            finally:
                client.close()
            wait_for(pub, 'done')
            time.sleep(0.3)
            assert stop(rec, signal.SIGINT) == 0, rec.output()
            log = rec.output()
    for line in ('~/split: now writing services_1.mcap', '~/pause: paused',
                 '~/pause: was paused already', '~/resume: resumed'):
        assert line in log, log  # each call is in the recorder's log
    assert metadata_problems(bag) == []
    info = metadata(bag)
    assert info['relative_file_paths'] == ['services_0.mcap', 'services_1.mcap']
    got = indices(read_with_mcap(bag)['/joint_states'], '/joint_states')
    assert got == sorted(got) and got[0] == 0 and got[-1] == count - 1
    missing = sorted(set(range(count)) - set(got))
    assert missing, 'nothing was dropped while paused'
    assert missing == list(range(missing[0], missing[-1] + 1))  # one gap: the pause
    paused = json.loads(info['custom_data']['dam_recorder.paused_messages'])
    assert paused['/joint_states'] == len(missing)
    first_file = info['files'][0]['message_count']
    assert 0 < first_file < info['message_count']


# Alone (exclusive), as the driver's storms: its 2 s exit bound is the issue's; beside another
# worker's stack three of 100 exits took 2.1-3.9 s, twice in one full run.
@pytest.mark.exclusive
def test_100_signals_at_random_moments_each_leave_a_whole_bag_or_none(tmp_path: Path) -> None:
    """SIGINT or SIGTERM (at random) at a random moment from the entry point's first line to
    well into recording, while messages flow: exit status 0 within 2 s, no traceback, and the
    bag either not made yet or whole (footer, summary, metadata.yaml that agrees with it)."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from test_shutdown_signals import run_trial

    from dam_recorder.recovery import mcap_is_complete

    rng = random.Random('recorder storm')
    # Up to 2.5 s: on a loaded machine the recorder takes over a second to start recording,
    # and the moments must cover recording too (at least a quarter of the bags hold messages).
    plans = [(rng.uniform(0.0, 2.5), rng.choice((signal.SIGINT, signal.SIGTERM)))
             for _ in range(100)]

    def one(i: int):
        bag = tmp_path / f'bag{i}'
        delay_s, signum = plans[i]
        # The exit bound of 2 s holds with the writing after the stop bounded below it (the
        # default, 2 s, is the bound itself: a backlog left at the signal would exceed it).
        return bag, run_trial([str(RECORDER), '-o', str(bag), '--stop-write-time', '1'],
                              None, delay_s, signum)

    with node_process(fixture_command('recorder_publishers.py', '--count', '100000000',
                                      '--wait-for', '--no-late')):
        with ThreadPoolExecutor(max_workers=2) as pool:
            trials = list(pool.map(one, range(len(plans))))
    problems = []
    with_messages = 0
    for bag, trial in trials:
        why = trial.problem()
        if not why and bag.exists():
            why = '; '.join(metadata_problems(bag))
            if not why and not all(mcap_is_complete(f) for f in bag.glob('*.mcap')):
                why = 'an MCAP file without footer and summary'
            if not why:
                counts = {t: len(r) for t, r in read_with_rosbags(bag).items() if r}
                listed = {t['topic_metadata']['name']: t['message_count']
                          for t in metadata(bag)['topics_with_message_count']}
                if {t: n for t, n in listed.items() if n} != counts:
                    why = f'metadata counts {listed} but the files hold {counts}'
                with_messages += sum(counts.values()) > 0
        if why:
            problems.append(f'{trial.signal_name} after {trial.delay_s:.3f} s: {why}\n'
                            f'{trial.output[-1000:]}')
    assert not problems, f'{len(problems)} of 100 not clean:\n' + '\n'.join(problems[:3])
    assert with_messages >= 25  # the moments cover recording, not only starting


def test_losses_the_middleware_reports_are_logged_and_stored(tmp_path: Path) -> None:
    """Provoked: the recorder is stopped (SIGSTOP) for a second while reliable publishers
    with a history of 5 messages send at 500 Hz; they drop what the recorder has not
    acknowledged, and the middleware tells the recorder when it resumes."""
    bag = tmp_path / 'lossy'
    count = 2500  # 5 s at 500 Hz
    with node_process(fixture_command('recorder_publishers.py', '--count', str(count),
                                      '--rate', '500', '--depth', '5', '--wait-for',
                                      '/joint_states', '--no-late')) as pub:
        wait_for(pub, 'waiting')
        with node_process([RECORDER, '-o', str(bag), '/joint_states',
                           '--ros-args', '-p', 'queue_depth:=5']) as rec:
            wait_for(pub, 'publishing')
            time.sleep(0.5)
            rec.process.send_signal(signal.SIGSTOP)
            time.sleep(3.0)
            rec.process.send_signal(signal.SIGCONT)
            wait_for(pub, 'done')
            time.sleep(0.5)
            assert stop(rec, signal.SIGINT) == 0, rec.output()
            log = rec.output()
    lost = json.loads(metadata(bag)['custom_data']['dam_recorder.lost_messages'])
    recorded = len(read_with_rosbags(bag)['/joint_states'])
    assert lost.get('/joint_states', 0) > 0, (recorded, log[-2000:])
    assert '/joint_states: the middleware reports' in log
    assert recorded + lost['/joint_states'] <= count  # what is recorded was not counted lost
    assert recorded < count


def test_an_incompatible_publisher_is_logged_once_and_counted(tmp_path: Path) -> None:
    """A best-effort publisher joining a topic recorded as reliable delivers nothing to the
    recording: said once per topic, however many such publishers join, and counted in the
    bag's custom data (it used to lose all its messages without a word)."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState

    bag = tmp_path / 'incompatible'
    with node_process(fixture_command('recorder_publishers.py', '--count', '400',
                                      '--rate', '100', '--wait-for', '/joint_states',
                                      '--no-late')) as pub:
        wait_for(pub, 'waiting')
        with node_process([RECORDER, '-o', str(bag), '/joint_states']) as rec:
            wait_for(pub, 'publishing')
            client = RosClient()
            try:
                best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
                late = [client.node.create_publisher(JointState, '/joint_states', best_effort)
                        for _ in range(2)]
                for i in range(50):
                    for p in late:
                        p.publish(JointState(name=['late'], position=[float(i)]))
                    client.spin_until(lambda: False, 0.02)
                wait_for(rec, 'cannot take', timeout=10.0)
                client.spin_until(lambda: False, 1.0)  # the second publisher's event
            finally:
                client.close()
            wait_for(pub, 'done')
            assert stop(rec, signal.SIGINT) == 0, rec.output()
            log = rec.output()
    assert log.count('a publisher joined offering a QoS this recording cannot take') == 1, log
    assert 'RELIABILITY' in log
    counted = json.loads(metadata(bag)['custom_data']['dam_recorder.incompatible_publishers'])
    assert counted.get('/joint_states', 0) == 2, counted
    records = read_with_rosbags(bag)['/joint_states']
    assert all('late' not in (r.values or {}).get('name', []) for r in records)


def test_a_topic_that_appears_late_counts_what_it_sent_before_it_was_found(
        tmp_path: Path) -> None:
    """A volatile topic that appears while recording: what its publisher sent before the
    recorder found it and subscribed is not in the bag, and the bag says exactly how much
    (the messages recorded and the count add up to what was published)."""
    from rosbags.highlevel import AnyReader
    from std_msgs.msg import Int64

    bag = tmp_path / 'late'
    sent = 300
    with node_process([RECORDER, '-o', str(bag), '/dam_test_late']) as rec:
        wait_for(rec, f'recording {bag}')
        client = RosClient()
        try:
            # The recording has begun without it (the topics found in the first
            # STARTUP_DISCOVERY_S were there when it began).
            client.spin_until(lambda: False, STARTUP_DISCOVERY_S + 0.5)
            pub = client.node.create_publisher(Int64, '/dam_test_late', 1000)
            for i in range(1, sent + 1):  # at once, 200 Hz: nobody listens yet
                pub.publish(Int64(data=i))
                client.spin_until(lambda: False, 0.005)
            client.spin_until(lambda: False, 1.0)
        finally:
            client.close()
        assert stop(rec, signal.SIGINT) == 0, rec.output()
        log = rec.output()
    missed = json.loads(metadata(bag)['custom_data']['dam_recorder.before_subscription_messages'])
    with AnyReader([bag]) as reader:
        values = [reader.deserialize(raw, conn.msgtype).data
                  for conn, _t, raw in reader.messages()]
    assert missed.get('/dam_test_late', 0) > 0, (missed, log[-1500:])
    assert values == list(range(missed['/dam_test_late'] + 1, sent + 1)), values[:5]
    assert 'appeared while recording' in log and 'not in the bag' in log


def test_a_topic_there_before_the_recording_counts_nothing_before_it(tmp_path: Path) -> None:
    """A publisher that runs before the recorder starts: what it sent before the start was
    never asked for, however long discovery takes on a busy machine (it was counted as sent
    before the subscription when the first discovery had not found it yet)."""
    from std_msgs.msg import Int64

    bag = tmp_path / 'there'
    client = RosClient()
    try:
        pub = client.node.create_publisher(Int64, '/dam_test_there', 1000)
        count = 0

        def publish_for(seconds: float) -> None:
            nonlocal count
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                count += 1
                pub.publish(Int64(data=count))
                client.spin_until(lambda: False, 0.005)

        publish_for(0.1)
        with node_process([RECORDER, '-o', str(bag), '/dam_test_there']) as rec:
            publish_for(STARTUP_DISCOVERY_S + 2.0)  # the recorder starts meanwhile
            assert stop(rec, signal.SIGINT) == 0, rec.output()
            log = rec.output()
    finally:
        client.close()
    custom = metadata(bag)['custom_data']
    assert json.loads(custom['dam_recorder.before_subscription_messages']) == {}, log[-1500:]
    assert 'appeared while recording' not in log


@pytest.mark.parametrize('clock', [True, False])
def test_messages_before_the_first_clock_are_held_not_stamped_1970(tmp_path: Path,
                                                                   clock: bool) -> None:
    """use_sim_time: messages that come before the first /clock are written once it comes,
    stamped with its time (counted); without any /clock they keep their receive time. No
    message is stamped 0 (a bag that starts in 1970) and none is lost."""
    from builtin_interfaces.msg import Time
    from rosbags.highlevel import AnyReader
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import Int64

    bag = tmp_path / 'sim'
    clock_start_ns = 100 * 10**9
    with node_process([RECORDER, '-o', str(bag), '/dam_test_counter',
                       '--ros-args', '-p', 'use_sim_time:=true']) as rec:
        wait_for(rec, f'recording {bag}')
        client = RosClient()
        try:
            pub = client.node.create_publisher(Int64, '/dam_test_counter', 1000)
            clock_pub = client.node.create_publisher(Clock, '/clock', 10)
            assert client.spin_until(lambda: pub.get_subscription_count() > 0, 20.0)
            for i in range(100):  # no clock yet
                pub.publish(Int64(data=i))
                client.spin_until(lambda: False, 0.005)
            client.spin_until(lambda: False, 1.0)
            if clock:  # the clock runs before the next message comes
                clock_pub.publish(Clock(clock=Time(sec=clock_start_ns // 10**9)))
                client.spin_until(lambda: False, 0.5)
            for i in range(100, 200):
                if clock:
                    t = clock_start_ns + (i - 100) * 10_000_000
                    clock_pub.publish(Clock(clock=Time(sec=t // 10**9, nanosec=t % 10**9)))
                pub.publish(Int64(data=i))
                client.spin_until(lambda: False, 0.01)
            client.spin_until(lambda: False, 1.0)
        finally:
            client.close()
        assert stop(rec, signal.SIGINT) == 0, rec.output()
        log = rec.output()
    with AnyReader([bag]) as reader:
        stamped = [(t, reader.deserialize(raw, conn.msgtype).data)
                   for conn, t, raw in reader.messages()]
    assert sorted(v for _t, v in stamped) == list(range(200)), log[-1500:]
    held = int(metadata(bag)['custom_data']['dam_recorder.before_clock_messages'])
    if clock:
        assert held == 100, log[-1500:]
        assert min(t for t, _v in stamped) >= clock_start_ns
        assert max(t for t, _v in stamped) < clock_start_ns + 10**10
        assert '100 messages arrived before the first /clock' in log
        # The wait for the clock (1.5 s for the first of them) is no backlog: only the 100
        # written after it are measured.
        backlog = json.loads(metadata(bag)['custom_data']['dam_recorder.backlog'])
        assert backlog['messages'] == 100 and backlog['max_s'] < 1.0, backlog
        assert 'behind the receipt' not in log
    else:
        assert held == 0
        assert min(t for t, _v in stamped) > 10**18  # receive times: not 1970
        assert 'no /clock came while recording' in log


def test_log_times_on_simulated_time_beside_two_burners(tmp_path: Path) -> None:
    """use_sim_time beside two CPU burners: an unstamped message's log time is the simulated
    time at its receipt (within one period of the clock tick published just before it), a
    stamped message's is its header stamp; none bunches up where the recorder wrote it."""
    from builtin_interfaces.msg import Time
    from rosbags.highlevel import AnyReader
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_msgs.msg import Header, Int64

    bag = tmp_path / 'sim_log_times'
    period_ns = 10_000_000
    start_ns = 50 * 10**9
    ticks = 400
    with cpu_burners(2), node_process([RECORDER, '-o', str(bag), '/dam_test_counter',
                                       '/dam_test_stamped', '--ros-args', '-p',
                                       'use_sim_time:=true']) as rec:
        wait_for(rec, f'recording {bag}')
        client = RosClient()
        try:
            counter = client.node.create_publisher(Int64, '/dam_test_counter', 1000)
            stamped = client.node.create_publisher(JointState, '/dam_test_stamped', 1000)
            clock_pub = client.node.create_publisher(Clock, '/clock', 1000)
            assert client.spin_until(lambda: counter.get_subscription_count() > 0
                                     and stamped.get_subscription_count() > 0, 30.0)
            wait_for(rec, 'recording /dam_test_stamped')
            for i in range(ticks):
                t = start_ns + i * period_ns
                now = Time(sec=t // 10**9, nanosec=t % 10**9)
                clock_pub.publish(Clock(clock=now))
                counter.publish(Int64(data=i))
                # Stamped half a period later than the tick: its header, not the receipt.
                half = t + period_ns // 2
                stamped.publish(JointState(header=Header(
                    stamp=Time(sec=half // 10**9, nanosec=half % 10**9))))
                client.spin_until(lambda: False, 0.01)
            client.spin_until(lambda: False, 1.0)
        finally:
            client.close()
        assert stop(rec, signal.SIGINT) == 0, rec.output()
        log = rec.output()
    with AnyReader([bag]) as reader:
        counts, stamps = {}, []
        for conn, t, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic == '/dam_test_counter':
                counts[msg.data] = t
            else:
                stamps.append((t, msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec))
    assert sorted(counts) == list(range(ticks)), log[-1500:]
    for i, t in counts.items():
        assert abs(t - (start_ns + i * period_ns)) <= period_ns, (i, t, log[-1500:])
    assert len(stamps) == ticks and all(t == header for t, header in stamps)
    assert metadata(bag)['custom_data']['dam_recorder.log_time'].startswith('header stamp')


def test_every_selected_topic_is_recorded_or_named_as_not_recorded(tmp_path: Path) -> None:
    """100 topics the regex selects: 60 published, 40 with only a subscriber; and one topic
    named that never appears. Each is in the bag with its messages, or named with the reason
    in the metadata and in the closing line."""
    from std_msgs.msg import Int64

    bag = tmp_path / 'many'
    published = [f'/dam_many/p{i:02d}' for i in range(60)]
    subscribed = [f'/dam_many/s{i:02d}' for i in range(40)]
    client = RosClient()
    try:
        pubs = [client.node.create_publisher(Int64, t, 10) for t in published]
        subs = [client.node.create_subscription(Int64, t, lambda _m: None, 10)
                for t in subscribed]
        with node_process([RECORDER, '-o', str(bag), '/dam_never', '--regex',
                           '^/dam_many/']) as rec:
            wait_for(rec, f'recording {bag}')
            deadline = time.monotonic() + 60.0
            while rec.output().count('recording /dam_many/p') < len(published):
                assert time.monotonic() < deadline, rec.output()[-2000:]
                client.spin_until(lambda: False, 0.2)
            for round_ in range(5):
                for pub in pubs:
                    pub.publish(Int64(data=round_))
                client.spin_until(lambda: False, 0.1)
            client.spin_until(lambda: False, 1.0)
            assert stop(rec, signal.SIGINT) == 0, rec.output()
            log = rec.output()
        assert subs
    finally:
        client.close()
    meta = metadata(bag)
    counts = {t['topic_metadata']['name']: t['message_count']
              for t in meta['topics_with_message_count']}
    assert {t: counts.get(t) for t in published} == {t: 5 for t in published}
    not_recorded = json.loads(meta['custom_data']['dam_recorder.not_recorded_topics'])
    assert sorted(not_recorded) == sorted([*subscribed, '/dam_never'])
    assert not_recorded['/dam_never'] == 'never appeared while recording'
    assert all('no publisher' in not_recorded[t] for t in subscribed)
    line = [x for x in log.splitlines() if f'closed {bag}' in x][-1]
    assert 'topics not recorded 41 (' in line and '/dam_many/s39: no publisher' in line, line


def test_record_sh_records_beside_a_session_until_stopped(tmp_path: Path) -> None:
    """scripts/record.sh: the default topics into $DAM_BAG_DIR/rosbag2_<time> until SIGINT."""
    import os

    script = Path(__file__).resolve().parents[2] / 'scripts' / 'record.sh'
    env = dict(os.environ, DAM_BAG_DIR=str(tmp_path / 'bags'))
    with node_process(fixture_command('recorder_publishers.py', '--count', str(COUNT),
                                      '--wait-for', '/joint_states', '--no-late')) as pub:
        wait_for(pub, 'waiting')
        with node_process(['bash', str(script)], env=env) as rec:
            wait_for(pub, 'done')
            time.sleep(0.5)
            assert stop(rec, signal.SIGINT) == 0, rec.output()
    [bag] = list((tmp_path / 'bags').iterdir())
    assert bag.name.startswith('rosbag2_')
    assert metadata_problems(bag) == []
    topics = read_with_rosbags(bag)
    assert indices(topics['/joint_states'], '/joint_states') == list(range(COUNT))


def test_help_and_an_existing_output_directory(tmp_path: Path) -> None:
    shown = subprocess.run([str(RECORDER), '--help'], capture_output=True, text=True,
                           timeout=60)
    assert shown.returncode == 0 and '--output' in shown.stdout and 'recover' in shown.stdout
    (tmp_path / 'taken').mkdir()
    refused = subprocess.run([str(RECORDER), '-o', str(tmp_path / 'taken')],
                             capture_output=True, text=True, timeout=60)
    assert refused.returncode == 1
    assert f'cannot start: {tmp_path / "taken"} exists already' in refused.stderr
    assert list((tmp_path / 'taken').iterdir()) == []
