"""``dam_state_publisher``: ``/tf`` and ``/tf_static`` of the hand and the object.

What ``robot_state_publisher`` does for the hand (that package is not among the PyPI wheels),
plus the object's pose as a frame, so that RViz and Foxglove show the hand and the object in
3D, live or from a recorded episode.

Topics
------
/robot_description : std_msgs/String (subscribed, transient local)
    The hand's URDF (the driver publishes it). Every new description replaces the model; one
    that cannot be used is logged as an error naming what is wrong, and the node stays up.
/joint_states : sensor_msgs/JointState (subscribed, best effort)
    Each movable joint's transform (parent link -> child link) goes to ``/tf`` with the joint
    state's stamp, at most ``publish_frequency`` times per second of the stamps.
/sim/object_pose : geometry_msgs/PoseStamped (subscribed; the stand-in only)
    Published on ``/tf`` as the frame ``object_frame`` with the parent ``object_parent_frame``.
/tf : tf2_msgs/TFMessage (published)
/tf_static : tf2_msgs/TFMessage (published, transient local)
    The fixed joints' transforms (the fingertip frames), once per description.

Parameters
----------
robot_state : bool (default true)
    Publish the hand's transforms. False where the real ``robot_state_publisher`` (apt's ROS 2
    Jazzy) publishes them: then only the object's frame is published.
publish_frequency : double (default 50.0) [Hz]
    Most hand transforms per second of the joint states' stamps (``/joint_states`` comes at
    250 or 500 Hz); 0: every joint state.
object_frame : string (default ``object``)
    The object's frame; empty: the object's pose is not published.
object_parent_frame : string (default ``hand_base``)
    The object frame's parent: the hand's root link, which is the world frame of the stand-in
    (z up, the table top at z = 0), in which ``/sim/object_pose`` is given.
"""

from __future__ import annotations

from geometry_msgs.msg import PoseStamped, TransformStamped
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from dam_common.forward_kinematics import RobotKinematics, Transform, UrdfError
from dam_common.hand_urdf import BASE_LINK
from dam_common.node import run_node

NODE_NAME = 'dam_state_publisher'
#: The frames of the stand-in's object pose that coincide with the hand's root link.
WORLD_FRAMES = ('world', '', BASE_LINK)


def _transform_msg(t: Transform, stamp: object) -> TransformStamped:
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = t.parent
    msg.child_frame_id = t.child
    msg.transform.translation.x, msg.transform.translation.y, msg.transform.translation.z = \
        t.translation
    r = msg.transform.rotation
    r.x, r.y, r.z, r.w = t.rotation
    return msg


