"""Message definitions and type hashes from the installed type descriptions (.json)."""

from __future__ import annotations

from pathlib import Path

import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from dam_recorder.errors import TypeDescriptionError
from dam_recorder.type_description import (
    FieldType,
    field_type_text,
    install_prefix_of,
    load_message_type,
    message_type_from_description,
)

JOINT_STATE_FIELDS = """\
std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
"""
SEPARATOR = '=' * 80


STANDARD_TYPES = ['sensor_msgs/msg/JointState', 'diagnostic_msgs/msg/DiagnosticArray',
                  'geometry_msgs/msg/PoseStamped', 'action_msgs/msg/GoalStatusArray',
                  'std_msgs/msg/String', 'sensor_msgs/msg/Imu', 'std_msgs/msg/Empty']


def test_joint_state_definition_is_the_msg_files_with_its_nested_types(prefixes) -> None:
    """The .msg files as installed (comments kept), each nested type in a section of its own
    (tests/dam_recorder/test_msg_definition.py compares it with rosbag2's construction)."""
    message_type = load_message_type('sensor_msgs/msg/JointState', prefixes)
    definition = message_type.definition()
    own, header, time = definition.split(f'\n{SEPARATOR}\n')
    assert '\n'.join(line for line in own.splitlines()
                     if line and not line.startswith('#')) + '\n' == JOINT_STATE_FIELDS
    assert header.startswith('MSG: std_msgs/Header\n')
    assert time.startswith('MSG: builtin_interfaces/Time\n')
    assert message_type.referenced_types() == ['std_msgs/msg/Header',
                                               'builtin_interfaces/msg/Time']


@pytest.mark.parametrize('type_name', STANDARD_TYPES)
def test_definition_and_hash_agree_with_rosbags_own_type_store(prefixes, type_name) -> None:
    """rosbags parses the definition into the fields its built-in store has, and computes the
    same RIHS01 hash from its own copy of the type (an independent implementation)."""
    message_type = load_message_type(type_name, prefixes)
    reference = get_typestore(Stores.ROS2_JAZZY)
    parsed = get_typestore(Stores.EMPTY)
    parsed.register(get_types_from_msg(message_type.definition(), type_name))
    for name in [type_name, *message_type.referenced_types()]:
        assert parsed.fielddefs[name][1] == reference.fielddefs[name][1], name
    assert message_type.type_hash == reference.hash_rihs01(type_name)
    assert message_type.type_hash.startswith('RIHS01_') and len(message_type.type_hash) == 71


def test_action_feedback_message_is_found_in_the_action_description(prefixes) -> None:
    message_type = load_message_type('dam_interfaces/action/DamGrasp_FeedbackMessage',
                                     prefixes)
    lines = message_type.definition().splitlines()
    # The nested type derived from the action is spelt bare in the field (the ros2msg grammar
    # has no three-part names) and by its full name in its section's header: read as
    # pkg/Name, rosbags would place it in pkg/msg and compute another hash than the one stored.
    assert lines[:2] == ['unique_identifier_msgs/UUID goal_id', 'DamGrasp_Feedback feedback']
    assert 'MSG: unique_identifier_msgs/UUID' in lines
    assert 'uint8[16] uuid' in lines
    assert 'MSG: dam_interfaces/action/DamGrasp_Feedback' in lines
    assert 'float64[] compliant_torque' in lines
    # rosbags builds a type from it with the fields of DamGrasp.action's feedback section, and
    # computes the hash the recorder stores (what rosbags' AnyReader checks).
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(message_type.definition(), message_type.name))
    feedback = [name for name, _ in
                store.fielddefs['dam_interfaces/action/DamGrasp_Feedback'][1]]
    assert feedback == ['phase', 'outcome', 'outcome_name', 'progress', 'lift_checked',
                        'lift_guaranteed',
                        'worst_case_margin', 'csm_lift', 'csm_margin', 'compliant_torque',
                        'compliant_torque_estimate', 'compliant_effort_measured']
    assert store.hash_rihs01(message_type.name) == message_type.type_hash


def test_dam_status_has_the_fields_of_its_msg_file(prefixes, typestore) -> None:
    message_type = load_message_type('dam_interfaces/msg/DamStatus', prefixes)
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(message_type.definition(), message_type.name))
    assert store.fielddefs[message_type.name][1] == \
        typestore.fielddefs['dam_interfaces/msg/DamStatus'][1]
    assert message_type.type_hash == typestore.hash_rihs01('dam_interfaces/msg/DamStatus')


@pytest.mark.parametrize('field_type, text', [
    (FieldType(11 + 48, capacity=3), 'float64[3]'),
    (FieldType(6 + 96, capacity=5), 'int32[<=5]'),
    (FieldType(21 + 144, string_capacity=8), 'string<=8[]'),
    (FieldType(21 + 48, capacity=2, string_capacity=4), 'string<=4[2]'),
    (FieldType(1 + 144, nested_type_name='geometry_msgs/msg/Point'), 'geometry_msgs/Point[]'),
    (FieldType(15), 'bool'),
    (FieldType(16 + 144), 'byte[]'),
])
def test_field_types_are_spelled_as_in_msg_files(field_type, text) -> None:
    assert field_type_text(field_type) == text


def _document(field_type_id: int) -> dict:
    return {'type_description_msg': {
        'type_description': {'type_name': 'pkg/msg/Wide', 'fields': [
            {'name': 'label', 'type': {'type_id': field_type_id}}]},
        'referenced_type_descriptions': []},
        'type_hashes': [{'type_name': 'pkg/msg/Wide', 'hash_string': 'RIHS01_00'}]}


def test_a_field_type_without_cdr_layout_here_is_refused_by_name() -> None:
    with pytest.raises(TypeDescriptionError, match=r"pkg/msg/Wide\.label: .*'wstring'"):
        message_type_from_description(_document(18), 'pkg/msg/Wide')
    assert message_type_from_description(_document(17), 'pkg/msg/Wide').definition() == \
        'string label\n'


def test_a_type_without_description_names_the_type(prefixes) -> None:
    with pytest.raises(TypeDescriptionError, match='sensor_msgs/msg/NoSuchThing'):
        load_message_type('sensor_msgs/msg/NoSuchThing', prefixes)
    with pytest.raises(TypeDescriptionError, match="'JointState'"):
        load_message_type('JointState', prefixes)


def test_install_prefix_is_found_above_the_python_package(tmp_path: Path) -> None:
    (tmp_path / 'share' / 'pkg').mkdir(parents=True)
    module = tmp_path / 'lib' / 'python3.11' / 'site-packages' / 'pkg' / '__init__.py'
    module.parent.mkdir(parents=True)
    module.write_text('')
    assert install_prefix_of(module, 'pkg') == tmp_path
    assert install_prefix_of(module, 'other') is None
