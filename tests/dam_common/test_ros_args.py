"""strip_ros_args: what a tool without rclpy keeps of its command line."""

from __future__ import annotations

from dam_common.ros_args import strip_ros_args


def test_ros_argument_blocks_are_dropped_and_the_rest_kept_in_order() -> None:
    argv = ['--friction-angles', '5', '--ros-args', '-r', '__ns:=/x', '--', '--out', 'm.png']
    assert strip_ros_args(argv) == ['--friction-angles', '5', '--out', 'm.png']
    assert strip_ros_args(['--ros-args', '-p', 'a:=1']) == []  # to the end without '--'
    assert strip_ros_args(['--k-max', '3']) == ['--k-max', '3']
    assert strip_ros_args(['--', 'x']) == ['--', 'x']  # '--' outside a block is an argument
