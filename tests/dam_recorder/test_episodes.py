"""Episode bags: the pre-roll and post-roll windows, latched topics, overlapping goals, the
metadata and the directory names, read back by two readers; when an episode is complete.

The goal events travel on ``/dam/episode`` as the recorder node hands them over: the message
(here a ``std_msgs/String`` naming the event) with the facts it read from it."""

from __future__ import annotations

import json
import math
import struct
import time
from pathlib import Path

import pytest
import yaml
from bag_readers import read_with_mcap, read_with_rosbags
from rosbag2_format import metadata_problems
from test_bag_writer import LATCHED, dam_status, joint_state

from dam_recorder.bag_writer import BagWriter
from dam_recorder.completeness import COMPLETE_KEY, MISSING_KEY
from dam_recorder.episodes import (
    CLOSE_MARGIN_NS,
    CONFIG_KEY,
    SUMMARY_KEY,
    EpisodeRecorder,
    TopicSpec,
    json_safe,
)
from dam_recorder.errors import ConfigurationError
from dam_recorder.qos import to_rosbags_qos
from dam_recorder.type_description import load_message_type

T0 = 1_700_000_000_000_000_000  # [ns]
MS = 1_000_000  # [ns]
GOAL = 'ab' * 16


def make_recorder(tmp_path: Path, pre_roll_s: float = 0.5, post_roll_s: float = 0.2,
                  storage: str = 'mcap') -> EpisodeRecorder:
    def open_bag(bag_dir: Path, stem: str, custom_data) -> BagWriter:
        return BagWriter(bag_dir, storage=storage,
                         compression='zstd' if storage == 'mcap' else 'none',
                         custom_data=custom_data, file_stem=stem)
    return EpisodeRecorder(tmp_path / 'episodes', open_bag, pre_roll_s, post_roll_s,
                           custom_data=lambda: {'dam_recorder.paused_messages': '{}'})


def specs(prefixes) -> tuple[TopicSpec, TopicSpec]:
    js = load_message_type('sensor_msgs/msg/JointState', prefixes)
    st = load_message_type('dam_interfaces/msg/DamStatus', prefixes)
    return (TopicSpec('/joint_states', js.name, js.definition(), js.type_hash, []),
            TopicSpec('/dam/status', st.name, st.definition(), st.type_hash,
                      [to_rosbags_qos(LATCHED)], latched=True))


def event_topic(rec: EpisodeRecorder) -> int:
    """The ``/dam/episode`` topic (its messages stand in for ``GraspEpisode``)."""
    return rec.add_topic(TopicSpec('/dam/episode', 'std_msgs/msg/String', 'string data\n', '',
                                   []))


def event(rec: EpisodeRecorder, key: int, stamp_ns: int, code: int, goal: str = GOAL) -> None:
    """A STARTED (0) or ENDED (1) event of ``goal`` received at ``stamp_ns``."""
    text = ('STARTED ', 'ENDED ')[code] + goal
    data = b'\x00\x01\x00\x00' + struct.pack('<I', len(text) + 1) + text.encode() + b'\x00'
    rec.write(key, stamp_ns, data, facts=(('event', (goal, code)),))


def summary(outcome_name: str = 'SUCCESS') -> dict:
    return {'goal_id': GOAL, 'ended_ns': 0, 'goal': {'k_theta': [], 'delta_theta_p': []},
            'k_theta': [10.0, 5.0, 5.0], 'delta_theta_p': [0.17] * 3,
            'friction_angle': math.radians(30), 'outcome': 1, 'outcome_name': outcome_name,
            'message': 'grasp done', 'duration_s': 4.2,
            'check_lift': {'ok': True, 'worst_case_margin': -math.inf, 'csm_margin': math.nan}}


def frame_ids(records) -> list[int]:
    return [int(r.values['header']['frame_id'].split('_')[1]) for r in records]


