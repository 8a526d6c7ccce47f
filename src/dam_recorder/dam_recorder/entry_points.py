"""Entry points of executables that must stop cleanly on SIGINT and SIGTERM.

Each catches both signals before it imports anything heavy (rclpy, rosbags, the node itself), so
that a signal during start-up is a request to stop like any other
(:mod:`dam_common.shutdown`).
"""

from __future__ import annotations

from dam_common.shutdown import run_node_entry


def recorder() -> None:
    """``ros2 run dam_recorder recorder``: the bag recorder."""
    run_node_entry('dam_recorder.recorder_node', own_help=True)  # its options: cli.py
