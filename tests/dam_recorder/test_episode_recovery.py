"""``recover`` on an episode whose recorder was killed with it open: the episode bag is
written in-process by the recorder's own episodes (real ``GraspEpisode``, ``GoalStatusArray``,
``DiagnosticArray`` and ``JointState`` messages with their installed definitions), the
directory copied while it is open (what a SIGKILL leaves), then recovered: the verdict, the
name, the metadata and ``bag info``."""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from bag_readers import read_with_rosbags
from test_bag_writer import LATCHED

from dam_recorder.bag_info import bag_info, episodes_info
from dam_recorder.bag_info_text import format_bag_info, format_episodes
from dam_recorder.bag_writer import BagWriter
from dam_recorder.completeness import COMPLETE_KEY, MISSING_KEY
from dam_recorder.episodes import CONFIG_KEY, SUMMARY_KEY, EpisodeRecorder, TopicSpec
from dam_recorder.errors import BagReadError
from dam_recorder.qos import to_rosbags_qos
from dam_recorder.recover_cli import main as recover_main
from dam_recorder.recovery import recover_bag
from dam_recorder.type_description import load_message_type

T0 = 1_700_000_000_000_000_000  # [ns]
MS = 1_000_000
GOAL = '0123456789abcdef' * 2
STARTED_MS, ENDED_MS = 3000, 6000
TOPICS = {'/joint_states': 'sensor_msgs/msg/JointState',
          '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
          '/dam/episode': 'dam_interfaces/msg/GraspEpisode',
          '/dam_grasp/_action/status': 'action_msgs/msg/GoalStatusArray',
          '/robot_description': 'std_msgs/msg/String'}


def plain(store, type_name: str, **values):
    """A message of ``type_name`` with every field not given zero, empty or false."""
    fields = {}
    for name, (node, desc) in store.fielddefs[type_name][1]:
        if name in values:
            continue
        if node == 1:  # a base type
            fields[name] = {'string': '', 'bool': False}.get(
                desc[0], 0.0 if desc[0].startswith('float') else 0)
        elif node == 2:  # a nested message
            fields[name] = plain(store, desc)
        else:  # an array (fixed length) or a sequence
            (inner, inner_desc), length = desc
            if inner == 1 and inner_desc[0] not in ('string', 'bool'):
                fields[name] = np.zeros(length if node == 3 else 0,
                                        dtype=np.uint8 if inner_desc[0] == 'uint8' else float)
            else:
                fields[name] = []
    return store.types[type_name](**fields, **values)


def serialize(store, type_name: str, message) -> bytes:
    return bytes(store.serialize_cdr(message, type_name))


def stamp(store, ns: int):
    return store.types['builtin_interfaces/msg/Time'](sec=ns // 1_000_000_000,
                                                      nanosec=ns % 1_000_000_000)


def header(store, ns: int):
    return store.types['std_msgs/msg/Header'](stamp=stamp(store, ns), frame_id='')


def event(store, code: int, at_ns: int) -> bytes:
    if code == 0:
        msg = plain(store, TOPICS['/dam/episode'], header=header(store, at_ns), event=0,
                    goal_id=GOAL, config_yaml='hand: {}\n', software_version='1.2.3')
    else:
        answer = plain(store, 'dam_interfaces/msg/LiftAnswer', ok=True,
                       lift_guaranteed=True, friction_angle=0.5)
        msg = plain(store, TOPICS['/dam/episode'], header=header(store, at_ns), event=1,
                    goal_id=GOAL, k_theta=np.array([10.0, 5.0, 5.0]),
                    delta_theta_p=np.array([0.1, 0.2, 0.3]), lift_checked=True,
                    check_lift=answer, outcome=1, outcome_name='SUCCESS',
                    message='grasp done', duration=3.0, object='cylinder')
    return serialize(store, TOPICS['/dam/episode'], msg)


def final_status(store, at_ns: int) -> bytes:
    t = store.types
    info = t['action_msgs/msg/GoalInfo'](
        goal_id=t['unique_identifier_msgs/msg/UUID'](
            uuid=np.frombuffer(bytes.fromhex(GOAL), dtype=np.uint8)),
        stamp=stamp(store, at_ns))
    msg = t['action_msgs/msg/GoalStatusArray'](
        status_list=[t['action_msgs/msg/GoalStatus'](goal_info=info, status=4)])
    return serialize(store, TOPICS['/dam_grasp/_action/status'], msg)


