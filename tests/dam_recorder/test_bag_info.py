"""``bag info``: counts, rates, gaps, the recorder's loss counts, the episode and the grasps of
one bag, and the table of a directory of episode bags, against the values the bags were
written with (tests/dam_recorder/grasp_bags.py)."""

from __future__ import annotations

import dataclasses
import json
import math
import shutil
from pathlib import Path

import grasp_bags as gb
import numpy as np
import pytest

from dam_recorder.bag_info import (
    bag_info,
    episodes_info,
    grasps_from_status,
    topic_stats,
)
from dam_recorder.bag_info_text import (
    bag_info_json,
    episodes_json,
    format_bag_info,
    format_episodes,
)
from dam_recorder.errors import BagReadError


@pytest.fixture(scope='module')
def grasp_bag(tmp_path_factory, typestore, prefixes) -> gb.GraspBag:
    return gb.write_grasp_bag(tmp_path_factory.mktemp('info') / 'grasp', typestore, prefixes,
                              episode=gb.summary())


def expected_rate(times: list[int]) -> float:
    return (len(times) - 1) / ((times[-1] - times[0]) / 1e9)


def test_counts_rates_and_gaps_are_those_written(grasp_bag: gb.GraspBag) -> None:
    info = bag_info(grasp_bag.path)
    by_name = {t.name: t for t in info.topics}
    assert sorted(by_name) == sorted(grasp_bag.times)
    for topic, times in grasp_bag.times.items():
        stats = by_name[topic]
        assert stats.count == len(times), topic
        assert (stats.first_ns, stats.last_ns) == (times[0], times[-1])
        assert stats.rate_hz == pytest.approx(expected_rate(times), rel=1e-12)
        gaps = np.diff(times)
        assert stats.max_gap_ns == gaps.max()
        assert stats.max_gap_at_ns == times[int(np.argmax(gaps))]
    js = by_name['/joint_states']
    assert js.count == gb.JS_COUNT - (gb.GAP_TO - gb.GAP_FROM)
    assert js.max_gap_ns == (gb.GAP_TO - gb.GAP_FROM + 1) * gb.JS_STEP_NS  # 70 ms
    assert js.max_gap_at_ns == gb.T0 + (gb.GAP_FROM - 1) * gb.JS_STEP_NS
    assert by_name['/dam/status'].rate_hz == pytest.approx(10.0)
    assert by_name['/dam/status'].type == 'dam_interfaces/msg/DamStatus'
    assert info.start_ns == grasp_bag.start_ns == gb.T0
    assert info.duration_ns == grasp_bag.end_ns - grasp_bag.start_ns
    assert info.message_count == sum(len(t) for t in grasp_bag.times.values())


def test_loss_counts_episode_and_grasps(grasp_bag: gb.GraspBag) -> None:
    info = bag_info(grasp_bag.path)
    by_name = {t.name: t for t in info.topics}
    assert (info.lost, info.paused, info.trimmed) == (gb.LOST, gb.PAUSED, gb.TRIMMED)
    assert by_name['/joint_states'].lost == 3 and by_name['/dam/status'].lost == 0
    assert by_name['/sim/object_pose'].paused == 2 and by_name['/dam/status'].trimmed == 1
    assert info.episode is not None
    assert info.episode.summary.outcome_name == 'SUCCESS'
    assert info.episode.summary.k_theta == tuple(gb.K_THETA)
    assert len(info.grasps) == 1
    grasp = info.grasps[0]
    first_active = gb.PHASES.index('APPROACH')
    first_done = gb.PHASES.index('DONE')
    assert grasp.start_ns == gb.T0 + gb.STATUS_OFFSET_NS + first_active * gb.STATUS_STEP_NS
    assert grasp.end_ns == gb.T0 + gb.STATUS_OFFSET_NS + first_done * gb.STATUS_STEP_NS
    assert (grasp.end_phase, grasp.outcome, grasp.message) == \
        ('DONE', 'SUCCESS', 'grasp done: enveloped')