def test_an_episode_holds_its_pre_roll_and_post_roll_and_is_named_by_outcome(
        tmp_path: Path, prefixes, typestore) -> None:
    rec = make_recorder(tmp_path)
    js = rec.add_topic(specs(prefixes)[0])
    events = event_topic(rec)
    # Joint state i arrives at T0 + i ms; the goal starts at 1000 ms and ends at 1500 ms.
    for i in range(1000):
        rec.write(js, T0 + i * MS, joint_state(typestore, i))
    event(rec, events, T0 + 1000 * MS, 0)
    # The event is stamped at 999 ms (the controller) and taken at 1200 ms (a busy recorder):
    # the pre-roll counts from the earlier.
    opened = rec.started(GOAL, T0 + 1200 * MS, accepted_ns=T0 + 1000 * MS,
                         start_info={CONFIG_KEY: 'hand: {}\n'})
    assert opened.parent == tmp_path / 'episodes' and opened.name.endswith('_recording')
    # While it is written, its metadata says it is not (yet) complete: what a kill leaves.
    custom = yaml.safe_load((opened / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']['custom_data']
    assert custom[COMPLETE_KEY] == 'false' and json.loads(custom[MISSING_KEY])[0]['kind'] == 'open'
    closed = []
    for i in range(1000, 1800):  # after 1690 ms (the post-roll's end): not in the episode
        rec.write(js, T0 + i * MS, joint_state(typestore, i))
        if i == 1500:  # taken at 1500 ms, stamped by the controller at 1490 ms
            event(rec, events, T0 + 1500 * MS, 1)
            assert rec.ended(GOAL, T0 + 1500 * MS, summary(), ended_ns=T0 + 1490 * MS)
        # Every message up to i ms has been handed over: it closes once that is 100 ms
        # (CLOSE_MARGIN_NS) after the post-roll's end.
        closed += [(i, c) for c in rec.poll(T0 + i * MS)]
    [(at_ms, (bag, outcome, missing))] = closed
    assert at_ms == 1690 + CLOSE_MARGIN_NS // MS
    assert outcome == 'SUCCESS' and missing == () and rec.open_goals == []
    assert not opened.exists()
    stem = time.strftime('%Y_%m_%d-%H_%M_%S', time.localtime((T0 + 1000 * MS) / 1e9))
    assert bag == tmp_path / 'episodes' / f'{stem}_success'
    assert metadata_problems(bag) == []
    for read in (read_with_rosbags, read_with_mcap):
        # pre-roll 0.5 s before 1000 ms: from 500 ms; post-roll 0.2 s after 1490 ms: to 1690 ms
        assert frame_ids(read(bag)['/joint_states']) == list(range(500, 1691))
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['relative_file_paths'] == [f'{stem}_0.mcap']
    custom = info['custom_data']
    assert custom[CONFIG_KEY] == 'hand: {}\n'
    assert (custom[COMPLETE_KEY], custom[MISSING_KEY]) == ('true', '[]')
    assert json.loads(custom['dam_recorder.lost_messages']) == {}
    assert json.loads(custom['dam_recorder.dropped_messages']) == {}
    stored = json.loads(custom[SUMMARY_KEY])  # standard JSON: no NaN or Infinity tokens
    assert stored['accepted_ns'] == T0 + 1000 * MS
    assert stored['pre_roll_s'] == 0.5 and stored['post_roll_s'] == 0.2
    assert stored['check_lift'] == {'ok': True, 'worst_case_margin': '-inf', 'csm_margin': 'nan'}
    assert stored['k_theta'] == [10.0, 5.0, 5.0] and stored['outcome_name'] == 'SUCCESS'


def test_latched_message_older_than_the_pre_roll_is_written_at_its_start(
        tmp_path: Path, prefixes, typestore) -> None:
    rec = make_recorder(tmp_path, pre_roll_s=0.1, post_roll_s=0.0)
    js_spec, status_spec = specs(prefixes)
    status = rec.add_topic(status_spec)
    rec.write(status, T0, dam_status(typestore, 4))  # latched, long before the goal
    js = rec.add_topic(js_spec)
    events = event_topic(rec)
    for i in range(1, 2000):
        rec.write(js, T0 + i * MS, joint_state(typestore, i))
    event(rec, events, T0 + 2000 * MS, 0)
    rec.started(GOAL, T0 + 2000 * MS)
    event(rec, events, T0 + 2001 * MS, 1)
    rec.ended(GOAL, T0 + 2001 * MS, summary('FAILURE'))
    rec.write(js, T0 + 2001 * MS, joint_state(typestore, 2001))
    # No later message: it closes once the caller has taken everything up to the margin.
    assert rec.poll(T0 + 2100 * MS) == []
    [(bag, outcome, missing)] = rec.poll(T0 + 2101 * MS)
    assert outcome == 'FAILURE' and bag.name.endswith('_failure') and missing == ()
    for read in (read_with_rosbags, read_with_mcap):
        topics = read(bag)
        [latched] = topics['/dam/status']
        assert latched.values['phase'] == 'PHASE_4'
        assert latched.timestamp == T0 + 1900 * MS  # the start of the pre-roll
        assert frame_ids(topics['/joint_states']) == [*range(1900, 2000), 2001]


def test_overlapping_goals_each_get_their_own_window(tmp_path: Path, prefixes,
                                                     typestore) -> None:
    rec = make_recorder(tmp_path, pre_roll_s=0.05, post_roll_s=0.05)
    js = rec.add_topic(specs(prefixes)[0])
    events = event_topic(rec)
    other = 'cd' * 16
    finished = []
    for i in range(500):
        now = T0 + i * MS
        if i == 100:
            event(rec, events, now, 0)
            rec.started(GOAL, now)
        if i == 150:
            event(rec, events, now, 0, other)
            rec.started(other, now)  # refused while the first runs
        if i == 151:
            event(rec, events, now, 1, other)
            rec.ended(other, now, dict(summary('REJECTED'), goal_id=other))
        if i == 300:
            event(rec, events, now, 1)
            rec.ended(GOAL, now, summary())
        rec.write(js, now, joint_state(typestore, i))
        finished += rec.poll(now)
    assert [(c.outcome, c.missing) for c in finished] == [('REJECTED', ()), ('SUCCESS', ())]
    windows = {outcome: frame_ids(read_with_rosbags(bag)['/joint_states'])
               for bag, outcome, _missing in finished}
    assert windows['SUCCESS'] == list(range(50, 351))
    assert windows['REJECTED'] == list(range(100, 202))
    # Both started in the same second: the second name gets the goal id.
    names = sorted(c.path.name for c in finished)
    assert names[0].endswith('_rejected') and names[1].endswith('_success')


def test_stopping_closes_open_episodes_as_unfinished_and_counts_losses_per_episode(
        tmp_path: Path, prefixes, typestore) -> None:
    rec = make_recorder(tmp_path, storage='sqlite3')
    js = rec.add_topic(specs(prefixes)[0])
    events = event_topic(rec)
    rec.note_lost(js, 5)  # before the episode: not its loss
    rec.write(js, T0 - MS, joint_state(typestore, 0), trimmed=True)  # in the pre-roll ring
    event(rec, events, T0, 0)
    rec.started(GOAL, T0)
    rec.write(js, T0 + MS, joint_state(typestore, 1), trimmed=True)
    rec.note_lost(js, 2)
    rec.note_paused(js)
    status = rec.add_topic(specs(prefixes)[1])  # a topic that appears during the episode
    rec.write(status, T0 + 2 * MS, dam_status(typestore, 2))
    [(bag, outcome, missing)] = rec.close_all(T0 + 3 * MS)
    # Stopped before the goal ended: no result, no ENDED event, and the loss the middleware
    # reported.
    assert outcome == 'UNKNOWN' and bag.name.endswith('_unknown_incomplete')
    assert [(m.kind, m.topic, m.short) for m in missing] == [
        ('result', '/dam/episode', None), ('end_event', '/dam/episode', None),
        ('dropped', '/joint_states', 2)]
    assert metadata_problems(bag) == []
    custom = yaml.safe_load((bag / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']['custom_data']
    assert custom[COMPLETE_KEY] == 'false'
    assert [m['kind'] for m in json.loads(custom[MISSING_KEY])] == [
        'result', 'end_event', 'dropped']
    assert json.loads(custom['dam_recorder.lost_messages']) == {'/joint_states': 2}
    assert json.loads(custom['dam_recorder.paused_messages']) == {'/joint_states': 1}
    # The trimmed ones written into the episode (from its pre-roll, and live).
    assert json.loads(custom['dam_recorder.trimmed_messages']) == {'/joint_states': 2}
    stored = json.loads(custom[SUMMARY_KEY])
    assert stored['outcome_name'] == 'UNKNOWN' and 'stopped before' in stored['message']
    topics = read_with_rosbags(bag)
    assert frame_ids(topics['/joint_states']) == [0, 1]
    assert [r.values['phase'] for r in topics['/dam/status']] == ['PHASE_2']


def test_a_stop_out_of_time_counts_what_the_backlog_and_the_episode_held_back(
        tmp_path: Path, prefixes, typestore) -> None:
    """The recorder's own losses (its full backlog, its stop's time run out) make the episode
    incomplete with their counts; past the close's deadline the messages held back are
    counted as not written, except the goal's events (protected), which are written."""
    rec = make_recorder(tmp_path)
    js = rec.add_topic(specs(prefixes)[0])
    events = rec.add_topic(TopicSpec('/dam/episode', 'std_msgs/msg/String', 'string data\n',
                                     '', [], protected=True))
    rec.note_shed(js, 3)  # before the episode: not its loss
    event(rec, events, T0, 0)
    rec.started(GOAL, T0)
    for i in range(1, 11):  # held back (HOLD_BACK_NS): none written yet
        rec.write(js, T0 + i * MS, joint_state(typestore, i))
    event(rec, events, T0 + 11 * MS, 1)
    rec.note_shed(js, 4)
    rec.note_unwritten_at_stop(js, 7)
    [(bag, _outcome, missing)] = rec.close_all(T0 + 12 * MS, deadline=time.monotonic())
    items = {(m.kind, m.topic): m for m in missing}
    assert items[('backlog_dropped', '/joint_states')].short == 4
    # The 7 left in the recorder's backlog and the 10 the episode held back.
    assert items[('not_written', '/joint_states')].short == 17
    assert items[('not_written', '/joint_states')].recorded == 0
    assert rec.held_unwritten == {'/joint_states': 10}
    custom = yaml.safe_load((bag / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']['custom_data']
    assert json.loads(custom['dam_recorder.backlog_dropped_messages']) == {'/joint_states': 4}
    assert json.loads(custom['dam_recorder.stop_unwritten_messages']) == {'/joint_states': 17}
    topics = read_with_rosbags(bag)
    assert len(topics['/dam/episode']) == 2 and not topics.get('/joint_states')


def test_a_goal_that_started_before_the_recorder_has_no_episode(tmp_path: Path) -> None:
    rec = make_recorder(tmp_path)
    assert rec.ended(GOAL, T0, summary()) is False
    assert rec.close_all() == [] and not (tmp_path / 'episodes').exists()


@pytest.mark.parametrize('pre_roll, post_roll', [(-1.0, 1.0), (1.0, math.nan), (math.inf, 0)])
def test_bad_rolls_are_refused_with_the_value(tmp_path: Path, pre_roll: float,
                                              post_roll: float) -> None:
    with pytest.raises(ConfigurationError, match='must be a finite number'):
        make_recorder(tmp_path, pre_roll, post_roll)


def test_json_safe_spells_non_finite_numbers() -> None:
    assert json_safe({'a': [math.nan, -math.inf, 1.5], 'b': (math.inf,), 'c': 'x'}) == \
        {'a': ['nan', '-inf', 1.5], 'b': ['inf'], 'c': 'x'}


def test_messages_handed_over_late_go_by_their_stamps(tmp_path: Path, prefixes,
                                                      typestore) -> None:
    """A recorder behind its queue: the goal's events are handled before the messages around
    them are written. The episode still holds exactly its window."""
    rec = make_recorder(tmp_path, pre_roll_s=0.1, post_roll_s=0.1)
    js = rec.add_topic(specs(prefixes)[0])
    for i in range(100):  # written before the start event is handled
        rec.write(js, T0 + i * MS, joint_state(typestore, i))
    rec.started(GOAL, T0 + 900 * MS, accepted_ns=T0 + 500 * MS)
    rec.ended(GOAL, T0 + 950 * MS, summary(), ended_ns=T0 + 700 * MS)
    finished = []
    for i in range(100, 1000):  # the backlog: older and newer than the window
        rec.write(js, T0 + i * MS, joint_state(typestore, i))
        finished += rec.poll(T0 + i * MS)  # handed over up to i ms
    [(bag, outcome, _missing)] = finished
    assert outcome == 'SUCCESS'
    assert frame_ids(read_with_rosbags(bag)['/joint_states']) == list(range(400, 801))


def test_an_ended_event_taken_after_later_messages_keeps_them_out(tmp_path: Path, prefixes,
                                                                  typestore) -> None:
    """The ENDED event comes late (e.g. resent), after messages from beyond the post-roll have
    been taken: the episode still ends at its post-roll (the messages were held back)."""
    rec = make_recorder(tmp_path, pre_roll_s=0.1, post_roll_s=0.1)
    js = rec.add_topic(specs(prefixes)[0])
    rec.started(GOAL, T0 + 200 * MS)
    for i in range(200, 2000):  # the goal ends at 700 ms; its event is taken at 2000 ms
        rec.write(js, T0 + i * MS, joint_state(typestore, i))
    assert rec.ended(GOAL, T0 + 2000 * MS, summary(), ended_ns=T0 + 700 * MS)
    [(bag, _outcome, _missing)] = rec.poll(T0 + 2000 * MS)  # handed over up to 2000 ms
    assert frame_ids(read_with_rosbags(bag)['/joint_states']) == list(range(200, 801))


def test_messages_are_held_back_for_a_bounded_time_only(tmp_path: Path, prefixes,
                                                        typestore) -> None:
    """An ENDED event later than the hold-back cannot take back what was written: the bound
    of the guarantee (HOLD_BACK_NS) is the one documented."""
    from dam_recorder.episodes import HOLD_BACK_NS

    rec = make_recorder(tmp_path, pre_roll_s=0.1, post_roll_s=0.1)
    js = rec.add_topic(specs(prefixes)[0])
    rec.started(GOAL, T0)
    late_ms = HOLD_BACK_NS // MS + 1000
    for i in range(0, late_ms, 10):
        rec.write(js, T0 + i * MS, joint_state(typestore, i))
    rec.ended(GOAL, T0 + late_ms * MS, summary(), ended_ns=T0 + 100 * MS)
    [(bag, _outcome, _missing)] = rec.close_all()
    ids = frame_ids(read_with_rosbags(bag)['/joint_states'])
    assert ids[:21] == list(range(0, 201, 10))  # the window itself is whole
    # Written before the event came: everything older than the hold-back at that time.
    assert max(ids) == (late_ms - 10) - HOLD_BACK_NS // MS - 10


def test_an_episode_on_a_simulated_clock_is_named_by_the_wall_clock() -> None:
    """A stand-in's clock starts at 0: its stamps are no dates (no 1970 names)."""
    from dam_recorder.episodes import episode_stem

    before = time.strftime('%Y_%m_%d-%H_%M', time.localtime())
    stem = episode_stem(3 * 1_000_000_000)
    after = time.strftime('%Y_%m_%d-%H_%M', time.localtime())
    assert stem[:16] in (before, after), stem
    assert episode_stem(T0) == time.strftime('%Y_%m_%d-%H_%M_%S', time.localtime(T0 / 1e9))
