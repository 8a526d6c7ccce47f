"""No malformed request takes a node down: a fuzz of the parameter services of every node.

Each node gets several hundred malformed requests on its six parameter services (unknown type
codes, empty and huge names, wrong array kinds, huge arrays, the wrong type for a declared
parameter, ``ros2 param delete``), as a buggy tool or a typo in ``ros2 service call`` sends
them. Every request must be answered (a set refused with a reason), the process must stay up
without a traceback, and a valid request afterwards must work.
"""

from __future__ import annotations

import random
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import pytest

from ros_testing import (
    RosClient,
    config_with_free_ports,
    fixture_command,
    installed_executable,
    node_process,
)

pytestmark = pytest.mark.integration

#: node name -> (a writable parameter, a valid value for it)
VALID = {
    'check_lift_server': ('default_friction_angle', 0.1),
    'spcm_controller': ('envelope_torque', 0.04),
    'hand_driver': ('use_sim_time', False),
    'hand_driver_sim': ('pose_rate_hz', 50.0),
    'dam_state_publisher': ('use_sim_time', False),  # its own parameters are read-only
}
REQUESTS_PER_NODE = 400
#: Requests sent before the oldest must be answered: below the services' default queue depth.
IN_FLIGHT = 5


@pytest.fixture(scope='module')
def nodes(tmp_path_factory: pytest.TempPathFactory) -> Iterator[dict[str, Any]]:
    """Every node of the suite: the analysis server, the driver with its stand-in
    (``hand_driver_sim``), the controller, the state publisher."""
    config = config_with_free_ports(tmp_path_factory.mktemp('fuzz'))
    env = {'DAM_CONFIG': str(config)}
    with ExitStack() as es:
        procs = {
            'check_lift_server': es.enter_context(node_process(
                [installed_executable('dam_analysis', 'check_lift_server')], env)),
            'hand_driver': es.enter_context(node_process(
                [installed_executable('dam_hand_driver', 'hand_driver'), '--ros-args',
                 '-p', 'backend:=sim', '-p', 'gui:=false'], env)),  # as bringup.sh does
            'spcm_controller': es.enter_context(node_process(
                [installed_executable('dam_spcm_controller', 'spcm_controller')], env)),
            'dam_state_publisher': es.enter_context(node_process(
                [installed_executable('dam_hand_driver', 'dam_state_publisher')], env)),
        }
        client = RosClient()
        es.callback(client.close)
        yield {'procs': procs, 'client': client}


def _random_name(rng: random.Random, declared: str) -> str:
    return rng.choice([
        '', declared, declared.upper(), 'no_such_parameter', 'x' * 10_000, '/', '..', 'ü' * 50,
        'qos_overrides./joint_states.publisher.depth', ' ', declared + '.', '\t'])


def _random_parameter(rng: random.Random, declared: str) -> Any:
    from rcl_interfaces.msg import Parameter, ParameterValue

    value = ParameterValue()
    value.type = rng.choice([0, 10, 42, 127, 128, 200, 254, 255, rng.randrange(256),
                             rng.randrange(1, 10)])
    kind = rng.randrange(9)
    big = rng.choice([0, 1, 5, 100_000])
    if kind == 0:
        value.bool_value = True
    elif kind == 1:
        value.integer_value = rng.choice([-2**63, 2**63 - 1, 0])
    elif kind == 2:
        value.double_value = rng.choice([float('nan'), float('inf'), -1e308, 0.1])
    elif kind == 3:
        value.string_value = 'x' * rng.choice([0, 10, 100_000])
    elif kind == 4:
        value.byte_array_value = [b'\x00'] * big
    elif kind == 5:
        value.bool_array_value = [True] * big
    elif kind == 6:
        value.integer_array_value = [1] * big
    elif kind == 7:
        value.double_array_value = [float('nan')] * big
    else:
        value.string_array_value = [''] * big
    return Parameter(name=_random_name(rng, declared), value=value)


def _fuzz_requests(rng: random.Random, node: str) -> list[tuple[str, Any, Any]]:
    """(service name, type, request) triples for ``node``'s parameter services."""
    from rcl_interfaces.srv import (
        DescribeParameters,
        GetParameters,
        GetParameterTypes,
        ListParameters,
        SetParameters,
        SetParametersAtomically,
    )

    declared = VALID[node][0]
    out = []
    for _ in range(REQUESTS_PER_NODE):
        which = rng.randrange(6)
        params = [_random_parameter(rng, declared) for _ in range(rng.randrange(0, 4))]
        names = [_random_name(rng, declared) for _ in range(rng.choice([0, 1, 3, 1000]))]
        if which == 0:
            out.append(('set_parameters', SetParameters,
                        SetParameters.Request(parameters=params)))
        elif which == 1:
            out.append(('set_parameters_atomically', SetParametersAtomically,
                        SetParametersAtomically.Request(parameters=params)))
        elif which == 2:
            out.append(('get_parameters', GetParameters, GetParameters.Request(names=names)))
        elif which == 3:
            out.append(('describe_parameters', DescribeParameters,
                        DescribeParameters.Request(names=names)))
        elif which == 4:
            out.append(('get_parameter_types', GetParameterTypes,
                        GetParameterTypes.Request(names=names)))
        else:
            out.append(('list_parameters', ListParameters, ListParameters.Request(
                prefixes=names[:3], depth=rng.choice([0, 1, 2**64 - 1]))))
    return out


