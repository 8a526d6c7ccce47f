"""``bag export``: one CSV file per topic whose rows are the written values, flattened as the
module documents (dotted names, elements by joint name or index, UUIDs in hex)."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import grasp_bags as gb
import numpy as np
import pytest

from dam_recorder.bag_export import csv_name, export_bag, seconds_text
from dam_recorder.errors import BagReadError, ExportError


@pytest.fixture(scope='module')
def exported(tmp_path_factory, typestore, prefixes) -> tuple[gb.GraspBag, Path, list]:
    root = tmp_path_factory.mktemp('export')
    bag = gb.write_grasp_bag(root / 'grasp', typestore, prefixes, episode=gb.summary())
    return bag, root / 'csv', export_bag(bag.path, root / 'csv')


def read_csv(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with open(path, newline='', encoding='utf-8') as stream:
        reader = csv.DictReader(stream)
        return list(reader.fieldnames or []), list(reader)


def test_one_file_per_topic_with_the_receive_times(exported) -> None:
    bag, out, files = exported
    assert sorted(p.name for p in out.iterdir()) == sorted(
        ['joint_states.csv', 'dam-status.csv', 'sim-object_pose.csv',
         'dam_grasp-_action-feedback.csv'])
    assert [f.topic for f in files] == sorted(bag.times)
    for f in files:
        header, rows = read_csv(f.path)
        assert header == f.columns and header[:2] == ['time_s', 'time_ns']
        assert f.rows == len(rows) == len(bag.times[f.topic])
        assert [int(r['time_ns']) for r in rows] == bag.times[f.topic]
        assert [float(r['time_s']) for r in rows] == \
            [(t - gb.T0) / 1e9 for t in bag.times[f.topic]]


def test_joint_states_are_keyed_by_joint_name(exported) -> None:
    _bag, out, _files = exported
    header, rows = read_csv(out / 'joint_states.csv')
    joints_order = [f'position.{n}' for n in gb.JOINTS]
    assert header == ['time_s', 'time_ns', 'header.stamp.sec', 'header.stamp.nanosec',
                      'header.frame_id', *joints_order, *[f'effort.{n}' for n in gb.JOINTS]]
    indices = [i for i in range(gb.JS_COUNT) if not gb.GAP_FROM <= i < gb.GAP_TO]
    for row, i in zip(rows, indices, strict=True):
        assert (row['header.stamp.sec'], row['header.stamp.nanosec'],
                row['header.frame_id']) == (str(100 + i), str(i), 'palm')
        for j, name in enumerate(gb.JOINTS):
            assert float(row[f'position.{name}']) == gb.js_position(i, j)  # exact round trip
            assert float(row[f'effort.{name}']) == gb.js_effort(i, j)


def test_status_pose_and_feedback_fields(exported) -> None:
    _bag, out, _files = exported
    header, rows = read_csv(out / 'dam-status.csv')
    assert 'finger_names.0' not in header and 'compliant_torque.finger2' in header
    assert not any(c.startswith('delta_theta_s') for c in header)  # always empty
    for k, row in enumerate(rows):
        assert row['phase'] == gb.PHASES[k]
        assert float(row['progress']) == k / 20
        assert float(row['compliant_torque.finger1']) == 0.1 * k
        assert row['outcome'] == ('1' if gb.PHASES[k] == 'DONE' else '0')
        assert row['message'] == ('grasp done: enveloped' if gb.PHASES[k] == 'DONE' else '')
    _header, poses = read_csv(out / 'sim-object_pose.csv')
    assert [float(r['pose.position.z']) for r in poses] == \
        [gb.pose_z(k) for k in range(gb.POSE_COUNT)]
    assert [r['pose.orientation.w'] for r in poses] == ['1.0'] * gb.POSE_COUNT
    assert poses[3]['header.frame_id'] == 'world' and poses[3]['pose.position.x'] == '0.003'
    header, feedback = read_csv(out / 'dam_grasp-_action-feedback.csv')
    assert header[2:] == ['goal_id.uuid', 'feedback.phase', 'feedback.outcome',
                          'feedback.outcome_name', 'feedback.progress',
                          'feedback.lift_checked', 'feedback.lift_guaranteed',
                          'feedback.worst_case_margin', 'feedback.csm_lift',
                          'feedback.csm_margin', 'feedback.compliant_torque.0',
                          'feedback.compliant_torque.1', 'feedback.compliant_torque_estimate.0',
                          'feedback.compliant_torque_estimate.1',
                          'feedback.compliant_effort_measured.0',
                          'feedback.compliant_effort_measured.1']
    assert [r['goal_id.uuid'] for r in feedback] == [gb.GOAL_ID] * 3
    assert [r['feedback.lift_checked'] for r in feedback] == ['false', 'true', 'true']
    assert feedback[0]['feedback.worst_case_margin'] == 'nan'
    assert math.isnan(float(feedback[0]['feedback.csm_margin']))
    assert float(feedback[2]['feedback.worst_case_margin']) == gb.FEEDBACK_MARGINS[1]
    assert feedback[1]['feedback.compliant_torque.1'] == '0.15'


def test_topics_are_selectable_and_unknown_ones_named(tmp_path: Path, exported) -> None:
    bag, _out, _files = exported
    files = export_bag(bag.path, tmp_path / 'some', ['/sim/object_pose', '/dam/status'])
    assert [f.topic for f in files] == ['/sim/object_pose', '/dam/status']
    assert sorted(p.name for p in (tmp_path / 'some').iterdir()) == \
        ['dam-status.csv', 'sim-object_pose.csv']
    with pytest.raises(BagReadError, match=r'no topic /nope in the bag \(it has: /dam/status'):
        export_bag(bag.path, tmp_path / 'none', ['/nope'])
    assert not (tmp_path / 'none').exists()
    (tmp_path / 'file').write_text('x')
    with pytest.raises(ExportError, match='cannot create the output directory'):
        export_bag(bag.path, tmp_path / 'file' / 'sub', ['/dam/status'])


def test_arrays_of_messages_and_varying_joint_sets(tmp_path: Path, typestore,
                                                   prefixes) -> None:
    from dam_recorder.bag_writer import BagWriter
    from dam_recorder.type_description import load_message_type

    t = typestore.types
    writer = BagWriter(tmp_path / 'mixed', storage='sqlite3', compression='none')
    ids = {}
    for topic, type_name in (('/diagnostics', 'diagnostic_msgs/msg/DiagnosticArray'),
                             ('/joint_states', 'sensor_msgs/msg/JointState')):
        kind = load_message_type(type_name, prefixes)
        ids[topic] = writer.add_topic(topic, kind.name, kind.definition(), kind.type_hash, [])
    header = t['std_msgs/msg/Header'](stamp=t['builtin_interfaces/msg/Time'](sec=1, nanosec=2),
                                      frame_id='')
    status = [t['diagnostic_msgs/msg/DiagnosticStatus'](
        level=k, name=f'dev, {k}', message='ok "quoted"', hardware_id='dam',
        values=[t['diagnostic_msgs/msg/KeyValue'](key='k', value=str(k))]) for k in range(2)]
    diag = t['diagnostic_msgs/msg/DiagnosticArray'](header=header, status=status)
    writer.write(ids['/diagnostics'], gb.T0 + 5,
                 bytes(typestore.serialize_cdr(diag, 'diagnostic_msgs/msg/DiagnosticArray')))
    for i, (names, position, velocity) in enumerate((
            (['a', 'b'], [0.0, 1.0], [1.5]), (['b', 'c'], [10.0, 11.0], [1.5]),
            (['a'], [20.0], [1.5]), (['z'], [], []))):
        js = t['sensor_msgs/msg/JointState'](
            header=header, name=names, position=np.array(position, np.float64),
            velocity=np.array(velocity, np.float64), effort=np.array([], np.float64))
        writer.write(ids['/joint_states'], gb.T0 + 1_000 * (i + 1),
                     bytes(typestore.serialize_cdr(js, 'sensor_msgs/msg/JointState')))
    writer.close()
    export_bag(tmp_path / 'mixed', tmp_path / 'out')
    header_row, rows = read_csv(tmp_path / 'out' / 'diagnostics.csv')
    assert header_row[5:] == ['status.0.level', 'status.0.name', 'status.0.message',
                              'status.0.hardware_id', 'status.0.values.0.key',
                              'status.0.values.0.value', 'status.1.level', 'status.1.name',
                              'status.1.message', 'status.1.hardware_id',
                              'status.1.values.0.key', 'status.1.values.0.value']
    assert rows[0]['status.1.level'] == '1' and rows[0]['status.1.name'] == 'dev, 1'
    assert rows[0]['status.0.message'] == 'ok "quoted"'
    assert rows[0]['time_s'] == '0.000000000'  # the first message of the bag
    header_row, rows = read_csv(tmp_path / 'out' / 'joint_states.csv')
    assert [r['time_s'] for r in rows] == ['0.000000995', '0.000001995', '0.000002995',
                                           '0.000003995']
    # velocity: one element for two names, so by index; for one name, by that name. The
    # last message has no array as long as its names, so the names get their own column.
    assert header_row[5:] == ['position.a', 'position.b', 'velocity.0', 'position.c',
                              'velocity.a', 'name.0']
    assert [[r[c] for c in header_row[5:]] for r in rows] == [
        ['0.0', '1.0', '1.5', '', '', ''],
        ['', '10.0', '1.5', '11.0', '', ''],
        ['20.0', '', '', '', '1.5', ''],
        ['', '', '', '', '', 'z']]


def test_file_names_and_seconds() -> None:
    assert csv_name('/dam_grasp/_action/feedback') == 'dam_grasp-_action-feedback.csv'
    assert csv_name('/joint_states') == 'joint_states.csv'
    assert seconds_text(1_500_000) == '0.001500000'
    assert seconds_text(12_000_000_001) == '12.000000001'
