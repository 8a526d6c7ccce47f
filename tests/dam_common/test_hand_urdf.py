"""The hand's URDF agrees with the analysis model: names, limits and forward kinematics."""

from __future__ import annotations

import subprocess
from xml.etree import ElementTree as ET

import numpy as np
import pytest

from dam_analysis.model import finger_geometries, joint_positions
from dam_common.config import load_config
from dam_common.hand_urdf import BASE_LINK, hand_urdf
from ros_testing import installed_executable


@pytest.fixture(scope='module')
def config():
    return load_config()


@pytest.fixture(scope='module')
def robot(config) -> ET.Element:
    return ET.fromstring(hand_urdf(config))


def _rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' formula (written here, independent of the generator)."""
    a = axis / np.linalg.norm(axis)
    k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
    return np.eye(3) + np.sin(angle) * k + (1.0 - np.cos(angle)) * (k @ k)


def _rpy(r: float, p: float, y: float) -> np.ndarray:
    return (_rotation(np.array([0.0, 0.0, 1.0]), y) @ _rotation(np.array([0.0, 1.0, 0.0]), p)
            @ _rotation(np.array([1.0, 0.0, 0.0]), r))


def _link_position(robot: ET.Element, link: str, angles: dict[str, float]) -> np.ndarray:
    """World position of ``link``'s frame by walking the URDF's joints from the root."""
    by_child = {j.find('child').get('link'): j for j in robot.findall('joint')}
    chain = []
    while link != BASE_LINK:
        joint = by_child[link]
        chain.append(joint)
        link = joint.find('parent').get('link')
    rot, pos = np.eye(3), np.zeros(3)
    for joint in reversed(chain):
        origin = joint.find('origin')
        xyz = np.array([float(v) for v in origin.get('xyz').split()])
        rpy = [float(v) for v in origin.get('rpy').split()]
        pos = pos + rot @ xyz
        rot = rot @ _rpy(*rpy)
        if joint.get('type') == 'revolute':
            axis = np.array([float(v) for v in joint.find('axis').get('xyz').split()])
            rot = rot @ _rotation(axis, angles[joint.get('name')])
    return pos


def test_joints_are_the_configured_ones_with_their_limits(config, robot) -> None:
    revolute = {j.get('name'): j for j in robot.findall('joint') if j.get('type') == 'revolute'}
    assert sorted(revolute) == sorted(config.hand.joint_names)
    for finger in config.hand.fingers:
        for role, name in zip(config.hand.joint_roles, finger.joint_names, strict=True):
            limit = revolute[name].find('limit')
            lower, upper = config.hand.joint_limits_rad[role]
            assert float(limit.get('lower')) == pytest.approx(lower, abs=1e-9)
            assert float(limit.get('upper')) == pytest.approx(upper, abs=1e-9)
            assert float(limit.get('effort')) == config.device.torque_limit_nm
    links = {link.get('name') for link in robot.findall('link')}
    assert all(j.find('child').get('link') in links and j.find('parent').get('link') in links
               for j in robot.findall('joint'))


def test_fingertips_match_the_analysis_forward_kinematics(config, robot) -> None:
    rng = np.random.default_rng(7)
    geometries = finger_geometries(config)
    for _ in range(20):
        angles = {}
        for finger in config.hand.fingers:
            for role, name in zip(config.hand.joint_roles, finger.joint_names, strict=True):
                lower, upper = config.hand.joint_limits_rad[role]
                angles[name] = float(rng.uniform(lower, upper))
        for finger, geometry in zip(config.hand.fingers, geometries, strict=True):
            theta = [angles[name] for name in finger.joint_names]
            expected = geometry.to_world(joint_positions(geometry, *theta))
            for k, link in enumerate([f'{finger.name}_{r}_link' for r in config.hand.joint_roles]
                                     + [f'{finger.name}_fingertip']):
                np.testing.assert_allclose(_link_position(robot, link, angles), expected[k],
                                           atol=1e-12)


def test_the_cli_prints_it_and_refuses_a_bad_file(tmp_path) -> None:
    exe = str(installed_executable('dam_hand_driver', 'hand_urdf'))
    out = subprocess.run([exe], capture_output=True, text=True, timeout=60)
    assert out.returncode == 0 and ET.fromstring(out.stdout).tag == 'robot'
    bad = tmp_path / 'bad.yaml'
    bad.write_text('format_version: 2\n', encoding='utf-8')
    out = subprocess.run([exe, str(bad)], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and 'hand' in out.stderr and 'Traceback' not in out.stderr
    out = subprocess.run([exe, str(bad), 'extra'], capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and 'one configuration at most' in out.stderr and not out.stdout
