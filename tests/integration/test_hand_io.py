"""Hand I/O end to end: the driver and its simulated stand-in as real processes, real UDP
link, real DDS. The driver (backend auto) finds no device and starts the stand-in itself.

Timing asserts are deliberately loose (a loaded 2-core machine); bench/ holds the rate targets.
"""

from __future__ import annotations

import math
import os
import signal
import socket
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
import yaml

from ros_testing import (
    RosClient,
    free_udp_ports,
    installed_executable,
    node_process,
    process_gone,
    thread_policies,
)

# Real-time runs on a shared 2-core machine: a test that fails is run once more (the rerun is
# reported as R in pytest's summary); a deterministic failure fails twice.
pytestmark = [pytest.mark.integration, pytest.mark.flaky(reruns=1)]

REPO_ROOT = Path(__file__).resolve().parents[2]
FINGER = 'finger1'


class _Observer:
    """Subscribes to /joint_states and /diagnostics, and publishes /hand/command."""

    def __init__(self) -> None:
        from diagnostic_msgs.msg import DiagnosticArray
        from sensor_msgs.msg import JointState

        from dam_interfaces.msg import HandCommand

        self.client = RosClient()
        node = self.client.node
        self.joint_states: list[tuple[float, JointState]] = []
        self.diagnostics: list[DiagnosticArray] = []
        node.create_subscription(JointState, '/joint_states',
                                 lambda m: self.joint_states.append((time.monotonic(), m)), 200)
        node.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append, 10)
        self.command_pub = node.create_publisher(HandCommand, '/hand/command', 10)

    def spin(self, seconds: float) -> None:
        self.client.spin_until(lambda: False, seconds)

    def latest(self) -> dict[str, tuple[float, float, float]]:
        msg = self.joint_states[-1][1]
        return {n: (p, v, e) for n, p, v, e in zip(msg.name, msg.position, msg.velocity,
                                                   msg.effort, strict=True)}

    def diag_values(self) -> dict[str, str]:
        status = self.diagnostics[-1].status[0]
        return {kv.key: kv.value for kv in status.values}

    def command(self, names: list[str], modes: list[int], setpoints: list[float],
                stiffness: list[float] | None = None, damping: list[float] | None = None
                ) -> None:
        from dam_interfaces.msg import HandCommand

        msg = HandCommand(name=names, mode=modes, setpoint=setpoints,
                          stiffness=stiffness or [], damping=damping or [])
        for _ in range(3):  # volatile QoS: repeat so that a late-matched publisher still lands
            self.command_pub.publish(msg)
            self.spin(0.05)


@pytest.fixture(scope='module')
def config_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    data = yaml.safe_load((REPO_ROOT / 'config' / 'dam.yaml').read_text(encoding='utf-8'))
    state_port, command_port = free_udp_ports(2)
    data['device']['state_port'] = state_port
    data['device']['command_port'] = command_port
    path = tmp_path_factory.mktemp('hand_io') / 'dam.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


@pytest.fixture(scope='module')
def cfg(config_file: Path):
    from dam_common.config import load_config

    return load_config(config_file)


@pytest.fixture(scope='module')
def system(config_file: Path) -> Iterator[tuple[object, _Observer]]:
    env = {'DAM_CONFIG': str(config_file)}
    with node_process([installed_executable('dam_hand_driver', 'hand_driver'),
                       '--ros-args', '-p', 'backend:=auto'], env=env) as driver:
        observer = _Observer()
        try:
            ok = observer.client.spin_until(lambda: len(observer.joint_states) > 50, 30.0)
            assert ok, driver.output()
            yield driver, observer
        finally:
            observer.client.close()


def test_robot_description_is_latched_for_late_subscribers(system, cfg) -> None:
    """A subscriber that comes after the driver published (transient local, as RViz and
    robot_state_publisher's consumers ask) still gets the URDF, with the configured joints."""
    from xml.etree import ElementTree as ET

    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import String

    _driver, obs = system
    got: list[str] = []
    qos = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                     reliability=ReliabilityPolicy.RELIABLE)
    sub = obs.client.node.create_subscription(String, '/robot_description',
                                              lambda m: got.append(m.data), qos)
    try:
        assert obs.client.spin_until(lambda: bool(got), 10.0), 'no /robot_description'
    finally:
        obs.client.node.destroy_subscription(sub)
    robot = ET.fromstring(got[0])
    joints = {j.get('name') for j in robot.findall('joint') if j.get('type') == 'revolute'}
    assert joints == set(cfg.hand.joint_names)


