"""The CDR end of a message: found by walking lengths, checked against rosbags' serializer."""

from __future__ import annotations

import random

import numpy as np
import pytest

from dam_recorder.cdr_end import CdrEnd
from dam_recorder.errors import CdrError
from dam_recorder.type_description import load_message_type

#: What ``rclpy.serialization.serialize_message`` (rmw_fastrtps, Jazzy wheels) returned for a
#: JointState with frame_id 'abc', names a/bb/ccc, position [1, 2, 3], velocity [0.5] and no
#: effort: 100 bytes, of which the last 4 are uninitialized memory after the 96-byte message.
RMW_SERIALIZED_JOINT_STATE = bytes.fromhex(
    '00010000000000000000000004000000616263000300000002000000610000000300000062620000'
    '040000006363630003000000000000000000f03f00000000000000400000000000000840010000006000'
    '0000000000000000e03f000000001529065d')


def joint_state(store, rng: random.Random):
    types = store.types
    n = rng.randrange(0, 5)
    return types['sensor_msgs/msg/JointState'](
        header=types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=rng.randrange(2**31), nanosec=5),
            frame_id='f' * rng.randrange(0, 9)),
        name=['j' * rng.randrange(1, 6) for _ in range(n)],
        position=np.array([rng.random() for _ in range(n)]),
        velocity=np.array([rng.random() for _ in range(rng.randrange(0, 3))]),
        effort=np.array([rng.random() for _ in range(rng.randrange(0, 3))]))


def dam_status(store, rng: random.Random):
    types = store.types
    return types['dam_interfaces/msg/DamStatus'](
        header=types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=1, nanosec=2), frame_id='x'),
        phase=rng.choice(['', 'IDLE', 'ROLLING_UP']), progress=rng.random(),
        finger_names=[f'f{k}' for k in range(rng.randrange(0, 4))],
        compliant_torque=np.array([rng.random() for _ in range(rng.randrange(0, 4))]),
        delta_theta_s=np.array([rng.random() for _ in range(rng.randrange(0, 4))]),
        outcome=rng.randrange(6), outcome_name='o' * rng.randrange(0, 9),
        message='m' * rng.randrange(0, 7),
        compliant_torque_estimate=np.array([rng.random() for _ in range(rng.randrange(0, 4))]),
        compliant_effort_measured=np.array([rng.random() for _ in range(rng.randrange(0, 4))]))


def diagnostics(store, rng: random.Random):
    types = store.types
    status = [types['diagnostic_msgs/msg/DiagnosticStatus'](
        level=rng.randrange(3), name='n' * rng.randrange(5), message='ok', hardware_id='',
        values=[types['diagnostic_msgs/msg/KeyValue'](key='k' * rng.randrange(4), value='v')
                for _ in range(rng.randrange(3))]) for _ in range(rng.randrange(3))]
    return types['diagnostic_msgs/msg/DiagnosticArray'](
        header=types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=1, nanosec=2), frame_id=''),
        status=status)


def feedback(store, rng: random.Random):
    types = store.types
    return types['dam_interfaces/action/DamGrasp_FeedbackMessage'](
        goal_id=types['unique_identifier_msgs/msg/UUID'](
            uuid=np.array([rng.randrange(256) for _ in range(16)], dtype=np.uint8)),
        feedback=types['dam_interfaces/msg/DamGrasp_Feedback'](
            phase='P' * rng.randrange(4), outcome=rng.randrange(6),
            outcome_name='o' * rng.randrange(0, 9), progress=0.5, lift_checked=True,
            lift_guaranteed=False, worst_case_margin=1.0, csm_lift=True, csm_margin=2.0,
            compliant_torque=np.array([rng.random() for _ in range(rng.randrange(4))]),
            compliant_torque_estimate=np.array([rng.random() for _ in range(rng.randrange(4))]),
            compliant_effort_measured=np.array([rng.random() for _ in range(rng.randrange(4))])))


CASES = [('sensor_msgs/msg/JointState', joint_state),
         ('dam_interfaces/msg/DamStatus', dam_status),
         ('diagnostic_msgs/msg/DiagnosticArray', diagnostics),
         ('dam_interfaces/action/DamGrasp_FeedbackMessage', feedback)]


@pytest.mark.parametrize('type_name, make', CASES)
@pytest.mark.parametrize('little_endian', [True, False])
def test_end_is_where_an_independent_serializer_stops(prefixes, typestore, type_name, make,
                                                       little_endian) -> None:
    end = CdrEnd(load_message_type(type_name, prefixes))
    rng = random.Random(type_name)
    store_name = type_name
    for _ in range(200):
        message = make(typestore, rng)
        data = bytes(typestore.serialize_cdr(message, store_name, little_endian=little_endian))
        garbage = bytes(rng.randrange(256) for _ in range(rng.randrange(0, 13)))
        assert end.end(data + garbage) == len(data)
        assert end.trim(data + garbage) == data
        if not garbage:
            assert end.trim(data) is data  # nothing to cut: no copy


def test_rmw_serialized_joint_state_is_cut_to_what_rosbags_reads(prefixes, typestore) -> None:
    from rosbags.serde import SerdeError

    with pytest.raises(SerdeError, match='size mismatch'):
        typestore.deserialize_cdr(RMW_SERIALIZED_JOINT_STATE, 'sensor_msgs/msg/JointState')
    end = CdrEnd(load_message_type('sensor_msgs/msg/JointState', prefixes))
    cut = end.trim(RMW_SERIALIZED_JOINT_STATE)
    assert len(cut) == 96
    message = typestore.deserialize_cdr(cut, 'sensor_msgs/msg/JointState')
    assert message.header.frame_id == 'abc' and message.name == ['a', 'bb', 'ccc']
    assert message.position.tolist() == [1.0, 2.0, 3.0]
    assert message.velocity.tolist() == [0.5] and message.effort.tolist() == []


def test_elements_of_empty_sequences_are_not_aligned(prefixes) -> None:
    # header(sec, nanosec, '') = 13 bytes, name [] -> 20, three empty float64 arrays: 4 bytes
    # each, no alignment to 8 in between: 32 bytes after the 4-byte encapsulation header.
    end = CdrEnd(load_message_type('sensor_msgs/msg/JointState', prefixes))
    data = bytes.fromhex('00010000') + bytes(8) + (1).to_bytes(4, 'little') + b'\0' \
        + bytes(3) + bytes(16)
    assert end.end(data) == 36


def test_truncated_or_foreign_data_is_an_error_naming_the_type(prefixes, typestore) -> None:
    end = CdrEnd(load_message_type('sensor_msgs/msg/JointState', prefixes))
    data = RMW_SERIALIZED_JOINT_STATE[:96]
    for cut in (0, 3, 10, 40, 95):
        with pytest.raises(CdrError, match='sensor_msgs/msg/JointState'):
            end.end(data[:cut])
    with pytest.raises(CdrError, match='not plain CDR'):
        end.end(bytes.fromhex('00030000') + data[4:])
    huge_name_count = data[:20] + (2**31).to_bytes(4, 'little') + data[24:]
    with pytest.raises(CdrError, match='truncated'):
        end.end(huge_name_count)
