"""Command-line arguments outside ``--ros-args ... [--]`` (no rclpy).

``ros2 run`` and launch files may pass ROS arguments to any executable. Command-line tools
that need no rclpy (``lift_map``, ``sweep_plot``) and nodes that read an option of their own
before rclpy starts (``sim_bridge --gui``) drop them by hand with :func:`strip_ros_args`.
"""

from __future__ import annotations

from collections.abc import Sequence


def strip_ros_args(argv: Sequence[str]) -> list[str]:
    """``argv`` (without the program name) without its ROS arguments: every
    ``--ros-args ... [--]`` block is dropped."""
    out: list[str] = []
    in_ros = False
    for arg in argv:
        if arg == '--ros-args':
            in_ros = True
        elif in_ros and arg == '--':
            in_ros = False
        elif not in_ros:
            out.append(arg)
    return out
