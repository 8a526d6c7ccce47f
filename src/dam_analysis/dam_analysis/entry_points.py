"""Entry points of executables that must stop cleanly on SIGINT and SIGTERM.

Each catches both signals before it imports anything heavy (rclpy, numpy, the node itself), so
that a signal during start-up is a request to stop like any other
(:mod:`dam_common.shutdown`).
"""

from __future__ import annotations

from dam_common.closed_output import quiet_when_output_closed
from dam_common.shutdown import run_client_entry, run_node_entry

#: Exit status of a client stopped by SIGINT or SIGTERM before its answer
#: (``dam_analysis.service_call.INTERRUPTED``, not imported here: it imports rclpy).
CLIENT_INTERRUPTED = 3


def check_lift_server() -> None:
    """``ros2 run dam_analysis check_lift_server``: the /check_lift server."""
    run_node_entry('dam_analysis.check_lift_server')


def check_lift() -> None:
    """``ros2 run dam_analysis check_lift``: one /check_lift request from the command line."""
    run_client_entry('dam_analysis.check_lift_client', CLIENT_INTERRUPTED)


def plan_lift() -> None:
    """``ros2 run dam_analysis plan_lift``: one /plan_lift request from the command line."""
    run_client_entry('dam_analysis.plan_lift_client', CLIENT_INTERRUPTED)


@quiet_when_output_closed
def csm_dependence() -> None:
    """``ros2 run dam_analysis csm_dependence``: SIGINT or SIGTERM at any moment, start-up
    included, ends it with one line and status 130."""
    import importlib  # noqa: PLC0415
    import signal  # noqa: PLC0415
    import sys  # noqa: PLC0415

    def interrupt(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    for signum in (signal.SIGINT, signal.SIGTERM):
        signal.signal(signum, interrupt)
    try:
        status = importlib.import_module('dam_analysis.csm_dependence').main()
    except KeyboardInterrupt:
        sys.stderr.write('csm_dependence: interrupted\n')
        status = 130
    sys.exit(status)
