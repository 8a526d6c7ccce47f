"""``use_sim_time`` on a DAM node: chosen at start-up, and said when nothing gives the time.

Every DAM node picks its timing when it starts: the driver stamps joint states with the
device's clock and waits for the commander, the stand-in steps only when answered, the
controller runs the grasp on the stamps of ``/joint_states``. None of them can switch while
running, so a run-time change of ``use_sim_time`` (``ros2 param set /node use_sim_time
true``) is refused with the reason instead of leaving the node half on one clock. A node
started with ``use_sim_time:=true`` with nothing publishing ``/clock`` would stamp everything
with 0: it says so once.
"""

from __future__ import annotations

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from dam_common.clock import create_steady_timer

#: How long a node with ``use_sim_time`` waits for a ``/clock`` publisher before it warns [s].
CLOCK_GRACE_S = 3.0
USE_SIM_TIME = 'use_sim_time'


def fix_use_sim_time(node: Node) -> None:
    """Refuse every later change of ``node``'s ``use_sim_time``; warn once if it is true and
    no ``/clock`` publisher appears within :data:`CLOCK_GRACE_S` of wall time."""
    started_with = bool(node.get_parameter(USE_SIM_TIME).value)

    def refuse_change(params: list[Parameter]) -> SetParametersResult:
        for param in params:
            if param.name == USE_SIM_TIME and param.value != started_with:
                return SetParametersResult(
                    successful=False,
                    reason=f'use_sim_time is fixed when {node.get_name()} starts (it chose its '
                           f'timing then; now {str(started_with).lower()}): restart it with '
                           f'--ros-args -p use_sim_time:={str(not started_with).lower()}')
        return SetParametersResult(successful=True)

    node.add_on_set_parameters_callback(refuse_change)
    if not started_with:
        return
    timer = None

    def check_clock() -> None:
        node.destroy_timer(timer)
        if node.count_publishers('/clock') == 0:
            node.get_logger().warning(
                f'use_sim_time is true but nothing publishes /clock after {CLOCK_GRACE_S:g} s: '
                'this node\'s clock stands at 0 (message stamps, /diagnostics) until a '
                'simulator publishes it (the stand-in does with use_sim_time:=true)')

    timer = create_steady_timer(node, CLOCK_GRACE_S, check_clock)
