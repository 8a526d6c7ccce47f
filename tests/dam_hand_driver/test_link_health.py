"""The driver's link health without ROS: rates over a window, status level and message,
latency summary (dam_hand_driver.link_health)."""

from __future__ import annotations

import math
from collections import deque

import pytest

from dam_hand_driver.link_health import (
    DriverState,
    Level,
    RateWindow,
    WindowRates,
    latency_summary_us,
    link_status,
)


def test_levels_are_numbered_as_diagnostic_status_numbers_them() -> None:
    assert (int(Level.OK), int(Level.WARN), int(Level.ERROR)) == (0, 1, 2)


def test_rates_are_counts_over_the_window_since_the_previous_look() -> None:
    window = RateWindow(now_s=100.0)
    first = window.advance(102.0, received=1000, published=990, device_ns=0, read_failures=3)
    assert first.dt_s == pytest.approx(2.0)
    assert first.state_rate_hz == pytest.approx(500.0)
    assert first.joint_states_rate_hz == pytest.approx(495.0)
    assert math.isnan(first.real_time_factor)  # no device stamp yet
    assert first.new_read_failures == 3
    second = window.advance(102.5, received=1200, published=1150, device_ns=7_000_000_000,
                            read_failures=3)
    assert second.state_rate_hz == pytest.approx(400.0)
    assert second.joint_states_rate_hz == pytest.approx(320.0)
    assert math.isnan(second.real_time_factor)  # the window began without a device stamp
    assert second.new_read_failures == 0
    # 0.25 s of device time in 0.5 s of wall time
    third = window.advance(103.0, received=1300, published=1250, device_ns=7_250_000_000,
                           read_failures=5)
    assert third.real_time_factor == pytest.approx(0.5)
    assert third.new_read_failures == 2
    # a window of no time does not divide by zero
    fourth = window.advance(103.0, received=1300, published=1250, device_ns=7_250_000_000,
                            read_failures=5)
    assert fourth.dt_s == 1e-9 and fourth.state_rate_hz == 0.0


def _rates(state_rate_hz: float = 500.0, new_read_failures: int = 0) -> WindowRates:
    return WindowRates(1.25, state_rate_hz, state_rate_hz, math.nan, new_read_failures)


def _status(state: DriverState = DriverState.ACTIVE, rates: WindowRates | None = None,
            sim_time: bool = False, tripped: bool = False, failing: int = 0,
            simulated: bool = False) -> tuple[Level, str]:
    return link_status(state, 'the port failed', rates or _rates(), 1.0 / 500.0, sim_time,
                       tripped, failing, 'timeout on servo 3', simulated)


def test_error_and_waiting_are_errors_whatever_the_link_does() -> None:
    assert _status(DriverState.ERROR, tripped=True) == (Level.ERROR, 'ERROR: the port failed')
    assert _status(DriverState.WAITING, failing=4) == (Level.ERROR, 'waiting for the device')


def test_a_healthy_active_link_is_ok_and_says_whether_it_is_simulated() -> None:
    assert _status() == (Level.OK, 'ACTIVE')
    assert _status(simulated=True) == (Level.OK, 'ACTIVE (simulator)')
    # 80 % of the target rate is still enough
    assert _status(rates=_rates(400.0)) == (Level.OK, 'ACTIVE')


def test_warnings_name_the_most_telling_fault_first() -> None:
    slow = _rates(399.0)
    assert _status(rates=slow) == (Level.WARN, 'state rate 399 Hz below target')
    assert _status(rates=slow, sim_time=True) == (Level.OK, 'ACTIVE')  # the simulation's rate
    assert _status(rates=slow, failing=2) == (
        Level.WARN, 'reads failing: 2 in a row (last: timeout on servo 3)')
    assert _status(rates=_rates(new_read_failures=4), failing=2) == (
        Level.WARN, '4 failed reads in 1.2 s (last: timeout on servo 3)')
    assert _status(rates=_rates(new_read_failures=4), tripped=True) == (
        Level.WARN, 'device watchdog tripped')


def test_latency_summary_is_median_and_largest_in_microseconds() -> None:
    assert latency_summary_us(deque()) == (0.0, 0.0)
    p50, top = latency_summary_us(deque([0.003, 0.0001, 0.0002, 0.0004]))
    assert p50 == pytest.approx(300.0) and top == pytest.approx(3000.0)
