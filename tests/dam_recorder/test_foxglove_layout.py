"""docs/foxglove/*.json: valid layouts that name only topics an episode records and fields
their messages have."""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

from dam_common.config import load_config
from dam_recorder.selection import DEFAULT_TOPICS

LAYOUTS = sorted((Path(__file__).resolve().parents[2] / 'docs' / 'foxglove').glob('*.json'))
#: ``/topic.field.field[3]``: a topic, then fields, each with an optional index.
_PATH = re.compile(r'^(?P<topic>(/[A-Za-z_][A-Za-z0-9_]*)+)(?P<fields>(\.[A-Za-z_][A-Za-z0-9_]*'
                   r'(\[\d+\])?)+)$')
_FIELD = re.compile(r'\.([A-Za-z_][A-Za-z0-9_]*)(?:\[(\d+)\])?')


def _topic_types() -> dict[str, Any]:
    from geometry_msgs.msg import PoseStamped
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from tf2_msgs.msg import TFMessage

    from dam_interfaces.action import DamGrasp
    from dam_interfaces.msg import DamStatus, GraspEpisode

    return {'/joint_states': JointState, '/dam/status': DamStatus,
            '/dam/episode': GraspEpisode, '/robot_description': String,
            '/sim/object_pose': PoseStamped, '/tf': TFMessage, '/tf_static': TFMessage,
            '/dam_grasp/_action/feedback': DamGrasp.Impl.FeedbackMessage}


def _message_paths(node: Any) -> list[dict[str, Any]]:
    """Every ``{"value": "/topic.field", ...}`` in a panel's configuration."""
    found = []
    if isinstance(node, dict):
        if isinstance(node.get('value'), str) and node['value'].startswith('/'):
            found.append(node)
        for value in node.values():
            found.extend(_message_paths(value))
    elif isinstance(node, list):
        for value in node:
            found.extend(_message_paths(value))
    return found


def _message_class(package: str, name: str) -> Any:
    """A message class of ``package`` by name, also one an action defines
    (``DamGrasp_Feedback``: :func:`dam_recorder.ros_types.message_class`)."""
    from dam_recorder.ros_types import message_class

    try:
        return message_class(f'{package}/msg/{name}')
    except Exception:  # noqa: BLE001 - not a plain message: one of an action's
        return message_class(f'{package}/action/{name}')


def _field_type(message_class: Any, fields: str) -> str:
    """The ROS type of ``fields`` (``.a.b[2]``) in ``message_class``; AssertionError naming
    the first field that does not exist or is indexed but not an array."""
    kind = message_class
    text = ''
    for name, index in _FIELD.findall(fields):
        types = kind.get_fields_and_field_types()
        assert name in types, f'{kind.__name__} has no field {name!r} (fields: {sorted(types)})'
        text = types[name]
        if index:
            assert text.startswith('sequence<') or text.endswith(']'), \
                f'{name} of {kind.__name__} is {text}, not an array: [{index}]'
            text = text.removeprefix('sequence<').split('>')[0].split('[')[0]
        base = text.split('<')[-1].rstrip('>')
        if '/' in base:
            package, message = base.split('/')
            kind = _message_class(package, message)
    return text


def _panels(layout: dict[str, Any]) -> list[str]:
    out = []

    def walk(node: Any) -> None:
        if isinstance(node, str):
            out.append(node)
        else:
            walk(node['first'])
            walk(node['second'])

    walk(layout['layout'])
    return out


@pytest.mark.parametrize('path', LAYOUTS, ids=lambda p: p.name)
def test_layout_names_only_recorded_topics_and_existing_fields(path: Path) -> None:
    layout = json.loads(path.read_text(encoding='utf-8'))
    assert set(_panels(layout)) == set(layout['configById'])
    types = _topic_types()
    paths = _message_paths(layout['configById'])
    assert paths
    for entry in paths:
        match = _PATH.match(entry['value'])
        assert match, f'{entry["value"]!r} is not a message path'
        topic = match['topic']
        assert topic in DEFAULT_TOPICS, f'{topic} is not recorded in episodes'
        _field_type(types[topic], match['fields'])
        if entry.get('timestampMethod') == 'headerStamp':
            assert 'header' in types[topic].get_fields_and_field_types(), entry['value']
    for panel in layout['configById'].values():
        for topic in panel.get('topics', {}):
            assert topic in DEFAULT_TOPICS, f'the 3D panel shows {topic}, not recorded'
        for layer in panel.get('layers', {}).values():
            if layer.get('sourceType') == 'topic':  # a URDF layer reads a std_msgs/String
                assert layer['topic'] in DEFAULT_TOPICS, layer
                assert types[layer['topic']].__name__ == 'String', layer


@pytest.mark.parametrize('path', LAYOUTS, ids=lambda p: p.name)
def test_the_3d_panel_draws_the_hand_from_the_recorded_description(path: Path) -> None:
    layout = json.loads(path.read_text(encoding='utf-8'))
    layers = [layer for panel in layout['configById'].values()
              for layer in panel.get('layers', {}).values()]
    assert {'layerId': 'foxglove.Urdf', 'sourceType': 'topic',
            'topic': '/robot_description'}.items() <= next(
                layer for layer in layers if layer['layerId'] == 'foxglove.Urdf').items()


@pytest.mark.parametrize('path', LAYOUTS, ids=lambda p: p.name)
def test_joint_series_are_labelled_with_the_joint_at_their_index(path: Path) -> None:
    """/joint_states carries the joints in the configuration's order (finger by finger)."""
    names = [n for f in load_config().hand.fingers for n in f.joint_names]
    layout = json.loads(path.read_text(encoding='utf-8'))
    joint_series = [e for e in _message_paths(layout['configById'])
                    if e['value'].startswith('/joint_states.')]
    assert joint_series
    for entry in joint_series:
        index = int(re.search(r'\[(\d+)\]$', entry['value'])[1])
        assert entry['label'] == names[index], entry


def test_a_wrong_field_is_caught() -> None:
    """The check itself: a path to a field that does not exist fails it."""
    from sensor_msgs.msg import JointState

    with pytest.raises(AssertionError, match="no field 'angle'"):
        _field_type(JointState, '.angle[0]')
    with pytest.raises(AssertionError, match='not an array'):
        _field_type(JointState, '.header[0]')
    assert _field_type(JointState, '.position[3]') == 'double'
