"""Bags of a grasp with known signals, for the bag tools' tests (no rclpy).

:func:`write_grasp_bag` writes, with the recorder's own :class:`BagWriter` and a ``rosbags``
type store, a bag whose every value is a simple function of the message index (kept in a
:class:`GraspBag`), so that a test can compute what ``info``, ``plot`` and ``export`` must find
without asking the code under test:

- ``/joint_states`` at 100 Hz with nine joints ``finger<f>_<role>_joint``; messages
  ``GAP_FROM`` .. ``GAP_TO - 1`` are left out, which makes the largest gap;
- ``/dam/status`` at 10 Hz through the phases in :data:`PHASES`, ``DONE`` with outcome 1;
- ``/sim/object_pose`` at 50 Hz, the object rising from 0.0125 m after 1.2 s;
- ``/dam_grasp/_action/feedback``, three messages, the last two with the margins;
- when asked for, ``/sim/object_table_contact`` at 50 Hz beside the pose (a bounce of two
  messages, then off the table from message ``LIFT_FROM`` on, back on it from message
  ``fall_at`` on when given, :func:`contact_state`) and the
  ENDED event on ``/dam/episode``, with the controller's estimate (``ESTIMATE``) in a
  ``GraspEpisode`` whose definition has its fields, or without;
- ``custom_data``: the recorder's lost, dropped, paused and trimmed counts, its backlog and
  (optionally) the episode metadata, complete unless ``custom`` says otherwise.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from dam_recorder.bag_writer import BagWriter
from dam_recorder.type_description import load_message_type

T0 = 1_750_000_000_000_000_000  # [ns] the first message
FINGERS = ('finger1', 'finger2', 'finger3')
ROLES = ('compliant', 'locked', 'position')
JOINTS = tuple(f'{f}_{r}_joint' for f in FINGERS for r in ROLES)
JS_STEP_NS = 10_000_000  # 100 Hz
JS_COUNT = 200
GAP_FROM, GAP_TO = 100, 106  # messages left out: a gap of 70 ms after message 99
STATUS_OFFSET_NS, STATUS_STEP_NS = 5_000_000, 100_000_000
#: Phase of status message k (20 messages, 10 Hz).
PHASES = ['IDLE'] * 3 + ['APPROACH'] * 5 + ['ROLLING_UP'] * 6 + ['ENVELOPE'] * 3 + ['DONE'] * 3
POSE_OFFSET_NS, POSE_STEP_NS, POSE_COUNT = 2_000_000, 20_000_000, 99
Z0 = 0.0125  # [m]
FEEDBACK_TIMES_NS = (300_000_000, 400_000_000, 500_000_000)
LOST = {'/joint_states': 3, '/tf': 4}
PAUSED = {'/sim/object_pose': 2}
TRIMMED = {'/dam/status': 1}
DROPPED = {'/sim/object_pose': 5}
BACKLOG = {'max_s': 0.0125, 'mean_s': 0.0031, 'messages': 400}
GOAL_ID = '0123456789abcdef' * 2
#: ``/sim/object_table_contact``: message k beside pose message k; a bounce (off the table for
#: messages BOUNCE[0] .. BOUNCE[1] - 1, 40 ms), then off from LIFT_FROM on (1.302 s).
BOUNCE = (30, 32)
LIFT_FROM = 65
ENDED_NS = T0 + 1_800_000_000  # the goal's end (the summary's ended_ns) [ns]
#: The controller's estimate in the ENDED event (GraspEpisode fields where the message has them).
ESTIMATE = {'object_rise': 0.0061, 'object_left_table': True, 'object_orientation': 0.2}
K_THETA = [10.0, 5.0, 5.0]
DELTA_THETA_P = [0.17453292519943295] * 3
CHECK_LIFT = {'ok': True, 'message': 'lift guaranteed', 'lift_guaranteed': True,
              'worst_case_margin': 0.04001, 'csm_lift': True, 'csm_margin': 1.337,
              'delta_theta_s': [-0.0477, -0.0477, -0.0477],
              'compliant_torque': [0.334, 0.167, 0.167]}
FEEDBACK_MARGINS = (False, -0.25, True, 0.75)  # lift_guaranteed, worst_case, csm_lift, csm


def js_position(i: int, j: int) -> float:
    """Angle of joint ``j`` in joint-state message ``i`` [rad]."""
    return 0.002 * i * (j % 3 + 1) - 0.05 * j


def js_effort(i: int, j: int) -> float:
    """Torque of joint ``j`` in joint-state message ``i`` [N*m]."""
    return 0.001 * i + 0.01 * j


def pose_z(k: int) -> float:
    """Height of the object in pose message ``k`` [m]."""
    t = k * POSE_STEP_NS * 1e-9
    return Z0 + max(0.0, t - 1.2) * 0.02


def contact_state(k: int, fall_at: int | None = None) -> tuple[bool, float, bool, bool]:
    """(on_table, off_table_s, lifted, off_table_at_end) of contact message ``k``, the object
    back on the table from message ``fall_at`` on (the stand-in's rule on its own clock: 50 ms
    off is a lift-off, and lifted stays true from then on; off for 0.1 s now is off the table
    at the end)."""
    step = POSE_STEP_NS * 1e-9
    last_off = k if fall_at is None else min(k, fall_at - 1)  # of the lift from LIFT_FROM
    lifted = (last_off - LIFT_FROM) * step >= 0.05 - 1e-9  # the bounce (40 ms) is none
    if BOUNCE[0] <= k < BOUNCE[1]:
        off = (k - BOUNCE[0]) * step
    elif k >= LIFT_FROM and (fall_at is None or k < fall_at):
        off = (k - LIFT_FROM) * step
    else:
        return True, 0.0, lifted, False
    return False, off, lifted, off >= 0.1 - 1e-9


def summary(**changes: Any) -> dict[str, Any]:
    """An episode summary as the recorder mode writes it (``changes`` replace keys)."""
    data = {'goal_id': GOAL_ID, 'accepted_ns': T0 + 250_000_000, 'ended_ns': T0 + 1_800_000_000,
            'goal': {'k_theta': [10.0], 'delta_theta_p': []}, 'k_theta': K_THETA,
            'delta_theta_p': DELTA_THETA_P, 'friction_angle': 0.08726646259971647,
            'check_lift': CHECK_LIFT, 'outcome': 1, 'outcome_name': 'SUCCESS',
            'message': 'grasp done: enveloped', 'duration_s': 1.55, 'pre_roll_s': 0.25,
            'post_roll_s': 0.2}
    data.update(changes)
    return data


@dataclass
class GraspBag:
    """What :func:`write_grasp_bag` wrote: receive times [ns] and messages per topic."""

    path: Path
    times: dict[str, list[int]] = field(default_factory=dict)
    values: dict[str, list[Any]] = field(default_factory=dict)

    @property
    def start_ns(self) -> int:
        return min(t[0] for t in self.times.values() if t)

    @property
    def end_ns(self) -> int:
        return max(t[-1] for t in self.times.values() if t)


def _header(t: Any, sec: int, nanosec: int, frame: str) -> Any:
    return t['std_msgs/msg/Header'](
        stamp=t['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec), frame_id=frame)


def write_grasp_bag(path: Path, typestore: Any, prefixes: list[str], *,
                    topics: tuple[str, ...] = ('/joint_states', '/dam/status',
                                               '/sim/object_pose',
                                               '/dam_grasp/_action/feedback'),
                    episode: dict[str, Any] | None = None,
                    custom: dict[str, str] | None = None, storage: str = 'mcap',
                    estimate: dict[str, Any] | None = None,
                    fall_at: int | None = None) -> GraspBag:
    """Write the grasp bag described in the module to ``path`` (only ``topics``); the ENDED
    event's GraspEpisode gets the fields of ``estimate`` (a definition with them) when given;
    the object falls back on the table at contact message ``fall_at`` when given."""
    t = typestore.types
    data = {'dam_recorder.lost_messages': json.dumps(LOST),
            'dam_recorder.paused_messages': json.dumps(PAUSED),
            'dam_recorder.trimmed_messages': json.dumps(TRIMMED),
            'dam_recorder.dropped_messages': json.dumps(DROPPED),
            'dam_recorder.backlog': json.dumps(BACKLOG)}
    if episode is not None:
        data['dam_episode.summary'] = json.dumps(episode)
        data['dam_episode.complete'] = 'true'
        data['dam_episode.missing'] = '[]'
        data['dam_episode.config'] = 'task:\n  k_theta_nm_per_rad: 10.0\n'
        data['dam_episode.version'] = '0.1.0'
    data.update(custom or {})
    writer = BagWriter(path, storage=storage,
                       compression='zstd' if storage == 'mcap' else 'none',
                       custom_data=lambda: data)
    types = {'/joint_states': 'sensor_msgs/msg/JointState',
             '/dam/status': 'dam_interfaces/msg/DamStatus',
             '/sim/object_pose': 'geometry_msgs/msg/PoseStamped',
             '/dam_grasp/_action/feedback': 'dam_interfaces/action/DamGrasp_FeedbackMessage',
             '/sim/object_table_contact': 'dam_interfaces/msg/ObjectTableContact',
             '/dam/episode': 'dam_interfaces/msg/GraspEpisode'}
    ids = {}
    stores = dict.fromkeys(topics, typestore)
    for topic in topics:
        kind = load_message_type(types[topic], prefixes)
        definition = kind.definition()
        if topic == '/dam/episode' and estimate is not None:
            definition, stores[topic] = _with_fields(definition, estimate)
        ids[topic] = writer.add_topic(topic, kind.name, definition, kind.type_hash, [])
    out = GraspBag(path)
    pending: list[tuple[int, str, Any]] = []
    if '/joint_states' in topics:
        for i in range(JS_COUNT):
            if GAP_FROM <= i < GAP_TO:
                continue
            msg = t['sensor_msgs/msg/JointState'](
                header=_header(t, 100 + i, i, 'palm'), name=list(JOINTS),
                position=np.array([js_position(i, j) for j in range(len(JOINTS))]),
                velocity=np.array([], dtype=np.float64),
                effort=np.array([js_effort(i, j) for j in range(len(JOINTS))]))
            pending.append((T0 + i * JS_STEP_NS, '/joint_states', msg))
    if '/dam/status' in topics:
        for k, phase in enumerate(PHASES):
            msg = t['dam_interfaces/msg/DamStatus'](
                header=_header(t, 200 + k, 0, ''), phase=phase, progress=k / 20,
                finger_names=list(FINGERS),
                compliant_torque=np.array([0.1 * k, 0.05 * k, 0.05 * k]),
                delta_theta_s=np.array([], dtype=np.float64),
                outcome=1 if phase == 'DONE' else 0,
                outcome_name='SUCCESS' if phase == 'DONE' else 'UNKNOWN',
                message='grasp done: enveloped' if phase == 'DONE' else '',
                compliant_torque_estimate=np.array([0.1 * k, 0.05 * k, 0.05 * k]),
                compliant_effort_measured=np.array([0.1 * k, 0.05 * k, 0.05 * k]))
            pending.append((T0 + STATUS_OFFSET_NS + k * STATUS_STEP_NS, '/dam/status', msg))
    if '/sim/object_pose' in topics:
        for k in range(POSE_COUNT):
            pose = t['geometry_msgs/msg/Pose'](
                position=t['geometry_msgs/msg/Point'](x=0.001 * k, y=0.0, z=pose_z(k)),
                orientation=t['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0))
            msg = t['geometry_msgs/msg/PoseStamped'](header=_header(t, 300 + k, 0, 'world'),
                                                     pose=pose)
            pending.append((T0 + POSE_OFFSET_NS + k * POSE_STEP_NS, '/sim/object_pose', msg))
    if '/dam_grasp/_action/feedback' in topics:
        for n, offset in enumerate(FEEDBACK_TIMES_NS):
            checked = n > 0
            lift, worst, csm, csm_margin = FEEDBACK_MARGINS if checked else (
                False, math.nan, False, math.nan)
            feedback = t['dam_interfaces/msg/DamGrasp_Feedback'](
                phase='CHECK_LIFT' if n == 0 else 'APPROACH', outcome=0, outcome_name='',
                progress=0.1 * n,
                lift_checked=checked, lift_guaranteed=lift, worst_case_margin=worst,
                csm_lift=csm, csm_margin=csm_margin, compliant_torque=np.array([0.3, 0.15]),
                compliant_torque_estimate=np.array([0.3, 0.15]),
                compliant_effort_measured=np.array([0.3, 0.15]))
            msg = t['dam_interfaces/action/DamGrasp_FeedbackMessage'](
                goal_id=t['unique_identifier_msgs/msg/UUID'](
                    uuid=np.frombuffer(bytes.fromhex(GOAL_ID), dtype=np.uint8).copy()),
                feedback=feedback)
            pending.append((T0 + offset, '/dam_grasp/_action/feedback', msg))
    if '/sim/object_table_contact' in topics:
        for k in range(POSE_COUNT):
            on, off, lifted, at_end = contact_state(k, fall_at)
            msg = t['dam_interfaces/msg/ObjectTableContact'](
                header=_header(t, 300 + k, 0, 'world'), table_contacts=2 if on else 0,
                on_table=on, off_table_s=off, lifted=lifted, off_table_at_end=at_end)
            pending.append((T0 + POSE_OFFSET_NS + k * POSE_STEP_NS, '/sim/object_table_contact',
                            msg))
    if '/dam/episode' in topics:
        pending.append((ENDED_NS, '/dam/episode',
                        _ended_event(stores['/dam/episode'], estimate or {})))
    pending.sort(key=lambda item: item[0])
    for time_ns, topic, msg in pending:
        store = stores[topic]
        writer.write(ids[topic], time_ns, bytes(store.serialize_cdr(msg, types[topic])))
        out.times.setdefault(topic, []).append(time_ns)
        out.values.setdefault(topic, []).append(msg)
    writer.close()
    for topic in topics:
        out.times.setdefault(topic, [])
        out.values.setdefault(topic, [])
    return out


_FIELD_TYPES = {bool: 'bool', float: 'float64'}


def _with_fields(definition: str, fields: dict[str, Any]) -> tuple[str, Any]:
    """A GraspEpisode definition with ``fields`` appended to its own part (as a newer
    controller's message would have them), and a type store of it."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    separator = '\n' + '=' * 80 + '\n'
    own, _, nested = definition.partition(separator)
    have = {line.split()[1] for line in own.splitlines()
            if line.strip() and not line.lstrip().startswith('#') and len(line.split()) > 1}
    lines = ''.join(f'{_FIELD_TYPES[type(v)]} {name}\n' for name, v in fields.items()
                    if name not in have)
    text = own.rstrip('\n') + '\n' + lines + (separator + nested if nested else '')
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(text, 'dam_interfaces/msg/GraspEpisode'))
    return text, store


