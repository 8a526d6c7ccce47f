"""When an episode's bag is complete, and what an incomplete one lacks (the rules of
``dam_recorder.completeness``), on message times made up here; the recorder's episodes and
``bag info`` carry the verdict (test_episodes.py, test_bag_info.py)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from dam_recorder.completeness import (
    COMPLETE_KEY,
    MISSING_KEY,
    Completeness,
    EpisodeAccount,
    Missing,
    completeness_custom_data,
    completeness_from_custom_data,
    diagnostic_counts,
    header_stamp_ns,
)
from dam_recorder.errors import EpisodeError

T0 = 1_800_000_000_000_000_000  # [ns]
MS = 1_000_000
S = 1_000_000_000
GOAL = 'ab' * 16
START = T0 + 3 * S  # the goal starts 3 s into the window (the pre-roll)
END = T0 + 12 * S  # the window's end (post-roll included)
TOPICS = ('/dam/episode', '/dam_grasp/_action/status', '/joint_states', '/hand/command',
          '/diagnostics', '/sim/object_pose', '/dam_grasp/_action/feedback',
          '/robot_description')


def full_account(skip=lambda topic, t: False, published=None) -> EpisodeAccount:
    """An episode as the stack records it: joint states and hand commands at 500 Hz (the
    commands from the goal's start to its end at 10 s), their publishers' counts every second
    on /diagnostics, the object pose at 100 Hz, the events and the final status.
    ``skip(topic, t)`` leaves messages out of the bag (t [ns]); ``published(topic, t)`` says
    whether the publisher sent a message (default: every one)."""
    account = EpisodeAccount(GOAL, START)
    account.add('/robot_description', T0, latched=True)
    account.add('/dam/episode', START, [('event', (GOAL, 0))])
    sent = {'/joint_states': 0, '/hand/command': 0}
    last = {'/joint_states': 0, '/hand/command': 0}
    for t in range(T0, END + 1, 2 * MS):
        for topic in ('/joint_states', '/hand/command'):
            if topic == '/hand/command' and not START <= t <= T0 + 10 * S:
                continue
            if published is not None and not published(topic, t):
                continue
            sent[topic] += 1
            last[topic] = t - 300_000  # the header stamp: when the publisher made it
            if not skip(topic, t):
                account.add(topic, t, [('stamp', last[topic])])
        if (t - T0) % (10 * MS) == 0 and not skip('/sim/object_pose', t):
            account.add('/sim/object_pose', t)
        if (t - T0) % S == 500 * MS:
            for topic in ('/joint_states', '/hand/command'):
                if not skip(f'count {topic}', t):
                    account.add('/diagnostics', t + MS, [('count', (topic, sent[topic],
                                                                    last[topic]))])
        if (t - T0) % (100 * MS) == 0 and START <= t <= T0 + 10 * S:
            account.add('/dam_grasp/_action/feedback', t)
    account.add('/dam_grasp/_action/status', T0 + 10 * S, [('status', (GOAL, 4))])
    account.add('/dam/episode', T0 + 10 * S + MS, [('event', (GOAL, 1))])
    return account


def judge(account: EpisodeAccount, **kwargs) -> list[Missing]:
    return account.judge(T0, END, TOPICS, True, **kwargs)


def test_a_whole_episode_is_complete() -> None:
    assert judge(full_account()) == []


def test_messages_missing_between_two_counts_are_named_with_how_many() -> None:
    gone = range(T0 + 5 * S, T0 + 5 * S + 37 * 2 * MS, 2 * MS)  # 37 joint states
    [missing] = judge(full_account(lambda topic, t: topic == '/joint_states' and t in gone))
    assert (missing.kind, missing.topic, missing.short, missing.basis) == \
        ('short', '/joint_states', 37, 'publisher count')
    # Compared from the first count 1 s inside the window to the last 1 s before its end.
    assert missing.expected == 9 * 500 and missing.recorded == 9 * 500 - 37
    assert missing.until_s == pytest.approx(10.501)
    assert 'between 1.501 s and 10.501 s' in missing.detail


def test_a_stream_that_stops_early_is_named_with_when_and_about_how_many() -> None:
    [missing] = judge(full_account(lambda topic, t: topic == '/sim/object_pose'
                                   and t > T0 + 6730 * MS))
    assert (missing.kind, missing.topic, missing.basis) == ('stopped', '/sim/object_pose', 'rate')
    assert missing.until_s == pytest.approx(6.73) and missing.end_s == pytest.approx(12.0)
    assert missing.short == 527 and missing.expected == missing.recorded + 527  # 5.27 s, 100 Hz
    assert missing.detail.startswith('stops at 6.730 s of 12.000 s: about 527 of')


def test_a_counted_topic_whose_publisher_stops_publishing_but_reports_is_complete() -> None:
    """The driver publishes no joint states in ERROR; its counts say so."""
    def publishing(topic: str, t: int) -> bool:
        return topic != '/joint_states' or not T0 + 4 * S < t < T0 + 8 * S
    assert judge(full_account(published=publishing)) == []


def test_a_counted_topic_whose_publisher_dies_stopped_at_its_last_message() -> None:
    def gone(topic: str, t: int) -> bool:  # the driver killed at 6 s: no more of either
        return topic in ('/joint_states', 'count /joint_states') and t > T0 + 6 * S
    [missing] = judge(full_account(published=lambda topic, t: not gone(topic, t), skip=gone))
    assert (missing.kind, missing.topic) == ('stopped', '/joint_states')
    assert missing.until_s == pytest.approx(6.0) and missing.short == 3000  # 6 s at 500 Hz
    assert "count on /diagnostics stops at 5.501 s" in missing.detail


def test_topics_that_follow_the_grasp_may_stop_with_it() -> None:
    """Hand commands stop when a failed grasp has ramped down (no count reported here); the
    feedback with the goal; neither makes the episode incomplete."""
    account = full_account(lambda topic, t: topic.startswith('count /hand')
                           or (topic == '/hand/command' and t > T0 + 9 * S))
    assert judge(account) == []


def test_events_result_and_final_status_are_required() -> None:
    account = EpisodeAccount(GOAL, START)
    account.add('/dam/episode', START, [('event', (GOAL, 0)), ('event', ('cd' * 16, 1))])
    account.add('/dam_grasp/_action/status', START, [('status', (GOAL, 2))])  # executing
    missing = account.judge(T0, END, ['/dam/episode', '/dam_grasp/_action/status'], False)
    assert [(m.kind, m.topic) for m in missing] == [
        ('result', '/dam/episode'), ('end_event', '/dam/episode'),
        ('final_status', '/dam_grasp/_action/status')]
    # Without the action status recorded, it is not asked for; without /dam/episode the
    # events are missing all the same.
    missing = EpisodeAccount(GOAL, START).judge(T0, END, [], True)
    assert [(m.kind, m.detail) for m in missing] == [
        ('start_event', 'no EVENT_STARTED of the goal (/dam/episode is not recorded)'),
        ('end_event', 'no EVENT_ENDED of the goal (/dam/episode is not recorded)')]


def test_drops_count_by_sequence_numbers_or_by_the_middleware_report() -> None:
    account = full_account()
    account.dropped('/sim/object_pose', 4)
    missing = judge(account, lost={'/sim/object_pose': 2, '/dam/status': 3})
    assert [(m.kind, m.topic, m.short, m.basis) for m in missing] == [
        ('dropped', '/sim/object_pose', 4, 'sequence numbers')]
    missing = judge(full_account(), lost={'/joint_states': 3})
    assert [(m.kind, m.short, m.basis) for m in missing] == [
        ('dropped', 3, 'middleware report')]


def test_the_verdict_round_trips_through_custom_data() -> None:
    missing = judge(full_account(lambda topic, t: topic == '/sim/object_pose' and t > T0 + 7 * S))
    data = completeness_custom_data(missing)
    assert data[COMPLETE_KEY] == 'false'
    assert json.loads(data[MISSING_KEY])[0]['until_s'] == pytest.approx(7.0)
    assert completeness_from_custom_data(data) == Completeness(False, tuple(missing))
    assert completeness_from_custom_data(completeness_custom_data([])) == Completeness(True, ())
    assert completeness_from_custom_data({}) is None


@pytest.mark.parametrize('custom, message', [
    ({COMPLETE_KEY: 'yes'}, 'expected "true" or "false"'),
    ({COMPLETE_KEY: 'false', MISSING_KEY: '{"a": 1}'}, 'expected a JSON list'),
    ({COMPLETE_KEY: 'false', MISSING_KEY: '[{"kind": "x"}]'}, r'\[0\]: expected the keys'),
    ({COMPLETE_KEY: 'true', MISSING_KEY: '[{"kind": "x", "topic": "/a", "detail": "d"}]'},
     'is true but dam_episode.missing lists 1'),
    ({COMPLETE_KEY: 'false', MISSING_KEY: '[]'}, 'is false but dam_episode.missing lists 0'),
])
def test_malformed_completeness_is_refused_naming_the_key(custom, message) -> None:
    with pytest.raises(EpisodeError, match=message):
        completeness_from_custom_data(custom)


def test_header_stamps_and_diagnostic_counts_are_read(typestore) -> None:
    t = typestore.types
    msg = t['sensor_msgs/msg/JointState'](
        header=t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](
            sec=1_800_000_000, nanosec=123), frame_id='x'),
        name=[], position=np.array([]), velocity=np.array([]), effort=np.array([]))
    data = bytes(typestore.serialize_cdr(msg, 'sensor_msgs/msg/JointState'))
    assert header_stamp_ns(data) == 1_800_000_000 * S + 123
    big_endian = bytes(typestore.serialize_cdr(msg, 'sensor_msgs/msg/JointState',
                                               little_endian=False))
    assert header_stamp_ns(big_endian) == 1_800_000_000 * S + 123
    assert header_stamp_ns(b'\x00\x01\x00\x00') is None
    statuses = [('dam_hand_driver: device link', {'joint_states_published': '120',
                                                  'joint_states_last_stamp_ns': '77'}),
                ('dam_spcm_controller: commands', {'hand_commands_published': '5',
                                                   'hand_commands_last_stamp_ns': '9'}),
                ('other', {'joint_states_published': 'many', 'joint_states_last_stamp_ns': '1'})]
    assert diagnostic_counts(statuses) == [('count', ('/joint_states', 120, 77)),
                                           ('count', ('/hand/command', 5, 9))]


def test_an_item_of_the_whole_bag_is_described_without_an_empty_topic() -> None:
    from dam_recorder.completeness import Missing, describe

    item = Missing('unwritten', '', '3 message(s) could not be written')
    assert describe([item]) == ['3 message(s) could not be written']
