"""Timing that protects the hand or a user runs on a steady clock, whatever ``use_sim_time`` says.

A node started with ``use_sim_time:=true`` takes ROS time from ``/clock``; a timer on that
clock does not fire while ``/clock`` is silent or paused. A watchdog, a phase timeout or a
service deadline on it would never trip when the thing it guards has died. These timers run on
``STEADY_TIME`` instead (``time.monotonic`` in plain Python); message stamps keep the node's
clock, so recorded data stay consistent with ``/clock``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.timer import Timer


def steady_clock() -> Clock:
    """A clock of type ``STEADY_TIME`` (monotonic, never simulated)."""
    return Clock(clock_type=ClockType.STEADY_TIME)


def create_steady_timer(node: Node, period_s: float, callback: Callable[[], Any]) -> Timer:
    """``node.create_timer`` on a steady clock: fires every ``period_s`` [s] of real time."""
    return node.create_timer(period_s, callback, clock=steady_clock())
