"""The Dynamixel backend's bus cycle against the emulated bus, with a bare SDK sync read of the
same registers as the baseline, same run.

Two parts, each against a baseline measured in the same run:

1. **Speed** (target: at least 250 cycles/s for nine servos at 4 Mbit/s). The cycle is what
``hand_driver`` does per bus cycle with ``backend:=dynamixel``: one Group Sync Read of
addresses 120-135 of the nine servos, the conversion to SI, the control law and one Group Sync
Write of 102-119 (:class:`dam_hand_driver.dynamixel_device.DynamixelDevice`, without its
pacing). The baseline is ``GroupSyncRead.txRxPacket()`` of the same block alone. The emulated
bus (``dynamixel_bus``, real time, its own process) answers both: on a pseudo-terminal the
emulator's own Python work, not the wire, bounds both numbers.
2. **The paced bus beside two CPU burners** (target: at most 1 % failed reads at 250 Hz):
   ``DynamixelDevice.receive`` (which paces the cycles at ``dynamixel.rate_hz``) and ``send``
   as the driver's link thread runs them, with the link thread's ``SCHED_FIFO`` priority 50
   (what ``hand_driver`` asks for on a real bus), against bare SDK sync reads of the same
   block paced at the same rate, in alternating one-second blocks. The emulated bus stands in
   for the servos' own processors, which host load does not reach: it runs at ``SCHED_FIFO``
   40 where permitted (else normally: said in the results).
"""

from __future__ import annotations

import os
import signal
import subprocess
import time

import numpy as np

from ros_testing import cpu_burners, installed_executable

#: The paced part's rate [Hz] and the duration of one block of each kind [s].
PACED_RATE_HZ = 250.0
PACED_BLOCK_S = 1.0


def _start_bus() -> tuple[subprocess.Popen[str], str]:
    proc = subprocess.Popen([str(installed_executable('dam_sim_bridge', 'dynamixel_bus'))],
                            stdout=subprocess.PIPE, text=True)
    assert proc.stdout is not None
    line = proc.stdout.readline().split()
    if len(line) != 2 or line[0] != 'DYNAMIXEL_PORT':
        proc.kill()
        raise RuntimeError(f'dynamixel_bus printed {line!r}')
    return proc, line[1]


def run(args) -> dict:
    import dynamixel_sdk as sdk

    from dam_common.config import load_config
    from dam_common.device_protocol import JointMode
    from dam_hand_driver.device import JointSample
    from dam_hand_driver.dynamixel_device import DynamixelDevice

    n = 200 if args.quick else 2000
    config = load_config()
    proc, port = _start_bus()
    try:
        device = DynamixelDevice(config, port)
        ids = [s.servo_id for s in config.dynamixel.servos]
        reader = sdk.GroupSyncRead(device._port, device._ph, 120, 16)
        for servo_id in ids:
            reader.addParam(servo_id)
        modes = np.full(len(ids), int(JointMode.HOLD), dtype=np.int64)
        zeros = np.zeros(len(ids))
        bare, cycle, failures = [], [], 0
        for _ in range(n):  # alternate, so that both see the same load
            t0 = time.perf_counter()
            ok = reader.txRxPacket() == sdk.COMM_SUCCESS
            bare.append(time.perf_counter() - t0)
            failures += not ok
            t0 = time.perf_counter()
            with device._lock:
                sample = device._read_state()
                if sample is None:
                    failures += 1
                    sample = JointSample(0, 0, zeros, zeros, zeros)
                device._write_goals(*device_goals(device, sample, modes, zeros))
            cycle.append(time.perf_counter() - t0)
        paced = _paced(device, reader, proc.pid, blocks=3 if args.quick else 15)
        device.close()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10.0)
    bare_s, cycle_s = np.array(bare), np.array(cycle)
    rate = 1.0 / float(np.median(cycle_s))
    return {
        **paced,
        'load_average_1min': round(os.getloadavg()[0], 2),
        'cycles': n,
        'failed_reads': failures,
        'bare_sync_read_p50_ms': round(float(np.median(bare_s)) * 1e3, 3),
        'bare_sync_read_p99_ms': round(float(np.percentile(bare_s, 99)) * 1e3, 3),
        'driver_cycle_p50_ms': round(float(np.median(cycle_s)) * 1e3, 3),
        'driver_cycle_p99_ms': round(float(np.percentile(cycle_s, 99)) * 1e3, 3),
        'driver_cycle_rate_hz': round(rate, 1),
        'ratio_cycle_to_bare_read_p50': round(float(np.median(cycle_s) / np.median(bare_s)),
                                              3),
        'target_hz': 250.0,
        'target_met': rate >= 250.0,
    }