def diagnostics(store, at_ns: int, published: int, last_ns: int) -> bytes:
    t = store.types
    values = [t['diagnostic_msgs/msg/KeyValue'](key=k, value=str(v)) for k, v in (
        ('joint_states_published', published), ('joint_states_last_stamp_ns', last_ns))]
    status = plain(store, 'diagnostic_msgs/msg/DiagnosticStatus', name='driver', values=values)
    msg = t['diagnostic_msgs/msg/DiagnosticArray'](header=header(store, at_ns),
                                                    status=[status])
    return serialize(store, TOPICS['/diagnostics'], msg)


def joint_state(store, at_ns: int) -> bytes:
    msg = plain(store, TOPICS['/joint_states'], header=header(store, at_ns),
                name=['a'], position=np.array([0.0]), velocity=np.zeros(0),
                effort=np.zeros(0))
    return serialize(store, TOPICS['/joint_states'], msg)


def killed_episode(tmp_path: Path, prefixes, typestore, *, end_ms: int, ended: bool = True,
                   gap_ms: tuple[int, int] | None = None) -> Path:
    """An episode bag as a SIGKILL at ``end_ms`` leaves it: joint states at 100 Hz, their
    publisher's count every second, the goal starting at 3 s (3 s of pre-roll) and, with
    ``ended``, its final status and ENDED event at 6 s. Joint states stamped in ``gap_ms``
    are published (counted) but never reach the recorder."""
    out = tmp_path / 'grasps'

    def open_bag(bag_dir: Path, stem: str, custom_data) -> BagWriter:
        return BagWriter(bag_dir, custom_data=custom_data, file_stem=stem)

    rec = EpisodeRecorder(out, open_bag, pre_roll_s=3.0, post_roll_s=2.0)
    keys = {}
    for name, type_name in TOPICS.items():
        described = load_message_type(type_name, prefixes)
        latched = name == '/robot_description'
        keys[name] = rec.add_topic(TopicSpec(
            name, described.name, described.definition(), described.type_hash,
            [to_rosbags_qos(LATCHED)] if latched else [], latched=latched,
            protected=name in ('/dam/episode', '/dam_grasp/_action/status')))
    description = typestore.types['std_msgs/msg/String'](data='<robot/>')
    rec.write(keys['/robot_description'], T0, serialize(typestore, 'std_msgs/msg/String',
                                                         description))
    published, last = 0, 0
    opened = None
    for ms in range(0, end_ms, 10):
        at = T0 + ms * MS
        published, last = published + 1, at
        if gap_ms is None or not gap_ms[0] <= ms < gap_ms[1]:
            rec.write(keys['/joint_states'], at, joint_state(typestore, at))
        if ms % 1000 == 500:
            rec.write(keys['/diagnostics'], at + MS, diagnostics(typestore, at + MS, published,
                                                                 last))
        if ms == STARTED_MS:
            opened = rec.started(GOAL, at, accepted_ns=at, start_info={CONFIG_KEY: 'hand: {}\n'})
            rec.write(keys['/dam/episode'], at, event(typestore, 0, at))
        if ms == ENDED_MS and ended:
            rec.write(keys['/dam_grasp/_action/status'], at, final_status(typestore, at))
            rec.write(keys['/dam/episode'], at + MS, event(typestore, 1, at + MS))
            # (the recorder hears of the end: the episode takes 2 s more)
            rec.ended(GOAL, at + MS, {'goal_id': GOAL}, ended_ns=at + MS)
        if ms % 1000 == 0:
            rec.flush()  # chunk_interval: 1 s
    assert opened is not None and opened.name.endswith('_recording')
    killed = tmp_path / 'killed' / opened.name
    shutil.copytree(opened, killed)  # the directory as the kill leaves it
    rec.close_all()  # (the live one, closed: not the one kept)
    return killed


def custom(bag: Path) -> dict[str, str]:
    return yaml.safe_load((bag / 'metadata.yaml').read_text())[
        'rosbag2_bagfile_information']['custom_data']


