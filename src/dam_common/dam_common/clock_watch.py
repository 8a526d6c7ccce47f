"""Faults of the node's clock, named: ``/clock`` jumps, two ``/clock`` publishers, and nodes on
different clocks.

A node on simulated time (``use_sim_time:=true``) takes its time from whatever publishes
``/clock``. A second publisher (a bag played beside the stand-in, a second simulator) makes the
clock jump between two time lines; a node on wall time beside a simulator stamps and times on
another clock than its peers. Either way a time-based check (a joint-state silence, a phase
timeout) reads nonsense, and without a word about the clock the fault looks like another one
(``/joint_states silent for 99993.578 s``). :class:`ClockWatch` names these faults:

* **a jump** of the node's clock: forward by more than ``forward_bound_s`` between two
  ``/clock`` messages, or backward at all (rcl's jump callbacks, on simulated time only). The
  first ``/clock`` message after start-up is no jump. Each jump is logged (at most once a
  second, with the count) and shown on ``/diagnostics``; :meth:`ClockWatch.steady_now_s` is
  the node's clock with the jumps taken out (the whole step of a jump: the time that passed
  between the two messages is lost with it), for checks that must not take a jump for a
  silence;
* **two or more publishers** of ``/clock`` (counted once a second);
* **a node on wall time while ``/clock`` is published**: its peers on simulated time run on
  another clock;
* **a stream stamped on another clock** (:meth:`ClockWatch.stamp_seen`): the stamps of a
  stream the node follows (the controller's ``/joint_states``) lie further than
  ``forward_bound_s`` from the node's clock: its publisher runs with the other
  ``use_sim_time`` (not checked within :data:`JUMP_SHOWN_S` of a jump).

Each condition is logged once when it appears (a warning) and once when it clears; the node
adds :meth:`ClockWatch.status` to its ``/diagnostics``: level WARN while a condition holds or
within :data:`JUMP_SHOWN_S` of a jump, with every condition in the message.
"""

from __future__ import annotations

import math
import threading
import time

from diagnostic_msgs.msg import DiagnosticStatus, KeyValue
from rclpy.clock import JumpHandle, JumpThreshold, TimeJump
from rclpy.duration import Duration
from rclpy.node import Node

from dam_common.clock import create_steady_timer

#: How long a jump keeps the clock status at WARN after it happened [s of wall time].
JUMP_SHOWN_S = 10.0
#: Period of the publisher count and the conditions' check [s of wall time].
CHECK_PERIOD_S = 1.0
CLOCK_TOPIC = '/clock'


def _seconds(ns: int) -> str:
    return f'{ns * 1e-9:.3f} s'


