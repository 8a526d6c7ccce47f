"""A controller on wall time beside a hand on simulated time is told so (issue #32): in its log
and on ``/diagnostics`` (status ``dam_spcm_controller: clock``).

The synthetic plant stands for the driver: started with ``use_sim_time:=true``, it stamps
``/joint_states`` with the simulated time this test publishes on ``/clock``; the controller
runs on wall time. A ``/clock`` jump on simulated time is in ``test_sim_time.py`` (during a
grasp), the watch itself in ``tests/dam_common/test_clock_watch.py``.
"""

from __future__ import annotations

import time
from contextlib import ExitStack

import pytest

from ros_testing import RosClient, fixture_command, installed_executable, node_process

pytestmark = [pytest.mark.integration]

STATUS = 'dam_spcm_controller: clock'


def test_a_controller_on_wall_time_beside_a_simulated_clock_names_it() -> None:
    from builtin_interfaces.msg import Time
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from rosgraph_msgs.msg import Clock

    with ExitStack() as es:
        es.enter_context(node_process(
            [*fixture_command('spcm_plant_node.py'), '--ros-args', '-p', 'use_sim_time:=true']))
        controller = es.enter_context(node_process(
            [str(installed_executable('dam_spcm_controller', 'spcm_controller')),
             '--ros-args', '-p', 'check_lift_timeout:=0.0']))
        ros = RosClient()
        es.callback(ros.close)
        clock = ros.node.create_publisher(Clock, '/clock', 10)
        statuses: list[DiagnosticStatus] = []
        ros.node.create_subscription(
            DiagnosticArray, '/diagnostics',
            lambda m: statuses.extend(s for s in m.status if s.name == STATUS), 10)
        t0 = time.monotonic()

        def named() -> bool:
            sim = 5.0 + (time.monotonic() - t0)  # the simulated time: 5 s on, at real time
            clock.publish(Clock(clock=Time(sec=int(sim), nanosec=int(sim % 1.0 * 1e9))))
            return bool(statuses) and statuses[-1].level == DiagnosticStatus.WARN and \
                'stamped' in statuses[-1].message

        ros.spin_until(named, 30.0)
        assert statuses, f'no {STATUS} status:\n{controller.output()[-3000:]}'
        status = statuses[-1]
        assert status.level == DiagnosticStatus.WARN, status
        # both faults, each with what to do
        assert 'runs on wall time (use_sim_time false) while /clock is published' in \
            status.message, status.message
        assert '/joint_states is stamped' in status.message and \
            'use_sim_time true?' in status.message, status.message
        values = {kv.key: kv.value for kv in status.values}
        assert values['use_sim_time'] == 'False' and values['clock_publishers'] == '1', values
        assert float(values['stamp_offset_s']) < -1e9, values  # about 5 s against the epoch
        log = controller.output()
        assert 'clock: this node runs on wall time' in log and \
            'clock: /joint_states is stamped' in log, log[-3000:]
        assert controller.alive()


def test_a_clock_that_starts_over_is_a_jump_named_and_the_next_grasp_runs() -> None:
    """A simulator reset or a bag played in a loop starts the simulated time over: the
    controller names the backward jump, and since the joint states follow the new time line it
    takes them as fresh (a clock that only took the jumps out would see them 100 s old)."""
    from builtin_interfaces.msg import Time
    from rclpy.action import ActionClient
    from rosgraph_msgs.msg import Clock

    from dam_interfaces.action import DamGrasp
    from dam_interfaces.msg import DamStatus

    sim = ['--ros-args', '-p', 'use_sim_time:=true']
    with ExitStack() as es:
        es.enter_context(node_process([*fixture_command('spcm_plant_node.py'), *sim]))
        controller = es.enter_context(node_process(
            [str(installed_executable('dam_spcm_controller', 'spcm_controller')), *sim,
             '-p', 'check_lift_timeout:=0.0']))
        ros = RosClient()
        es.callback(ros.close)
        clock = ros.node.create_publisher(Clock, '/clock', 10)
        phases: list[str] = []
        ros.node.create_subscription(DamStatus, '/dam/status',
                                     lambda m: phases.append(m.phase), 10)
        start = {'wall': time.monotonic(), 'sim': 100.0}

        def tick() -> None:
            t = start['sim'] + time.monotonic() - start['wall']
            clock.publish(Clock(clock=Time(sec=int(t), nanosec=int(t % 1.0 * 1e9))))

        def ticking(predicate):
            def step() -> bool:
                tick()
                return predicate()
            return step

        action = ActionClient(ros.node, DamGrasp, '/dam_grasp')
        es.callback(action.destroy)
        assert ros.spin_until(ticking(lambda: action.server_is_ready() and bool(phases)), 30.0)
        ros.spin_until(ticking(lambda: False), 1.0)
        start.update(wall=time.monotonic(), sim=1.0)  # the time starts over at 1 s
        assert ros.spin_until(ticking(lambda: 'to 1.0' in controller.output()), 10.0), \
            controller.output()[-3000:]
        assert '/clock jumped from 10' in controller.output(), controller.output()[-3000:]
        seen = len(phases)
        sent = action.send_goal_async(DamGrasp.Goal())
        assert ros.spin_until(ticking(
            lambda: sent.done() and 'APPROACH' in phases[seen:]), 20.0), \
            (phases[seen:], controller.output()[-3000:])
        cancel = sent.result().cancel_goal_async()
        assert ros.spin_until(ticking(cancel.done), 10.0)
        assert controller.alive()
