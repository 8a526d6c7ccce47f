"""The message definitions the recorder stores are what rosbag2 writes, and every reader decodes
every message with them: ``mcap-ros2-support`` (with the definition as stored) and ``rosbags``
(which also checks the type hash against it), field by field (issue 20)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from bag_readers import read_with_mcap, read_with_rosbags
from mcap_ros2._dynamic import generate_dynamic
from rosbag2_format import rosbag2_msg_definition
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.base import Nodetype

from dam_recorder.bag_writer import BagWriter
from dam_recorder.msg_definition import SECTION_SEPARATOR
from dam_recorder.type_description import load_message_type

#: The type of every topic the recorder records by default (selection.DEFAULT_TOPICS).
DEFAULT_TYPES = {
    '/joint_states': 'sensor_msgs/msg/JointState',
    '/hand/command': 'dam_interfaces/msg/HandCommand',
    '/dam/status': 'dam_interfaces/msg/DamStatus',
    '/dam/episode': 'dam_interfaces/msg/GraspEpisode',
    '/dam_grasp/_action/status': 'action_msgs/msg/GoalStatusArray',
    '/dam_grasp/_action/feedback': 'dam_interfaces/action/DamGrasp_FeedbackMessage',
    '/diagnostics': 'diagnostic_msgs/msg/DiagnosticArray',
    '/robot_description': 'std_msgs/msg/String',
    '/sim/object_pose': 'geometry_msgs/msg/PoseStamped',
}
PLAIN_TYPES = sorted({t for t in DEFAULT_TYPES.values() if '/msg/' in t}
                     | {'sensor_msgs/msg/Imu', 'std_msgs/msg/Empty',
                        'geometry_msgs/msg/TransformStamped'})
#: A field's type in a section of a definition (the first word of a line that is no comment).
FIELD_TYPE = re.compile(r'^\s*([A-Za-z0-9_/]+)(?:\[[^\]]*\])?(?:<=\d+)?\s+\w', re.MULTILINE)


@pytest.mark.parametrize('type_name', PLAIN_TYPES)
def test_definition_of_a_message_type_is_the_one_rosbag2_writes(prefixes, type_name) -> None:
    """Byte for byte the text rosbag2's MCAP storage builds from the installed .msg files."""
    definition = load_message_type(type_name, prefixes).definition()
    assert definition == rosbag2_msg_definition(type_name, prefixes)


def sections(definition: str) -> list[str]:
    return definition.split(f'\n{SECTION_SEPARATOR}\n')


@pytest.mark.parametrize('type_name', sorted(set(DEFAULT_TYPES.values())))
def test_every_nested_type_is_spelt_in_the_ros2msg_grammar(prefixes, type_name) -> None:
    """No field names a type in three parts (``pkg/action/Name``): the grammar has ``pkg/Name``
    and bare names only. A section of a type derived from the action is headed by its full
    name, under which rosbags files it (and computes the hash stored)."""
    message_type = load_message_type(type_name, prefixes)
    definition = message_type.definition()
    for text in sections(definition):
        for line in text.splitlines():
            if line.startswith('MSG: '):
                continue
            match = FIELD_TYPE.match(line.split('#')[0])
            if match:
                assert match.group(1).count('/') <= 1, (type_name, line)
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(definition, type_name))
    assert store.hash_rihs01(type_name) == message_type.type_hash


def test_action_feedback_definition_decodes_with_mcap_ros2_support(prefixes) -> None:
    """The definition as stored, handed to mcap-ros2-support's parser (it refuses the name
    ``DamGrasp_FeedbackMessage`` itself, so the root goes under another name): the nested
    ``DamGrasp_Feedback`` resolves (issue 20: it raised InvalidResourceName)."""
    message_type = load_message_type('dam_interfaces/action/DamGrasp_FeedbackMessage', prefixes)
    definition = message_type.definition()
    assert definition.splitlines()[:2] == ['unique_identifier_msgs/UUID goal_id',
                                           'DamGrasp_Feedback feedback']
    assert 'MSG: dam_interfaces/action/DamGrasp_Feedback' in definition.splitlines()
    decoders = generate_dynamic('dam_interfaces/action/DamGraspFeedbackMessage', definition)
    assert 'dam_interfaces/DamGrasp_Feedback' in decoders


# -- a bag with every default type, read by both readers --------------------------------------

def _value(store: Any, node: tuple, i: int, k: int) -> Any:
    kind, spec = node
    if kind == Nodetype.BASE:
        name = spec[0]
        if name == 'string':
            return f's{i}_{k}' * (1 + (i + k) % 3)
        if name == 'bool':
            return (i + k) % 2 == 0
        if name.startswith('float'):
            return (i + 1) * 0.25 + k
        return (i * 7 + k) % (100 if name.startswith('int') else 200)
    if kind == Nodetype.NAME:
        return make_message(store, spec, i + k)
    inner, size = spec
    count = size if kind == Nodetype.ARRAY else (1 + (i + k) % 3 if not size else 1)
    values = [_value(store, inner, i, k + n) for n in range(count)]
    if inner[0] == Nodetype.BASE and inner[1][0] != 'string':
        dtype = {'bool': np.bool_, 'byte': np.uint8, 'char': np.uint8}.get(inner[1][0],
                                                                          inner[1][0])
        return np.array(values, dtype=dtype)
    return values


def make_message(store: Any, type_name: str, i: int) -> Any:
    """A message of ``type_name`` whose every field has a value that depends on ``i``."""
    _, fields = store.fielddefs[type_name]
    return store.types[type_name](**{name: _value(store, node, i, k)
                                     for k, (name, node) in enumerate(fields)})


def test_every_message_of_every_default_type_reads_the_same_in_both_readers(
        tmp_path: Path, prefixes, typestore) -> None:
    writer = BagWriter(tmp_path / 'bag')
    ids = {}
    for topic, type_name in DEFAULT_TYPES.items():
        kind = load_message_type(type_name, prefixes)
        ids[topic] = writer.add_topic(topic, type_name, kind.definition(), kind.type_hash, [])
    written: dict[str, list[bytes]] = {}
    for i in range(5):
        for topic, type_name in DEFAULT_TYPES.items():
            data = bytes(typestore.serialize_cdr(make_message(typestore, type_name, i),
                                                 type_name))
            writer.write(ids[topic], 1_000 + 10 * i + len(written.get(topic, [])), data)
            written.setdefault(topic, []).append(data)
    writer.close()
    by_mcap, by_rosbags = read_with_mcap(tmp_path / 'bag'), read_with_rosbags(tmp_path / 'bag')
    assert set(by_mcap) == set(by_rosbags) == set(DEFAULT_TYPES)
    for topic in DEFAULT_TYPES:
        assert [r.data for r in by_mcap[topic]] == written[topic], topic
        assert all(r.values is not None for r in by_mcap[topic]), topic
        assert [r.values for r in by_mcap[topic]] == [r.values for r in by_rosbags[topic]], \
            topic