def test_joint_states_rate_and_simulator_backend(system, cfg) -> None:
    driver, obs = system
    obs.joint_states.clear()
    obs.spin(2.0)
    stamps = np.array([t for t, _ in obs.joint_states])
    rate = (len(stamps) - 1) / (stamps[-1] - stamps[0])
    assert 0.5 * cfg.device.rate_hz < rate < 1.3 * cfg.device.rate_hz, rate
    assert list(obs.joint_states[-1][1].name) == list(cfg.hand.joint_names)
    assert 'RUNNING ON THE SIMULATOR' in driver.output()
    assert obs.client.spin_until(lambda: bool(obs.diagnostics), 3.0)
    values = obs.diag_values()
    assert values['state'] == 'ACTIVE'
    assert values['standin_pid'].isdigit()
    assert int(values['frames_accepted']) > 0


def _fifo_threads(pid: int) -> list[int]:
    """Real-time priorities of the SCHED_FIFO threads of process ``pid``."""
    return [priority for policy, priority in thread_policies(pid) if policy == 1]


@pytest.mark.skipif(not os.path.isdir('/proc'), reason='reads /proc')
def test_nothing_runs_real_time_with_the_stand_in(system) -> None:
    """A simulation has no physical deadline: with the stand-in no thread of the driver or
    of the stand-in runs SCHED_FIFO (default thread_priority 50 is for a real hand's
    device-link thread), and the diagnostics say why."""
    driver, obs = system
    obs.diagnostics.clear()
    assert obs.client.spin_until(lambda: bool(obs.diagnostics), 3.0)
    values = obs.diag_values()
    assert values['link_thread_scheduling'] == 'normal (simulated device: no physical deadline)'
    standin = int(values['standin_pid'])
    for pid in (driver.pid, standin):
        assert _fifo_threads(pid) == [], (pid, thread_policies(pid))


def _gravity_torques(cfg, angles: np.ndarray) -> np.ndarray:
    """Static joint torques [N*m] holding one finger against gravity (closed form)."""
    lengths = np.asarray(cfg.hand.link_lengths_m)
    masses = np.asarray(cfg.hand.link_masses_kg)
    g = cfg.task.gravity_m_per_s2
    phi = np.cumsum(angles)  # link directions from straight down, positive inward
    joints_x = np.concatenate([[0.0], np.cumsum(lengths * np.sin(phi))])
    com_x = joints_x[:3] + 0.5 * lengths * np.sin(phi)
    return np.array([g * np.sum(masses[i:] * (com_x[i:] - joints_x[i])) for i in range(3)])


def test_gravity_torques_of_a_finger_with_a_horizontal_distal_link(system, cfg) -> None:
    _, obs = system
    from dam_interfaces.msg import HandCommand

    angles = np.radians([60.0, 0.0, 30.0])  # the distal link points horizontally inward
    names = [f'{FINGER}_{role}_joint' for role in cfg.hand.joint_roles]
    obs.command(names, [HandCommand.MODE_POSITION] * 3, angles.tolist())
    obs.spin(1.5)
    state = obs.latest()
    measured_q = np.array([state[n][0] for n in names])
    measured_tau = np.array([state[n][2] for n in names])
    assert measured_q == pytest.approx(angles, abs=math.radians(1.0))
    expected = _gravity_torques(cfg, measured_q)
    # distal joint: m3 g L3 / 2 exactly, for a horizontal link
    m3, l3 = cfg.hand.link_masses_kg[2], cfg.hand.link_lengths_m[2]
    assert expected[2] == pytest.approx(m3 * cfg.task.gravity_m_per_s2 * l3 / 2, rel=0.02)
    assert measured_tau == pytest.approx(expected, rel=0.05, abs=2e-4)