def _ended_event(store: Any, fields: dict[str, Any]) -> Any:
    """The goal's ENDED event, every field a plain value, with ``fields`` added."""
    t = store.types
    known = dict(
        ok=True, message='', lift_guaranteed=True, worst_case_margin=0.04, csm_lift=True,
        csm_margin=1.3, delta_theta_s=np.zeros(3), compliant_torque=np.zeros(3),
        friction_angle=0.087, torque_limit=0.6, within_torque_limit=True,
        csm_penetration=np.zeros(3), csm_in_domain=True, object='cylinder')
    for name, (_, (base, _)) in store.fielddefs['dam_interfaces/msg/LiftAnswer'][1]:
        if name not in known:  # a field added since: false, or NaN (not answered)
            known[name] = False if base == 'bool' else math.nan
    answer = t['dam_interfaces/msg/LiftAnswer'](**known)
    values = {name: {'bool': False, 'float64': math.nan}.get(desc[1][0]) if desc[0] == 1
              else None for name, desc in store.fielddefs['dam_interfaces/msg/GraspEpisode'][1]}
    values.update(
        header=_header(t, 400, 0, ''), event=1, goal_id=GOAL_ID,
        goal_k_theta=np.array([10.0]), goal_delta_theta_p=np.zeros(0), object='cylinder',
        k_theta=np.array(K_THETA), delta_theta_p=np.array(DELTA_THETA_P), lift_checked=True,
        check_lift=answer, outcome=1, outcome_name='SUCCESS', message='grasp done: enveloped',
        duration=1.55, config_source='', config_yaml='', software_version='')
    values.update(fields)
    return t['dam_interfaces/msg/GraspEpisode'](**values)
