"""Simulated time: the stand-in is the suite's clock, so that a loaded machine slows a grasp down
and changes nothing else.

The stand-in (started by the driver), the driver, the analysis server and the controller run as
separate processes over DDS with ``use_sim_time:=true``, as the scripts start them on the
stand-in. The reference for every outcome is the lockstep trial of the same pair
(``run_experiment``, what ``sweep`` runs), with the latency the live path has (a command reaches
the world two device periods after the state it was computed from): the live grasp must end
with the lockstep trial's outcome and its ground-truth rise within :data:`RISE_TOLERANCE_M`,
with two CPU-burning processes beside it and across a stall of the stand-in. No reruns: an
outcome that depends on the machine's load is the failure these tests are for.

The rise is compared with the lockstep trials started after each of :data:`HOLDS_BEFORE_S`:
a live goal arrives at any moment after the world's reset, and the final seat of a lifted
cylinder in the hand has two configurations (about 8.1 and 9.8 mm) that this moment selects
even in lockstep (one physics step of difference is enough), while the outcome stays the same.
"""

from __future__ import annotations

import math
import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from grasp_testing import Grasper, config_with_free_ports, grasp_stack

from ros_testing import (
    RosClient,
    child_pids,
    cpu_burners,
    installed_executable,
    node_process,
    thread_policies,
)

pytestmark = [pytest.mark.integration]

#: How far the live grasp's ground-truth rise may lie from the lockstep trial's [m]: the
#: controller's commands reach the world at the same device cycle on both paths; what differs
#: is the driver's torque slew (it runs on the state the command answers, one cycle later
#: than in the lockstep trial) and the moment the rise is read (the result's arrival).
RISE_TOLERANCE_M = 0.5e-3
#: The wall-clock bound of a standing simulated clock in these tests [s].
STALL_TIMEOUT_S = 2.0
DELTA_THETA_P = math.radians(10.0)
#: Times the reset world runs before the goal in the lockstep references [s].
HOLDS_BEFORE_S = (0.0, 0.001, 0.05, 0.25, 0.5, 1.0)


@pytest.fixture(scope='module')
def config_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = config_with_free_ports(tmp_path_factory.mktemp('sim_time'))
    data = yaml.safe_load(path.read_text(encoding='utf-8'))
    data['sim']['stall_timeout_s'] = STALL_TIMEOUT_S
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


@pytest.fixture(scope='module')
def stack(config_file: Path) -> Iterator[Grasper]:
    with grasp_stack(config_file, sim_time=True) as grasper:
        yield grasper


def _lockstep_rise(config_file: Path, k_theta: float, object_name: str = ''
                   ) -> tuple[str, list[float]]:
    """(outcome name, rises of the object when the controller is done [m]) of the lockstep
    trials started after each of :data:`HOLDS_BEFORE_S`; their outcomes agree."""
    from dam_common.config import load_config
    from dam_sim_bridge.experiment import run_experiment
    from dam_sim_bridge.world import HandWorld

    config = load_config(config_file).with_object(object_name)
    outcomes, rises = set(), []
    with HandWorld(config) as world:
        for hold in HOLDS_BEFORE_S:
            result = run_experiment(config, k_theta, DELTA_THETA_P, world=world,
                                    latency_cycles=2, hold_before=hold)
            outcomes.add(result.outcome.name)
            rises.append(float(result.lift_final))
    assert len(outcomes) == 1, f'k_theta {k_theta:g} is on an outcome boundary: {outcomes}'
    return outcomes.pop(), rises


def _grasp(grasper: Grasper, k_theta: float) -> tuple[object, float]:
    """Reset the world and grasp; (result, ground-truth rise when the result came [m])."""
    grasper.reset_world()
    z_before = grasper.z()
    result = grasper.result(grasper.send(k_theta, DELTA_THETA_P), timeout=90.0).result
    grasper.client.spin_until(lambda: False, 0.2)  # the pose of the result's moment
    return result, grasper.z() - z_before