@pytest.mark.parametrize('node', list(VALID))
def test_parameter_services_survive_a_fuzz(nodes: dict[str, Any], node: str) -> None:
    from rcl_interfaces.msg import Parameter as ParameterMsg
    from rcl_interfaces.msg import ParameterType, ParameterValue
    from rcl_interfaces.srv import GetParameters, SetParameters
    from rclpy.parameter import Parameter

    client: RosClient = nodes['client']
    rng = random.Random(f'fuzz-{node}')
    clients: dict[str, Any] = {}
    pending = []
    for service, srv_type, request in _fuzz_requests(rng, node):
        name = f'/{node}/{service}'
        if name not in clients:
            clients[name] = client.node.create_client(srv_type, name)
            assert clients[name].wait_for_service(timeout_sec=30.0), name
        pending.append((service, request, clients[name].call_async(request)))
        if len(pending) > IN_FLIGHT:  # fewer in flight than a service queue holds (10)
            assert client.wait_future(pending[-IN_FLIGHT - 1][2], 30.0), \
                f'{name} stopped answering'
    for service, request, future in pending:
        assert client.wait_future(future, 30.0), f'/{node}/{service} left a request unanswered'
        response = future.result()
        if service == 'set_parameters':
            assert len(response.results) == len(request.parameters)
            for param, result in zip(request.parameters, response.results, strict=True):
                if param.value.type not in range(1, 10) or not param.name:
                    assert not result.successful and result.reason, (param.name[:20], result)
        elif service == 'set_parameters_atomically':
            bad = [p for p in request.parameters if p.value.type not in range(1, 10)]
            if bad:
                assert not response.result.successful and response.result.reason
    # Specific malformed requests from the issue, with the reason they must give.
    declared, good_value = VALID[node]
    unknown_type = SetParameters.Request(parameters=[
        ParameterMsg(name=declared, value=ParameterValue(type=255))])
    answer = client.call(SetParameters, f'/{node}/set_parameters', unknown_type)
    assert not answer.results[0].successful
    assert '255' in answer.results[0].reason and declared in answer.results[0].reason
    wrong_kind = SetParameters.Request(parameters=[ParameterMsg(
        name=declared, value=ParameterValue(type=ParameterType.PARAMETER_STRING_ARRAY,
                                            string_array_value=['a'] * 1000))])
    answer = client.call(SetParameters, f'/{node}/set_parameters', wrong_kind)
    assert not answer.results[0].successful and answer.results[0].reason
    undeclared = SetParameters.Request(parameters=[Parameter('no_such_param', value=1.0)
                                                   .to_parameter_msg()])
    answer = client.call(SetParameters, f'/{node}/set_parameters', undeclared)
    assert not answer.results[0].successful
    assert "'no_such_param'" in answer.results[0].reason, answer.results[0].reason
    # The node is still up and a valid request works.
    proc = nodes['procs'].get(node, nodes['procs']['hand_driver'])
    assert proc.alive(), proc.output()[-3000:]
    good = SetParameters.Request(parameters=[Parameter(declared, value=good_value)
                                             .to_parameter_msg()])
    answer = client.call(SetParameters, f'/{node}/set_parameters', good)
    assert answer.results[0].successful, answer.results[0].reason
    read = client.call(GetParameters, f'/{node}/get_parameters',
                       GetParameters.Request(names=[declared]))
    assert Parameter.from_parameter_msg(ParameterMsg(name=declared, value=read.values[0])
                                        ).value == good_value
    assert 'Traceback' not in proc.output()
    assert 'matches no parameter' not in proc.output()  # every override was taken


def test_a_callback_that_raises_does_not_end_the_node(tmp_path: Path) -> None:
    """A fixture node whose service and timer raise: the service is answered as failed, the
    node logs the error and goes on serving."""
    from std_srvs.srv import Trigger

    with node_process(fixture_command('raising_node.py')) as proc:
        client = RosClient()
        try:
            for _ in range(3):
                answer = client.call(Trigger, '/raising_node/explode', Trigger.Request())
                assert not answer.success
                assert 'ZeroDivisionError' in answer.message
            assert client.spin_until(lambda: 'a callback raised' in proc.output(), 10.0), \
                proc.output()
            answer = client.call(Trigger, '/raising_node/ping', Trigger.Request())
            assert answer.success
        finally:
            client.close()
        assert proc.alive(), proc.output()
        assert proc.stop() == 0
