"""Recording: the recorder's sustained rate without loss, and /joint_states timing beside it.

1. A publisher process sends ``sensor_msgs/JointState`` messages of the hand's size (9 joints,
   position, velocity, effort: 300 bytes serialized) on one reliable topic at a fixed rate for
   a few seconds; the recorder (its own process, default settings: MCAP, zstd) records them;
   the bag is counted against what the publisher says it sent. The rate is raised step by
   step; the sustained rate is the highest step with nothing lost. Baseline in the same run:
   ``rosbags``' own rosbag2 writer (MCAP, zstd chunks) writing the same serialized message in
   a loop in this process, i.e. the most a recorder built on it could store. Reported: both
   rates and their ratio.
2. ``/joint_states`` periods from the driver and its stand-in, as ``bench_joint_states``
   measures them, without and with a recorder of the default topics running, in the same run.
   Target: unchanged, at least 99 % of periods within 20 % at 500 Hz with the recorder.

The publisher paces itself with the stand-in's pacing (sleep, then spin to the deadline).
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml
from bench_joint_states import _config_copy, _joint_state_periods, _period_stats

from ros_testing import installed_executable, node_process

_PUBLISHER = """
import sys, time
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from dam_sim_bridge.pacing import sleep_until
rate, seconds = float(sys.argv[1]), float(sys.argv[2])
rclpy.init()
node = rclpy.create_node('bench_publisher')
pub = node.create_publisher(JointState, '/bench/joint_states',
                            QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
msg = JointState()
msg.name = [f'finger{f}_{r}_joint' for f in (1, 2, 3) for r in ('compliant', 'locked', 'position')]
msg.position = [0.1] * 9
msg.velocity = [0.0] * 9
msg.effort = [0.01] * 9
deadline = time.monotonic() + 30.0
while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
    time.sleep(0.01)
time.sleep(0.5)
sent = 0
start = time.monotonic()
next_t = start
while next_t < start + seconds:
    next_t += 1.0 / rate
    sleep_until(next_t)
    msg.header.stamp.nanosec = sent % 1_000_000_000
    pub.publish(msg)
    sent += 1
time.sleep(1.0)
print('SENT', sent, flush=True)
node.destroy_node()
rclpy.shutdown()
"""


def _serialized_joint_state() -> bytes:
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    msg = JointState()
    msg.name = [f'finger{f}_{r}_joint' for f in (1, 2, 3)
                for r in ('compliant', 'locked', 'position')]
    msg.position = [0.1] * 9
    msg.velocity = [0.0] * 9
    msg.effort = [0.01] * 9
    return bytes(serialize_message(msg))


def _raw_writer_rate(directory: Path, count: int) -> float:
    """Messages per second ``rosbags``' rosbag2 writer stores (MCAP, zstd chunks)."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode
    from rosbags.typesys import Stores, get_typestore

    data = _serialized_joint_state()
    store = get_typestore(Stores.ROS2_JAZZY)
    bag = directory / 'raw'
    writer = Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP)
    writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with writer:
        connection = writer.add_connection('/bench/joint_states', 'sensor_msgs/msg/JointState',
                                           typestore=store)
        t0 = time.perf_counter()
        for i in range(count):
            writer.write(connection, 1_700_000_000_000_000_000 + i * 100_000, data)
    return count / (time.perf_counter() - t0)


def _recorded_step(directory: Path, rate: float, seconds: float) -> tuple[int, int]:
    """(sent, recorded) for one rate step."""
    bag = directory / f'rate_{int(rate)}'
    recorder = [installed_executable('dam_recorder', 'recorder'), '-o', str(bag),
                '/bench/joint_states']
    with node_process(recorder) as rec:
        publisher = subprocess.run(
            [sys.executable, '-c', _PUBLISHER, str(rate), str(seconds)], capture_output=True,
            text=True, timeout=seconds + 90.0, check=False)
        rec.stop()
    sent = int(publisher.stdout.split('SENT')[-1]) if 'SENT' in publisher.stdout else 0
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    return sent, int(info['message_count'])


def run(args) -> dict:
    seconds = 2.0 if args.quick else 5.0
    rates = (1000.0, 2000.0, 4000.0) if args.quick else \
        (1000.0, 2000.0, 4000.0, 6000.0, 8000.0, 12000.0)
    report: dict = {}
    sustained = 0.0
    with tempfile.TemporaryDirectory(prefix='dam-bench-') as tmp:
        raw = _raw_writer_rate(Path(tmp), 20_000 if args.quick else 100_000)
        for rate in rates:
            sent, recorded = _recorded_step(Path(tmp), rate, seconds)
            achieved = sent / seconds
            report[f'step_{int(rate)}hz_sent_recorded'] = f'{sent} / {recorded}'
            if sent == 0 or recorded < sent:
                break
            sustained = achieved
    report['recorder_sustained_msgs_per_s'] = round(sustained)
    report['rosbags_writer_msgs_per_s'] = round(raw)
    report['recorder_vs_rosbags_writer_ratio'] = round(sustained / raw, 4)

    window = 10.0 if args.quick else 60.0
    recorder_cmd = [str(installed_executable('dam_recorder', 'recorder'))]
    with tempfile.TemporaryDirectory(prefix='dam-bench-') as tmp:
        alone = _period_stats(_joint_state_periods(_config_copy(Path(tmp)), window)['received'],
                              500.0)
    with tempfile.TemporaryDirectory(prefix='dam-bench-') as tmp:
        bag = Path(tmp) / 'beside'
        recorded = _period_stats(_joint_state_periods(
            _config_copy(Path(tmp)), window, beside=[[*recorder_cmd, '-o', str(bag)]]
        )['received'], 500.0)
    report.update({f'joint_states_alone_{k}': v for k, v in alone.items()})
    report.update({f'joint_states_with_recorder_{k}': v for k, v in recorded.items()})
    report['with_vs_without_recorder_fraction_ratio'] = round(
        recorded['fraction_within_20pct'] / max(alone['fraction_within_20pct'], 1e-9), 4)
    report['measured_seconds_each'] = window
    report['target'] = ('with the recorder: >= 99 % of /joint_states periods within 20 % of '
                        'nominal at 500 Hz')
    report['target_met'] = bool(recorded['fraction_within_20pct'] >= 0.99)
    return report