def _assert_as_in_lockstep(result, rise: float, expected: tuple[str, list[float]], what: str
                           ) -> None:
    outcome, lockstep_rises = expected
    assert result.outcome_name == outcome, f'{what}: {result.outcome_name} ({result.message})'
    nearest = min(lockstep_rises, key=lambda r: abs(r - rise))
    assert abs(rise - nearest) < RISE_TOLERANCE_M, (
        f'{what}: rise {rise * 1e3:.3f} mm live, in lockstep '
        f'{[round(r * 1e3, 3) for r in lockstep_rises]} mm')


def _standin_pid(grasper: Grasper) -> int:
    children = child_pids(grasper.driver.pid)
    assert len(children) == 1, children
    return children[0]


def _diagnostics(client: RosClient, key: str = 'real_time_factor') -> dict[str, str]:
    """The driver's newest /diagnostics values (waits for one that has ``key``)."""
    from diagnostic_msgs.msg import DiagnosticArray

    got: list[dict[str, str]] = []

    def take(msg: DiagnosticArray) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if key in values:
                got.append(values)

    sub = client.node.create_subscription(DiagnosticArray, '/diagnostics', take, 10)
    try:
        assert client.spin_until(lambda: len(got) >= 2, 5.0), 'no /diagnostics of the driver'
    finally:
        client.node.destroy_subscription(sub)
    return got[-1]


# The two tests that bring up a stack of their own come first: the module's stack (the
# fixture `stack`) would hold the device ports and answer /diagnostics beside theirs.

def test_a_hex_bar_lift_equals_the_lockstep_trial_under_load(config_file: Path) -> None:
    """k 5, 10 deg: inside hex_bar's sufficient region; the bar rises about 8 mm."""
    expected = _lockstep_rise(config_file, 5.0, 'hex_bar')
    assert expected[0] == 'SUCCESS' and min(expected[1]) > 5e-3, expected
    with grasp_stack(config_file, 'hex_bar', sim_time=True) as grasper, cpu_burners(2):
        result, rise = _grasp(grasper, 5.0)
    _assert_as_in_lockstep(result, rise, expected, 'hex_bar k_theta 5')


def test_the_same_stall_on_the_real_time_link_is_an_error(config_file: Path) -> None:
    """Without simulated time the stand-in is a device with a clock of its own: a 0.5 s stall
    is five times the driver's state timeout, and the driver goes to ERROR, as a real hand's
    driver must."""
    client = RosClient()
    env = {'DAM_CONFIG': str(config_file)}
    try:
        with node_process([installed_executable('dam_hand_driver', 'hand_driver'),
                           '--ros-args', '-p', 'backend:=sim'], env=env) as driver:
            assert _diagnostics(client)['state'] == 'ACTIVE', driver.output()
            children = child_pids(driver.pid)
            assert len(children) == 1
            os.kill(children[0], signal.SIGSTOP)
            try:
                time.sleep(0.5)
            finally:
                os.kill(children[0], signal.SIGCONT)
            client.spin_until(lambda: 'ERROR: no state frame' in driver.output(), 5.0)
            assert 'ERROR: no state frame' in driver.output(), driver.output()[-2000:]
    finally:
        client.close()


@pytest.mark.skipif(not os.path.isdir('/proc'), reason='reads /proc')
def test_no_thread_of_any_node_runs_sched_fifo(stack: Grasper) -> None:
    pids = {'driver': stack.driver.pid, 'stand-in': _standin_pid(stack),
            'controller': stack.controller.pid, 'analysis': stack.analysis.pid}
    for name, pid in pids.items():
        policies = thread_policies(pid)
        assert len(policies) > 1, (name, policies)
        assert all(policy == 0 for policy, _ in policies), (name, policies)


def test_the_driver_reports_the_real_time_factor(stack: Grasper) -> None:
    values = _diagnostics(stack.client)
    assert values['use_sim_time'] == 'True'
    rtf = float(values['real_time_factor'])
    # At most real time (paced), and running; 1.0 on an idle machine is measured in bench/.
    assert 0.05 < rtf < 1.05, values


