"""Parameters every DAM node shares (ROS layer; imports rclpy)."""

from __future__ import annotations

from rcl_interfaces.msg import ParameterDescriptor
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
