"""``bag plot``: the Figure's lines equal the written joint angles [deg] and torques [N*m],
the phase spans lie where ``/dam/status`` changed phase, the height curve is the rise in mm,
the margins and the title are written; missing topics are named, not fatal."""

from __future__ import annotations

import json
import math
from pathlib import Path

import grasp_bags as gb
import numpy as np
import pytest

from dam_recorder.bag_plot import phase_spans, plot_bag


@pytest.fixture(scope='module')
def grasp_bag(tmp_path_factory, typestore, prefixes) -> gb.GraspBag:
    return gb.write_grasp_bag(tmp_path_factory.mktemp('plot') / 'grasp', typestore, prefixes,
                              episode=gb.summary())


def js_indices() -> list[int]:
    return [i for i in range(gb.JS_COUNT) if not gb.GAP_FROM <= i < gb.GAP_TO]


def lines_by_label(ax) -> dict[str, object]:
    return {line.get_label(): line for line in ax.get_lines()}


def all_text(figure) -> str:
    texts = [t.get_text() for t in figure.findobj(lambda a: hasattr(a, 'get_text'))]
    return '\n'.join(t for t in texts if isinstance(t, str))


def test_joint_lines_are_the_written_angles_in_deg_and_torques(grasp_bag, tmp_path) -> None:
    result = plot_bag(grasp_bag.path, tmp_path / 'grasp.png')
    assert (tmp_path / 'grasp.png').read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    axes = result.figure.axes
    assert len(axes) == 8  # 3 fingers x (angle, torque) + height + text
    indices = js_indices()
    times = [(gb.T0 + i * gb.JS_STEP_NS - gb.T0) / 1e9 for i in indices]
    for row, finger in enumerate(gb.FINGERS):
        angle_ax, torque_ax = axes[2 * row], axes[2 * row + 1]
        assert 'angle [deg]' in angle_ax.get_ylabel() and finger in angle_ax.get_ylabel()
        assert torque_ax.get_ylabel() == 'torque [N*m]'
        angles, torques = lines_by_label(angle_ax), lines_by_label(torque_ax)
        assert sorted(angles) == sorted(torques) == [f'{finger}_compliant_joint',
                                                     f'{finger}_position_joint']
        for role in ('compliant', 'position'):
            name = f'{finger}_{role}_joint'
            j = gb.JOINTS.index(name)
            assert np.allclose(angles[name].get_xdata(), times, atol=1e-12)
            assert np.allclose(angles[name].get_ydata(),
                               [math.degrees(gb.js_position(i, j)) for i in indices],
                               rtol=0, atol=1e-12)
            assert np.allclose(torques[name].get_ydata(), [gb.js_effort(i, j) for i in indices],
                               rtol=0, atol=1e-15)
    assert result.data.missing == []


def test_phases_are_spans_from_one_change_to_the_next(grasp_bag) -> None:
    figure = plot_bag(grasp_bag.path).figure
    stamp = [(gb.STATUS_OFFSET_NS + k * gb.STATUS_STEP_NS) / 1e9 for k in range(len(gb.PHASES))]
    firsts = {p: stamp[gb.PHASES.index(p)] for p in gb.PHASES}
    end = (grasp_bag.end_ns - gb.T0) / 1e9
    expected = [('APPROACH', firsts['APPROACH'], firsts['ROLLING_UP']),
                ('ROLLING_UP', firsts['ROLLING_UP'], firsts['ENVELOPE']),
                ('ENVELOPE', firsts['ENVELOPE'], firsts['DONE']), ('DONE', firsts['DONE'], end)]
    for ax in figure.axes[:7]:  # every time axis, the height too
        spans = [p for p in ax.patches if p.get_gid() == 'phase']
        found = [(p.get_label().removeprefix('phase '), p.get_x(), p.get_x() + p.get_width())
                 for p in spans]
        assert [f[0] for f in found] == [e[0] for e in expected]  # IDLE is not shaded
        for (_, x0, x1), (_, e0, e1) in zip(found, expected, strict=True):
            assert (x0, x1) == (pytest.approx(e0, abs=1e-12), pytest.approx(e1, abs=1e-12))
    labels = [t.get_text() for t in figure.axes[0].texts if t.get_gid() == 'phase_label']
    assert labels == ['APPROACH', 'ROLLING_UP', 'ENVELOPE', 'DONE']