@pytest.mark.parametrize('k_theta', [10.0, 0.5], ids=['lift', 'no-lift'])
def test_the_live_grasp_under_load_equals_the_lockstep_trial(stack: Grasper, config_file: Path,
                                                             k_theta: float) -> None:
    """The configured pair (k 10, inside the sufficient region) lifts the cylinder and k 0.5
    does not, with two CPU-burning processes beside the suite, as in lockstep."""
    expected = _lockstep_rise(config_file, k_theta)
    with cpu_burners(2):
        result, rise = _grasp(stack, k_theta)
    _assert_as_in_lockstep(result, rise, expected, f'k_theta {k_theta:g}')
    if expected[0] == 'SUCCESS':
        assert math.isfinite(result.object_rise) and result.object_rise > 5e-3, result


def test_a_stall_of_the_stand_in_changes_nothing(stack: Grasper, config_file: Path) -> None:
    """SIGSTOP for 0.5 s in the middle of ROLLING_UP (five times the device's state timeout):
    the driver stays ACTIVE and the grasp ends as in lockstep."""
    expected = _lockstep_rise(config_file, 10.0)
    stack.reset_world()
    z_before = stack.z()
    handle = stack.send(10.0, DELTA_THETA_P)
    assert stack.client.spin_until(lambda: 'ROLLING_UP' in stack.feedback_phases, 30.0), \
        stack.feedback_phases
    stack.client.spin_until(lambda: False, 0.5)
    standin = _standin_pid(stack)
    os.kill(standin, signal.SIGSTOP)
    try:
        time.sleep(0.5)
    finally:
        os.kill(standin, signal.SIGCONT)
    result = stack.result(handle, timeout=90.0).result
    stack.client.spin_until(lambda: False, 0.2)
    _assert_as_in_lockstep(result, stack.z() - z_before, expected, 'stalled for 0.5 s')
    assert _diagnostics(stack.client)['state'] == 'ACTIVE'
    assert 'ERROR' not in stack.driver.output(), stack.driver.output()[-2000:]


def test_use_sim_time_cannot_be_changed_at_run_time(stack: Grasper) -> None:
    """What `ros2 param set /spcm_controller use_sim_time false` shows: refused, with the
    reason and how to restart; the node keeps serving."""
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import GetParameters, SetParameters

    for node in ('/spcm_controller', '/hand_driver', '/check_lift_server'):
        request = SetParameters.Request(parameters=[Parameter(
            name='use_sim_time', value=ParameterValue(type=ParameterType.PARAMETER_BOOL,
                                                      bool_value=False))])
        answer = stack.client.call(SetParameters, f'{node}/set_parameters', request)
        assert not answer.results[0].successful, node
        assert 'fixed' in answer.results[0].reason and 'use_sim_time:=false' in \
            answer.results[0].reason, answer.results[0].reason
        got = stack.client.call(GetParameters, f'{node}/get_parameters',
                                GetParameters.Request(names=['use_sim_time']))
        assert got.values[0].bool_value is True, node


def test_a_dead_stand_in_is_noticed_within_a_bounded_wall_time(stack: Grasper) -> None:
    """Last in this module (it kills the stand-in): a simulated clock that stands still does
    not hide a death. The driver goes to ERROR at once (its stand-in child exited) and the
    grasp fails within sim.stall_timeout_s of wall time."""
    from dam_interfaces.action import DamGrasp

    stack.reset_world()
    handle = stack.send(10.0, DELTA_THETA_P)
    assert stack.client.spin_until(lambda: 'ROLLING_UP' in stack.feedback_phases, 30.0)
    os.kill(_standin_pid(stack), signal.SIGKILL)
    t_kill = time.monotonic()
    result = stack.result(handle, timeout=STALL_TIMEOUT_S + 10.0).result
    took = time.monotonic() - t_kill
    assert result.outcome == DamGrasp.Result.OUTCOME_ABORTED, result.message
    assert 'silent' in result.message and 'wall time' in result.message, result.message
    assert took < STALL_TIMEOUT_S + 3.0, took
    assert 'exited with code' in stack.driver.output(), stack.driver.output()[-2000:]
