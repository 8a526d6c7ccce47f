"""``/dam/episode`` events (``dam_interfaces/msg/GraspEpisode``) as the plain values that
:mod:`dam_recorder.episodes` stores (the ROS side of episodes)."""

from __future__ import annotations

import math
from typing import Any

from dam_recorder.episodes import CONFIG_KEY, CONFIG_SOURCE_KEY, VERSION_KEY

#: Topic and type of the controller's goal events.
EPISODE_TOPIC = '/dam/episode'
EPISODE_TYPE = 'dam_interfaces/msg/GraspEpisode'


def stamp_ns(stamp: Any) -> int:
    """A ``builtin_interfaces/Time`` in nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def start_info(msg: Any) -> dict[str, str]:
    """The ``custom_data`` entries a STARTED event gives its episode."""
    return {CONFIG_KEY: msg.config_yaml, VERSION_KEY: msg.software_version,
            CONFIG_SOURCE_KEY: msg.config_source}


def summary_from_event(msg: Any) -> dict[str, Any]:
    """The episode summary (``dam_episode.summary``) of an ENDED event."""
    answer = msg.check_lift
    check_lift = None
    if msg.lift_checked:
        check_lift = {
            'ok': bool(answer.ok), 'message': answer.message,
            'lift_guaranteed': bool(answer.lift_guaranteed),
            'worst_case_margin': float(answer.worst_case_margin),
            'csm_lift': bool(answer.csm_lift), 'csm_margin': float(answer.csm_margin),
            'delta_theta_s': [float(v) for v in answer.delta_theta_s],
            'compliant_torque': [float(v) for v in answer.compliant_torque],
            'friction_angle': float(answer.friction_angle),
            'torque_limit': float(answer.torque_limit),
            'within_torque_limit': bool(answer.within_torque_limit),
            'csm_penetration': [float(v) for v in answer.csm_penetration],
            'csm_in_domain': bool(answer.csm_in_domain)}
    return {
        'goal_id': msg.goal_id, 'ended_ns': stamp_ns(msg.header.stamp),
        'goal': {'k_theta': [float(v) for v in msg.goal_k_theta],
                 'delta_theta_p': [float(v) for v in msg.goal_delta_theta_p]},
        'object': msg.object,
        'k_theta': [float(v) for v in msg.k_theta],
        'delta_theta_p': [float(v) for v in msg.delta_theta_p],
        'friction_angle': check_lift['friction_angle'] if check_lift else math.nan,
        'check_lift': check_lift, 'outcome': int(msg.outcome),
        'outcome_name': msg.outcome_name or 'UNKNOWN', 'message': msg.message,
        'duration_s': float(msg.duration),
        # (a controller's message without the field: its duration is on the wall clock)
        **({'wall_duration_s': float(msg.wall_duration)}
           if hasattr(msg, 'wall_duration') else {})}