def test_text_names_every_topic_with_its_figures(grasp_bag: gb.GraspBag) -> None:
    text = format_bag_info(bag_info(grasp_bag.path))
    line = next(x for x in text.splitlines() if x.startswith('/joint_states '))
    count = gb.JS_COUNT - (gb.GAP_TO - gb.GAP_FROM)
    rate = expected_rate(grasp_bag.times['/joint_states'])
    gap_at = (gb.GAP_FROM - 1) * gb.JS_STEP_NS / 1e9
    assert line.split() == ['/joint_states', 'sensor_msgs/msg/JointState', str(count),
                            f'{rate:.2f}', '0.070', 'at', f'{gap_at:.3f}', '3', '0', '0', '0']
    pose = next(x for x in text.splitlines() if x.startswith('/sim/object_pose '))
    assert pose.split()[-4:] == ['0', '5', '2', '0']  # lost, dropped, paused, trimmed
    assert '(not in the bag) /tf: lost 4' in text
    assert 'episode:    SUCCESS (grasp done: enveloped)' in text
    assert 'k_theta [N*m/rad] [10, 5, 5]   delta_theta_p [deg] [10, 10, 10]' in text
    assert 'worst-case margin +0.04001 N' in text and 'margin +1.337 N' in text
    assert '1: 0.305 s to 1.705 s: DONE, outcome SUCCESS (grasp done: enveloped)' in text
    assert 'complete:   yes' in text
    assert 'backlog:    max 0.013 s, mean 0.003 s over 400 messages' in text
    data = json.loads(json.dumps(bag_info_json(bag_info(grasp_bag.path))))
    assert data['duration_ns'] == grasp_bag.end_ns - gb.T0
    assert data['lost'] == gb.LOST and data['dropped'] == gb.DROPPED
    assert data['completeness'] == {'complete': True, 'missing': []}
    assert data['backlog'] == gb.BACKLOG
    assert data['episode']['summary']['check_lift']['csm_margin'] == 1.337


def test_times_say_their_clock_and_a_simulated_start_is_no_date(
        grasp_bag: gb.GraspBag) -> None:
    """A bag on simulated time printed "start: 1970-01-01 ..." and its simulated duration
    beside the grasp's wall-clock one, unlabelled; now each time says its clock."""
    wall = bag_info(grasp_bag.path)  # stamped in 2025: the wall clock
    text = format_bag_info(wall)
    assert '(wall-clock time)' in text.splitlines()[2], text
    duration = grasp_bag.end_ns - gb.T0
    assert f'duration:   {duration * 1e-9:.3f} s wall-clock time' in text
    # the summary has no wall_duration_s (an older controller): its duration is wall time
    assert 'grasp 1.550 s wall-clock, pre-roll 0.25 s, post-roll 0.2 s (bag time)' in text
    # the same bag on the stand-in's clock, 9.5 s after it started
    shift = gb.T0 - 9_500_000_000
    assert wall.start_ns is not None and wall.end_ns is not None and wall.episode is not None
    summary = dataclasses.replace(wall.episode.summary, wall_duration_s=2.25)
    sim = dataclasses.replace(
        wall, start_ns=wall.start_ns - shift, end_ns=wall.end_ns - shift,
        grasps=[dataclasses.replace(g, start_ns=g.start_ns - shift,
                                    end_ns=None if g.end_ns is None else g.end_ns - shift)
                for g in wall.grasps],
        episode=dataclasses.replace(wall.episode, summary=summary))
    text = format_bag_info(sim)
    assert '1970' not in text
    assert text.splitlines()[2] == ('start:      sim 9.500 s (simulated time: the stand-in\'s '
                                    '/clock counts from 0 at its start, so no date)')
    assert f'duration:   {duration * 1e-9:.3f} s simulated time' in text
    assert 'grasp 1.550 s simulated (2.250 s wall-clock)' in text
    assert '1: 0.305 s to 1.705 s: DONE' in text  # from the bag's start, as before