def test_torque_command_flexes_a_compliant_joint(system, cfg) -> None:
    _, obs = system
    from dam_interfaces.msg import HandCommand

    joint = 'finger2_compliant_joint'
    q0 = obs.latest()[joint][0]
    obs.command([joint], [HandCommand.MODE_TORQUE], [0.02])
    obs.spin(0.5)
    q1, _, tau1 = obs.latest()[joint]
    assert q1 > q0 + math.radians(5.0), (q0, q1)
    obs.command([joint], [HandCommand.MODE_TORQUE], [-0.02])
    obs.spin(0.8)
    q2, _, tau2 = obs.latest()[joint]
    assert q2 < q1 - math.radians(5.0), (q1, q2)
    assert tau2 == pytest.approx(-0.02, abs=1e-3)
    obs.command([joint], [HandCommand.MODE_HOLD], [0.0])


def _straight_finger_equilibrium(cfg, theta_0: float, k: float) -> float:
    """Angle [rad] of a straight finger (locked and position joints at 0) whose compliant
    joint has the impedance k (theta_0 - theta): k (theta_0 - theta) = g sin(theta) sum m_i r_i,
    r_i the distance of link i's centre from the compliant joint; solved by bisection."""
    lengths = np.asarray(cfg.hand.link_lengths_m)
    masses = np.asarray(cfg.hand.link_masses_kg)
    moment = cfg.task.gravity_m_per_s2 * float(masses @ (np.cumsum(lengths) - lengths / 2))
    lo, hi = -math.pi / 2, math.pi / 2
    for _ in range(80):
        mid = 0.5 * (lo + hi)
        if k * (theta_0 - mid) - moment * math.sin(mid) > 0.0:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def test_impedance_command_settles_where_stiffness_balances_gravity(system, cfg) -> None:
    """Finger 2 straight and tilted outward (away from the object) to -15 deg, then its
    compliant joint in MODE_IMPEDANCE with theta_0 = -20 deg and a soft k: the device's law
    lets gravity pull the finger back to where k (theta_0 - theta) balances it."""
    driver, obs = system
    from dam_interfaces.msg import HandCommand

    names = [f'finger2_{role}_joint' for role in cfg.hand.joint_roles]
    start = math.radians(-15.0)
    obs.command(names, [HandCommand.MODE_POSITION] * 3, [start, 0.0, 0.0])
    obs.spin(1.0)
    assert obs.latest()[names[0]][0] == pytest.approx(start, abs=math.radians(1.0))
    theta_0, k, d = math.radians(-20.0), 0.1, 0.03
    expected = _straight_finger_equilibrium(cfg, theta_0, k)
    assert abs(expected - theta_0) > math.radians(2.0)  # gravity matters at this stiffness
    obs.command(names, [HandCommand.MODE_IMPEDANCE, HandCommand.MODE_POSITION,
                        HandCommand.MODE_POSITION], [theta_0, 0.0, 0.0], [k, 0.0, 0.0],
                [d, 0.0, 0.0])
    obs.spin(3.0)
    q, qd, tau = obs.latest()[names[0]]
    assert q == pytest.approx(expected, abs=math.radians(0.5)), (math.degrees(q),
                                                                math.degrees(expected))
    assert abs(qd) < 0.01
    # the torque sensor shows the device's impedance torque, which now holds gravity
    assert tau == pytest.approx(k * (theta_0 - q), abs=2e-3)
    assert 'rejected' not in driver.output()

    # Bad impedance commands: rejected with the field and value named; the joint stays put.
    bad = [([], [], [theta_0]),  # MODE_IMPEDANCE without gains
           ([-1.0], [0.1], [theta_0]),
           ([cfg.device.max_stiffness_nm_per_rad * 2], [0.1], [theta_0]),
           ([1.0], [-0.5], [theta_0]),
           ([1.0], [float('nan')], [theta_0]),
           ([1.0], [0.1], [math.radians(80.0)])]
    obs.diagnostics.clear()
    assert obs.client.spin_until(lambda: bool(obs.diagnostics), 3.0)
    rejected_before = int(obs.diag_values()['hand_commands_rejected'])
    obs.command([names[0]], [HandCommand.MODE_IMPEDANCE], [theta_0])  # no gains at all
    obs.spin(1.1)  # the driver's rejection log is throttled to one a second
    for stiffness, damping, setpoint in bad[1:]:
        obs.command([names[0]], [HandCommand.MODE_IMPEDANCE], setpoint, stiffness, damping)
        obs.spin(1.1)  # the driver's rejection log is throttled to one a second
    obs.diagnostics.clear()
    assert obs.client.spin_until(lambda: bool(obs.diagnostics), 3.0)
    assert int(obs.diag_values()['hand_commands_rejected']) >= rejected_before + len(bad)
    assert driver.alive()
    out = driver.output()
    assert 'stiffness -1.0 N*m/rad is outside' in out
    assert 'damping -0.5 N*m*s/rad is outside' in out
    assert 'equilibrium theta_0' in out
    assert 'MODE_IMPEDANCE needs stiffness and damping' in out
    assert obs.latest()[names[0]][0] == pytest.approx(expected, abs=math.radians(0.5))
    obs.command(names, [HandCommand.MODE_HOLD] * 3, [0.0] * 3)


