"""Entry points of executables that must stop cleanly on SIGINT and SIGTERM.

Each catches both signals before it imports anything heavy (rclpy, numpy, the node itself), so
that a signal during start-up is a request to stop like any other
(:mod:`dam_common.shutdown`).
"""

from __future__ import annotations

from dam_common.closed_output import quiet_when_output_closed
from dam_common.shutdown import catch_signals, run_node_entry


def spcm_controller() -> None:
    """``ros2 run dam_spcm_controller spcm_controller``: the controller node."""
    run_node_entry('dam_spcm_controller.controller_node')


@quiet_when_output_closed
def dam_grasp() -> None:
    """``ros2 run dam_spcm_controller dam_grasp``: the grasp client."""
    catch_signals()
    from dam_spcm_controller.grasp_client import main

    main()