def test_an_incomplete_episode_is_marked_with_what_it_lacks(tmp_path: Path, typestore,
                                                           prefixes) -> None:
    bag = gb.write_grasp_bag(tmp_path / 'cut', typestore, prefixes, topics=('/dam/status',),
                             episode=gb.summary(),
                             custom={'dam_episode.complete': 'false',
                                     'dam_episode.missing': json.dumps(INCOMPLETE)})
    info = bag_info(bag.path)
    assert info.completeness.complete is False
    assert [m.kind for m in info.completeness.missing] == ['end_event', 'stopped']
    text = format_bag_info(info).splitlines()
    at = text.index('complete:   NO, INCOMPLETE: the bag lacks')
    assert text[at + 1:at + 3] == ['  /dam/episode: no EVENT_ENDED of the goal in the bag',
                                   '  /joint_states: ' + INCOMPLETE[1]['detail']]
    data = json.loads(json.dumps(bag_info_json(info)))
    assert data['completeness']['complete'] is False
    assert data['completeness']['missing'][1]['short'] == 2755
    broken = tmp_path / 'broken'
    shutil.copytree(bag.path, broken)
    meta = (broken / 'metadata.yaml').read_text()
    (broken / 'metadata.yaml').write_text(meta.replace("dam_episode.complete: 'false'",
                                                       "dam_episode.complete: 'maybe'"))
    with pytest.raises(BagReadError, match='broken: dam_episode.complete: expected "true"'):
        bag_info(broken)


def test_a_bag_without_status_or_episode(tmp_path: Path, typestore, prefixes) -> None:
    bag = gb.write_grasp_bag(tmp_path / 'plain', typestore, prefixes,
                             topics=('/joint_states',), storage='sqlite3')
    info = bag_info(bag.path)
    assert [t.name for t in info.topics] == ['/joint_states']
    assert info.episode is None and info.grasps == []
    assert info.topics[0].count == len(bag.times['/joint_states'])
    text = format_bag_info(info)
    assert 'episode:    none' in text and 'grasps on /dam/status: none' in text


def test_topic_stats_of_few_messages() -> None:
    assert topic_stats('/a', 't', np.array([], np.int64)).rate_hz is None
    one = topic_stats('/a', 't', np.array([5], np.int64))
    assert (one.count, one.rate_hz, one.max_gap_ns, one.first_ns) == (1, None, None, 5)
    two = topic_stats('/a', 't', np.array([10, 4, 7], np.int64))  # sorted first
    assert (two.max_gap_ns, two.max_gap_at_ns, two.first_ns, two.last_ns) == (3, 4, 4, 10)
    assert two.rate_hz == pytest.approx(2 / 6e-9)


def test_grasps_from_status_sequences() -> None:
    status = [(1, 'IDLE', 0, ''), (2, 'APPROACH', 0, ''), (3, 'ROLLING_UP', 0, ''),
              (4, 'FAILED', 3, 'not lifted'), (5, 'IDLE', 3, ''), (6, 'APPROACH', 0, ''),
              (7, 'ABORTED', 4, 'cancelled'), (8, 'RELEASING', 0, ''), (9, 'APPROACH', 0, '')]
    grasps = grasps_from_status(status)
    assert [(g.start_ns, g.end_ns, g.end_phase, g.outcome) for g in grasps] == [
        (2, 4, 'FAILED', 'FAILURE'), (6, 7, 'ABORTED', 'ABORTED'),
        (9, None, 'APPROACH', 'UNKNOWN')]


