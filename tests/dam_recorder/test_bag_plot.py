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


def test_a_phase_too_short_for_its_name_is_labelled_upright() -> None:
    from matplotlib.figure import Figure

    from dam_recorder.bag_plot import PhaseSpan, _shade_phases

    ax = Figure().add_subplot()
    _shade_phases(ax, [PhaseSpan('ROLLING_UP', 0.0, 9.0), PhaseSpan('ENVELOPE', 9.0, 9.1),
                       PhaseSpan('DONE', 9.1, 10.0)], label=True)
    texts = {t.get_text(): t.get_rotation() for t in ax.texts if t.get_gid() == 'phase_label'}
    assert texts == {'ROLLING_UP': 0.0, 'ENVELOPE': 90.0, 'DONE': 0.0}


def test_height_is_the_rise_in_mm_and_the_margins_and_title_are_written(grasp_bag) -> None:
    result = plot_bag(grasp_bag.path)
    height_ax = result.figure.axes[6]
    assert height_ax.get_ylabel() == 'object rise [mm]'
    line = lines_by_label(height_ax)['object rise']
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
