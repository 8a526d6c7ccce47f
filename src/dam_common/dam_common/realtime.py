"""Real-time scheduling of one thread (no rclpy): what a hand's device-link thread asks of the OS.

A thread that must keep a 1-2 ms period on a shared machine is delayed by every other runnable
process on its core. As ``ros2_control``'s controller manager does, the timed threads of the
driver and of the simulated stand-in ask for the ``SCHED_FIFO`` policy at a configurable
priority; where that is not permitted (an unprivileged user without an ``rtprio`` limit, a
non-Linux OS) they run on with the normal policy and say so once.

Grant the permission on Linux with, e.g., ``/etc/security/limits.d/realtime.conf``::

    @realtime  -  rtprio  98

and membership of the group ``realtime`` (log in again afterwards).
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import sys

#: The ``thread_priority`` parameter's range; 0 disables real-time scheduling.
PRIORITY_RANGE = (0, 99)
#: ``sys.setswitchinterval`` of a node with a timed thread: the longest another thread of the
#: process may keep it from the interpreter [s] (Python's default is 5 ms).
SWITCH_INTERVAL_S = 2.0e-4
_PR_SET_PDEATHSIG = 1
_PR_SET_TIMERSLACK = 29


def _prctl(option: int, value: int) -> bool:
    """``prctl(option, value)`` on Linux; ``False`` where it is not available or fails."""
    if not sys.platform.startswith('linux'):
        return False
    try:
        libc = ctypes.CDLL(ctypes.util.find_library('c') or 'libc.so.6', use_errno=True)
        return libc.prctl(option, int(value), 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def die_with_parent() -> bool:
    """Have the kernel send the calling process SIGTERM when its parent dies, however it dies
    (Linux). Meant as ``preexec_fn`` of a child process.

    Returns
    -------
    bool
        ``True`` if set, ``False`` where the OS has no such setting.
    """
    return _prctl(_PR_SET_PDEATHSIG, signal.SIGTERM)


def reduce_timer_slack(slack_ns: int = 1000) -> bool:
    """Set the calling thread's timer slack to ``slack_ns`` [ns] (Linux only), so that a sleep
    ends within about that much of its deadline (the default slack is 50 us).

    Returns
    -------
    bool
        ``True`` if the slack was set, ``False`` where the OS has no such setting.
    """
    return _prctl(_PR_SET_TIMERSLACK, slack_ns)


def set_thread_priority(priority: int, inherit: bool = False) -> str | None:
    """Run the calling thread under ``SCHED_FIFO`` at ``priority`` (1-99), with a short timer
    slack; ``0`` leaves the thread as it is.

    Threads and processes the thread starts later get the normal policy back
    (``SCHED_RESET_ON_FORK``), unless ``inherit``.

    Returns
    -------
    str | None
        ``None`` on success (or for ``0``), else why the policy could not be set; the thread
        keeps its normal policy then.

    Raises
    ------
    ValueError
        ``priority`` is outside [0, 99].
    """
    if isinstance(priority, bool) or not isinstance(priority, int):
        raise ValueError(f'thread priority {priority!r} is not an integer')
    if not PRIORITY_RANGE[0] <= priority <= PRIORITY_RANGE[1]:
        raise ValueError(f'thread priority {priority!r} is outside {list(PRIORITY_RANGE)}')
    if priority == 0:
        return None
    reduce_timer_slack()
    if not hasattr(os, 'sched_setscheduler'):
        return f'SCHED_FIFO is not available on {sys.platform}'
    policy = os.SCHED_FIFO | (0 if inherit else getattr(os, 'SCHED_RESET_ON_FORK', 0))
    try:
        # pid 0: the calling thread (Linux schedules threads, not processes).
        os.sched_setscheduler(0, policy, os.sched_param(priority))
    except OSError as exc:
        return f'SCHED_FIFO priority {priority} refused: {exc.strerror or exc}'
    return None


def set_process_priority(priority: int) -> str | None:
    """Run every thread the process has now (Linux: ``/proc/self/task``) under ``SCHED_FIFO``
    at ``priority``; ``0`` leaves them as they are. For a node whose middleware threads and
    executor together make its control loop (they exist once the node is built).

    Returns
    -------
    str | None
        ``None`` on success, else why not (threads already set keep the policy).

    Raises
    ------
    ValueError
        ``priority`` is outside [0, 99].
    """
    refused = set_thread_priority(priority, inherit=True)  # validates; the calling thread
    if refused or priority == 0:
        return refused
    try:
        tids = [int(t) for t in os.listdir('/proc/self/task')]
    except OSError:
        return None  # no /proc: the calling thread at least
    for tid in tids:
        try:
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
        except ProcessLookupError:
            continue  # the thread ended meanwhile
        except OSError as exc:
            return f'SCHED_FIFO priority {priority} refused for thread {tid}: {exc.strerror}'
    return None
