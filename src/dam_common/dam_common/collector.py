"""Garbage collection at a time of the node's choosing, not in the middle of a control cycle.

CPython's cyclic garbage collector runs whenever allocations pass its thresholds, in whichever
thread allocates, and holds the interpreter lock for the whole collection. In a node with a timed
thread that lock is the timed thread's: a collection in the executor thread (which allocates for
every callback) stops the device thread for its duration. Here a collection of the stand-in's
executor took about 45 ms (a finaliser in it raised and caught a C++ exception, whose unwinding
is slow), and pauses of 0.1 s stopped the device stream long enough for the driver to declare
the device lost.

:class:`ScheduledCollector` turns the automatic collector off and runs a full collection from the
owner's executor every ``period_s`` instead: the pauses are as long as before but rare, at a
known rate, and measured (:attr:`ScheduledCollector.max_pause_s`). Objects that exist when the
node starts are frozen first (``gc.freeze``), so a collection scans only what the running node
allocated. Reference cycles are still freed, every ``period_s``.
"""

from __future__ import annotations

import gc
import time

from rclpy.node import Node

from dam_common.clock import create_steady_timer

#: Default time between two collections [s].
PERIOD_S = 5.0
#: A collection longer than this is logged as a warning [s].
WARN_PAUSE_S = 0.010


class ScheduledCollector:
    """Automatic garbage collection off; a full collection every ``period_s`` instead.

    Parameters
    ----------
    node : Node
        Its executor runs the collections (a steady timer); its logger reports long ones.
    period_s : float
        Time between two collections [s], positive.

    Raises
    ------
    ValueError
        ``period_s`` is not a positive finite number.
    """

    def __init__(self, node: Node, period_s: float = PERIOD_S) -> None:
        if not (period_s > 0.0 and period_s < float('inf')):
            raise ValueError(f'garbage collection period {period_s!r} s must be positive')
        self._node = node
        #: Number of collections run so far.
        self.collections = 0
        #: Objects the collections found unreachable, in all.
        self.collected = 0
        #: Duration of the last and of the longest collection [s].
        self.last_pause_s = 0.0
        self.max_pause_s = 0.0
        gc.freeze()  # start-up objects are never scanned again
        gc.disable()
        self._timer = create_steady_timer(node, period_s, self.collect)

    def collect(self) -> int:
        """Run a full collection now; the number of unreachable objects it found."""
        start = time.perf_counter()
        found = gc.collect()
        pause = time.perf_counter() - start
        self.collections += 1
        self.collected += found
        self.last_pause_s = pause
        self.max_pause_s = max(self.max_pause_s, pause)
        if pause > WARN_PAUSE_S:
            self._node.get_logger().warning(
                f'garbage collection took {pause * 1e3:.1f} ms ({found} objects)',
                throttle_duration_sec=60.0)
        return found

    def stop(self) -> None:
        """Automatic collection on again (the timer goes with the node)."""
        self._timer.cancel()
        gc.enable()