def test_an_end_phase_entered_before_the_outcome_takes_the_outcome_reported_next() -> None:
    # The controller publishes DONE at once and its outcome once it has classified the grasp.
    status = [(1, 'APPROACH', 0, ''), (2, 'DONE', 0, ''), (3, 'DONE', 1, 'lifted'),
              (4, 'DONE', 1, 'lifted'), (5, 'APPROACH', 0, ''), (6, 'DONE', 0, ''),
              (7, 'IDLE', 0, ''), (8, 'IDLE', 2, 'late')]
    grasps = grasps_from_status(status)
    assert [(g.end_ns, g.outcome, g.message) for g in grasps] == [
        (2, 'SUCCESS', 'lifted'), (6, 'UNKNOWN', '')]


#: What the incomplete episode of make_episode_dir lacks.
INCOMPLETE = [{'kind': 'end_event', 'topic': '/dam/episode',
               'detail': 'no EVENT_ENDED of the goal in the bag'},
              {'kind': 'stopped', 'topic': '/joint_states', 'detail': 'stops at 6.730 s of '
               '12.240 s: about 2755 of 6120 messages missing at its rate of 500 Hz',
               'expected': 6120, 'recorded': 3365, 'short': 2755, 'until_s': 6.73,
               'end_s': 12.24, 'until_ns': gb.T0 + 6_730_000_000, 'basis': 'rate'}]


def make_episode_dir(root: Path, typestore, prefixes) -> dict[str, dict]:
    """Five episode bags (one with no summary, one incomplete) and a directory that is no
    bag."""
    gb.write_grasp_bag(root / '2026_11_29-18_10_05_success_incomplete', typestore, prefixes,
                       topics=('/dam/status',), episode=gb.summary(),
                       custom={'dam_episode.complete': 'false',
                               'dam_episode.missing': json.dumps(INCOMPLETE)})
    runs = {
        '2026_11_29-18_05_12_success': gb.summary(),
        '2026_11_29-18_06_40_failure': gb.summary(
            outcome=3, outcome_name='FAILURE', k_theta=[0.5, 0.25, 0.25], duration_s=4.25,
            check_lift=dict(gb.CHECK_LIFT, lift_guaranteed=False, worst_case_margin='-inf')),
        '2026_11_29-18_08_02_success': gb.summary(check_lift=None, duration_s=2.5,
                                                  wall_duration_s=3.75),
        '2026_11_29-18_09_30_aborted': None,
    }
    for name, episode in runs.items():
        gb.write_grasp_bag(root / name, typestore, prefixes, topics=('/dam/status',),
                           episode=episode)
    (root / 'notes').mkdir()
    return {**runs, '2026_11_29-18_10_05_success_incomplete': gb.summary()}


def test_a_directory_of_ordinary_bags_lists_them_as_bags(tmp_path: Path, typestore,
                                                          prefixes) -> None:
    """``bag info DIR`` on ordinary bags (no episode metadata, no episode's name) called them
    "3 episodes ... UNKNOWN"; now they are bags, with their sizes, and count in no outcome,
    beside the episodes of the same directory."""
    for name in ('rosbag2_2026_11_29-18_05_12', 'calibration', 'morning_run'):
        gb.write_grasp_bag(tmp_path / name, typestore, prefixes)
    gb.write_grasp_bag(tmp_path / '2026_11_29-18_06_40_failure', typestore, prefixes,
                       topics=('/dam/status',), episode=gb.summary(outcome=3,
                                                                   outcome_name='FAILURE'))
    info = episodes_info(tmp_path)
    assert [r.name for r in info.bags] == ['calibration', 'morning_run',
                                           'rosbag2_2026_11_29-18_05_12']
    assert [r.name for r in info.episodes] == ['2026_11_29-18_06_40_failure']
    assert all(r.outcome == '-' and r.kind == 'bag' for r in info.bags)
    assert len({r.message_count for r in info.bags}) == 1  # the same bag three times
    assert info.bags[0].topic_count == 4 and info.bags[0].message_count > 100
    assert info.totals == {'FAILURE': 1}
    text = format_episodes(info)
    assert text.splitlines()[0].endswith(': 1 episode, 3 other bags (not episodes)'), text
    assert 'UNKNOWN' not in text
    bags = text.split('bags (no episode metadata')[1].splitlines()[1:]
    assert bags[0].split()[:4] == ['bag', 'start', 'duration', '[s]']
    assert [line.split()[0] for line in bags[1:-1]] == [r.name for r in info.bags]
    assert bags[-1] == '(start and duration on the bag\'s clock: "sim" is simulated time)'
    data = episodes_json(info)
    assert [b['name'] for b in data['bags']] == [r.name for r in info.bags]
    assert [e['name'] for e in data['episodes']] == ['2026_11_29-18_06_40_failure']


