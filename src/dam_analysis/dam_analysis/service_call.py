"""One call of one service from a command-line client, as ``ros2 service call`` makes it.

The small clients of the analysis server (``check_lift``, ``plan_lift``) share it: wait for
the service, send the request, wait for the answer, print it; their exit status says which
of these failed. SIGINT and SIGTERM end every wait at once (:mod:`dam_common.shutdown`): the
client destroys its node, shuts its context down and exits with :data:`INTERRUPTED`, no
traceback.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.signals import SignalHandlerOptions
from rclpy.utilities import remove_ros_args

from dam_common.progress import Progress
from dam_common.shutdown import SHUTDOWN, ShutdownRequest

#: Exit status when the service is not there or does not answer in time.
NO_ANSWER = 1
#: Exit status when the service answered that the request is malformed (``ok`` false).
REJECTED = 2
#: Exit status when SIGINT or SIGTERM stopped the client before it had an answer.
INTERRUPTED = 3
#: Longest time a wait goes on after a stop request [s].
_POLL_S = 0.05


def _wait_for_service(client: Any, timeout_s: float, shutdown: ShutdownRequest) -> bool:
    """``True`` once the service is there; ``False`` after ``timeout_s`` [s] or a stop."""
    deadline = time.monotonic() + timeout_s
    while not client.service_is_ready():
        if shutdown.requested or time.monotonic() >= deadline:
            return False
        shutdown.wait(_POLL_S)  # wakes at once on a signal
    return True


def _spin_until(executor: SingleThreadedExecutor, future: Any, timeout_s: float,
                shutdown: ShutdownRequest) -> bool:
    """Spin until ``future`` is done (``True``), ``timeout_s`` [s] passed or a stop came."""
    deadline = time.monotonic() + timeout_s
    while not future.done():
        remaining = deadline - time.monotonic()
        if shutdown.requested or remaining <= 0.0:
            return False
        executor.spin_once(timeout_sec=min(remaining, _POLL_S))
    return True


def _stopped(prog: str, shutdown: ShutdownRequest, waiting_for: str) -> int:
    print(f'{prog}: stopped by {shutdown.signal_name or "a stop request"} while waiting for '
          f'{waiting_for}', file=sys.stderr)
    return INTERRUPTED


def user_args(prog: str, argv: Sequence[str]) -> list[str]:
    """The command's own arguments: ``argv`` without the program name and its ROS arguments.

    Raises
    ------
    SystemExit
        Status 2, with one line naming the problem, for malformed ROS arguments
        (``--ros-args -p bad``; rclpy raised with a traceback).
    """
    try:
        return remove_ros_args(list(argv))[1:]
    except _rclpy.RCLError as exc:
        print(f'{prog}: invalid ROS arguments: {" ".join(str(exc).split())}', file=sys.stderr)
        raise SystemExit(REJECTED) from None


def call_and_print(prog: str, argv: Sequence[str], srv_type: Any, service: str, request: Any,
                   timeout_s: float, render: Callable[[Any], str]) -> int:
    """Call ``service`` once with ``request`` and print ``render(response)``.

    Parameters
    ----------
    prog : the command's name, for its messages.
    argv : the command line (ROS arguments are passed to ``rclpy.init``).
    srv_type, service, request : the service type, its name and the request.
    timeout_s : how long to wait for the service, then for the answer [s].
    render : the answer as text.

    Returns
    -------
    int
        0 for an answer with ``ok`` true, :data:`REJECTED` for ``ok`` false,
        :data:`NO_ANSWER` when the service is missing or silent, :data:`INTERRUPTED` when
        SIGINT or SIGTERM came first (the signals are the entry point's:
        :func:`dam_common.shutdown.run_client_entry`).
    """
    shutdown = SHUTDOWN
    shutdown.started()  # from here on a signal is a request that every wait looks at
    if shutdown.requested:
        return _stopped(prog, shutdown, 'nothing yet')
    context = rclpy.Context()
    try:
        rclpy.init(args=list(argv), context=context,
                   signal_handler_options=SignalHandlerOptions.NO)
    except _rclpy.RCLError as exc:  # a malformed --ros-args part
        print(f'{prog}: invalid ROS arguments: {" ".join(str(exc).split())}', file=sys.stderr)
        return REJECTED
    node = None
    executor = None
    try:
        node = rclpy.create_node(f'{prog}_client', context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        client = node.create_client(srv_type, service)
        with Progress(prog, f'waiting for the service {service}'):
            found = _wait_for_service(client, timeout_s, shutdown)
        if not found:
            if shutdown.requested:
                return _stopped(prog, shutdown, f'service {service}')
            print(f'{prog}: service {service} is not available '
                  f'(is check_lift_server running in this ROS_DOMAIN_ID?)', file=sys.stderr)
            return NO_ANSWER
        future = client.call_async(request)
        # a line on stderr every few seconds while the server works (dam_common.progress)
        with Progress(prog, f'waiting for the answer of {service}'):
            answered = _spin_until(executor, future, timeout_s, shutdown)
        if not answered:
            if shutdown.requested:
                return _stopped(prog, shutdown, f'the answer of {service}')
            print(f'{prog}: no answer from {service} within {timeout_s} s', file=sys.stderr)
            return NO_ANSWER
        response = future.result()
        if response is None:
            print(f'{prog}: no answer from {service}', file=sys.stderr)
            return NO_ANSWER
        print(render(response))
        return 0 if response.ok else REJECTED
    finally:
        if executor is not None:
            executor.shutdown()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown(context=context)
