"""Receive times on the simulated clock (the core, no rclpy).

With ``use_sim_time`` a message's log time is the simulated time *at its receipt*: the value
of the last ``/clock`` message the recorder's middleware had received when it received the
message (what a node's ROS clock read at that moment). Both receipts are stamped by the
middleware on the system clock as the data arrives, so the log time does not depend on when
the recorder gets the CPU time to write the message: a recorder that falls behind writes late,
but its log times stay where the messages arrived (they never collapse onto the moment the
backlog is written).

:class:`ClockReceipts` keeps the ``/clock`` receipts of the last :data:`KEEP_S` seconds of
system time and maps a receive stamp to the simulated time then.
"""

from __future__ import annotations

import bisect

from dam_recorder.completeness import header_stamp_ns

#: How much system time of ``/clock`` receipts is kept [s] (a message that waited longer in
#: the recorder's backlog gets the oldest kept value: it is counted as held, see the node).
KEEP_S = 600.0


def clock_ns_of(data: bytes | memoryview) -> int | None:
    """The time [ns] in a CDR-serialized ``rosgraph_msgs/Clock`` (``None`` if too short): its
    ``builtin_interfaces/Time`` comes first, where a header's stamp is."""
    return header_stamp_ns(data)


class ClockReceipts:
    """The ``/clock`` values as received, by their receive stamps.

    One thread adds (:meth:`add`, in receive order), another may read (:meth:`at`) at the
    same time: the samples are swapped in whole when old ones are cut.
    """

    def __init__(self, keep_s: float = KEEP_S) -> None:
        self._keep_ns = int(keep_s * 1e9)
        self._samples: tuple[list[int], list[int]] = ([], [])
        #: The latest ``/clock`` value went backwards at least once (a reset or a second
        #: publisher): counted, the mapping follows the receipts.
        self.backward_jumps = 0

    @property
    def started(self) -> bool:
        """A ``/clock`` message has been received."""
        return bool(self._samples[1])

    def add(self, received_ns: int, clock_ns: int) -> None:
        """The ``/clock`` value ``clock_ns`` [ns] was received at ``received_ns`` [ns, system
        clock]. Receipts out of order (an older receive stamp) are ignored."""
        walls, clocks = self._samples
        if walls and received_ns < walls[-1]:
            return
        if clocks and clock_ns < clocks[-1]:
            self.backward_jumps += 1
        if walls and received_ns - walls[0] > 2 * self._keep_ns:
            cut = bisect.bisect_left(walls, received_ns - self._keep_ns)
            walls, clocks = walls[cut:], clocks[cut:]
            self._samples = (walls, clocks)
        clocks.append(clock_ns)  # (clocks first: a reader takes the shorter length)
        walls.append(received_ns)

    def at(self, received_ns: int) -> int | None:
        """The simulated time [ns] at the receive stamp ``received_ns`` [ns, system clock]:
        the value of the last ``/clock`` received at or before it; the first value for a
        stamp before every kept receipt; ``None`` before any ``/clock``."""
        walls, clocks = self._samples
        count = min(len(walls), len(clocks))
        if not count:
            return None
        index = bisect.bisect_right(walls, received_ns, 0, count) - 1
        return clocks[max(index, 0)]