class StatePublisherNode(Node):
    """The hand's and the object's frames on ``/tf`` and ``/tf_static`` (module docstring)."""

    def __init__(self) -> None:
        super().__init__(NODE_NAME)
        self.robot_state = bool(self.declare_parameter(
            'robot_state', True,
            ParameterDescriptor(description='publish the hand\'s transforms from '
                                            '/robot_description and /joint_states (false '
                                            'where robot_state_publisher does)',
                                read_only=True)).value)
        self.publish_frequency = float(self.declare_parameter(
            'publish_frequency', 50.0,
            ParameterDescriptor(description='most hand transforms per second of the joint '
                                            'states\' stamps [Hz]; 0: every joint state',
                                floating_point_range=[FloatingPointRange(
                                    from_value=0.0, to_value=10000.0)],
                                read_only=True)).value)
        self.object_frame = str(self.declare_parameter(
            'object_frame', 'object',
            ParameterDescriptor(description='frame of the object\'s pose; empty: none',
                                read_only=True)).value)
        self.object_parent_frame = str(self.declare_parameter(
            'object_parent_frame', BASE_LINK,
            ParameterDescriptor(description='parent of the object frame (the stand-in\'s '
                                            'world frame, the hand\'s root link)',
                                read_only=True)).value)
        self._period_ns = (0 if self.publish_frequency == 0.0
                           else int(round(1e9 / self.publish_frequency)))
        self._last_ns: int | None = None
        self._kinematics: RobotKinematics | None = None
        self._warned: set[str] = set()
        self._tf_pub = self.create_publisher(TFMessage, '/tf', QoSProfile(
            depth=100, reliability=ReliabilityPolicy.RELIABLE))
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                             reliability=ReliabilityPolicy.RELIABLE)
        self._static_pub = self.create_publisher(TFMessage, '/tf_static', latched)
        newest = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                            reliability=ReliabilityPolicy.BEST_EFFORT)
        if self.robot_state:
            self.create_subscription(String, '/robot_description', self._on_description,
                                     latched)
            self.create_subscription(JointState, '/joint_states', self._on_joint_states,
                                     newest)
        if self.object_frame:
            self.create_subscription(PoseStamped, '/sim/object_pose', self._on_object_pose,
                                     newest)
        self.get_logger().info(
            f'{NODE_NAME}: '
            + ('hand from /robot_description and /joint_states ('
               + (f'at most {self.publish_frequency:g} Hz' if self._period_ns
                  else 'every joint state') + ')' if self.robot_state
               else 'no hand transforms (robot_state false)')
            + (f'; object pose as frame {self.object_frame!r} in '
               f'{self.object_parent_frame!r}' if self.object_frame else '; no object frame'))

    def _warn_once(self, key: str, text: str) -> None:
        if key not in self._warned:
            self._warned.add(key)
            self.get_logger().warning(text)

    def _on_description(self, msg: String) -> None:
        try:
            kinematics = RobotKinematics(msg.data)
        except UrdfError as exc:
            self.get_logger().error(f'/robot_description not used: {exc}')
            return
        self._kinematics = kinematics
        self._last_ns = None
        stamp = self.get_clock().now().to_msg()
        self._static_pub.publish(TFMessage(transforms=[
            _transform_msg(t, stamp) for t in kinematics.fixed_transforms()]))
        self.get_logger().info(
            f'robot description: {len(kinematics.moving)} movable joints, '
            f'{len(kinematics.fixed)} fixed frames on /tf_static, root '
            f'{", ".join(kinematics.roots)}')

    def _on_joint_states(self, msg: JointState) -> None:
        kinematics = self._kinematics
        if kinematics is None:
            return
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        if (self._last_ns is not None and self._period_ns
                and 0 <= stamp_ns - self._last_ns < self._period_ns):
            return
        if len(msg.position) != len(msg.name):
            self._warn_once('lengths', f'/joint_states with {len(msg.name)} names and '
                                       f'{len(msg.position)} positions ignored')
            return
        unknown = kinematics.unknown_joints(list(msg.name))
        if unknown:
            self._warn_once('unknown:' + ','.join(unknown),
                            f'/joint_states names {unknown} that are no movable joint of '
                            f'/robot_description: not published')
        try:
            transforms = kinematics.moving_transforms(dict(zip(msg.name, msg.position,
                                                               strict=True)))
        except ValueError as exc:
            self._warn_once('value', f'/joint_states not published: {exc}')
            return
        self._last_ns = stamp_ns
        self._tf_pub.publish(TFMessage(transforms=[
            _transform_msg(t, msg.header.stamp) for t in transforms]))

    def _on_object_pose(self, msg: PoseStamped) -> None:
        if msg.header.frame_id not in WORLD_FRAMES + (self.object_parent_frame,):
            self._warn_once('frame:' + msg.header.frame_id,
                            f'/sim/object_pose in frame {msg.header.frame_id!r}, not the '
                            f'world frame: not published as {self.object_frame!r}')
            return
        p, q = msg.pose.position, msg.pose.orientation
        t = TransformStamped()
        t.header.stamp = msg.header.stamp
        t.header.frame_id = self.object_parent_frame
        t.child_frame_id = self.object_frame
        t.transform.translation.x, t.transform.translation.y = p.x, p.y
        t.transform.translation.z = p.z
        t.transform.rotation = q
        self._tf_pub.publish(TFMessage(transforms=[t]))


def main(args: list[str] | None = None) -> None:
    """``ros2 run dam_hand_driver dam_state_publisher``."""
    run_node(StatePublisherNode, NODE_NAME, args)
