"""A refused request of a million values gets a short reason, in its reply and in the log.

Before, the reason quoted the whole input: a ``k_theta`` of 1e6 numbers gave a reply, a log
line and a ``/rosout`` message of megabytes each. Now every quote of a received value is cut
(``dam_common.echo``): the reply, the node's log and ``/rosout`` stay at a few kilobytes, and
the node goes on answering.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from contextlib import ExitStack

import pytest

from ros_testing import RosClient, fixture_command, installed_executable, node_process

pytestmark = [pytest.mark.integration]

HUGE = 1_000_000
#: Longest reply text, log line and /rosout message allowed [characters].
SHORT = 4096


@pytest.fixture(scope='module')
def stack() -> Iterator[tuple[RosClient, dict, list]]:
    """The plant, the analysis server, the controller; a client node recording /rosout."""
    from rcl_interfaces.msg import Log
    from rclpy.qos import QoSProfile

    with ExitStack() as es:
        es.enter_context(node_process(fixture_command('spcm_plant_node.py')))
        procs = {
            'check_lift_server': es.enter_context(node_process(
                [str(installed_executable('dam_analysis', 'check_lift_server'))])),
            'spcm_controller': es.enter_context(node_process(
                [str(installed_executable('dam_spcm_controller', 'spcm_controller')),
                 '--ros-args', '-p', 'check_lift_timeout:=0.0'])),
        }
        ros = RosClient()
        es.callback(ros.close)
        rosout: list = []
        ros.node.create_subscription(Log, '/rosout', rosout.append, QoSProfile(depth=1000))
        yield ros, procs, rosout
        for name, proc in procs.items():
            assert proc.alive(), f'{name} died:\n{proc.output()[-3000:]}'
            longest = max(map(len, proc.output().splitlines()), default=0)
            assert longest < SHORT, f'{name} logged a line of {longest} characters'
        assert all(len(m.msg) < SHORT for m in rosout), \
            f'a /rosout message of {max(len(m.msg) for m in rosout)} characters'


def test_check_lift_refuses_a_million_stiffnesses_briefly(stack) -> None:
    from dam_interfaces.srv import CheckLift

    ros, _procs, _rosout = stack
    request = CheckLift.Request()
    request.k_theta = [1.0] * HUGE
    answer = ros.call(CheckLift, '/check_lift', request, timeout=30.0)
    assert not answer.ok
    assert len(answer.message) < SHORT, len(answer.message)
    assert 'k_theta' in answer.message and f'({HUGE} values)' in answer.message, answer.message
    request.delta_theta_p = [-1.0] * HUGE
    request.k_theta = []
    answer = ros.call(CheckLift, '/check_lift', request, timeout=30.0)
    assert not answer.ok and len(answer.message) < SHORT, len(answer.message)
    request.object = 'x' * HUGE
    answer = ros.call(CheckLift, '/check_lift', request, timeout=30.0)
    assert not answer.ok and len(answer.message) < SHORT, len(answer.message)
    assert f'({HUGE} characters)' in answer.message, answer.message
    assert ros.call(CheckLift, '/check_lift', CheckLift.Request()).ok  # still serving


def test_plan_lift_refuses_a_huge_object_name_briefly(stack) -> None:
    from dam_interfaces.srv import PlanLift

    ros, _procs, _rosout = stack
    request = PlanLift.Request()
    request.object = 'y' * HUGE
    answer = ros.call(PlanLift, '/plan_lift', request, timeout=30.0)
    assert not answer.ok and len(answer.message) < SHORT, len(answer.message)


def test_a_goal_of_a_million_stiffnesses_is_refused_briefly(stack) -> None:
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient

    from dam_interfaces.action import DamGrasp

    ros, _procs, _rosout = stack
    action = ActionClient(ros.node, DamGrasp, '/dam_grasp')
    try:
        assert action.wait_for_server(timeout_sec=30.0)
        goal = DamGrasp.Goal(k_theta=[7.0] * HUGE, delta_theta_p=[math.radians(10.0)])
        sent = action.send_goal_async(goal)
        assert ros.wait_future(sent, 30.0) and sent.result().accepted
        result = sent.result().get_result_async()
        assert ros.wait_future(result, 30.0), 'no result'
        answer = result.result()
        assert answer.status == GoalStatus.STATUS_ABORTED
        assert answer.result.outcome == DamGrasp.Result.OUTCOME_REJECTED
        assert len(answer.result.message) < SHORT, len(answer.result.message)
        assert f'({HUGE} values)' in answer.result.message, answer.result.message
    finally:
        action.destroy()


def test_a_parameter_of_a_huge_name_is_refused_briefly(stack) -> None:
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    ros, _procs, _rosout = stack
    request = SetParameters.Request(parameters=[Parameter(
        name='z' * HUGE,
        value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=1.0))])
    for node in ('spcm_controller', 'check_lift_server'):
        answer = ros.call(SetParameters, f'/{node}/set_parameters', request, timeout=30.0)
        result = answer.results[0]
        assert not result.successful and len(result.reason) < SHORT, len(result.reason)
        assert f'({HUGE} characters)' in result.reason, result.reason
