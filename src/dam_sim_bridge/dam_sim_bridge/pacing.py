"""Sub-millisecond pacing of a periodic loop on a general-purpose OS (no rclpy).

``time.sleep`` alone wakes up late by the kernel's timer slack (50 us by default on Linux) plus
the scheduling delay, and by more under load. :func:`sleep_until` sleeps to just before the
deadline and spins the rest, so the deadline is met to a few microseconds whenever the thread
is running (:func:`dam_common.realtime.set_thread_priority` sees to that on a busy
machine).
"""

from __future__ import annotations

import time
from collections.abc import Callable

#: Sleep until this long before the deadline [s], then spin. Every 0.1 ms of spin costs 5 % of a
#: core of real-time budget at 500 Hz; a SCHED_FIFO sleeper with a short timer slack wakes
#: within about 0.1 ms in the median here, and a frame that late is still well inside the
#: 20 % (0.4 ms) period tolerance of /joint_states.
SPIN_MARGIN_S = 1.0e-4


def sleep_until(deadline_s: float, clock: Callable[[], float] = time.monotonic,
                spin_margin_s: float = SPIN_MARGIN_S) -> float:
    """Return at ``deadline_s`` on ``clock`` [s]: sleep, then spin the last ``spin_margin_s``.

    Returns
    -------
    float
        How late the call returned [s] (>= 0).
    """
    delay = deadline_s - clock() - spin_margin_s
    if delay > 0.0:
        time.sleep(delay)
    while True:
        now = clock()
        if now >= deadline_s:
            return now - deadline_s
