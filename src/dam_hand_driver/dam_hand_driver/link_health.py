"""The driver's states and the health of its device link, as ``/diagnostics`` shows it (no ROS).

The driver node (:mod:`dam_hand_driver.driver_node`) owns the state and the counters; once a
second it hands them here: :class:`RateWindow` turns counts into rates over the last period,
:func:`link_status` decides the level and message of the status ``dam_hand_driver: device
link``, :func:`latency_summary_us` sums up the device-link thread's answer latencies.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Collection
from typing import NamedTuple

import numpy as np


class DriverState(enum.Enum):
    """The driver's states (the module docstring of :mod:`dam_hand_driver.driver_node`)."""

    WAITING = 'WAITING'
    ACTIVE = 'ACTIVE'
    ERROR = 'ERROR'


class Level(enum.IntEnum):
    """Diagnostic levels, numbered as ``diagnostic_msgs/DiagnosticStatus`` numbers them."""

    OK = 0
    WARN = 1
    ERROR = 2


class WindowRates(NamedTuple):
    """What happened since the previous :meth:`RateWindow.advance`."""

    dt_s: float  #: length of the window [s] (at least 1 ns)
    state_rate_hz: float  #: state frames received per second [Hz]
    joint_states_rate_hz: float  #: /joint_states published per second [Hz]
    #: device time per wall time (the real-time factor of a simulated device); NaN unless
    #: both ends of the window have a device stamp
    real_time_factor: float
    new_read_failures: int  #: failed reads of the device in the window


class RateWindow:
    """Counts at the previous look, to turn the next counts into rates over the window.

    Parameters
    ----------
    now_s
        Start of the first window [s, monotonic]; every count starts at 0 there.
    """

    def __init__(self, now_s: float) -> None:
        #: (time [s], frames received, joint states published, device stamp [ns])
        self._prev: tuple[float, int, int, int] = (now_s, 0, 0, 0)
        self._read_failures = 0

    def advance(self, now_s: float, received: int, published: int, device_ns: int,
                read_failures: int) -> WindowRates:
        """Close the window at ``now_s`` [s, monotonic] with these totals since the start;
        the next window starts here.

        ``device_ns`` is the stamp [ns] of the newest state frame (0: none yet).
        """
        t0, received0, published0, device_ns0 = self._prev
        dt = max(now_s - t0, 1e-9)
        rtf = (device_ns - device_ns0) * 1e-9 / dt if device_ns0 and device_ns else math.nan
        self._prev = (now_s, received, published, device_ns)
        failures0, self._read_failures = self._read_failures, read_failures
        return WindowRates(dt, (received - received0) / dt, (published - published0) / dt, rtf,
                           read_failures - failures0)


def link_status(state: DriverState, error_reason: str, rates: WindowRates, period_s: float,
                sim_time: bool, watchdog_tripped: bool, failing_reads: int, last_failure: str,
                simulated: bool) -> tuple[Level, str]:
    """Level and message of the device link's diagnostic status.

    Parameters
    ----------
    state, error_reason
        The driver's state and, in ERROR, why.
    rates
        The last window (:meth:`RateWindow.advance`).
    period_s
        The device period [s]: a state rate below 80 % of ``1 / period_s`` warns (not on
        simulated time, whose rate is the simulation's).
    sim_time
        The driver runs on simulated time.
    watchdog_tripped
        The newest state frame says the device's watchdog tripped.
    failing_reads, last_failure
        Reads failed in a row now, and what went wrong with the newest failed read.
    simulated
        The newest state frame comes from a simulated device.
    """
    if state is DriverState.ERROR:
        return Level.ERROR, f'ERROR: {error_reason}'
    if state is DriverState.WAITING:
        return Level.ERROR, 'waiting for the device'
    failures = rates.new_read_failures
    if (rates.state_rate_hz < 0.8 / period_s and not sim_time) or watchdog_tripped \
            or failures > 0 or failing_reads:
        return Level.WARN, (
            'device watchdog tripped' if watchdog_tripped else
            f'{failures} failed reads in {rates.dt_s:.1f} s (last: {last_failure})'
            if failures > 0 else
            f'reads failing: {failing_reads} in a row (last: {last_failure})'
            if failing_reads else
            f'state rate {rates.state_rate_hz:.0f} Hz below target')
    return Level.OK, 'ACTIVE' + (' (simulator)' if simulated else '')


def latency_summary_us(latencies_s: Collection[float]) -> tuple[float, float]:
    """Median and largest of ``latencies_s`` [s], in [us]; (0, 0) when there are none."""
    lat = np.array(latencies_s) if latencies_s else np.zeros(1)
    return float(np.percentile(lat, 50) * 1e6), float(lat.max() * 1e6)
