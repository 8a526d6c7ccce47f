"""Baseline for service benchmarks: a std_srvs/Trigger server that does no work at all."""

import sys

import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from std_srvs.srv import Trigger


class TriggerServer(Node):
    def __init__(self, name: str) -> None:
        super().__init__('bench_trigger_server')
        self.create_service(Trigger, name, self.on_request)

    def on_request(self, request: Trigger.Request,
                   response: Trigger.Response) -> Trigger.Response:
        response.success = True
        return response


def main() -> None:
    rclpy.init()
    node = TriggerServer(sys.argv[1] if len(sys.argv) > 1 else '/bench/trigger')
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
