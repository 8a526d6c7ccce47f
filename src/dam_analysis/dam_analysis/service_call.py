"""One call of one service from a command-line client, as ``ros2 service call`` makes it.

The small clients of the analysis server (``check_lift``, ``plan_lift``) share it: wait for
the service, send the request, wait for the answer, print it; their exit status says which
of these failed.
"""

from __future__ import annotations

import sys
from collections.abc import Callable, Sequence
from typing import Any

import rclpy

#: Exit status when the service is not there or does not answer in time.
NO_ANSWER = 1
#: Exit status when the service answered that the request is malformed (``ok`` false).
REJECTED = 2


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
        :data:`NO_ANSWER` when the service is missing, silent or the call is interrupted.
    """
    rclpy.init(args=list(argv))
    node = rclpy.create_node(f'{prog}_client')
    try:
        client = node.create_client(srv_type, service)
        if not client.wait_for_service(timeout_sec=timeout_s):
            print(f'{prog}: service {service} is not available '
                  f'(is check_lift_server running in this ROS_DOMAIN_ID?)', file=sys.stderr)
            return NO_ANSWER
        future = client.call_async(request)
        rclpy.spin_until_future_complete(node, future, timeout_sec=timeout_s)
        if not future.done() or future.result() is None:
            print(f'{prog}: no answer from {service} within {timeout_s} s', file=sys.stderr)
            return NO_ANSWER
        response = future.result()
        print(render(response))
        return 0 if response.ok else REJECTED
    except KeyboardInterrupt:
        return NO_ANSWER
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