def test_bad_commands_are_rejected_and_the_driver_stays_up(system, cfg) -> None:
    driver, obs = system
    from dam_interfaces.msg import HandCommand

    joint = 'finger3_compliant_joint'
    q0 = obs.latest()[joint][0]
    obs.command(['no_such_joint'], [HandCommand.MODE_TORQUE], [0.01])
    obs.command([joint, joint], [HandCommand.MODE_TORQUE] * 2, [0.01, 0.01])
    obs.command([joint], [HandCommand.MODE_TORQUE], [float('nan')])
    obs.command([joint], [HandCommand.MODE_TORQUE], [5.0 * cfg.device.torque_limit_nm])
    obs.command([joint], [HandCommand.MODE_POSITION, HandCommand.MODE_HOLD], [0.1])
    obs.diagnostics.clear()
    assert obs.client.spin_until(lambda: bool(obs.diagnostics), 3.0)
    assert int(obs.diag_values()['hand_commands_rejected']) >= 5
    assert driver.alive()
    assert obs.latest()[joint][0] == pytest.approx(q0, abs=math.radians(1.0))
    out = driver.output()
    assert 'no_such_joint' in out


def test_killing_the_standin_puts_the_driver_in_error(system, cfg) -> None:
    from diagnostic_msgs.msg import DiagnosticStatus

    driver, obs = system
    obs.diagnostics.clear()
    assert obs.client.spin_until(lambda: bool(obs.diagnostics), 3.0)
    pid = int(obs.diag_values()['standin_pid'])
    os.kill(pid, signal.SIGKILL)  # the stand-in the driver started for this test
    killed = time.monotonic()
    obs.diagnostics.clear()
    assert obs.client.spin_until(
        lambda: bool(obs.diagnostics)
        and obs.diagnostics[-1].status[0].level == DiagnosticStatus.ERROR, 5.0), \
        driver.output()
    assert obs.diag_values()['state'] == 'ERROR'
    # /joint_states stopped within the state timeout (plus delivery slack)
    last_js = obs.joint_states[-1][0]
    assert last_js - killed < cfg.device.state_timeout_s + 0.5
    count = len(obs.joint_states)
    obs.spin(0.5)
    assert len(obs.joint_states) == count
    assert 'ERROR: no state frame' in driver.output()
    # Without a device, ~/reset cannot recover.
    from std_srvs.srv import Trigger

    response = obs.client.call(Trigger, '/hand_driver/reset', Trigger.Request())
    assert response.success is False
    assert driver.alive()


# --- Stand-in started by hand, driver with backend hardware, recovery through ~/reset -------
# Everything is remapped under /hw so that it cannot mix with the processes above.

_HW_REMAPS = ['-r', '/joint_states:=/hw/joint_states', '-r', '/diagnostics:=/hw/diagnostics',
              '-r', '/sim/object_pose:=/hw/object_pose', '-r', '/clock:=/hw/clock']


def _sim_command() -> list[str]:
    return [str(installed_executable('dam_sim_bridge', 'sim_bridge')), '--ros-args',
            '-r', '__node:=hw_sim', '-p', 'publish_clock:=true', *_HW_REMAPS]


