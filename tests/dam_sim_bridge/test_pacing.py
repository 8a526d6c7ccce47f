"""Pacing of the stand-in's real-time loop: deadlines met, state frames sent at the moment
they describe (no ROS)."""

from __future__ import annotations

import socket
import sys
import threading
import time

import numpy as np
import pytest

from dam_common.config import load_config
from dam_common.device_protocol import FrameDecoder, FrameKind, StateFrame
from dam_common.realtime import SWITCH_INTERVAL_S, set_thread_priority
from dam_sim_bridge.pacing import sleep_until
from dam_sim_bridge.sim_device import SimDevice


def test_sleep_until_never_returns_before_the_deadline() -> None:
    late = []
    for delay in (0.0, 1e-5, 2e-4, 1e-3, 3e-3):
        deadline = time.monotonic() + delay
        reported = sleep_until(deadline)
        assert time.monotonic() >= deadline
        assert reported >= 0.0
        late.append(reported)
    assert min(late) < 1e-3  # and it does return (generous: a loaded machine)


def test_sleep_until_a_past_deadline_returns_at_once() -> None:
    start = time.monotonic()
    late = sleep_until(start - 1.0)
    assert late >= 1.0
    assert time.monotonic() - start < 0.05


@pytest.mark.flaky(reruns=1)  # real time on a shared machine
def test_real_time_state_frames_are_stamped_one_period_apart_and_sent_on_time() -> None:
    cfg = load_config()
    n = len(cfg.hand.joint_names)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(('127.0.0.1', 0))
    sock.settimeout(2.0)
    device = SimDevice(cfg, host='127.0.0.1', command_port=0,
                       state_port=sock.getsockname()[1])

    def run_as_the_node_does() -> None:
        # The stand-in's node runs its device thread under SCHED_FIFO at its thread_priority
        # (50) where that is permitted, and normally where not.
        set_thread_priority(50)
        device.run()

    thread = threading.Thread(target=run_as_the_node_does, daemon=True)
    decoder = FrameDecoder(FrameKind.STATE, n)
    stamps, lateness = [], []
    # ... and it shortens the interpreter's switch interval, so that this (receiving) thread
    # cannot keep the device thread waiting for the interpreter lock for 5 ms.
    switch_interval = sys.getswitchinterval()
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    thread.start()
    try:
        while len(stamps) < 300:
            frame = decoder.decode(sock.recv(2048))
            now = time.monotonic()
            assert isinstance(frame, StateFrame)
            stamps.append(frame.timestamp_ns * 1e-9)
            lateness.append(now - frame.timestamp_ns * 1e-9)
    finally:
        device.stop()
        thread.join(timeout=2.0)
        device.close()
        sock.close()
        sys.setswitchinterval(switch_interval)
    periods = np.diff(stamps)
    # Stamps are the deadlines: exactly one period apart unless a deadline was skipped.
    regular = np.isclose(periods, device.period_s, rtol=0.0, atol=1e-6)
    assert np.mean(regular) >= 0.9, periods  # (a stall of this process skips a few)
    # A frame never arrives before the moment it describes (same monotonic clock) ...
    assert min(lateness) >= 0.0
    # ... and mostly within a fraction of a period of it (loose: a loaded machine).
    assert np.median(lateness) < 0.5 * device.period_s