class ClockWatch:
    """Watches ``node``'s clock for the faults of this module's docstring.

    Parameters
    ----------
    node : Node
        The node; its ``use_sim_time`` is read once (the suite's nodes fix it at start-up).
    name : str
        The diagnostic status's name (``'<package>: clock'``).
    forward_bound_s : float
        Largest forward step of ``/clock`` between two messages that is not a jump [s]; also
        the largest distance of a followed stream's stamps from the node's clock [s]. Positive.
    """

    def __init__(self, node: Node, name: str, forward_bound_s: float) -> None:
        if not (math.isfinite(forward_bound_s) and forward_bound_s > 0.0):
            raise ValueError(f'forward_bound_s must be a positive number of seconds, got '
                             f'{forward_bound_s!r}')
        self._node = node
        self._name = name
        self._bound_s = float(forward_bound_s)
        self.sim_time = bool(node.get_parameter('use_sim_time').value)
        self._lock = threading.Lock()
        self._offset_ns = 0  # sum of the jumps: the clock minus this has none
        self._jumps = 0
        self._last_jump = ''  # 'from X to Y' of the newest jump
        self._last_jump_wall = -math.inf  # time.monotonic() of the newest jump [s]
        self._jump_logged_wall = -math.inf  # time.monotonic() of the last jump logged [s]
        self._before_ns = 0
        self._publishers = 0
        self._stream = ''  # the stream whose stamps are compared, with its newest offset
        self._stamp_offset_s = math.nan
        self._conditions: dict[str, str] = {}  # kind -> what holds now (logged once)
        self._handle: JumpHandle | None = None
        if self.sim_time:
            self._handle = node.get_clock().create_jump_callback(
                JumpThreshold(min_forward=Duration(nanoseconds=int(forward_bound_s * 1e9)),
                              min_backward=Duration(nanoseconds=-1), on_clock_change=False),
                pre_callback=self._before_jump, post_callback=self._on_jump)
        self._timer = create_steady_timer(node, CHECK_PERIOD_S, self.check)

    # ----------------------------------------------------------------------------------
    # Jumps (called by rcl while the node takes a /clock message)

    def _before_jump(self) -> None:
        self._before_ns = self._node.get_clock().now().nanoseconds

    def _on_jump(self, jump: TimeJump) -> None:
        before = self._before_ns
        if before == 0:
            return  # the first /clock message: the clock starts, it does not jump
        delta = jump.delta.nanoseconds
        with self._lock:
            self._offset_ns += delta
            self._jumps += 1
            self._last_jump = (f'from {_seconds(before)} to {_seconds(before + delta)} '
                               f'({"+" if delta > 0 else ""}{_seconds(delta)})')
            self._last_jump_wall = now = time.monotonic()
            count, text = self._jumps, self._last_jump
            if now - self._jump_logged_wall < 1.0:
                return  # at most one line a second (two publishers jump at their rates)
            self._jump_logged_wall = now
        self._publishers = self._node.count_publishers(CLOCK_TOPIC)
        self._node.get_logger().warning(
            f'/clock jumped {text} (jump {count}; {self._publishers_text()}): times on this '
            f'node\'s clock across the jump are meaningless')

    def steady_now_s(self) -> float:
        """The node's clock with every jump taken out [s]: continuous across jumps (on wall
        time, the node's clock itself)."""
        now = self._node.get_clock().now().nanoseconds
        with self._lock:
            return (now - self._offset_ns) * 1e-9

    @property
    def jumps(self) -> int:
        """Jumps of the clock since start-up."""
        with self._lock:
            return self._jumps

    def last_jump(self, within_s: float = math.inf) -> str:
        """'from X to Y (+D)' of the newest jump if it happened within ``within_s`` [s of wall
        time], else ''."""
        with self._lock:
            if time.monotonic() - self._last_jump_wall <= within_s:
                return self._last_jump
            return ''

    # ----------------------------------------------------------------------------------
    # Stamps of a followed stream

    def stamp_seen(self, topic: str, stamp_ns: int) -> None:
        """A message of ``topic`` stamped ``stamp_ns`` [ns] arrived (cheap: call it for every
        message, from any thread). Its distance from the node's clock is checked once a
        second, except within :data:`JUMP_SHOWN_S` of a jump (the jump is the fault named
        then)."""
        now = self._node.get_clock().now().nanoseconds
        if now == 0:
            return  # simulated time before the first /clock: nothing to compare yet
        self._stream = topic
        self._stamp_offset_s = (stamp_ns - now) * 1e-9

    # ----------------------------------------------------------------------------------
    # Conditions, logs and the diagnostic status

    def _publishers_text(self) -> str:
        n = self._publishers
        return f'{n} publisher{"" if n == 1 else "s"} of /clock'

    def check(self) -> None:
        """Count the /clock publishers and log conditions that appeared or cleared (the watch's
        own 1 Hz timer calls it)."""
        try:
            self._publishers = self._node.count_publishers(CLOCK_TOPIC)
        except Exception:  # noqa: BLE001 - a node being destroyed: nothing to check
            return
        found: dict[str, str] = {}
        if self._publishers > 1:
            found['publishers'] = (
                f'{self._publishers} publishers of /clock: a node on simulated time follows two '
                'time lines (a bag played beside the stand-in? a second simulator?)')
        if not self.sim_time and self._publishers > 0:
            found['wall_time'] = (
                f'this node runs on wall time (use_sim_time false) while /clock is published '
                f'({self._publishers_text()}): nodes on simulated time beside it run on '
                'another clock; start every node with the same use_sim_time')
        offset = self._stamp_offset_s
        if math.isfinite(offset) and abs(offset) > self._bound_s and \
                not self.last_jump(JUMP_SHOWN_S):
            found['stamps'] = (
                f'{self._stream} is stamped {offset:+.3f} s from this node\'s '
                f'{"simulated" if self.sim_time else "wall"} clock: its publisher runs on '
                f'another clock (use_sim_time {str(not self.sim_time).lower()}?); start every '
                'node with the same use_sim_time')
        logger = self._node.get_logger()
        for kind, text in found.items():
            if kind not in self._conditions:
                logger.warning(f'clock: {text}')
        for kind in self._conditions.keys() - found.keys():
            logger.info(f'clock: cleared ({self._conditions[kind].split(":")[0]} no longer '
                        f'holds; now {self._publishers_text()})')
        self._conditions = found

    @property
    def conditions(self) -> list[str]:
        """The clock faults that hold now (jumps aside), each in words."""
        return list(self._conditions.values())

    def status(self) -> DiagnosticStatus:
        """The clock's diagnostic status: WARN while a condition holds or a jump is recent."""
        recent = self.last_jump(JUMP_SHOWN_S)
        problems = self.conditions + ([f'/clock jumped {recent}'] if recent else [])
        status = DiagnosticStatus()
        status.name = self._name
        status.level = DiagnosticStatus.WARN if problems else DiagnosticStatus.OK
        status.message = '; '.join(problems) if problems else \
            f'{"simulated" if self.sim_time else "wall"} time, no clock fault'
        offset = self._stamp_offset_s
        with self._lock:
            jumps, last = self._jumps, self._last_jump
        status.values = [
            KeyValue(key='use_sim_time', value=str(self.sim_time)),
            KeyValue(key='clock_publishers', value=str(self._publishers)),
            KeyValue(key='clock_jumps', value=str(jumps)),
            KeyValue(key='clock_last_jump', value=last),
            KeyValue(key='clock_jump_bound_s', value=f'{self._bound_s:g}'),
            KeyValue(key='stamp_offset_s',
                     value=f'{offset:.3f}' if math.isfinite(offset) else 'none')]
        return status

    def destroy(self) -> None:
        """Stop watching (the jump callback and the timer)."""
        if self._handle is not None:
            self._handle.unregister()
            self._handle = None
        self._node.destroy_timer(self._timer)