def test_sim_bridge_services_and_driver_recovery(tmp_path: Path, cfg) -> None:
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import PoseStamped
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import JointState
    from std_srvs.srv import Trigger

    from dam_interfaces.srv import SetFrictionAngle

    data = yaml.safe_load((REPO_ROOT / 'config' / 'dam.yaml').read_text(encoding='utf-8'))
    data['device']['state_port'], data['device']['command_port'] = free_udp_ports(2)
    config_file = tmp_path / 'dam.yaml'
    config_file.write_text(yaml.safe_dump(data), encoding='utf-8')
    env = {'DAM_CONFIG': str(config_file)}
    client = RosClient()
    poses: list[PoseStamped] = []
    clocks: list[Clock] = []
    states: list[JointState] = []
    diags: list[DiagnosticArray] = []
    node = client.node
    node.create_subscription(PoseStamped, '/hw/object_pose', poses.append, 50)
    node.create_subscription(Clock, '/hw/clock', clocks.append, 50)
    node.create_subscription(JointState, '/hw/joint_states', states.append, 200)
    node.create_subscription(DiagnosticArray, '/hw/diagnostics', diags.append, 10)
    try:
        with node_process(_sim_command(), env=env) as sim:
            assert client.spin_until(lambda: len(poses) > 20 and len(clocks) > 20, 20.0), \
                sim.output()
            assert poses[-1].header.frame_id == 'world'
            z = poses[-1].pose.position.z
            assert z == pytest.approx(cfg.object.radius_m, abs=0.01)  # lies on the table
            t0 = clocks[0].clock.sec + 1e-9 * clocks[0].clock.nanosec
            t1 = clocks[-1].clock.sec + 1e-9 * clocks[-1].clock.nanosec
            assert t1 > t0
            bad = client.call(SetFrictionAngle, '/hw_sim/set_friction_angle',
                              SetFrictionAngle.Request(friction_angle=2.0))
            assert bad.success is False and '2.0' in bad.message
            good = client.call(SetFrictionAngle, '/hw_sim/set_friction_angle',
                               SetFrictionAngle.Request(friction_angle=0.3))
            assert good.success is True
            reset = client.call(Trigger, '/hw_sim/reset', Trigger.Request())
            assert reset.success is True
            clocks.clear()
            assert client.spin_until(lambda: bool(clocks), 5.0)
            assert clocks[-1].clock.sec < 2  # simulated time restarted from zero

            with node_process([installed_executable('dam_hand_driver', 'hand_driver'),
                               '--ros-args', '-r', '__node:=hw_driver', '-p',
                               'backend:=hardware', *_HW_REMAPS], env=env) as driver:
                assert client.spin_until(lambda: len(states) > 50, 20.0), driver.output()
                assert 'RUNNING ON THE SIMULATOR' not in driver.output()
                assert sim.stop() == 0  # the device goes away ...
                diags.clear()
                assert client.spin_until(
                    lambda: bool(diags)
                    and diags[-1].status[0].level == DiagnosticStatus.ERROR, 5.0)
                # ... and comes back: a new stand-in, then ~/reset
                with node_process(_sim_command(), env=env):
                    client.spin_until(lambda: False, 0.5)  # take what was queued before
                    states.clear()
                    client.spin_until(lambda: False, 2.0)
                    assert not states  # still in ERROR: no recovery without ~/reset
                    response = client.call(Trigger, '/hw_driver/reset', Trigger.Request(),
                                           wait=10.0)
                    assert response.success is True, response.message
                    assert client.spin_until(lambda: len(states) > 20, 5.0)
                assert driver.alive()
    finally:
        client.close()


@pytest.mark.skipif(not os.path.isdir('/proc'), reason='reads /proc')
def test_a_killed_driver_takes_its_standin_with_it(tmp_path: Path) -> None:
    from diagnostic_msgs.msg import DiagnosticArray

    data = yaml.safe_load((REPO_ROOT / 'config' / 'dam.yaml').read_text(encoding='utf-8'))
    data['device']['state_port'], data['device']['command_port'] = free_udp_ports(2)
    config_file = tmp_path / 'dam.yaml'
    config_file.write_text(yaml.safe_dump(data), encoding='utf-8')
    client = RosClient()
    diags: list[DiagnosticArray] = []
    client.node.create_subscription(DiagnosticArray, '/kill/diagnostics', diags.append, 10)
    try:
        with node_process([installed_executable('dam_hand_driver', 'hand_driver'),
                           '--ros-args', '-r', '__node:=kill_driver', '-p', 'backend:=sim',
                           '-r', '/diagnostics:=/kill/diagnostics', '-r',
                           '/joint_states:=/kill/joint_states'],
                          env={'DAM_CONFIG': str(config_file)}) as driver:
            assert client.spin_until(lambda: bool(diags), 30.0), driver.output()
            values = {kv.key: kv.value for kv in diags[-1].status[0].values}
            standin = int(values['standin_pid'])
            assert not process_gone(standin)
            os.kill(driver.pid, signal.SIGKILL)  # no chance to stop its child itself
            deadline = time.monotonic() + 10.0
            while time.monotonic() < deadline and not process_gone(standin):
                time.sleep(0.05)
            gone = process_gone(standin)
            if not gone:
                os.kill(standin, signal.SIGKILL)  # do not leave it behind
            assert gone, 'the stand-in outlived its driver'
    finally:
        client.close()


