"""dam_state_publisher over DDS: /tf_static (latched) and /tf of the hand and the object.

The test publishes what the driver and the stand-in publish (/robot_description, latched;
/joint_states; /sim/object_pose) and composes the frames it receives into fingertip
positions, which it compares with PyBullet's fingertips of the stand-in's hand at the same
joint angles (an independent computation).
"""

from __future__ import annotations

import numpy as np
import pytest

from dam_common.config import load_config
from dam_common.hand_urdf import BASE_LINK, hand_urdf
from ros_testing import RosClient, installed_executable, node_process

pytestmark = pytest.mark.integration

#: Longest wait for a process and DDS discovery on a loaded machine [s] (not a property of
#: the node: it only ends a test that would otherwise hang).
WAIT_S = 120.0


def _matrix(t) -> np.ndarray:  # noqa: ANN001 - geometry_msgs/Transform
    from dam_common.forward_kinematics import rotation_matrix

    r, p = t.rotation, t.translation
    m = np.eye(4)
    m[:3, :3] = rotation_matrix((r.x, r.y, r.z, r.w))
    m[:3, 3] = (p.x, p.y, p.z)
    return m


def _pose_in_root(frames: dict, link: str) -> np.ndarray:
    pose = np.eye(4)
    while link != BASE_LINK:
        parent, m = frames[link]
        pose = m @ pose
        link = parent
    return pose


def test_hand_and_object_frames_match_pybullet() -> None:
    from geometry_msgs.msg import PoseStamped
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from sensor_msgs.msg import JointState
    from std_msgs.msg import String
    from tf2_msgs.msg import TFMessage

    from dam_sim_bridge.world import HandWorld

    config = load_config()
    latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                         reliability=ReliabilityPolicy.RELIABLE)
    client = RosClient()
    static: list[TFMessage] = []
    dynamic: list[TFMessage] = []
    try:
        description = client.node.create_publisher(String, '/robot_description', latched)
        joints = client.node.create_publisher(JointState, '/joint_states', 10)
        pose_pub = client.node.create_publisher(PoseStamped, '/sim/object_pose', 10)
        # A description that is no URDF first: refused by name, the node stays up.
        description.publish(String(data='<robot><joint name="j" type="floating"><parent '
                                        'link="a"/><child link="b"/></joint></robot>'))
        exe = installed_executable('dam_hand_driver', 'dam_state_publisher')
        with node_process([exe, '--ros-args', '-p', 'publish_frequency:=200.0']) as node:
            assert client.spin_until(lambda: "type 'floating'" in node.output(), WAIT_S), \
                node.output()
            assert node.alive()
            description.publish(String(data=hand_urdf(config)))
            # /tf_static is latched: a subscriber that comes later still gets it.
            assert client.spin_until(lambda: 'fixed frames on /tf_static' in node.output(),
                                     WAIT_S), node.output()
            client.node.create_subscription(TFMessage, '/tf_static', static.append, latched)
            client.node.create_subscription(TFMessage, '/tf', dynamic.append, 100)
            assert client.spin_until(lambda: bool(static), WAIT_S)
            with HandWorld(config) as world:
                rng = np.random.default_rng(7)
                q = rng.uniform(world.joint_lower_limits, world.joint_upper_limits)
                world.reset(joint_positions=q)
                expected_tips = world.fingertip_positions()
                names = list(world.joint_names)
            msg = JointState(name=names, position=q.tolist())
            msg.header.stamp.sec = 12
            pose = PoseStamped()
            pose.header.frame_id = 'world'
            pose.header.stamp.sec = 12
            pose.pose.position.x, pose.pose.position.z = 0.01, 0.05
            pose.pose.orientation.w = 1.0

            def joint_frames_arrived() -> bool:
                joints.publish(msg)
                pose_pub.publish(pose)
                children = {t.child_frame_id for m in dynamic for t in m.transforms}
                return 'object' in children and len(children) == len(names) + 1

            assert client.spin_until(joint_frames_arrived, WAIT_S), dynamic[-1:]
            assert node.alive()
    finally:
        client.close()
    frames = {}
    for m in static + dynamic:
        for t in m.transforms:
            frames[t.child_frame_id] = (t.header.frame_id, _matrix(t.transform))
    fixed = {t.child_frame_id for t in static[-1].transforms}
    assert fixed == {f'{f.name}_fingertip' for f in config.hand.fingers}
    tips = np.array([_pose_in_root(frames, f'{f.name}_fingertip')[:3, 3]
                     for f in config.hand.fingers])
    np.testing.assert_allclose(tips, expected_tips, atol=1e-6)
    stamped = [t for m in dynamic for t in m.transforms if t.child_frame_id != 'object']
    assert {t.header.stamp.sec for t in stamped} == {12}
    parent, obj = frames['object']
    assert parent == BASE_LINK
    np.testing.assert_allclose(obj[:3, 3], [0.01, 0.0, 0.05])
