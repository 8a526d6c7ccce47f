"""``/dam/episode``: the controller tells recorders when each ``/dam_grasp`` goal starts and ends.

A recorder in episode mode (``dam_recorder``) turns each goal into one bag; the ENDED event
carries what the bag's metadata needs (the pair as run, the ``/check_lift`` answer, the outcome),
the STARTED event the configuration and the software version.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

from dam_common.version import software_version
from dam_interfaces.action import DamGrasp
from dam_interfaces.msg import GraspEpisode, LiftAnswer
from dam_interfaces.srv import CheckLift

#: Topic of the episode events.
EPISODE_TOPIC = '/dam/episode'
#: Volatile on purpose: a recorder that starts later must not take old goals for new ones.
EPISODE_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)


def goal_id_hex(goal_id: Sequence[int] | bytes) -> str:
    """A goal's UUID (16 bytes) as 32 hexadecimal digits."""
    return bytes(bytearray(goal_id)).hex()


def lift_answer(response: CheckLift.Response) -> LiftAnswer:
    """A ``/check_lift`` response as a :class:`LiftAnswer` message: every field of the
    message, copied from the response's field of the same name."""
    answer = LiftAnswer()
    for name, kind in LiftAnswer.get_fields_and_field_types().items():
        value = getattr(response, name)
        if kind.startswith('sequence<'):
            value = [float(v) for v in value]
        setattr(answer, name, value)
    return answer


@dataclass
class _Goal:
    k_theta: list[float] = field(default_factory=list)
    delta_theta_p: list[float] = field(default_factory=list)
    check_lift: CheckLift.Response | None = None


class EpisodeEvents:
    """Publishes the STARTED and ENDED events of each goal on :data:`EPISODE_TOPIC`.

    Parameters
    ----------
    node : Node
        The controller node (it owns the publisher).
    config_source : str
        Path of the configuration file the controller loaded; its content goes into every
        STARTED event (read once, here: the file as it was when the controller started).
    object_name : str
        The library object the controller grasps (its ``object`` parameter), in every event.
    """

    def __init__(self, node: Node, config_source: str, object_name: str = '') -> None:
        self._node = node
        self._object = str(object_name)
        self._pub = node.create_publisher(GraspEpisode, EPISODE_TOPIC, EPISODE_QOS)
        self._config_source = str(config_source)
        try:
            self._config_yaml = Path(config_source).read_text(encoding='utf-8')
        except OSError as exc:
            self._config_yaml = f'# not readable: {exc}'
        self._version = software_version()
        self._goals: dict[str, _Goal] = {}

    def _event(self, event: int, goal_id: str, goal: DamGrasp.Goal) -> GraspEpisode:
        msg = GraspEpisode()
        msg.header.stamp = self._node.get_clock().now().to_msg()
        msg.event = event
        msg.goal_id = goal_id
        msg.goal_k_theta = [float(v) for v in goal.k_theta]
        msg.goal_delta_theta_p = [float(v) for v in goal.delta_theta_p]
        msg.object = self._object
        return msg

    def started(self, goal_id: Sequence[int], goal: DamGrasp.Goal) -> None:
        """A goal arrived (before it is checked)."""
        key = goal_id_hex(goal_id)
        self._goals[key] = _Goal()
        msg = self._event(GraspEpisode.EVENT_STARTED, key, goal)
        msg.config_source = self._config_source
        msg.config_yaml = self._config_yaml
        msg.software_version = self._version
        self._publish(msg)

    def running(self, goal_id: Sequence[int], k_theta: Sequence[float],
                delta_theta_p: Sequence[float]) -> None:
        """The goal runs with these per-finger ``k_theta`` [N*m/rad], ``delta_theta_p`` [rad]."""
        goal = self._goals.setdefault(goal_id_hex(goal_id), _Goal())
        goal.k_theta = [float(v) for v in k_theta]
        goal.delta_theta_p = [float(v) for v in delta_theta_p]

    def checked(self, goal_id: Sequence[int], response: CheckLift.Response | None) -> None:
        """``/check_lift`` answered the goal's pair (``None``: no answer)."""
        self._goals.setdefault(goal_id_hex(goal_id), _Goal()).check_lift = response

    def ended(self, goal_id: Sequence[int], goal: DamGrasp.Goal, result: DamGrasp.Result
              ) -> None:
        """The goal ended with ``result``."""
        key = goal_id_hex(goal_id)
        state = self._goals.pop(key, _Goal())
        msg = self._event(GraspEpisode.EVENT_ENDED, key, goal)
        msg.k_theta = state.k_theta
        msg.delta_theta_p = state.delta_theta_p
        if state.check_lift is not None:
            msg.lift_checked = True
            msg.check_lift = lift_answer(state.check_lift)
        else:
            for name in ('worst_case_margin', 'csm_margin', 'friction_angle', 'torque_limit',
                         'rolling_margin', 'rolling_turn', 'rolling_slide', 'csm_path_margin',
                         'csm_path_delta_theta_p'):
                setattr(msg.check_lift, name, math.nan)
        msg.outcome = int(result.outcome)
        msg.outcome_name = result.outcome_name
        msg.message = result.message
        msg.duration = float(result.duration)
        msg.wall_duration = float(result.wall_duration)
        msg.object_rise = float(result.object_rise)
        msg.object_left_table = bool(result.object_left_table)
        msg.object_orientation = float(result.object_orientation)
        self._publish(msg)

    def _publish(self, msg: GraspEpisode) -> None:
        try:
            self._pub.publish(msg)
        except Exception as exc:  # noqa: BLE001 - a goal must never fail for its event
            self._node.get_logger().warning(f'{EPISODE_TOPIC} not published: {exc!r}')
