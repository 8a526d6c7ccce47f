"""Simulated time: the stand-in is the suite's clock, so that a loaded machine slows a grasp down
and changes nothing else.

The stand-in (started by the driver), the driver, the analysis server and the controller run as
separate processes over DDS with ``use_sim_time:=true``, as the scripts start them on the
stand-in. The reference for an outcome is the lockstep trial of the same pair
(``grasp_testing.lockstep_reference``, with the latency the live path has: a command reaches
the world two device periods after the state it was computed from). Here: a 0.5 s stall of the
stand-in changes neither the outcome nor the rise, a dead stand-in is noticed within a bounded
wall time, nothing runs SCHED_FIFO with the stand-in and only the device-link thread with a
hand, ``use_sim_time`` is fixed at start-up and refused for a hand, the real-time factor is
reported, and the same stall on the real-time link is the driver's ERROR. The grasps beside two
CPU-burning processes, compared with the lockstep trial, are in ``test_dam_grasp.py`` (a lift
and a no-lift of the cylinder, a LIFTED_DAM_FAILED pair) and ``test_column_grasp.py`` (a lift
of ``hex_bar``). No reruns: an outcome that depends on the machine's load is the failure these
tests are for.
"""

from __future__ import annotations

import math
import os
import re
import signal
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
import yaml
from grasp_testing import (
    Grasper,
    assert_as_in_lockstep,
    config_with_free_ports,
    grasp_stack,
    lockstep_reference,
)

from ros_testing import (
    FakeStateDevice,
    RosClient,
    child_pids,
    installed_executable,
    node_process,
    thread_policies,
)

pytestmark = [pytest.mark.integration]

#: The wall-clock bound of a standing simulated clock in these tests [s].
STALL_TIMEOUT_S = 2.0
DELTA_THETA_P = math.radians(10.0)


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


def _standin_pid(grasper: Grasper) -> int:
    children = child_pids(grasper.driver.pid)
    assert len(children) == 1, children
    return children[0]


def _diagnostics(client: RosClient, key: str = 'real_time_factor', name: str = ''
                 ) -> dict[str, str]:
    """The newest /diagnostics values that have ``key`` (the driver's by default), of the
    status named ``name`` if given."""
    from diagnostic_msgs.msg import DiagnosticArray

    got: list[dict[str, str]] = []

    def take(msg: DiagnosticArray) -> None:
        for status in msg.status:
            values = {kv.key: kv.value for kv in status.values}
            if key in values and (not name or status.name == name):
                got.append(values)

    sub = client.node.create_subscription(DiagnosticArray, '/diagnostics', take, 10)
    try:
        # (the driver's start-up included: seconds on a loaded machine)
        assert client.spin_until(lambda: len(got) >= 2, 15.0), 'no /diagnostics of the driver'
    finally:
        client.node.destroy_subscription(sub)
    return got[-1]


# The tests that bring up a process of their own come first: the module's stack (the
# fixture `stack`) would hold the device ports and answer /diagnostics beside theirs.

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
def test_with_a_real_hand_only_the_device_link_thread_runs_sched_fifo(config_file: Path
                                                                     ) -> None:
    """A device without the SIMULATED bit is a hand: its deadline is real, and the driver's
    device-link thread alone asks for SCHED_FIFO at thread_priority (50); the executor, the
    /hand/command intake and the middleware's threads keep the normal policy."""
    client = RosClient()
    device = FakeStateDevice(config_file, status=0)
    try:
        with node_process([installed_executable('dam_hand_driver', 'hand_driver'),
                           '--ros-args', '-p', 'backend:=hardware'],
                          env={'DAM_CONFIG': str(config_file)}) as driver:
            values = _diagnostics(client)
            reported = values['link_thread_scheduling']
            policies = thread_policies(driver.pid)
            if reported.startswith('normal ('):  # no rtprio permission on this machine
                assert all(policy == 0 for policy, _ in policies), policies
                pytest.skip(reported)
            assert reported == 'SCHED_FIFO 50', values
            assert sorted(policies).count((1, 50)) == 1, policies
            assert all(p == (0, 0) for p in policies if p != (1, 50)), policies
    finally:
        device.close()
        client.close()


@pytest.mark.parametrize('backend', ['hardware', 'auto'])
def test_use_sim_time_is_refused_for_a_real_hand(config_file: Path, backend: str) -> None:
    """One fatal line and a non-zero exit: a real hand's deadline is real."""
    device = FakeStateDevice(config_file, status=0)
    try:
        with node_process([installed_executable('dam_hand_driver', 'hand_driver'),
                           '--ros-args', '-p', f'backend:={backend}', '-p',
                           'use_sim_time:=true'],
                          env={'DAM_CONFIG': str(config_file)}) as driver:
            deadline = time.monotonic() + 20.0
            while driver.alive() and time.monotonic() < deadline:
                time.sleep(0.1)
            assert not driver.alive(), driver.output()
            assert driver.process.returncode != 0, driver.output()
            assert 'cannot start' in driver.output() and 'use_sim_time' in driver.output(), \
                driver.output()
    finally:
        device.close()


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
    # At most real time (paced), and running; the figure itself is measured in bench/.
    assert 0.05 < rtf < 1.05, values


def _jump_clock(client: RosClient, seconds: float, for_s: float) -> None:
    """A second /clock publisher in ``client`` sends ``seconds`` onwards at about 100 Hz for
    ``for_s`` [s] of wall time (the clock jumps between the two time lines), then goes."""
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock

    pub = client.node.create_publisher(Clock, '/clock', 10)
    try:
        client.spin_until(lambda: pub.get_subscription_count() >= 3, 5.0)
        t0 = time.monotonic()
        while (elapsed := time.monotonic() - t0) < for_s:
            pub.publish(Clock(clock=Time(sec=int(seconds),
                                         nanosec=int(elapsed * 1e9) % 1_000_000_000)))
            client.spin_until(lambda: False, 0.01)
    finally:
        client.node.destroy_publisher(pub)


def test_a_stall_of_the_stand_in_and_a_clock_jump_change_nothing(stack: Grasper,
                                                                 config_file: Path) -> None:
    """SIGSTOP for 0.5 s in the middle of ROLLING_UP (five times the device's state timeout),
    then a second /clock publisher at 1e5 s for 0.5 s (the clock jumps between the two time
    lines, five times the state timeout at 100 Hz): the driver stays
    ACTIVE, the grasp ends as in lockstep (the jump is no joint-state silence), and the
    controller names the jump in its log and on /diagnostics."""
    expected = lockstep_reference(config_file, 10.0, DELTA_THETA_P)
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
    _jump_clock(stack.client, 1e5, 0.5)
    result = stack.result(handle, timeout=90.0).result
    stack.client.spin_until(lambda: False, 0.2)
    assert_as_in_lockstep(result, stack.z() - z_before, expected,
                          'stalled for 0.5 s, /clock jumped')
    assert _diagnostics(stack.client)['state'] == 'ACTIVE'
    assert 'ERROR' not in stack.driver.output(), stack.driver.output()[-2000:]
    log = stack.controller.output()
    # (the second publisher's clock runs on from 1e5 s: the first value seen may be past it)
    assert re.search(r'/clock jumped from [0-9.]+ s to 10000[0-9]\.[0-9]{3} s', log), \
        log[-3000:]
    clock = _diagnostics(stack.client, 'clock_jumps', 'dam_spcm_controller: clock')
    assert int(clock['clock_jumps']) >= 2, clock  # there and back
    assert 's to 100000.' in clock['clock_last_jump'] or \
        clock['clock_last_jump'].startswith('from 100000.'), clock


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
