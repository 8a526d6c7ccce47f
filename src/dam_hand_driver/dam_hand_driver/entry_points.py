"""Entry points of executables that must stop cleanly on SIGINT and SIGTERM.

Each catches both signals before it imports anything heavy (rclpy, numpy, the node itself), so
that a signal during start-up is a request to stop like any other
(:mod:`dam_common.shutdown`).
"""

from __future__ import annotations

from dam_common.shutdown import run_node_entry


def hand_driver() -> None:
    """``ros2 run dam_hand_driver hand_driver``: the driver node."""
    run_node_entry('dam_hand_driver.driver_node')


def dam_state_publisher() -> None:
    """``ros2 run dam_hand_driver dam_state_publisher``: /tf and /tf_static of the hand and the
    object."""
    run_node_entry('dam_hand_driver.state_publisher')