def _overlapping_labels(figure) -> list[tuple[str, str]]:
    """Pairs of visible phase labels of one axes whose drawn boxes overlap."""
    renderer = figure.canvas.get_renderer()
    pairs = []
    for ax in figure.axes:
        boxes = [(t.get_text(), t.get_window_extent(renderer)) for t in ax.texts
                 if t.get_gid() == 'phase_label' and t.get_visible()]
        for i, (name_a, a) in enumerate(boxes):
            for name_b, b in boxes[i + 1:]:
                if a.overlaps(b):
                    pairs.append((name_a, name_b))
    return pairs


def test_short_phases_side_by_side_have_labels_that_never_overlap() -> None:
    """A short ENVELOPE between ROLLING_UP and DONE, then CLASSIFYING, DONE, RELEASING, IDLE
    within a second (a grasp and its release): labels overlapped; each now takes a row where
    it clears the others."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from dam_recorder.bag_plot import PhaseSpan, _shade_phases, _stack_labels

    figure = Figure(figsize=(6, 3))
    FigureCanvasAgg(figure)
    ax = figure.add_subplot()
    spans = [PhaseSpan('ROLLING_UP', 0.0, 9.0), PhaseSpan('ENVELOPE', 9.0, 9.1),
             PhaseSpan('CLASSIFYING', 9.1, 9.2), PhaseSpan('DONE', 9.2, 9.3),
             PhaseSpan('RELEASING', 9.3, 9.6), PhaseSpan('CHECK_LIFT', 9.6, 9.7),
             PhaseSpan('APPROACH', 9.7, 20.0)]
    _shade_phases(ax, spans, label=True)
    ax.set_xlim(0.0, 20.0)
    figure.canvas.draw()
    assert _overlapping_labels(figure), 'the test must start from overlapping labels'
    _stack_labels(figure)
    figure.canvas.draw()
    assert _overlapping_labels(figure) == []
    labels = [t for t in ax.texts if t.get_gid() == 'phase_label']
    assert {t.get_text() for t in labels} == {s.phase for s in spans}
    assert len({round(t.get_position()[1], 6) for t in labels}) > 1  # stacked in rows


def test_height_is_the_rise_in_mm_and_the_margins_and_title_are_written(grasp_bag) -> None:
    result = plot_bag(grasp_bag.path)
    height_ax = result.figure.axes[6]
    assert height_ax.get_ylabel() == 'object rise [mm]'
    line = lines_by_label(height_ax)['object rise (stand-in)']
    k = np.arange(gb.POSE_COUNT)
    assert np.allclose(line.get_xdata(), (gb.POSE_OFFSET_NS + k * gb.POSE_STEP_NS) / 1e9,
                       atol=1e-12)
    assert np.allclose(line.get_ydata(), [(gb.pose_z(i) - gb.Z0) * 1000 for i in k], atol=1e-9)
    assert line.get_ydata()[0] == 0.0 and line.get_ydata()[-1] == pytest.approx(
        (gb.pose_z(gb.POSE_COUNT - 1) - gb.Z0) * 1000)
    margins = [t.get_text() for t in result.figure.axes[7].texts if t.get_gid() == 'margins']
    assert len(margins) == 1
    assert 'lift guaranteed (eq. 18): yes, worst-case margin +0.04001 N' in margins[0]
    assert 'contact stiffness model: yes, margin +1.337 N' in margins[0]
    assert 'episode metadata' in margins[0]
    title = result.figure.get_suptitle()
    assert title == ('grasp: SUCCESS, k_theta = [10, 5, 5] N*m/rad, delta_theta_p = '
                     '[10, 10, 10] deg')


def test_without_episode_the_margins_come_from_the_last_checked_feedback(
        tmp_path: Path, typestore, prefixes) -> None:
    bag = gb.write_grasp_bag(tmp_path / 'nometa', typestore, prefixes)
    result = plot_bag(bag.path)
    lift, worst, csm, csm_margin = gb.FEEDBACK_MARGINS
    m = result.data.margins
    assert m is not None and m.source == 'action feedback'
    assert (m.lift_guaranteed, m.worst_case_margin, m.csm_lift, m.csm_margin) == \
        (lift, worst, csm, csm_margin)
    text = all_text(result.figure)
    assert 'lift guaranteed (eq. 18): no, worst-case margin -0.25 N' in text
    assert 'contact stiffness model: yes, margin +0.75 N' in text
    assert result.figure.get_suptitle().startswith('nometa: SUCCESS, k_theta and '
                                                   'delta_theta_p unknown')


def test_missing_topics_are_named_and_the_rest_is_plotted(tmp_path: Path, typestore,
                                                          prefixes) -> None:
    bag = gb.write_grasp_bag(tmp_path / 'status_only', typestore, prefixes,
                             topics=('/dam/status',))
    result = plot_bag(bag.path, tmp_path / 'status_only.png')
    assert (tmp_path / 'status_only.png').stat().st_size > 0
    assert result.data.missing == ['/joint_states: not in the bag',
                                   '/sim/object_pose: not in the bag',
                                   '/dam_grasp/_action/feedback: not in the bag',
                                   'check_lift margins: none recorded']
    assert all(not ax.get_lines() for ax in result.figure.axes)
    assert len([p for p in result.figure.axes[0].patches if p.get_gid() == 'phase']) == 4
    text = all_text(result.figure)
    assert '/joint_states: not in the bag' in text
    assert 'no /sim/object_pose in the bag' in text
    assert 'no finger1 joints in /joint_states' in text
    assert result.figure.get_suptitle().startswith('status_only: SUCCESS')


def test_an_incomplete_episode_says_so_in_the_title_and_names_what_it_lacks(
        tmp_path: Path, typestore, prefixes) -> None:
    lacks = [{'kind': 'end_event', 'topic': '/dam/episode',
              'detail': 'no EVENT_ENDED of the goal in the bag'}]
    bag = gb.write_grasp_bag(tmp_path / 'cut', typestore, prefixes, episode=gb.summary(),
                             custom={'dam_episode.complete': 'false',
                                     'dam_episode.missing': json.dumps(lacks)})
    result = plot_bag(bag.path)
    assert result.figure.get_suptitle().startswith('cut: SUCCESS, INCOMPLETE episode, k_theta')
    assert result.data.missing[-1] == 'episode: /dam/episode: no EVENT_ENDED of the goal in ' \
        'the bag'
    assert 'episode: /dam/episode: no EVENT_ENDED' in all_text(result.figure)


def test_joints_without_effort_are_named(tmp_path: Path, typestore, prefixes) -> None:
    bag = gb.write_grasp_bag(tmp_path / 'js', typestore, prefixes, topics=('/joint_states',))
    t = typestore.types
    # A second bag whose joint states lack finger3 and every effort.
    from dam_recorder.bag_writer import BagWriter
    from dam_recorder.type_description import load_message_type

    kind = load_message_type('sensor_msgs/msg/JointState', prefixes)
    writer = BagWriter(tmp_path / 'partial')
    topic = writer.add_topic('/joint_states', kind.name, kind.definition(), kind.type_hash, [])
    names = [n for n in gb.JOINTS if not n.startswith('finger3')]
    for i in range(5):
        msg = t['sensor_msgs/msg/JointState'](
            header=t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](
                sec=i, nanosec=0), frame_id=''), name=names,
            position=np.full(len(names), 0.1 * i), velocity=np.array([], np.float64),
            effort=np.array([], np.float64))
        writer.write(topic, gb.T0 + i * 1_000_000,
                     bytes(typestore.serialize_cdr(msg, 'sensor_msgs/msg/JointState')))
    writer.close()
    result = plot_bag(tmp_path / 'partial')
    assert 'finger3_compliant_joint: not in /joint_states' in result.data.missing
    assert 'finger1_position_joint: no effort (torque)' in result.data.missing
    assert not result.figure.axes[1].get_lines()  # no torque line without effort
    assert np.allclose(lines_by_label(result.figure.axes[0])['finger1_compliant_joint']
                       .get_ydata(), np.degrees(0.1 * np.arange(5)))
    assert plot_bag(bag.path).data.outcome == 'outcome unknown'


def test_phase_spans_of_status_samples() -> None:
    spans = phase_spans([(0.0, 'IDLE'), (0.5, 'IDLE'), (1.0, 'APPROACH'), (2.0, 'DONE')], 3.0)
    assert [(s.phase, s.start_s, s.end_s) for s in spans] == \
        [('IDLE', 0.0, 1.0), ('APPROACH', 1.0, 2.0), ('DONE', 2.0, 3.0)]
    assert phase_spans([], 1.0) == []


# -- a bag of several grasps --------------------------------------------------------------

#: Three grasps 30 s apart (outcomes SUCCESS, FAILURE, LIFTED_DAM_FAILED), /joint_states only
#: while each runs (100 Hz), so the stream pauses for about 25 s between them.
MULTI_GRASPS = ((1, 'SUCCESS'), (3, 'FAILURE'), (2, 'LIFTED_DAM_FAILED'))
MULTI_START_S = (2.0, 32.0, 62.0)
MULTI_PHASES = [('APPROACH', 1.0), ('ROLLING_UP', 2.0), ('ENVELOPE', 0.1), ('CLASSIFYING', 0.1),
                ('DONE', 0.5), ('RELEASING', 0.3), ('IDLE', 0.5)]


@pytest.fixture(scope='module')
def multi_bag(tmp_path_factory, typestore, prefixes) -> Path:
    from dam_recorder.bag_writer import BagWriter
    from dam_recorder.type_description import load_message_type

    t = typestore.types
    path = tmp_path_factory.mktemp('multi') / 'afternoon'
    writer = BagWriter(path, storage='mcap', compression='zstd', custom_data=dict)
    ids = {}
    for topic, type_name in (('/joint_states', 'sensor_msgs/msg/JointState'),
                             ('/dam/status', 'dam_interfaces/msg/DamStatus')):
        kind = load_message_type(type_name, prefixes)
        ids[topic] = (writer.add_topic(topic, kind.name, kind.definition(), kind.type_hash, []),
                      type_name)
    pending = []

    def header(time_s):
        return t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](
            sec=int(time_s), nanosec=0), frame_id='')

    def status(time_s, phase, outcome):
        names = {0: 'UNKNOWN', 1: 'SUCCESS', 2: 'LIFTED_DAM_FAILED', 3: 'FAILURE'}
        pending.append((time_s, '/dam/status', t['dam_interfaces/msg/DamStatus'](
            header=header(time_s), phase=phase, progress=0.5, finger_names=list(gb.FINGERS),
            compliant_torque=np.zeros(3), delta_theta_s=np.zeros(3), outcome=outcome,
            outcome_name=names[outcome], message='', compliant_torque_estimate=np.zeros(3),
            compliant_effort_measured=np.zeros(3))))

    status(0.0, 'IDLE', 0)
    for (outcome, _name), start in zip(MULTI_GRASPS, MULTI_START_S, strict=True):
        now = start
        for phase, length in MULTI_PHASES:
            ended = phase in ('DONE',)
            for k in range(int(round(length / 0.1))):
                status(now + 0.1 * k, phase, outcome if ended else 0)
            now += length
        for i in range(int((now - start) * 100)):
            time_s = start + 0.01 * i
            pending.append((time_s, '/joint_states', t['sensor_msgs/msg/JointState'](
                header=header(time_s), name=list(gb.JOINTS),
                position=np.full(len(gb.JOINTS), 0.01 * i), velocity=np.array([]),
                effort=np.full(len(gb.JOINTS), 0.1))))
    for time_s, topic, msg in sorted(pending, key=lambda item: item[0]):
        topic_id, type_name = ids[topic]
        writer.write(topic_id, gb.T0 + int(round(time_s * 1e9)),
                     bytes(typestore.serialize_cdr(msg, type_name)))
    writer.close()
    return path


def test_a_bag_of_several_grasps_shows_the_last_and_names_the_others(multi_bag,
                                                                     tmp_path) -> None:
    result = plot_bag(multi_bag, tmp_path / 'last.png')
    data = result.data
    assert data.outcome == 'LIFTED_DAM_FAILED'  # the grasp shown: the last
    assert '(grasp 3 of 3)' in data.title()
    low, high = result.figure.axes[0].get_xlim()
    # from 1 s before its first active phase (APPROACH at 62 s) to 3 s after DONE
    assert low == pytest.approx(MULTI_START_S[2] - 1.0) and high < 70.0, (low, high)
    notes = data.selection.notes
    assert notes[0] == 'the bag holds 3 grasps; shown: the last. The others:'
    assert notes[1].startswith('  1: 2.000 s to ') and notes[1].endswith(', SUCCESS')
    assert notes[2].startswith('  2: 32.000 s to ') and notes[2].endswith(', FAILURE')
    assert 'choose one with --episode N' in all_text(result.figure)
    assert _overlapping_labels(result.figure) == []


def test_episode_n_shows_that_grasp_with_its_own_outcome(multi_bag) -> None:
    data = plot_bag(multi_bag, episode=2).data
    assert data.outcome == 'FAILURE' and '(grasp 2 of 3)' in data.title()
    series = data.joints['finger1_compliant_joint']
    assert series.time_s.min() >= 31.0 and series.time_s.max() <= 61.0


def test_a_time_window_shows_what_lies_in_it(multi_bag) -> None:
    data = plot_bag(multi_bag, start_s=30.0, end_s=40.0).data
    series = data.joints['finger1_compliant_joint']
    assert 32.0 <= series.time_s.min() and series.time_s.max() <= 40.0
    assert data.outcome == 'FAILURE'  # the one grasp that starts in the window
    assert data.phases[0].start_s == pytest.approx(30.0)  # the phase at the window's start
    assert data.phases[0].phase == 'IDLE'


def test_lines_break_at_a_pause_instead_of_crossing_it(multi_bag) -> None:
    figure = plot_bag(multi_bag, start_s=0.0, end_s=70.0).figure
    line = lines_by_label(figure.axes[0])['finger1_compliant_joint']
    x = np.asarray(line.get_xdata(), dtype=float)
    y = np.asarray(line.get_ydata(), dtype=float)
    breaks = np.flatnonzero(np.isnan(y))
    assert len(breaks) == 2  # between grasps 1 and 2, 2 and 3
    finite = ~np.isnan(y)
    steps = np.diff(x[finite])
    # the only long steps of the drawn line are across the breaks
    assert np.sum(steps > 1.0) == 2 and all(np.isnan(y[i]) for i in breaks)


@pytest.mark.parametrize(('kwargs', 'says'), [
    ({'episode': 4}, '--episode 4: the bag holds grasps 1 to 3: 1: 2.000 s'),
    ({'episode': 1, 'start_s': 3.0}, '--episode and --start/--end choose the same thing'),
    ({'start_s': 10.0, 'end_s': 5.0}, '--start 10 s is not before --end 5 s'),
    ({'start_s': 500.0}, 'lies outside the bag'),
])
def test_a_selection_the_bag_cannot_give_is_refused_naming_it(multi_bag, kwargs, says) -> None:
    from dam_recorder.errors import BagReadError

    with pytest.raises(BagReadError) as caught:
        plot_bag(multi_bag, **kwargs)
    assert says in str(caught.value)


def test_export_takes_the_same_selection(multi_bag, tmp_path) -> None:
    import csv

    from dam_recorder.bag_export import export_bag
    from dam_recorder.bag_plot import read_selection

    chosen = read_selection(multi_bag, episode=1)
    [joint_states, _status] = sorted(
        export_bag(multi_bag, tmp_path / 'one', selection=chosen), key=lambda e: e.topic)
    with open(joint_states.path, encoding='utf-8', newline='') as stream:
        times = [float(row['time_s']) for row in csv.DictReader(stream)]
    assert times and min(times) >= 1.0 and max(times) <= 31.0
    whole = sorted(export_bag(multi_bag, tmp_path / 'all'), key=lambda e: e.topic)
    assert whole[0].rows > joint_states.rows * 2.5


def test_the_command_line_takes_the_selection(multi_bag, tmp_path, capsys) -> None:
    from dam_recorder.bag_cli import main

    assert main(['plot', str(multi_bag), '-o', str(tmp_path / 'two.png'), '--episode', '2']) == 0
    out = capsys.readouterr().out
    assert '(grasp 2 of 3): FAILURE' in out and 'shown: grasp 2: 32.000 s' in out, out
    assert main(['plot', str(multi_bag), '-o', str(tmp_path / 'last.png')]) == 0
    out = capsys.readouterr().out
    assert 'the bag holds 3 grasps; shown: the last' in out and '1: 2.000 s' in out, out
    assert main(['export', str(multi_bag), '-o', str(tmp_path / 'csv'), '--start', '30',
                 '--end', '40s']) == 0
    assert '30.000 s to 40.000 s' in capsys.readouterr().out
    assert main(['plot', str(multi_bag), '--episode', '9']) == 1
    assert 'bag plot: --episode 9: the bag holds grasps 1 to 3' in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(['plot', str(multi_bag), '--episode', '0'])
    assert 'grasps are numbered from 1' in capsys.readouterr().err
