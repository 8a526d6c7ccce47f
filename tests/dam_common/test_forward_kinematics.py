"""The forward-kinematics core of dam_state_publisher against PyBullet's link poses."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_common.config import load_config
from dam_common.forward_kinematics import (
    RobotKinematics,
    UrdfError,
    quaternion_from_rpy,
    rotation_matrix,
)
from dam_common.hand_urdf import BASE_LINK, hand_urdf


def _pybullet_frame(world, link_index: int) -> np.ndarray:  # noqa: ANN001
    state = world.client.getLinkState(world.hand_id, link_index,
                                      computeForwardKinematics=True)
    m = np.eye(4)
    m[:3, :3] = np.array(world.client.getMatrixFromQuaternion(state[5])).reshape(3, 3)
    m[:3, 3] = state[4]
    return m


def test_link_poses_match_pybullet_for_the_hand_in_several_postures() -> None:
    from dam_sim_bridge.world import HandWorld

    config = load_config()
    kinematics = RobotKinematics(hand_urdf(config))
    assert kinematics.roots == [BASE_LINK]
    rng = np.random.default_rng(34)
    with HandWorld(config) as world:
        pb = world.client
        link_of_joint = {pb.getJointInfo(world.hand_id, j)[1].decode(): j
                         for j in range(pb.getNumJoints(world.hand_id))}
        lower, upper = world.joint_lower_limits, world.joint_upper_limits
        for _ in range(5):
            q = rng.uniform(lower, upper)
            world.reset(joint_positions=q)
            poses = kinematics.link_poses(dict(zip(world.joint_names, q.tolist(), strict=True)))
            for joint in kinematics.moving:
                expected = _pybullet_frame(world, link_of_joint[joint.name])
                np.testing.assert_allclose(poses[joint.child], expected, atol=1e-6,
                                           err_msg=joint.name)
            # The fixed fingertip frames (absent from PyBullet's model) sit where the
            # stand-in puts the fingertips.
            tips = np.array([poses[f'{f.name}_fingertip'][:3, 3] for f in config.hand.fingers])
            np.testing.assert_allclose(tips, world.fingertip_positions(), atol=1e-6)


def test_transforms_are_the_joint_origin_then_its_motion() -> None:
    urdf = """<robot name="r">
      <link name="a"/><link name="b"/><link name="c"/><link name="d"/>
      <joint name="turn" type="revolute"><parent link="a"/><child link="b"/>
        <origin xyz="1 0 0" rpy="0 0 1.5707963267948966"/><axis xyz="0 0 2"/></joint>
      <joint name="slide" type="prismatic"><parent link="b"/><child link="c"/>
        <axis xyz="1 0 0"/></joint>
      <joint name="tip" type="fixed"><parent link="c"/><child link="d"/>
        <origin xyz="0 0 0.5"/></joint>
    </robot>"""
    k = RobotKinematics(urdf)
    assert [j.name for j in k.moving] == ['turn', 'slide']
    assert [(t.parent, t.child) for t in k.fixed_transforms()] == [('c', 'd')]
    poses = k.link_poses({'turn': math.pi / 2, 'slide': 0.25})
    # turn: yaw 90 deg from the origin plus 90 deg about z: b's x axis along a's -x
    np.testing.assert_allclose(poses['b'][:3, 0], [-1.0, 0.0, 0.0], atol=1e-12)
    # slide: 0.25 m along b's x, i.e. along a's -x, from (1, 0, 0)
    np.testing.assert_allclose(poses['c'][:3, 3], [0.75, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(poses['d'][:3, 3], [0.75, 0.0, 0.5], atol=1e-12)
    only_turn = k.moving_transforms({'turn': 0.0, 'elsewhere': 1.0})
    assert [t.child for t in only_turn] == ['b']
    assert k.unknown_joints(['turn', 'tip', 'elsewhere']) == ['tip', 'elsewhere']
    with pytest.raises(ValueError, match="'slide' position nan"):
        k.moving_transforms({'slide': float('nan')})


def test_rpy_is_yaw_pitch_roll_about_fixed_axes() -> None:
    roll, pitch, yaw = 0.3, -0.7, 1.1
    rx = np.array([[1, 0, 0], [0, math.cos(roll), -math.sin(roll)],
                   [0, math.sin(roll), math.cos(roll)]])
    ry = np.array([[math.cos(pitch), 0, math.sin(pitch)], [0, 1, 0],
                   [-math.sin(pitch), 0, math.cos(pitch)]])
    rz = np.array([[math.cos(yaw), -math.sin(yaw), 0], [math.sin(yaw), math.cos(yaw), 0],
                   [0, 0, 1]])
    np.testing.assert_allclose(rotation_matrix(quaternion_from_rpy(roll, pitch, yaw)),
                               rz @ ry @ rx, atol=1e-12)


@pytest.mark.parametrize(('urdf', 'words'), [
    ('<robot><joint', 'not XML'),
    ('<model/>', 'not <robot>'),
    ('<robot><joint name="j" type="floating"><parent link="a"/><child link="b"/></joint>'
     '</robot>', "type 'floating'"),
    ('<robot><joint name="j" type="revolute"><parent link="a"/><child link="b"/>'
     '<axis xyz="0 0 0"/></joint></robot>', 'zero axis'),
    ('<robot><joint name="j" type="fixed"><parent link="a"/><child link="b"/>'
     '<origin xyz="1 x 0"/></joint></robot>', "'1 x 0' is not three numbers"),
    ('<robot><joint name="j" type="fixed"><parent link="a"/></joint></robot>', 'lacks'),
])
def test_bad_descriptions_are_refused_by_name(urdf: str, words: str) -> None:
    with pytest.raises(UrdfError, match=words):
        RobotKinematics(urdf)
