"""Fixtures of the recorder's unit tests (no rclpy): where type descriptions are installed, and
a ``rosbags`` type store that knows the DAM interfaces from their ``.msg`` files (independently
of the recorder's own definitions, which come from the ``.json`` type descriptions)."""

from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
INSTALL = REPO_ROOT / 'ros2_ws' / 'install'
TESTS_DIR = Path(__file__).resolve().parent
if str(TESTS_DIR) not in sys.path:
    sys.path.insert(0, str(TESTS_DIR))  # recorder_samples, bag_readers


@pytest.fixture(scope='session')
def prefixes() -> list[str]:
    """Install prefixes holding ``share/<package>/msg/*.json``: the ROS 2 install (the
    interpreter's prefix with the PyPI wheels, or ``AMENT_PREFIX_PATH``) and the workspace."""
    found = [p for p in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep) if p]
    found += [sys.prefix, str(INSTALL / 'dam_interfaces')]
    if not any((Path(p) / 'share' / 'sensor_msgs' / 'msg' / 'JointState.json').is_file()
               for p in found):
        pytest.skip('no installed sensor_msgs type descriptions (run scripts/setup.sh)')
    if not (INSTALL / 'dam_interfaces' / 'share' / 'dam_interfaces').is_dir():
        pytest.skip('dam_interfaces is not built (run scripts/setup.sh)')
    return found


@pytest.fixture(scope='session')
def typestore():
    """A ``rosbags`` Jazzy type store plus the DAM interfaces, parsed from their ``.msg`` and
    ``.action`` files."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_JAZZY)
    src = REPO_ROOT / 'src' / 'dam_interfaces'
    types = {}
    for path in sorted((src / 'msg').glob('*.msg')):
        types.update(get_types_from_msg(path.read_text(), f'dam_interfaces/msg/{path.stem}'))
    goal, result, feedback = (src / 'action' / 'DamGrasp.action').read_text().split('---')
    types.update(get_types_from_msg(feedback, 'dam_interfaces/msg/DamGrasp_Feedback'))
    types.update(get_types_from_msg(
        'unique_identifier_msgs/UUID goal_id\ndam_interfaces/DamGrasp_Feedback feedback',
        'dam_interfaces/action/DamGrasp_FeedbackMessage'))
    store.register(types)
    return store
