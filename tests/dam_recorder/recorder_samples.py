"""The messages the recorder tests publish, as plain values (no rclpy): message ``i`` of each
topic has field values computed from ``i``, so that a test can check every field it reads back.

The fixture ``tests/fixtures/recorder_publishers.py`` builds ROS messages from these values;
the tests compare what two independent bag readers decode with them.
"""

from __future__ import annotations

from typing import Any

#: Topic -> (type, how the fixture publishes it). ``serialized`` topics are published as the
#: buffer ``rclpy.serialization.serialize_message`` returns (with its trailing bytes), the others
#: as message objects.
TOPICS: dict[str, tuple[str, str]] = {
    '/joint_states': ('sensor_msgs/msg/JointState', 'serialized'),
    '/dam/status': ('dam_interfaces/msg/DamStatus', 'serialized'),
    '/hand/command': ('dam_interfaces/msg/HandCommand', 'object'),
    '/sim/object_pose': ('geometry_msgs/msg/PoseStamped', 'object'),
    '/dam_grasp/_action/feedback': ('dam_interfaces/action/DamGrasp_FeedbackMessage', 'object'),
}
#: Published once, latched (transient local), before the recorder starts.
LATCHED_TOPIC = '/robot_description'
LATCHED_TEXT = '<robot name="dam_hand"><link name="palm"/></robot>'
#: A topic whose publisher appears only after the others are recorded.
LATE_TOPIC = '/diagnostics'
#: Best-effort publishers (the others are reliable).
BEST_EFFORT_TOPICS = ('/sim/object_pose',)


def sample(topic: str, i: int) -> dict[str, Any]:
    """Field values of message ``i`` on ``topic`` (nested messages as dicts)."""
    stamp = {'sec': 1000 + i, 'nanosec': 7 * i}
    if topic == '/joint_states':
        # Empty velocity: the float64 array layout that makes serialize_message pad most.
        return {'header': {'stamp': stamp, 'frame_id': f'hand_{i}'},
                'name': ['f1_compliant_joint', 'f1_locked_joint', f'extra_{i % 3}'],
                'position': [0.001 * i, -0.5, 1.5 + i], 'velocity': [], 'effort': [0.25 * i]}
    if topic == '/dam/status':
        return {'header': {'stamp': stamp, 'frame_id': ''}, 'phase': ['APPROACH', 'ROLLING_UP',
                                                                      'ENVELOPE'][i % 3],
                'progress': i / 1000.0, 'finger_names': ['f1', 'f2', 'f3'][: 1 + i % 3],
                'compliant_torque': [0.1 * i, 0.2], 'delta_theta_s': [],
                'compliant_torque_estimate': [0.1 * i, 0.2], 'compliant_effort_measured': [],
                'outcome': i % 6, 'outcome_name': 'o' * (i % 4), 'message': 'x' * (i % 5)}
    if topic == '/hand/command':
        return {'header': {'stamp': stamp, 'frame_id': 'palm'},
                'name': ['f1_position_joint', 'f2_position_joint'], 'mode': [1, 3],
                'setpoint': [0.01 * i, -0.01 * i], 'stiffness': [2.0, 3.0],
                'damping': [0.05, 0.5 * (i % 2)]}
    if topic == '/sim/object_pose':
        return {'header': {'stamp': stamp, 'frame_id': 'world'},
                'pose': {'position': {'x': 0.001 * i, 'y': 0.0, 'z': 0.01},
                         'orientation': {'x': 0.0, 'y': 0.0, 'z': 0.0, 'w': 1.0}}}
    if topic == '/dam_grasp/_action/feedback':
        return {'goal_id': {'uuid': [(i + k) % 256 for k in range(16)]},
                'feedback': {'phase': 'ROLLING_UP', 'outcome': i % 6,
                             'outcome_name': 'o' * (i % 3), 'progress': 0.5, 'lift_checked': True,
                             'lift_guaranteed': i % 2 == 0, 'worst_case_margin': -1.0 * i,
                             'csm_lift': False, 'csm_margin': float('inf') if i == 0 else 1.0,
                             'compliant_torque': [0.3, 0.15, 0.15],
                             'compliant_torque_estimate': [0.3, 0.15, 0.15],
                             'compliant_effort_measured': [0.0, 0.1, 0.2]}}
    if topic == LATE_TOPIC:
        return {'header': {'stamp': stamp, 'frame_id': ''},
                'status': [{'level': 1, 'name': f'device {i}', 'message': 'ok',
                            'hardware_id': 'dam', 'values': [{'key': 'i', 'value': str(i)}]}]}
    if topic == LATCHED_TOPIC:
        return {'data': LATCHED_TEXT}
    raise KeyError(topic)


def index_of(topic: str, values: dict[str, Any]) -> int:
    """The ``i`` a decoded message of ``topic`` was made from."""
    if topic == LATCHED_TOPIC:
        return 0
    if topic == '/dam_grasp/_action/feedback':
        return values['goal_id']['uuid'][0]
    return values['header']['stamp']['sec'] - 1000