# --- The torque slew limit, frame by frame ----------------------------------------------------
# The stand-in started by hand sends its state frames to a tap in this process, which forwards
# each one to the driver (backend hardware) at once and notes its sequence number: every
# /joint_states message can then be placed exactly in the device's frame sequence, although
# the driver publishes only the newest of the frames that arrived while it was busy.

#: Allowance for torque-sensor noise in the frame-to-frame effort check [N*m]. The stand-in
#: reports the torque it applied, quantised to 1e-5 N*m; a real joint torque sensor is noisier.
EFFORT_NOISE_NM = 1e-3

_TAP_REMAPS = ['-r', '/joint_states:=/tap/joint_states', '-r', '/hand/command:=/tap/command',
               '-r', '/diagnostics:=/tap/diagnostics', '-r', '/sim/object_pose:=/tap/pose']


class _StateTap:
    """Forwards state datagrams from ``listen_port`` to ``forward_port`` (loopback) and keeps
    ``(seq, state in SI)`` of every valid state frame."""

    def __init__(self, cfg, listen_port: int, forward_port: int) -> None:
        from dam_common.device_protocol import Calibration, FrameDecoder, FrameKind

        self.calibration = Calibration.from_config(cfg)
        self.decoder = FrameDecoder(FrameKind.STATE, len(cfg.hand.joint_names))
        self.frames: list[tuple[int, np.ndarray, np.ndarray]] = []
        self._forward = ('127.0.0.1', forward_port)
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._sock.bind(('127.0.0.1', listen_port))
        self._sock.settimeout(0.1)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        while not self._stop.is_set():
            try:
                data = self._sock.recv(2048)
            except OSError:  # timeout, or closed
                continue
            self._sock.sendto(data, self._forward)
            frame = self.decoder.decode(data)
            if frame is not None:
                q, _, tau = self.calibration.state_si(frame)
                self.frames.append((frame.seq, q, tau))

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self._sock.close()


def _frame_numbers(frames: list[tuple[int, np.ndarray, np.ndarray]], messages: list
                   ) -> np.ndarray:
    """The device frame (seq) each /joint_states message was made from, increasing: the
    latest frame with the message's positions and efforts (bitwise) that lies before the
    frame of the next message. Several frames of a joint at rest can share one state; the
    latest of them is the one the next change starts from."""
    by_state: dict[tuple[bytes, bytes], list[int]] = {}
    for seq, q, tau in frames:
        by_state.setdefault((q.tobytes(), tau.tobytes()), []).append(seq)
    out = []
    after = math.inf
    for msg in reversed(messages):
        key = (np.array(msg.position).tobytes(), np.array(msg.effort).tobytes())
        candidates = [seq for seq in by_state[key] if seq < after]
        after = max(candidates)
        out.append(after)
    return np.array(out[::-1])