def test_directory_of_episodes_table_and_totals(tmp_path: Path, typestore, prefixes) -> None:
    runs = make_episode_dir(tmp_path, typestore, prefixes)
    info = episodes_info(tmp_path)
    assert [r.name for r in info.rows] == sorted(runs)
    rows = {r.name: r for r in info.rows}
    ok = rows['2026_11_29-18_05_12_success']
    assert (ok.outcome, ok.k_theta, ok.lift_guaranteed, ok.grasp_duration_s) == \
        ('SUCCESS', tuple(gb.K_THETA), True, 1.55)
    status_span = (len(gb.PHASES) - 1) * gb.STATUS_STEP_NS
    assert ok.start_ns == gb.T0 + gb.STATUS_OFFSET_NS
    assert ok.bag_duration_s == pytest.approx(status_span / 1e9)
    failed = rows['2026_11_29-18_06_40_failure']
    assert (failed.outcome, failed.lift_guaranteed, failed.k_theta) == \
        ('FAILURE', False, (0.5, 0.25, 0.25))
    assert rows['2026_11_29-18_08_02_success'].lift_guaranteed is None
    bare = rows['2026_11_29-18_09_30_aborted']  # no summary: the outcome from the name
    assert (bare.outcome, bare.grasp_duration_s, bare.k_theta) == ('ABORTED', None, ())
    assert (ok.complete, bare.complete) == (True, None)  # the metadata says, or does not
    cut = rows['2026_11_29-18_10_05_success_incomplete']
    assert (cut.outcome, cut.complete) == ('SUCCESS', False)
    assert cut.missing == ('/dam/episode: no EVENT_ENDED of the goal in the bag',
                           '/joint_states: ' + INCOMPLETE[1]['detail'])
    # Every episode counts in its outcome (the totals counted an incomplete one only as
    # INCOMPLETE: a directory of incomplete episodes had no outcome at all); how many of
    # each are incomplete is said beside.
    assert info.totals == {'SUCCESS': 3, 'FAILURE': 1, 'ABORTED': 1}
    assert list(info.totals) == ['SUCCESS', 'FAILURE', 'ABORTED']
    assert info.incomplete_totals == {'SUCCESS': 1}
    assert info.errors == []
    text = format_episodes(info)
    lines = text.splitlines()
    assert lines[0].endswith(': 5 episodes')
    row = next(x for x in lines if x.startswith('2026_11_29-18_06_40_failure'))
    # a summary without the wall time: its duration is the wall time (an older controller)
    assert row.split()[3:] == ['1.900', '-', '4.250', 'FAILURE', 'yes', '[0.5,', '0.25,',
                               '0.25]', '[10,', '10,', '10]', 'no']
    row = next(x for x in lines if x.startswith('2026_11_29-18_08_02_success'))
    assert row.split()[4:6] == ['2.500', '3.750']  # the grasp's clock, then the wall's
    assert rows['2026_11_29-18_08_02_success'].grasp_wall_s == 3.75
    assert any(x.startswith('(start, bag [s] and grasp [s] on the bag\'s clock') for x in lines)
    row = next(x for x in lines if x.startswith('2026_11_29-18_10_05_success_incomplete'))
    assert row.split()[6:8] == ['SUCCESS', 'NO']
    row = next(x for x in lines if x.startswith('2026_11_29-18_09_30_aborted'))
    assert row.split()[6:8] == ['ABORTED', '-']
    assert text.split('incomplete (the bag lacks part of the episode):\n')[1].splitlines()[:3] \
        == ['  2026_11_29-18_10_05_success_incomplete:',
            '    /dam/episode: no EVENT_ENDED of the goal in the bag',
            '    /joint_states: ' + INCOMPLETE[1]['detail']]
    assert lines[-5:] == ['totals (every episode by its outcome):',
                          '  SUCCESS            3  (1 of them INCOMPLETE)',
                          '  FAILURE            1', '  ABORTED            1',
                          '  INCOMPLETE         1  (counted above by their outcome)']
    data = episodes_json(info)
    assert data['totals'] == {'SUCCESS': 3, 'FAILURE': 1, 'ABORTED': 1}
    assert data['incomplete'] == {'SUCCESS': 1}
    assert data['episodes'][1]['lift_guaranteed'] is False
    assert data['episodes'][4]['complete'] is False


