"""Every request of a burst is answered: goals, cancels and results of /dam_grasp, and the
services of the nodes (/check_lift, /plan_lift, ~/release, the parameter services).

With rclpy's default service queues (depth 10) a burst of 50 goals from one client got 10
answers; the goal that ran could be one whose sender never heard of it. The nodes' services
now keep every request and every reply (``dam_common.service_qos``). The clients here use the
same profile: a client's own queues are its own business (docs/architecture.md, "Services").

The controller runs on the synthetic plant (no PyBullet) with ``check_lift_timeout:=0`` (no
wait for /check_lift before a grasp); the analysis server serves the service bursts.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from contextlib import ExitStack

import pytest

from ros_testing import RosClient, fixture_command, installed_executable, node_process

pytestmark = [pytest.mark.integration]

BURST = 50
CANCELS = 40
#: Longest wait for all answers of a burst [s] (a second or two on a quiet machine).
ANSWER_WITHIN_S = 30.0
#: Every goal of a burst accepted or refused with its reason within this [s] (issue #32).
GOAL_ANSWER_BOUND_S = 2.0
GOAL = {'k_theta': [7.0], 'delta_theta_p': [math.radians(10.0)]}  # inside the sufficient region
#: A slow ROLLING_UP (20 s): the grasp that runs still runs when the burst's cancels come.
CONTROLLER = [str(installed_executable('dam_spcm_controller', 'spcm_controller')), '--ros-args',
              '-p', 'trajectory_duration:=20.0', '-p', 'phase_timeout:=60.0', '-p',
              'approach_speed:=0.5', '-p', 'damping:=0.02', '-p', 'check_lift_timeout:=0.0']


@pytest.fixture(scope='module')
def stack() -> Iterator[RosClient]:
    """The synthetic plant, the analysis server and the controller, and a client node."""
    with ExitStack() as es:
        es.enter_context(node_process(fixture_command('spcm_plant_node.py')))
        es.enter_context(node_process(
            [str(installed_executable('dam_analysis', 'check_lift_server'))]))
        controller = es.enter_context(node_process(CONTROLLER))
        ros = RosClient()
        es.callback(ros.close)
        yield ros
        assert controller.alive(), controller.output()[-3000:]


def _unanswered(futures: list) -> int:
    return sum(not f.done() for f in futures)


def _wait_all(ros: RosClient, futures: list, what: str) -> None:
    ros.spin_until(lambda: _unanswered(futures) == 0, ANSWER_WITHIN_S)
    assert _unanswered(futures) == 0, \
        f'{_unanswered(futures)} of {len(futures)} {what} unanswered after {ANSWER_WITHIN_S} s'


def _action_clients(ros: RosClient, n: int) -> list:
    from rclpy.action import ActionClient

    from dam_common.service_qos import action_server_qos
    from dam_interfaces.action import DamGrasp

    clients = [ActionClient(ros.node, DamGrasp, '/dam_grasp', **action_server_qos())
               for _ in range(n)]
    for client in clients:
        assert client.wait_for_server(timeout_sec=30.0), '/dam_grasp did not appear'
    return clients


def _goal_burst(ros: RosClient, n_clients: int) -> float:
    """BURST goals at once from ``n_clients`` clients: every goal answered and accepted, one
    runs, the others end at once with OUTCOME_REJECTED and the reason; then CANCELS cancel
    requests at once (the running goal's among them): every one answered, the running goal
    cancelled. Returns the time from the burst to the last refusal [s]."""
    from action_msgs.msg import GoalStatus

    from dam_interfaces.action import DamGrasp

    clients = _action_clients(ros, n_clients)
    try:
        t_burst = time.monotonic()
        sent = [clients[i % n_clients].send_goal_async(DamGrasp.Goal(**GOAL))
                for i in range(BURST)]
        _wait_all(ros, sent, 'goal requests')
        handles = [f.result() for f in sent]
        assert all(h.accepted for h in handles), 'a goal was not accepted'
        results = [h.get_result_async() for h in handles]
        ros.spin_until(lambda: _unanswered(results) <= 1, ANSWER_WITHIN_S)
        refused_within = time.monotonic() - t_burst
        running = [h for h, r in zip(handles, results, strict=True) if not r.done()]
        assert len(running) == 1, f'{len(running)} goals without a result, expected the one ' \
                                  'that runs'
        for result in (r.result() for r in results if r.done()):
            assert result.status == GoalStatus.STATUS_ABORTED, result.status
            assert result.result.outcome == DamGrasp.Result.OUTCOME_REJECTED
            assert 'already running' in result.result.message, result.result.message
        others = [h for h in handles if h is not running[0]][:CANCELS - 1]
        cancels = [h.cancel_goal_async() for h in [*others, running[0]]]
        _wait_all(ros, cancels, 'cancel requests')
        assert len(cancels[-1].result().goals_canceling) == 1, 'the running goal not cancelled'
        _wait_all(ros, results, 'result requests')
        last = results[handles.index(running[0])].result()
        assert last.status == GoalStatus.STATUS_CANCELED, (last.status, last.result.message)
        return refused_within
    finally:
        for client in clients:
            client.destroy()


def test_a_burst_of_goals_and_cancels_from_one_client_is_answered(stack) -> None:
    _goal_burst(stack, 1)


def test_a_burst_of_goals_and_cancels_from_five_clients_is_answered(stack) -> None:
    """Every goal accepted, and refused with its reason within the 2 s of issue #32 (at load 4
    it took 0.23 to 0.36 s, bursts 2 s apart). The clients keep every reply
    (docs/grasping.md): with rclpy's default depth of 10, five clients of one node lost replies of
    such a burst at load 4 (38 of 49 results), and at no load right after another burst."""
    took = _goal_burst(stack, 5)
    assert took < GOAL_ANSWER_BOUND_S, f'the refusals took {took:.2f} s'


def _service_burst(ros: RosClient, srv_type, name: str, request) -> list:
    """BURST calls of ``name`` at once; their answers (all of them, or the test fails)."""
    from dam_common.service_qos import SERVICE_QOS

    client = ros.node.create_client(srv_type, name, qos_profile=SERVICE_QOS)
    try:
        assert client.wait_for_service(timeout_sec=30.0), f'{name} did not appear'
        calls = [client.call_async(request) for _ in range(BURST)]
        _wait_all(ros, calls, f'{name} requests')
        return [c.result() for c in calls]
    finally:
        ros.node.destroy_client(client)


def test_a_burst_of_check_lift_requests_is_answered(stack) -> None:
    from dam_interfaces.srv import CheckLift

    answers = _service_burst(stack, CheckLift, '/check_lift', CheckLift.Request())
    assert all(a.ok for a in answers), answers[0].message


def test_a_burst_of_plan_lift_requests_is_answered(stack) -> None:
    from dam_interfaces.srv import PlanLift

    request = PlanLift.Request()
    # NaN is refused at once, no planning (a negative value would mean 'the configuration's')
    request.mass_min, request.mass_max = math.nan, 0.05
    answers = _service_burst(stack, PlanLift, '/plan_lift', request)
    assert not any(a.ok for a in answers)
    assert all('mass_min' in a.message for a in answers), answers[0].message


def test_a_burst_of_release_requests_is_answered(stack) -> None:
    """One releases the hand; the others wait for it (one callback group) and are told."""
    from std_srvs.srv import Trigger

    answers = _service_burst(stack, Trigger, '/spcm_controller/release', Trigger.Request())
    assert sum(a.success for a in answers) >= 1, [a.message for a in answers[:3]]


def test_a_burst_of_parameter_requests_is_answered(stack) -> None:
    from rcl_interfaces.srv import GetParameters

    request = GetParameters.Request(names=['damping'])
    answers = _service_burst(stack, GetParameters, '/spcm_controller/get_parameters', request)
    assert all(len(a.values) == 1 for a in answers)
