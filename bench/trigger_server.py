"""Baseline for service benchmarks: a std_srvs/Trigger server that does no work at all."""

import sys

from rclpy.node import Node
from std_srvs.srv import Trigger

from dam_common.node import run_node


class TriggerServer(Node):
    def __init__(self, name: str) -> None:
        super().__init__('bench_trigger_server')
        self.create_service(Trigger, name, self.on_request)

    def on_request(self, request: Trigger.Request,
                   response: Trigger.Response) -> Trigger.Response:
        response.success = True
        return response


def main() -> None:
    service = sys.argv[1] if len(sys.argv) > 1 else '/bench/trigger'
    run_node(lambda: TriggerServer(service), 'bench_trigger_server')


if __name__ == '__main__':
    main()
