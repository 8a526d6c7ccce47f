"""``ClockWatch`` names the clock's faults: a ``/clock`` jump, two ``/clock`` publishers, a node
on wall time beside a simulated clock, a stream stamped on another clock.

Real rclpy nodes in this process talk over DDS (the run's own ``ROS_DOMAIN_ID``): a watched
node on simulated time, one on wall time, and the publishers of ``/clock``.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Iterator

import pytest
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticStatus
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock

from dam_common.clock_watch import ClockWatch

BOUND_S = 5.0


class Graph:
    """An rclpy context with an executor; the nodes made by :meth:`node` spin in it."""

    def __init__(self) -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes: list[Node] = []

    def node(self, name: str, sim_time: bool = False) -> Node:
        node = rclpy.create_node(name, context=self.context, parameter_overrides=[
            Parameter('use_sim_time', value=sim_time)])
        self.executor.add_node(node)
        self.nodes.append(node)
        return node

    def spin_until(self, predicate: Callable[[], bool], timeout_s: float = 10.0) -> None:
        deadline = time.monotonic() + timeout_s
        while not predicate():
            assert time.monotonic() < deadline, 'condition not reached'
            self.executor.spin_once(timeout_sec=0.02)

    def close(self) -> None:
        self.executor.shutdown()
        for node in self.nodes:
            node.destroy_node()
        rclpy.try_shutdown(context=self.context)


@pytest.fixture
def graph() -> Iterator[Graph]:
    g = Graph()
    yield g
    g.close()


def _publish(graph: Graph, pub, watched: Node, seconds: float) -> None:
    """Publish ``seconds`` on /clock and spin until ``watched``'s clock shows it."""
    sec = int(seconds)
    msg = Clock(clock=Time(sec=sec, nanosec=round((seconds - sec) * 1e9)))
    target = sec * 1_000_000_000 + msg.clock.nanosec

    def arrived() -> bool:
        if watched.get_clock().now().nanoseconds == target:
            return True
        pub.publish(msg)  # again: /clock is best effort
        return False

    graph.spin_until(arrived)


def test_a_jump_is_named_and_taken_out_of_the_steady_time(graph: Graph) -> None:
    watched = graph.node('watched', sim_time=True)
    source = graph.node('clock_source')
    watch = ClockWatch(watched, 'test: clock', BOUND_S)
    pub = source.create_publisher(Clock, '/clock', 10)
    graph.spin_until(lambda: watched.count_subscribers('/clock') >= 1)
    _publish(graph, pub, watched, 100.0)  # the start of the clock: no jump
    _publish(graph, pub, watched, 104.5)  # forward within the bound: no jump
    assert watch.jumps == 0
    assert watch.status().level == DiagnosticStatus.OK
    _publish(graph, pub, watched, 1e5)
    assert watch.jumps == 1
    assert 'from 104.500 s to 100000.000 s' in watch.last_jump(), watch.last_jump()
    assert watch.steady_now_s() == pytest.approx(104.5, abs=1e-6)
    _publish(graph, pub, watched, 104.51)  # back: a jump too
    assert watch.jumps == 2 and 'to 104.510 s' in watch.last_jump()
    # the whole step of a jump is taken out; the clock goes on from there
    assert watch.steady_now_s() == pytest.approx(104.5, abs=1e-6)
    _publish(graph, pub, watched, 104.52)
    assert watch.jumps == 2
    assert watch.steady_now_s() == pytest.approx(104.51, abs=1e-6)
    status = watch.status()
    assert status.level == DiagnosticStatus.WARN
    assert '/clock jumped' in status.message and 'to 104.510 s' in status.message
    assert {kv.key: kv.value for kv in status.values}['clock_jumps'] == '2'
    # a second publisher, and a node on wall time beside the simulated clock
    other = graph.node('second_clock_source').create_publisher(Clock, '/clock', 10)
    assert other is not None
    graph.spin_until(lambda: watched.count_publishers('/clock') == 2)
    watch.check()
    assert any('2 publishers of /clock' in c for c in watch.conditions), watch.conditions
    wall = graph.node('on_wall_time')
    wall_watch = ClockWatch(wall, 'test: wall clock', BOUND_S)
    graph.spin_until(lambda: wall.count_publishers('/clock') == 2)
    wall_watch.check()
    assert any('runs on wall time' in c for c in wall_watch.conditions), wall_watch.conditions


def test_a_stream_stamped_on_another_clock_is_named(graph: Graph) -> None:
    wall = graph.node('stamps_on_wall_time')
    watch = ClockWatch(wall, 'test: clock', BOUND_S)
    now_ns = wall.get_clock().now().nanoseconds
    watch.stamp_seen('/joint_states', now_ns - 10_000_000)  # 10 ms old: the same clock
    watch.check()
    assert watch.conditions == []
    watch.stamp_seen('/joint_states', 12_345_000_000)  # a simulated time of 12 s
    watch.check()
    assert len(watch.conditions) == 1
    assert '/joint_states is stamped' in watch.conditions[0] and \
        'use_sim_time true?' in watch.conditions[0], watch.conditions
    assert watch.status().level == DiagnosticStatus.WARN


def test_a_bound_that_is_no_duration_is_refused(graph: Graph) -> None:
    with pytest.raises(ValueError, match='forward_bound_s.*nan'):
        ClockWatch(graph.node('bad'), 'test: clock', float('nan'))