def test_a_killed_episode_with_its_end_in_the_bag_gets_its_outcome_and_what_it_lacks(
        tmp_path: Path, prefixes, typestore, capsys) -> None:
    killed = killed_episode(tmp_path, prefixes, typestore, end_ms=7500, gap_ms=(1600, 2100))
    stem = time.strftime('%Y_%m_%d-%H_%M_%S', time.localtime((T0 + STARTED_MS * MS) / 1e9))
    assert killed.name == f'{stem}_recording'
    taken = killed.parent / f'{stem}_success_incomplete'
    taken.mkdir()  # an episode of the same second: the name is taken
    assert recover_main([str(killed)]) == 0
    out = capsys.readouterr().out
    bag = killed.parent / f'{stem}_success_incomplete_{GOAL[:8]}'
    assert not killed.exists() and bag.is_dir()
    assert f'episode SUCCESS: {bag}\n' in out
    assert f'{bag.name} is INCOMPLETE (goal {GOAL[:8]}; outcome from the goal\'s ENDED ' \
           'event), the bag lacks:' in out
    data = custom(bag)
    assert data[COMPLETE_KEY] == 'false'
    missing = json.loads(data[MISSING_KEY])
    # The 50 joint states that never reached the recorder, by their publisher's count; the
    # kill. The goal's events and final status are in the bag; every stream goes to its end.
    assert [m['kind'] for m in missing] == ['short', 'killed'], missing
    assert (missing[0]['topic'], missing[0]['short'], missing[0]['basis']) == \
        ('/joint_states', 50, 'publisher count')
    assert 'killed with the episode open' in missing[1]['detail']
    messages = read_with_rosbags(bag)
    last = max(r.timestamp for records in messages.values() for r in records)
    assert missing[1]['until_ns'] == last
    # Killed at 7.5 s in the post-roll (written at once: the goal has ended), flushed every
    # second: the bag ends at the last flush.
    assert last == T0 + 7000 * MS
    summary = json.loads(data[SUMMARY_KEY])
    assert (summary['goal_id'], summary['outcome_name'], summary['outcome']) == \
        (GOAL, 'SUCCESS', 1)
    assert summary['k_theta'] == [10.0, 5.0, 5.0] and summary['message'] == 'grasp done'
    assert summary['accepted_ns'] == T0 + STARTED_MS * MS
    assert summary['ended_ns'] == T0 + ENDED_MS * MS + MS
    assert summary['pre_roll_s'] == 3.0
    assert summary['post_roll_s'] == pytest.approx((last - summary['ended_ns']) * 1e-9,
                                                   abs=1e-3)
    assert data[CONFIG_KEY] == 'hand: {}\n' and data['dam_episode.version'] == '1.2.3'

    # bag info: the outcome, INCOMPLETE with the reasons; never RECORDING.
    text = format_bag_info(bag_info(bag))
    assert 'episode:    SUCCESS (grasp done)' in text
    assert 'complete:   NO, INCOMPLETE: the bag lacks\n  /joint_states: 50 of the ' in text
    assert '\n  the recorder was killed with the episode open' in text
    assert 'RECORDING' not in text.upper().replace('RECORDED', '')
    [row] = [r for r in episodes_info(bag.parent).episodes if r.name == bag.name]
    assert (row.outcome, row.complete) == ('SUCCESS', False)
    assert 'RECORDING' not in format_episodes(episodes_info(bag.parent))

    # Recovered again: a closed episode, left as it is.
    again = recover_bag(bag)
    assert again.episode is None and again.path == bag and custom(bag) == data


def test_a_killed_episode_without_its_end_is_unknown(tmp_path: Path, prefixes,
                                                     typestore) -> None:
    killed = killed_episode(tmp_path, prefixes, typestore, end_ms=7500, ended=False)
    # Not recovered: bag info says it is open and what to do.
    with pytest.raises(BagReadError, match=r'an episode its recorder has not closed \(still '
                       r'being recorded, or killed\): cannot open the bag: .*; if its '
                       r'recorder was killed .*`ros2 run dam_recorder recover DIR`'):
        bag_info(killed)
    [row] = episodes_info(killed.parent).episodes
    assert (row.name, row.outcome, row.complete) == (killed.name, 'OPEN', False)
    assert row.missing[-1].startswith('(if its recorder was killed')
    report = recover_bag(killed)
    stem = killed.name.removesuffix('_recording')
    assert report.path == killed.parent / f'{stem}_unknown_incomplete'
    verdict = report.episode
    assert (verdict.goal_id, verdict.outcome, verdict.got_result) == (GOAL, 'UNKNOWN', False)
    # No result, no ENDED event, no final status of the goal: it was still running.
    assert [m.kind for m in verdict.missing] == ['result', 'end_event', 'final_status',
                                                 'killed']
    data = custom(report.path)
    summary = json.loads(data[SUMMARY_KEY])
    assert (summary['outcome_name'], summary['goal_id']) == ('UNKNOWN', GOAL)
    assert summary['accepted_ns'] == T0 + STARTED_MS * MS and summary['ended_ns'] == 0
    assert 'killed' in summary['message']
    assert [m['kind'] for m in json.loads(data[MISSING_KEY])][-1] == 'killed'
    text = format_bag_info(bag_info(report.path))
    assert 'episode:    UNKNOWN (the recorder was killed' in text
    assert 'complete:   NO, INCOMPLETE' in text