def test_an_unreadable_episode_is_a_row_with_its_error(tmp_path: Path, typestore,
                                                       prefixes) -> None:
    make_episode_dir(tmp_path, typestore, prefixes)
    bad = tmp_path / '2026_11_29-18_05_12_success'
    shutil.rmtree(bad)
    gb.write_grasp_bag(bad, typestore, prefixes, topics=('/dam/status',),
                       episode=gb.summary(outcome='one'))
    info = episodes_info(tmp_path)
    assert info.rows[0].outcome == 'ERROR'
    assert len(info.errors) == 1
    assert 'dam_episode.summary.outcome: expected an integer' in info.errors[0]
    assert str(tmp_path / '2026_11_29-18_05_12_success') in info.errors[0]
    assert info.totals['ERROR'] == 1


def test_paths_that_are_no_bag_are_refused(tmp_path: Path, typestore, prefixes) -> None:
    with pytest.raises(BagReadError, match='no such'):
        bag_info(tmp_path / 'absent')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(BagReadError, match='not a bag'):
        bag_info(tmp_path / 'empty')
    with pytest.raises(BagReadError, match='no bag directories'):
        episodes_info(tmp_path / 'empty')
    bag = gb.write_grasp_bag(tmp_path / 'one', typestore, prefixes, topics=('/dam/status',))
    with pytest.raises(BagReadError, match='is one bag'):
        episodes_info(bag.path)
    broken = tmp_path / 'broken'
    shutil.copytree(bag.path, broken)
    (broken / 'metadata.yaml').write_text('rosbag2_bagfile_information: {version: [9\n')
    with pytest.raises(BagReadError, match=r'broken/metadata.yaml: not valid YAML \(line \d'):
        bag_info(broken)
    (broken / 'metadata.yaml').write_text('other: 1\n')
    with pytest.raises(BagReadError, match='no rosbag2_bagfile_information'):
        bag_info(broken)
    meta = (bag.path / 'metadata.yaml').read_text()
    (broken / 'metadata.yaml').write_text(meta.replace(
        "dam_recorder.lost_messages: '{\"/joint_states\": 3, \"/tf\": 4}'",
        'dam_recorder.lost_messages: many'))
    with pytest.raises(BagReadError, match="lost_messages: expected JSON .*'many'"):
        bag_info(broken)


def test_an_unknown_time_reads_as_a_dash_in_every_column() -> None:
    """An episode cut short has no grasp wall time (NaN in its summary): the table showed
    'nan' in one column and '-' in the next for the same unknown."""
    from dam_recorder.bag_info_text import _num

    assert _num(math.nan, '.3f') == _num(None, '.3f') == '-'
    assert _num(1.5, '.3f') == '1.500'
