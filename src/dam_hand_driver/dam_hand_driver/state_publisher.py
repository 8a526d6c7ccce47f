"""``dam_state_publisher``: ``/tf`` and ``/tf_static`` of the hand and the object.

What ``robot_state_publisher`` does for the hand (that package is not among the PyPI wheels),
plus the object's pose as a frame, so that RViz and Foxglove show the hand and the object in
3D, live or from a recorded episode.

Topics
------
/robot_description : std_msgs/String (subscribed, transient local)
    The hand's URDF (the driver publishes it). Every new description replaces the model; one
    that cannot be used is logged as an error naming what is wrong, and the node stays up.
/joint_states : sensor_msgs/JointState (subscribed, best effort, newest only)
    ``publish_frequency`` times per second the newest joint state, if new, gives each movable
    joint's transform (parent link -> child link) on ``/tf``, with the joint state's stamp.
/sim/object_pose : geometry_msgs/PoseStamped (subscribed, newest only; the stand-in only)
    The newest pose, if new, goes to ``/tf`` at the same rate as the frame ``object_frame``
    with the parent ``object_parent_frame``.
/tf : tf2_msgs/TFMessage (published)
/tf_static : tf2_msgs/TFMessage (published, transient local)
    The fixed joints' transforms (the fingertip frames), once per description.

Parameters
----------
robot_state : bool (default true)
    Publish the hand's transforms. False where the real ``robot_state_publisher`` (apt's ROS 2
    Jazzy) publishes them: then only the object's frame is published.
publish_frequency : double (default 50.0) [Hz], in (0, 1000]
    How often the newest joint state and object pose are published on ``/tf`` (on the node's
    clock: simulated time with ``use_sim_time``). ``/joint_states`` comes at 250 or 500 Hz:
    the node takes only the newest message at its own rate, without a callback per message,
    which in Python would cost more than a tenth of a core (measured: 12 % for the callbacks
    alone at 500 Hz, 2 % for taking the newest at 50 Hz).
object_frame : string (default ``object``)
    The object's frame; empty: the object's pose is not published.
object_parent_frame : string (default ``hand_base``)
    The object frame's parent: the hand's root link, which is the world frame of the stand-in
    (z up, the table top at z = 0), in which ``/sim/object_pose`` is given.

The two high-rate subscriptions belong to a hidden side node (``_dam_state_publisher_reader``,
no parameter services, never spun) of the same process, whose messages the node takes itself
(``take_message``, as rclpy's executor does), so the executor never wakes for them.
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
from rclpy.subscription import Subscription
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

from dam_common.forward_kinematics import RobotKinematics, Transform, UrdfError
from dam_common.hand_urdf import BASE_LINK
from dam_common.node import run_node

NODE_NAME = 'dam_state_publisher'
#: The frames of the stand-in's object pose that coincide with the hand's root link.
WORLD_FRAMES = ('world', '', BASE_LINK)
#: Highest ``publish_frequency`` [Hz].
MAX_FREQUENCY_HZ = 1000.0


def _take_newest(subscription: Subscription) -> object | None:
    """The message waiting in ``subscription`` (depth 1: the newest), or ``None``."""
    with subscription.handle:
        taken = subscription.handle.take_message(subscription.msg_type, subscription.raw)
    return None if taken is None else taken[0]


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
            ParameterDescriptor(description='how often the newest joint state and object '
                                            'pose go to /tf [Hz], in (0, 1000]',
                                floating_point_range=[FloatingPointRange(
                                    from_value=0.0, to_value=MAX_FREQUENCY_HZ)],
                                read_only=True)).value)
        if not self.publish_frequency > 0.0:
            raise ValueError(f'publish_frequency {self.publish_frequency!r} Hz must be above '
                             f'0 (at most {MAX_FREQUENCY_HZ:g})')
        self.object_frame = str(self.declare_parameter(
            'object_frame', 'object',
            ParameterDescriptor(description='frame of the object\'s pose; empty: none',
                                read_only=True)).value)
        self.object_parent_frame = str(self.declare_parameter(
            'object_parent_frame', BASE_LINK,
            ParameterDescriptor(description='parent of the object frame (the stand-in\'s '
                                            'world frame, the hand\'s root link)',
                                read_only=True)).value)
        self._last_ns: int | None = None
        self._last_pose_ns: int | None = None
        self._kinematics: RobotKinematics | None = None
        self._warned: set[str] = set()
        self._tf_pub = self.create_publisher(TFMessage, '/tf', QoSProfile(
            depth=100, reliability=ReliabilityPolicy.RELIABLE))
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                             reliability=ReliabilityPolicy.RELIABLE)
        self._static_pub = self.create_publisher(TFMessage, '/tf_static', latched)
        newest = QoSProfile(depth=1, history=HistoryPolicy.KEEP_LAST,
                            reliability=ReliabilityPolicy.BEST_EFFORT)
        # the high-rate topics on a side node the executor never waits on (module docstring)
        self._reader = Node(f'_{NODE_NAME}_reader', context=self.context,
                            start_parameter_services=False, enable_rosout=False)
        self._joint_sub: Subscription | None = None
        self._pose_sub: Subscription | None = None
        if self.robot_state:
            self.create_subscription(String, '/robot_description', self._on_description,
                                     latched)
            self._joint_sub = self._reader.create_subscription(
                JointState, '/joint_states', lambda _msg: None, newest)
        if self.object_frame:
            self._pose_sub = self._reader.create_subscription(
                PoseStamped, '/sim/object_pose', lambda _msg: None, newest)
        if self._joint_sub is not None or self._pose_sub is not None:
            self.create_timer(1.0 / self.publish_frequency, self._publish_newest)
        self.get_logger().info(
            f'{NODE_NAME}: '
            + (f'hand from /robot_description and /joint_states at '
               f'{self.publish_frequency:g} Hz' if self.robot_state
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

    def _publish_newest(self) -> None:
        """Each period: the newest joint state's and object pose's frames, if new."""
        transforms: list[TransformStamped] = []
        if self._joint_sub is not None:
            msg = _take_newest(self._joint_sub)
            if isinstance(msg, JointState):
                transforms += self._joint_transforms(msg)
        if self._pose_sub is not None:
            pose = _take_newest(self._pose_sub)
            if isinstance(pose, PoseStamped):
                transforms += self._object_transform(pose)
        if transforms:
            self._tf_pub.publish(TFMessage(transforms=transforms))

    def _joint_transforms(self, msg: JointState) -> list[TransformStamped]:
        kinematics = self._kinematics
        if kinematics is None:
            return []
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        if stamp_ns == self._last_ns:
            return []
        if len(msg.position) != len(msg.name):
            self._warn_once('lengths', f'/joint_states with {len(msg.name)} names and '
                                       f'{len(msg.position)} positions ignored')
            return []
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
            return []
        self._last_ns = stamp_ns
        return [_transform_msg(t, msg.header.stamp) for t in transforms]

    def _object_transform(self, msg: PoseStamped) -> list[TransformStamped]:
        stamp_ns = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        if stamp_ns == self._last_pose_ns:
            return []
        if msg.header.frame_id not in WORLD_FRAMES + (self.object_parent_frame,):
            self._warn_once('frame:' + msg.header.frame_id,
                            f'/sim/object_pose in frame {msg.header.frame_id!r}, not the '
                            f'world frame: not published as {self.object_frame!r}')
            return []
        self._last_pose_ns = stamp_ns
        p, q = msg.pose.position, msg.pose.orientation
        t = TransformStamped()
        t.header.stamp = msg.header.stamp
        t.header.frame_id = self.object_parent_frame
        t.child_frame_id = self.object_frame
        t.transform.translation.x, t.transform.translation.y = p.x, p.y
        t.transform.translation.z = p.z
        t.transform.rotation = q
        return [t]

    def destroy_node(self) -> None:
        """Destroy the side node of the high-rate subscriptions too."""
        reader = getattr(self, '_reader', None)
        if reader is not None:
            reader.destroy_node()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    """``ros2 run dam_hand_driver dam_state_publisher``."""
    run_node(StatePublisherNode, NODE_NAME, args, startup_errors=(ValueError,))
