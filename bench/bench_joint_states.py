"""Hand I/O timing: /joint_states periods, device-link round trip, lockstep world speed.

1. ``hand_driver`` (backend sim: it starts the stand-in) runs as its own process; this process
   subscribes to /joint_states and records arrival times. Target: rate >= 95 % of
   ``device.rate_hz`` and p99 period <= 2.5 nominal periods.
2. This process plays the device for a ``hand_driver`` process (backend hardware): it sends
   state frames and times each until the command frame that references it comes back.
   Target: p99 round trip < 2 ms (one device period at 500 Hz).
3. :class:`SimDevice` in lockstep (UDP state frames included): simulated time over wall time.
   Target: >= 10x real time.

Every run uses its own free UDP ports (a copy of the configuration).
"""

from __future__ import annotations

import socket
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

from ros_testing import RosClient, installed_executable, node_process

REPO_ROOT = Path(__file__).resolve().parents[1]


def _config_copy(directory: Path) -> Path:
    data = yaml.safe_load((REPO_ROOT / 'config' / 'dam.yaml').read_text(encoding='utf-8'))
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(2)]
    for s in socks:
        s.bind(('127.0.0.1', 0))
    data['device']['state_port'], data['device']['command_port'] = (
        s.getsockname()[1] for s in socks)
    for s in socks:
        s.close()
    path = directory / 'dam.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


def _joint_state_periods(config_file: Path, seconds: float) -> np.ndarray:
    from sensor_msgs.msg import JointState

    arrivals: list[float] = []
    cmd = [installed_executable('dam_hand_driver', 'hand_driver'), '--ros-args', '-p',
           'backend:=sim']
    with node_process(cmd, env={'DAM_CONFIG': str(config_file)}):
        client = RosClient()
        try:
            client.node.create_subscription(
                JointState, '/joint_states', lambda _m: arrivals.append(time.perf_counter()),
                500)
            if not client.spin_until(lambda: len(arrivals) > 100, 30.0):
                raise RuntimeError('no /joint_states from hand_driver')
            arrivals.clear()
            client.spin_until(lambda: False, seconds)
        finally:
            client.close()
    return np.diff(np.array(arrivals))


def _round_trips(config_file: Path, n: int, rate_hz: float) -> np.ndarray:
    from dam_analysis.config import load_config
    from dam_hand_driver.protocol import FrameDecoder, FrameKind, encode_state

    cfg = load_config(config_file)
    dev = cfg.device
    joints = len(cfg.hand.joint_names)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind((dev.host, dev.command_port))
    sock.settimeout(0.05)
    decoder = FrameDecoder(FrameKind.COMMAND, joints)
    zeros = [0] * joints
    cmd = [installed_executable('dam_hand_driver', 'hand_driver'), '--ros-args', '-p',
           'backend:=hardware']
    times: list[float] = []
    with node_process(cmd, env={'DAM_CONFIG': str(config_file)}):
        seq = 0
        deadline = time.monotonic() + 30.0
        sent: dict[int, float] = {}
        period = 1.0 / rate_hz
        next_t = time.perf_counter()
        while len(times) < n and time.monotonic() < deadline:
            seq += 1
            frame = encode_state(seq, seq * 1000, zeros, zeros, zeros, [3] * joints, status=0)
            sent[seq] = time.perf_counter()
            sock.sendto(frame, (dev.host, dev.state_port))
            while True:
                try:
                    data = sock.recv(2048)
                except TimeoutError:
                    break
                got = time.perf_counter()
                command = decoder.decode(data)
                if command is not None and command.ref_state_seq in sent:
                    if seq > 200:  # after warm-up
                        times.append(got - sent.pop(command.ref_state_seq))
                    if command.ref_state_seq == seq:
                        break
            next_t += period
            delay = next_t - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
    sock.close()
    return np.array(times)


def _lockstep_speed(cycles: int) -> float:
    from dam_analysis.config import load_config
    from dam_sim_bridge.sim_device import SimDevice

    cfg = load_config()
    sink = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sink.bind(('127.0.0.1', 0))
    device = SimDevice(cfg, host='127.0.0.1', command_port=0,
                       state_port=sink.getsockname()[1], lockstep=True)
    try:
        start = time.perf_counter()
        for _ in range(cycles):
            device.cycle()
        wall = time.perf_counter() - start
        return device.now() / wall
    finally:
        device.close()
        sink.close()


def run(args) -> dict:
    from dam_analysis.config import load_config

    rate_hz = float(load_config().device.rate_hz)
    seconds = 3.0 if args.quick else 15.0
    with tempfile.TemporaryDirectory(prefix='dam-bench-') as tmp:
        periods = _joint_state_periods(_config_copy(Path(tmp)), seconds)
    with tempfile.TemporaryDirectory(prefix='dam-bench-') as tmp:
        rtt = _round_trips(_config_copy(Path(tmp)), 500 if args.quick else 5000, rate_hz)
    speed = _lockstep_speed(1000 if args.quick else 5000)
    nominal = 1.0 / rate_hz
    rate = 1.0 / float(np.mean(periods))
    p50, p99, pmax = (np.percentile(periods, [50, 99]).tolist() + [float(periods.max())])
    r50, r99 = np.percentile(rtt, [50, 99]) * 1e3
    rate_ok = rate >= 0.95 * rate_hz and p99 <= 2.5 * nominal
    rtt_ok = r99 < 2.0
    speed_ok = speed >= 10.0
    return {
        'joint_states_samples': int(periods.size),
        'joint_states_rate_hz': round(rate, 1),
        'joint_states_rate_ratio': round(rate / rate_hz, 3),
        'joint_states_period_p50_ms': round(p50 * 1e3, 3),
        'joint_states_period_p99_ms': round(p99 * 1e3, 3),
        'joint_states_period_max_ms': round(pmax * 1e3, 3),
        'joint_states_p99_over_nominal': round(p99 / nominal, 2),
        'link_round_trips': int(rtt.size),
        'link_round_trip_p50_ms': round(float(r50), 4),
        'link_round_trip_p99_ms': round(float(r99), 4),
        'lockstep_speed_factor': round(speed, 1),
        'target': ('rate >= 0.95 rate_hz and p99 period <= 2.5 periods; link p99 < 2 ms; '
                   'lockstep >= 10x real time'),
        'target_met': bool(rate_ok and rtt_ok and speed_ok),
    }
