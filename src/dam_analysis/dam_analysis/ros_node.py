"""What every DAM node shares in its ROS layer: the config_file parameter and main()."""

from __future__ import annotations

import gc
import sys
from collections.abc import Callable

import rclpy
from rcl_interfaces.msg import IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

CONFIG_FILE_DESCRIPTION = ('DAM configuration file (YAML); empty: DAM_CONFIG or the installed '
                           'config/dam.yaml')


def declare_config_file(node: Node) -> str:
    """Declare the read-only ``config_file`` parameter on ``node`` and return its value.

    Pass the value, or ``None`` when it is empty, to :func:`dam_analysis.config.load_config`.
    """
    return str(node.declare_parameter(
        'config_file', '',
        ParameterDescriptor(description=CONFIG_FILE_DESCRIPTION, read_only=True)).value)


def declare_thread_priority(node: Node, default: int = 50,
                            what: str = 'the timed device thread') -> int:
    """Declare the read-only ``thread_priority`` parameter on ``node`` and return its value.

    The priority (1-99) of the ``SCHED_FIFO`` policy ``what`` asks for, as ``ros2_control``'s
    controller manager does; ``0`` keeps the normal policy. See
    :mod:`dam_hand_driver.realtime`.
    """
    return int(node.declare_parameter(
        'thread_priority', default,
        ParameterDescriptor(
            description=f'SCHED_FIFO priority of {what} (1-99); 0: normal scheduling. Needs '
                        'the rtprio permission; without it the node warns and runs with '
                        'normal scheduling',
            integer_range=[IntegerRange(from_value=0, to_value=99, step=1)],
            read_only=True)).value)


def run_node(make_node: Callable[[], Node], name: str, args: list[str] | None = None,
             startup_errors: tuple[type[BaseException], ...] = (),
             startup_exit_code: int = 1, switch_interval_s: float | None = None) -> None:
    """Initialise rclpy, build the node with ``make_node``, spin it, and shut down cleanly.

    Once the node is built, every object that exists is moved out of the garbage collector's
    sight (``gc.freeze``), so later collections scan only what the running node allocates:
    no pause of several milliseconds in the middle of a control cycle. A node with a timed
    thread of its own (the driver's device link, the stand-in's device) passes
    ``switch_interval_s`` [s], the longest time another thread may keep that thread from the
    interpreter (``sys.setswitchinterval``; Python's default is 5 ms).

    SIGINT and an external shutdown end it with exit status 0. An exception of one of
    ``startup_errors`` (a bad configuration) or an rclpy ``ParameterException`` (a parameter
    override of the wrong type or out of its range) is logged as one fatal line
    ``cannot start: ...`` under the logger ``name`` and ends the process with
    ``startup_exit_code``; anything else propagates with its traceback.
    """
    rclpy.init(args=args)
    node = None
    try:
        try:
            node = make_node()
        except (*startup_errors, ParameterException) as exc:
            rclpy.logging.get_logger(name).fatal(f'cannot start: {exc}')
            raise SystemExit(startup_exit_code) from None
        if switch_interval_s is not None:
            sys.setswitchinterval(switch_interval_s)
        gc.freeze()  # no gc.collect() first: a full collection could stall a running thread
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
