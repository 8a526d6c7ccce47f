"""ScheduledCollector: automatic collection off, full collections from the node's executor."""

from __future__ import annotations

import gc
import time

import pytest

rclpy = pytest.importorskip('rclpy')
from rclpy.executors import SingleThreadedExecutor  # noqa: E402

from dam_common.collector import ScheduledCollector  # noqa: E402


class _Cycle:
    def __init__(self) -> None:
        self.me = self


def test_collections_run_on_the_executor_and_free_cycles_the_automatic_collector_left() -> None:
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('collector_test', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    was_enabled = gc.isenabled()
    try:
        collector = ScheduledCollector(node, period_s=0.2)
        assert not gc.isenabled()
        for _ in range(2000):  # far past the automatic threshold (700 allocations)
            _Cycle()
        assert collector.collections == 0  # nothing collected them in between
        deadline = time.monotonic() + 5.0
        while collector.collections < 2 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.05)
        assert collector.collections >= 2
        assert collector.collected >= 2000  # the cycles (and their dicts) were freed
        assert 0.0 < collector.last_pause_s <= collector.max_pause_s
        collector.stop()
        assert gc.isenabled()
    finally:
        gc.unfreeze()
        if was_enabled:
            gc.enable()
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


@pytest.mark.parametrize('period', [0.0, -1.0, float('nan'), float('inf')])
def test_a_period_that_is_not_positive_and_finite_is_refused(period: float) -> None:
    with pytest.raises(ValueError, match='period'):
        ScheduledCollector(None, period)  # type: ignore[arg-type]
