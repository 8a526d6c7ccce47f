"""Entry points of executables that must stop cleanly on SIGINT and SIGTERM.

Each catches both signals before it imports anything heavy (rclpy, numpy, the node itself), so
that a signal during start-up is a request to stop like any other
(:mod:`dam_common.shutdown`).
"""

from __future__ import annotations

from dam_common.shutdown import run_node_entry


def check_lift_server() -> None:
    """``ros2 run dam_analysis check_lift_server``: the /check_lift server."""
    run_node_entry('dam_analysis.check_lift_server')
