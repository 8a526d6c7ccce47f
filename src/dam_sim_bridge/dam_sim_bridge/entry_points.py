"""Entry points of executables that must stop cleanly on SIGINT and SIGTERM.

Each catches both signals before it imports anything heavy (rclpy, numpy, the node itself), so
that a signal during start-up is a request to stop like any other
(:mod:`dam_common.shutdown`).
"""

from __future__ import annotations

from dam_common.shutdown import run_node_entry


def sim_bridge() -> None:
    """``ros2 run dam_sim_bridge sim_bridge``: the PyBullet stand-in node."""
    run_node_entry('dam_sim_bridge.sim_bridge_node')
