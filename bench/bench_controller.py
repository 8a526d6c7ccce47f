"""spcm_controller: per-cycle compute time and /joint_states -> /hand/command latency.

1. Compute: ``DamSequence.step`` during ROLLING_UP (driven offline by the synthetic plant)
   against a trivial numpy baseline (the impedance law on the same (9,) arrays), same run.
2. Latency: this process plays the hand at 500 Hz (synthetic plant, /joint_states out,
   /hand/command in, the device's impedance law for MODE_IMPEDANCE joints) while the installed
   ``spcm_controller`` runs a grasp with its default parameters; each command carries the stamp
   of the joint state it answers, so the latency is receive time minus send time.

Target (issue): step under 0.2 ms and /joint_states -> /hand/command latency p99 under 2 ms.
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

from ros_testing import RosClient, installed_executable, node_process

REPO_ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO_ROOT / 'tests' / 'dam_spcm_controller'))

PERIOD = 1.0 / 500.0  # control period [s]


def _compute(n: int) -> dict:
    from spcm_plant import SyntheticHand

    from dam_common.config import load_config
    from dam_spcm_controller.sequence import DamSequence, Phase, SequenceParams

    # The synthetic plant is massless: it needs a damping below its friction (as in the tests).
    params = SequenceParams.from_config(load_config(), trajectory_duration=60.0,
                                        phase_timeout=120.0, damping=0.02)
    seq = DamSequence(params)
    hand = SyntheticHand(params.layout)
    t, dt = 0.0, 1e-3
    seq.step(t, hand.q, hand.qd, hand.effort)
    seq.start(7.0, math.radians(10.0))
    while seq.phase is not Phase.ROLLING_UP:
        t += dt
        hand.apply(seq.step(t, hand.q, hand.qd, hand.effort), dt)
        if t > 20.0:
            raise RuntimeError(f'ROLLING_UP not reached (phase {seq.phase})')
    k = np.full(3, 7.0)
    theta_0 = seq.theta_0
    t_step = np.empty(n)
    t_base = np.empty(n)
    for i in range(n):
        t += dt
        q, qd, eff = hand.q.copy(), hand.qd.copy(), hand.effort.copy()
        start = time.perf_counter()
        cmd = seq.step(t, q, qd, eff)
        t_step[i] = time.perf_counter() - start
        start = time.perf_counter()
        np.clip(k * (theta_0 - q[0::3]) - 0.005 * qd[0::3], -0.6, 0.6)
        t_base[i] = time.perf_counter() - start
        hand.apply(cmd, dt)
    if seq.phase is not Phase.ROLLING_UP:
        raise RuntimeError(f'left ROLLING_UP during the measurement (phase {seq.phase})')
    p50_s, p99_s = np.percentile(t_step, [50, 99]) * 1e6
    p50_b, p99_b = np.percentile(t_base, [50, 99]) * 1e6
    return {'steps': n, 'step_p50_us': round(p50_s, 2), 'step_p99_us': round(p99_s, 2),
            'baseline_p50_us': round(p50_b, 2), 'baseline_p99_us': round(p99_b, 2),
            'step_over_baseline_p50': round(p50_s / p50_b, 2)}


def _latency(seconds: float) -> dict:
    from rclpy.action import ActionClient
    from sensor_msgs.msg import JointState
    from spcm_plant import SyntheticHand

    from dam_common.config import load_config
    from dam_interfaces.action import DamGrasp
    from dam_interfaces.msg import HandCommand
    from dam_spcm_controller.commands import HandLayout, JointCommand, JointMode

    core_mode = {HandCommand.MODE_TORQUE: JointMode.TORQUE,
                 HandCommand.MODE_POSITION: JointMode.POSITION,
                 HandCommand.MODE_HOLD: JointMode.HOLD,
                 HandCommand.MODE_IMPEDANCE: JointMode.IMPEDANCE}
    layout = HandLayout.from_hand_config(load_config().hand)
    names = list(layout.joint_names)
    hand = SyntheticHand(layout, b=0.1)
    state = {'cmd': JointCommand(np.full(9, JointMode.HOLD, dtype=np.int8), hand.q.copy()),
             'last': time.monotonic()}
    sent: dict[tuple[int, int], float] = {}
    latencies: list[float] = []
    command = [str(installed_executable('dam_spcm_controller', 'spcm_controller')),
               '--ros-args', '-p', 'check_lift_timeout:=0.0',
               '-p', f'trajectory_duration:={seconds + 5.0:.1f}',
               '-p', f'phase_timeout:={seconds + 20.0:.1f}', '-p', 'approach_speed:=0.5']
    with node_process(command):
        client = RosClient()
        node = client.node
        try:
            pub = node.create_publisher(JointState, '/joint_states', 10)

            def on_command(msg: HandCommand) -> None:
                now = time.perf_counter()
                key = (msg.header.stamp.sec, msg.header.stamp.nanosec)
                if key in sent:
                    latencies.append(now - sent.pop(key))
                index = layout.index_of(list(msg.name))
                modes = np.array([core_mode[int(m)] for m in msg.mode], dtype=np.int8)[index]
                gains = {}
                if len(msg.stiffness):  # IMPEDANCE joints: the plant plays the device's law
                    gains = {'stiffness': np.asarray(msg.stiffness)[index],
                             'damping': np.asarray(msg.damping)[index]}
                state['cmd'] = JointCommand(modes, np.asarray(msg.setpoint)[index], **gains)

            def on_timer() -> None:
                now = time.monotonic()
                elapsed = min(now - state['last'], 0.05)
                state['last'] = now
                steps = max(1, int(round(elapsed / 1e-3)))
                for _ in range(steps):
                    hand.apply(state['cmd'], elapsed / steps)
                msg = JointState(name=names, position=hand.q.tolist(),
                                 velocity=hand.qd.tolist(), effort=hand.effort.tolist())
                msg.header.stamp = node.get_clock().now().to_msg()
                sent[(msg.header.stamp.sec, msg.header.stamp.nanosec)] = time.perf_counter()
                pub.publish(msg)
                if len(sent) > 5000:
                    sent.clear()

            node.create_subscription(HandCommand, '/hand/command', on_command, 100)
            node.create_timer(PERIOD, on_timer)
            action = ActionClient(node, DamGrasp, '/dam_grasp')
            if not action.wait_for_server(timeout_sec=30.0):
                raise RuntimeError('/dam_grasp did not appear')
            client.spin_until(lambda: False, 1.0)
            goal = DamGrasp.Goal(k_theta=[7.0], delta_theta_p=[math.radians(10.0)])
            future = action.send_goal_async(goal)
            if not client.spin_until(future.done, 10.0) or not future.result().accepted:
                raise RuntimeError('grasp goal not accepted')
            client.spin_until(lambda: False, 1.0)  # approach; then measure
            latencies.clear()
            t0 = time.monotonic()
            client.spin_until(lambda: False, seconds)
            wall = time.monotonic() - t0
            cancel = future.result().cancel_goal_async()
            client.spin_until(cancel.done, 5.0)
            action.destroy()
        finally:
            client.close()
    lat = np.asarray(latencies) * 1e3
    if lat.size == 0:
        raise RuntimeError('no command answered a joint state')
    return {'commands_matched': int(lat.size),
            'command_rate_hz': round(lat.size / wall, 1),
            'latency_p50_ms': round(float(np.percentile(lat, 50)), 3),
            'latency_p99_ms': round(float(np.percentile(lat, 99)), 3),
            'latency_max_ms': round(float(lat.max()), 3)}


def run(args) -> dict:
    report = _compute(2000 if args.quick else 20000)
    report.update(_latency(3.0 if args.quick else 10.0))
    report['target'] = 'step p99 < 200 us and joint_states->hand/command latency p99 < 2 ms'
    report['target_met'] = bool(report['step_p99_us'] < 200.0
                                and report['latency_p99_ms'] < 2.0)
    return report
