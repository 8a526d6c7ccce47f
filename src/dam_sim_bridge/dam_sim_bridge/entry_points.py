"""Entry points of executables that must stop cleanly on SIGINT and SIGTERM.

Each catches both signals before it imports anything heavy (rclpy, numpy, the node itself), so
that a signal during start-up is a request to stop like any other
(:mod:`dam_common.shutdown`).
"""

from __future__ import annotations

import sys

from dam_common.closed_output import quiet_when_output_closed
from dam_common.shutdown import StartupInterrupted, catch_signals, run_node_entry


def sim_bridge() -> None:
    """``ros2 run dam_sim_bridge sim_bridge``: the PyBullet stand-in node."""
    run_node_entry('dam_sim_bridge.sim_bridge_node')


@quiet_when_output_closed
def dynamixel_bus() -> None:
    """``dynamixel_bus``: the emulated Dynamixel bus (not a node; see
    :func:`dam_sim_bridge.dynamixel_bus_program.main`). A signal at any moment ends it with
    status 0; a bad argument with status 2."""
    shutdown = catch_signals(interrupt_startup=True)
    try:
        from dam_sim_bridge.dynamixel_bus_program import main  # noqa: PLC0415

        status = main()
    except StartupInterrupted:
        status = 0
    except Exception:
        if not shutdown.requested:
            raise
        status = 0  # the interrupt surfaced as another error (a C extension's init wraps it)
    sys.exit(status)
