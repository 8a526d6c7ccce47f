"""What the tests of the Dynamixel backend share: the SDK against the emulated bus in one
process, and a ROS client of the driver."""

from __future__ import annotations

import sys
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any


@contextmanager
def fast_gil_handoff() -> Iterator[None]:
    """The host (the SDK polls the port in a busy loop) and the emulated bus share this
    process's GIL in these tests; with the default 5 ms switch interval a sync read can outlast
    the SDK's ~34 ms packet timeout. (In use the bus runs in a process of its own.)"""
    before = sys.getswitchinterval()
    sys.setswitchinterval(0.0005)
    try:
        yield
    finally:
        sys.setswitchinterval(before)


class DriverClient:
    """A client of the driver (diagnostics, joint states, ~/reset) and of the stand-in's fault
    parameters."""

    def __init__(self) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import JointState

        from ros_testing import RosClient

        self.client = RosClient()
        self.last_joint_state_s = 0.0  #: time.monotonic() of the newest /joint_states
        self.diag: dict[str, str] = {}
        self.joint_states = 0
        node = self.client.node
        node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 10)
        node.create_subscription(JointState, '/joint_states', self._on_js, 50)

    def _on_diag(self, msg: Any) -> None:
        for status in msg.status:  # the driver's own status (not its clock watch's)
            if status.name.startswith('dam_hand_driver') and \
                    status.name != 'dam_hand_driver: clock':
                self.diag = {kv.key: kv.value for kv in status.values}
                self.diag['message'] = status.message

    def _on_js(self, msg: Any) -> None:
        import time

        self.joint_states += 1
        self.last_joint_state_s = time.monotonic()

    def state(self) -> str:
        return self.diag.get('state', '')

    def wait_state(self, state: str, timeout: float) -> bool:
        self.diag = {}
        return self.client.spin_until(lambda: self.state() == state, timeout)

    def set_fault(self, name: str, values: list[int] | float) -> Any:
        from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
        from rcl_interfaces.srv import SetParameters

        if isinstance(values, list) and not values:  # as `ros2 param set NODE NAME "[]"`
            value = ParameterValue(type=ParameterType.PARAMETER_BOOL_ARRAY, bool_array_value=[])
        elif isinstance(values, float):
            value = ParameterValue(type=ParameterType.PARAMETER_DOUBLE, double_value=values)
        else:
            value = ParameterValue(type=ParameterType.PARAMETER_INTEGER_ARRAY,
                                   integer_array_value=values)
        request = SetParameters.Request(parameters=[Parameter(name=name, value=value)])
        return self.client.call(SetParameters, '/hand_driver_sim/set_parameters', request)

    def reset(self) -> Any:
        from std_srvs.srv import Trigger

        return self.client.call(Trigger, '/hand_driver/reset', Trigger.Request(), timeout=30.0)