def device_goals(device, sample, modes: np.ndarray, zeros: np.ndarray):
    """Goal Current and Goal Position as ``DynamixelDevice.send`` computes them."""
    from dam_hand_driver.dynamixel_goals import goals_raw

    current, position, _ = goals_raw(device.table, sample.position, sample.velocity, modes,
                                     zeros, zeros, zeros, sample.position,
                                     device.torque_limit_nm, device.hold_stiffness,
                                     device.hold_damping)
    return current, position


def _paced(device, reader, bus_pid: int, blocks: int) -> dict:
    """The paced bus beside two CPU burners: the driver's cycle and bare sync reads, in
    alternating blocks of :data:`PACED_BLOCK_S`."""
    import dynamixel_sdk as sdk

    from dam_common.realtime import set_thread_priority

    try:
        os.sched_setscheduler(bus_pid, os.SCHED_FIFO, os.sched_param(40))
        bus_scheduling = 'SCHED_FIFO 40'
    except OSError as exc:
        bus_scheduling = f'normal ({exc.strerror})'
    refused = set_thread_priority(50)
    link_scheduling = f'normal ({refused})' if refused else 'SCHED_FIFO 50'
    n = device.n
    hold = np.full(n, 2, dtype=np.int64)  # MODE_HOLD
    zeros = np.zeros(n)
    driver = {'attempts': 0, 'samples': 0, 'failed': 0, 'seconds': 0.0}
    bare = {'attempts': 0, 'samples': 0, 'failed': 0, 'seconds': 0.0}
    period = 1.0 / PACED_RATE_HZ
    with cpu_burners(2):
        time.sleep(0.5)  # the burners at full speed
        load = os.getloadavg()[0]
        for _ in range(blocks):
            failures0 = device.read_failures
            t0 = time.monotonic()
            while time.monotonic() - t0 < PACED_BLOCK_S:
                driver['attempts'] += 1
                sample = device.receive(0.1)
                if sample is not None:
                    driver['samples'] += 1
                    device.send(sample, hold, zeros, zeros, zeros)
            driver['failed'] += device.read_failures - failures0
            driver['seconds'] += time.monotonic() - t0
            t0 = deadline = time.monotonic()
            while time.monotonic() - t0 < PACED_BLOCK_S:
                wait = deadline - time.monotonic()
                if wait > 0.0:
                    time.sleep(wait)
                deadline = max(deadline + period, time.monotonic() - period)
                bare['attempts'] += 1
                if reader.txRxPacket() == sdk.COMM_SUCCESS:
                    bare['samples'] += 1
                else:
                    bare['failed'] += 1
                    device._clear_input()
            bare['seconds'] += time.monotonic() - t0
    if not refused:  # the rest of the benchmarks run normally
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))

    def share(counts: dict) -> float:
        return round(100.0 * counts['failed'] / max(counts['failed'] + counts['samples'], 1), 3)

    driver_failed = share(driver)
    return {
        'paced_rate_target_hz': PACED_RATE_HZ,
        'paced_load_average_1min_with_burners': round(load, 2),
        'paced_link_thread_scheduling': link_scheduling,
        'paced_bus_scheduling': bus_scheduling,
        'paced_driver_reads': driver['samples'] + driver['failed'],
        'paced_driver_failed_reads_percent': driver_failed,
        'paced_driver_rate_hz': round(driver['samples'] / driver['seconds'], 1),
        'paced_bare_reads': bare['samples'] + bare['failed'],
        'paced_bare_failed_reads_percent': share(bare),
        'paced_bare_rate_hz': round(bare['samples'] / bare['seconds'], 1),
        'paced_target_met': driver_failed <= 1.0,
    }
