"""Queues of the suite's services and action servers deep enough for any burst of requests.

rclpy gives a service, and each of an action server's three services, a history of depth 10
(``qos_profile_services_default``). A client that sends 50 goals at once to ``/dam_grasp``
fills it: the middleware keeps the newest 10 requests that the executor has not yet taken and
the newest 10 replies that the client has not yet acknowledged, and the rest are dropped
without a word. Their senders wait for ever, and a goal that ran may be one whose sender never
learnt it was accepted, so that it can neither cancel it nor ask for its result.

Every service and action server of the suite is made with :data:`SERVICE_QOS` instead:
reliable, volatile, KEEP_ALL, so that every request is kept until the node has taken it and
every reply until its client has it. Each request is then answered, however many come at
once (a goal that cannot run is answered too: ``/dam_grasp`` accepts it and ends it at once
with ``OUTCOME_REJECTED`` and the reason). The client's own queue is the client's: a client
that sends bursts of more than 10 requests gives its own client or action client the same
profile (rclpy's parameter services use depth 1000 on both ends for the same reason).
"""

from __future__ import annotations

from typing import Any

from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

#: The profile of every service of the suite's nodes, and of an action server's services.
SERVICE_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)


def action_server_qos() -> dict[str, Any]:
    """Keyword arguments of ``rclpy.action.ActionServer`` that give its goal, cancel and
    result services :data:`SERVICE_QOS` (feedback and status keep rclpy's profiles: the
    newest feedback and the newest status are what a client needs)."""
    return {'goal_service_qos_profile': SERVICE_QOS,
            'cancel_service_qos_profile': SERVICE_QOS,
            'result_service_qos_profile': SERVICE_QOS}
