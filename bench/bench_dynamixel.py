"""The Dynamixel backend's bus cycle against the emulated bus, with a bare SDK sync read of the
same registers as the baseline, same run.

Target (issue): at least 250 cycles/s for nine servos at 4 Mbit/s. The cycle is what
``hand_driver`` does per bus cycle with ``backend:=dynamixel``: one Group Sync Read of
addresses 120-135 of the nine servos, the conversion to SI, the control law and one Group Sync
Write of 102-119 (:class:`dam_hand_driver.dynamixel_device.DynamixelDevice`, without its
pacing). The baseline is ``GroupSyncRead.txRxPacket()`` of the same block alone. The emulated
bus (``dynamixel_bus``, real time, its own process) answers both: on a pseudo-terminal the
emulator's own Python work, not the wire, bounds both numbers.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time

import numpy as np

from ros_testing import installed_executable


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
        device.close()
    finally:
        proc.send_signal(signal.SIGINT)
        proc.wait(timeout=10.0)
    bare_s, cycle_s = np.array(bare), np.array(cycle)
    rate = 1.0 / float(np.median(cycle_s))
    return {
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