def test_an_impedance_step_is_slew_limited_frame_by_frame(tmp_path: Path, cfg) -> None:
    """The issue's command: MODE_IMPEDANCE with theta_0 0.675 rad from the measured angle and
    k_theta 10 (6.75 N*m demanded; it used to jump from 0 to the 1 N*m limit within one frame).
    In /joint_states the effort of that joint changes from one state frame to the next by at
    most device.torque_rate_limit_nm_per_s / device.rate_hz (plus EFFORT_NOISE_NM; n times
    that where the driver skipped n - 1 frames), and the joint still reaches theta_0."""
    from sensor_msgs.msg import JointState

    from dam_interfaces.msg import HandCommand

    data = yaml.safe_load((REPO_ROOT / 'config' / 'dam.yaml').read_text(encoding='utf-8'))
    tap_port, driver_port, command_port = free_udp_ports(3)
    data['device']['command_port'] = command_port
    data['device']['state_port'] = tap_port
    sim_config = tmp_path / 'sim.yaml'
    sim_config.write_text(yaml.safe_dump(data), encoding='utf-8')
    data['device']['state_port'] = driver_port
    driver_config = tmp_path / 'driver.yaml'
    driver_config.write_text(yaml.safe_dump(data), encoding='utf-8')
    tap = _StateTap(cfg, tap_port, driver_port)
    client = RosClient()
    received: list[JointState] = []
    client.node.create_subscription(JointState, '/tap/joint_states', received.append, 1000)
    publisher = client.node.create_publisher(HandCommand, '/tap/command', 10)
    names = [f'finger2_{role}_joint' for role in cfg.hand.joint_roles]
    j = list(cfg.hand.joint_names).index(names[0])

    def command(modes: list[int], setpoints: list[float], stiffness: list[float],
                damping: list[float]) -> None:
        msg = HandCommand(name=names, mode=modes, setpoint=setpoints, stiffness=stiffness,
                          damping=damping)
        for _ in range(3):  # volatile QoS: repeat so that a late-matched publisher still lands
            publisher.publish(msg)
            client.spin_until(lambda: False, 0.05)

    def settled_at(angle: float) -> bool:
        if not received:
            return False
        i = list(received[-1].name).index(names[0])
        return (abs(received[-1].position[i] - angle) < math.radians(0.5)
                and abs(received[-1].velocity[i]) < 0.01)

    try:
        with node_process([installed_executable('dam_sim_bridge', 'sim_bridge'), '--ros-args',
                           '-r', '__node:=tap_sim', *_TAP_REMAPS],
                          env={'DAM_CONFIG': str(sim_config)}), \
                node_process([installed_executable('dam_hand_driver', 'hand_driver'),
                              '--ros-args', '-r', '__node:=tap_driver', '-p',
                              'backend:=hardware', *_TAP_REMAPS],
                             env={'DAM_CONFIG': str(driver_config)}) as driver:
            assert client.spin_until(lambda: len(received) > 50, 30.0), driver.output()
            # finger 2 with its distal link curled in: it swings above the object
            posture = [math.radians(-30.0), 0.0, math.radians(90.0)]
            command([HandCommand.MODE_POSITION] * 3, posture, [], [])
            assert client.spin_until(lambda: settled_at(posture[0]), 10.0), driver.output()
            client.spin_until(lambda: False, 0.2)
            theta_0 = received[-1].position[j] + 0.675
            k, d = 10.0, cfg.controller.damping_nms_per_rad
            assert k * 0.675 > cfg.device.torque_limit_nm
            received.clear()
            command([HandCommand.MODE_IMPEDANCE, HandCommand.MODE_POSITION,
                     HandCommand.MODE_POSITION], [theta_0, *posture[1:]], [k, 0.0, 0.0],
                    [d, 0.0, 0.0])
            # theta_0 is approached at rate / k (2 rad/s): 0.34 s of device time
            reached = client.spin_until(lambda: settled_at(theta_0), 10.0)
            client.spin_until(lambda: False, 0.2)
    finally:
        client.close()
        tap.close()
    seqs = _frame_numbers(tap.frames, received)
    efforts = np.array([m.effort[j] for m in received])
    angles = np.array([m.position[j] for m in received])
    step = cfg.device.torque_rate_limit_nm_per_s / cfg.device.rate_hz
    gaps = np.diff(seqs)
    allowed = step * gaps + EFFORT_NOISE_NM
    changes = np.abs(np.diff(efforts))
    worst = int(np.argmax(changes - allowed))
    assert np.all(changes <= allowed), (
        f'effort changed by {changes[worst]:.4f} N*m from frame {seqs[worst]} to frame '
        f'{seqs[worst + 1]} (allowed {allowed[worst]:.4f} N*m); efforts '
        f'{np.round(efforts[:40], 4).tolist()}')
    assert np.mean(gaps == 1) > 0.5  # mostly consecutive frames: the check is frame by frame
    # The device's own frames, every one of them, obey the bound as well.
    device_efforts = np.array([tau[j] for seq, _, tau in tap.frames if seq >= seqs[0]])
    assert np.abs(np.diff(device_efforts)).max() <= step + EFFORT_NOISE_NM
    assert changes.max() > 0.5 * step  # the torque did ramp near the limit ...
    assert reached, (theta_0, angles[-1])  # ... and drove the joint to theta_0
