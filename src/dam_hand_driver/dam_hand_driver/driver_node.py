"""``hand_driver``: the ROS 2 driver of the DAM hand.

Run it with ``ros2 run dam_hand_driver hand_driver [--ros-args -p backend:=sim]``. A control
thread exchanges frames with the device (``docs/device_protocol.md``): for every state frame it
publishes ``/joint_states`` and answers with one command frame computed from the newest
``/hand/command``.

Topics
------
/joint_states : sensor_msgs/JointState (published)
    Names from the configuration; positions [rad] and velocities [rad/s] from the encoders,
    efforts [N*m] from the joint torque sensors. Not published in ERROR.
/robot_description : std_msgs/String (published once, transient local)
    The hand's URDF generated from the configuration (:mod:`dam_hand_driver.urdf`), for
    ``robot_state_publisher``, RViz and Foxglove; ``hand_urdf`` prints the same document.
/hand/command : dam_interfaces/HandCommand (subscribed)
    Taken in a thread of its own, outside the node's executor
    (:mod:`dam_common.intake`; the node's remapping rules apply).
    Mode and setpoint per named joint (and, for MODE_IMPEDANCE, stiffness and damping); joints
    not named keep their command. A malformed message (unknown or duplicate name, length
    mismatch, unknown mode, NaN/inf, a torque beyond ``device.torque_limit_nm``, an angle or
    impedance equilibrium beyond the joint limits, a stiffness outside
    (0, ``device.max_stiffness_nm_per_rad``], a damping outside
    [0, ``device.max_damping_nms_per_rad``]) is rejected as a whole with a logged reason naming
    the field and the value (throttled). MODE_IMPEDANCE joints go to the device in its
    IMPEDANCE mode: the device runs the impedance law at its physics rate. Every frame the
    driver moves a TORQUE setpoint by at most ``device.torque_rate_limit_nm_per_s`` times the
    device period and an impedance equilibrium by at most that over the stiffness
    (:mod:`dam_hand_driver.slew`), so that no command steps the torque faster.
/diagnostics : diagnostic_msgs/DiagnosticArray (published, 1 Hz)
    Driver state, backend, achieved rate, frame counts by rejection reason, loop latency,
    device watchdog state; ``joint_states_published`` (joint states published since start)
    with ``joint_states_last_stamp_ns`` (the header stamp of the last one [ns]), so that a
    recording can be checked for completeness.

Services
--------
~/reset : std_srvs/Trigger
    Leave ERROR: the device recovers what it can (the Dynamixel backend opens a failed port
    again, reboots servos in a hardware error, clears tripped watchdogs);
    succeeds when state frames arrive again, and every joint then HOLDs its measured position,
    the slew of later torque commands starting afresh from the measured torques. A failure
    says why, and the driver is then in ERROR with that reason: the answer is the state.

Parameters
----------
config_file : string, read-only
    DAM configuration file; empty: ``DAM_CONFIG`` or the installed ``config/dam.yaml``.
config_overlay : string, read-only
    A YAML file holding part of a configuration, merged over ``config_file`` (e.g. the
    ``dynamixel:`` zero offsets ``dynamixel_setup zero`` wrote); empty: none.
backend : string, read-only, one of auto, hardware, sim, dynamixel
    ``auto`` probes the device for ``device.probe_timeout_s`` and starts the simulated
    stand-in (``dam_sim_bridge sim_bridge``, a child process) when nothing answers;
    ``hardware`` never falls back; ``sim`` always starts the stand-in; ``dynamixel`` drives
    Dynamixel servos on a serial bus (``docs/dynamixel.md``).
port : string, read-only
    ``backend:=dynamixel``: the serial port (empty: ``dynamixel.port``; both empty: the
    emulated bus, started here). The port is opened exclusively: a second driver is refused.
object : string, read-only
    The column object of the configuration's ``object.library`` a stand-in this driver starts
    puts on the table (empty: ``object.default``); a real hand ignores it.
thread_priority : int, read-only, in [0, 99], default 50
    ``SCHED_FIFO`` priority of the device-link thread when the device is a real hand (0:
    normal scheduling). Only that thread asks for it: the executor, the middleware's threads
    and a stand-in keep the normal policy, and with a simulated device nothing of the driver
    runs real-time (a simulation has no physical deadline). Without the permission the node
    warns once and runs on.
use_sim_time : bool, fixed at start-up
    Run on the stand-in's simulated time (``docs/simulation_grasp.md``, "Simulated time"):
    a stand-in this driver starts gets it too; ``/joint_states`` are stamped with the device's
    simulated time; before answering a state frame the driver waits (at most
    ``sim.command_wait_s`` of wall time) for the command that answers the previous joint state
    while a commander streams; the state timeout becomes ``sim.stall_timeout_s`` of wall time,
    and a stand-in child that exits is an ERROR at once. Refused with ``backend:=hardware``
    and when a real hand answers. Clock faults (a ``/clock`` jump, two ``/clock``
    publishers, this node on wall time while ``/clock`` is published) are logged and shown in
    ``/diagnostics`` as the status ``dam_hand_driver: clock`` (``dam_common.clock_watch``).

States
------
WAITING (no state frame yet) -> ACTIVE (on the first state frame: clean start, every joint
HOLDs, the command slew starts afresh) -> ERROR (no state frame for ``device.state_timeout_s``,
with ``use_sim_time`` ``sim.stall_timeout_s`` of wall time or the stand-in child exited:
no more /joint_states, no more command frames, so the device's watchdog takes it to its safe
state; at once for a fault the device names: a hardware error, a tripped servo watchdog, a
port that failed, an exception in the device-link thread) -> ACTIVE only through ``~/reset``.
"""

from __future__ import annotations

import array
import subprocess
import threading
import time
import traceback
from collections import deque

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from dam_common.clock import create_steady_timer
from dam_common.clock_watch import ClockWatch
from dam_common.collector import PERIOD_S as GC_PERIOD_S
from dam_common.config import load_config
from dam_common.device_protocol import JointMode
from dam_common.hand_urdf import hand_urdf
from dam_common.intake import SubscriptionThread
from dam_common.node import (
    STREAM_HISTORY_DEPTH,
    declare_config_file,
    declare_config_overlay,
    declare_object,
    declare_thread_priority,
    run_node,
)
from dam_common.realtime import (
    SWITCH_INTERVAL_S,
    die_with_parent,
    set_thread_priority,
)
from dam_common.service_qos import SERVICE_QOS
from dam_common.shutdown import SHUTDOWN
from dam_hand_driver.command_check import (
    WIRE_MODES,
    CommandItem,
    CommandRejected,
    check_joint_commands,
)
from dam_hand_driver.device import HandDevice, JointSample
from dam_hand_driver.dynamixel_device import DynamixelDevice
from dam_hand_driver.errors import HandDriverError
from dam_hand_driver.link_health import (
    DriverState,
    Level,
    RateWindow,
    latency_summary_us,
    link_status,
)
from dam_hand_driver.slew import CommandSlew
from dam_hand_driver.standin import START_TIMEOUT_S as STANDIN_START_TIMEOUT_S
from dam_hand_driver.standin import (
    await_port_file,
    new_port_file,
    signal_standin,
    standin_command,
    standin_executable,
    stop_standin,
)
from dam_hand_driver.udp_device import UdpDevice
from dam_interfaces.msg import HandCommand

BACKENDS = ('auto', 'hardware', 'sim', 'dynamixel')
#: HandCommand mode -> wire protocol mode (:data:`dam_hand_driver.command_check.WIRE_MODES`).
MSG_TO_WIRE_MODE: dict[int, JointMode] = WIRE_MODES
_LOG_THROTTLE_S = 1.0
#: On simulated time, the newest command is sent again after this much wall time without a
#: state frame (twice the stand-in's own resend period) [s].
_RESEND_AFTER_S = 2.0 * 0.1
#: :class:`~dam_hand_driver.link_health.Level` -> ``DiagnosticStatus`` level.
_DIAGNOSTIC_LEVELS = {Level.OK: DiagnosticStatus.OK, Level.WARN: DiagnosticStatus.WARN,
                      Level.ERROR: DiagnosticStatus.ERROR}


def validate_command(msg: HandCommand, index: dict[str, int], torque_limit_nm: float,
                     lower_rad: np.ndarray, upper_rad: np.ndarray,
                     max_stiffness_nm_per_rad: float, max_damping_nms_per_rad: float
                     ) -> list[CommandItem]:
    """Check a HandCommand and turn it into one :class:`CommandItem` per named joint
    (:func:`dam_hand_driver.command_check.check_joint_commands`, whose parameters follow
    ``msg``).

    Raises
    ------
    CommandRejected
        The message is malformed; the reason names the field and the value.
    """
    return check_joint_commands(list(msg.name), list(msg.mode), list(msg.setpoint),
                                list(msg.stiffness), list(msg.damping), index,
                                torque_limit_nm, lower_rad, upper_rad,
                                max_stiffness_nm_per_rad, max_damping_nms_per_rad)



class HandDriverNode(Node):
    """Device link, /joint_states, /hand/command, /diagnostics, backend selection.

    Raises
    ------
    DamAnalysisError
        The configuration cannot be read.
    HandDriverError
        A bad parameter (backend) or the stand-in could not be started.
    OSError
        The state port is in use.
    """

    def __init__(self) -> None:
        super().__init__('hand_driver')
        config_file = declare_config_file(self)
        self._overlays = declare_config_overlay(self)
        self.backend = str(self.declare_parameter(
            'backend', 'auto', ParameterDescriptor(
                description='auto: probe the UDP device link, else start the simulator; '
                            'hardware: never fall back; sim: always start the simulator; '
                            'dynamixel: Dynamixel servos on a serial bus (port, or the '
                            'emulated bus when no port is configured)',
                additional_constraints='one of auto, hardware, sim, dynamixel',
                read_only=True)).value)
        if self.backend not in BACKENDS:
            raise HandDriverError(f'backend {self.backend!r} is not one of {BACKENDS}')
        self._port = str(self.declare_parameter(
            'port', '', ParameterDescriptor(
                description='backend dynamixel: the serial port of the bus (empty: '
                            'dynamixel.port of the configuration; both empty: start the '
                            'emulated bus)', read_only=True)).value)
        self.thread_priority = declare_thread_priority(self)
        self._gui = bool(self.declare_parameter(
            'gui', False, ParameterDescriptor(
                description='open the PyBullet window of a stand-in this driver starts (needs '
                            'a display)', read_only=True)).value)
        self._scheduling = 'not started'
        self._sim_time = bool(self.get_parameter('use_sim_time').value)
        if self._sim_time and self.backend == 'hardware':
            raise HandDriverError('use_sim_time:=true runs on the stand-in\'s clock; '
                                  'backend:=hardware drives a real hand in real time')
        #: The device is the simulated stand-in (started here, or it said so when probed).
        self._simulated_device = self.backend == 'sim'
        self.config = declare_object(self, load_config(config_file or None, self._overlays))
        dev = self.config.device
        hand = self.config.hand
        self.joint_names = list(hand.joint_names)
        self.n = len(self.joint_names)
        self._index = {name: j for j, name in enumerate(self.joint_names)}
        roles = [r for _ in hand.fingers for r in hand.joint_roles]
        self._lower = np.array([hand.joint_limits_rad[r][0] for r in roles])
        self._upper = np.array([hand.joint_limits_rad[r][1] for r in roles])
        if self.backend == 'dynamixel':
            if self.config.dynamixel is None:
                raise HandDriverError(
                    f'backend dynamixel needs the dynamixel: section in the configuration '
                    f'({self.config.source}); see docs/dynamixel.md')
            self._port = self._port or self.config.dynamixel.port
            if self._sim_time and self._port:
                raise HandDriverError(
                    f'use_sim_time:=true runs on the emulated bus\'s clock, which the driver '
                    f'starts itself when no port is configured; port {self._port!r} is a real '
                    f'bus: start the driver without use_sim_time')
            self.period_s = 1.0 / float(self.config.dynamixel.rate_hz)
        else:
            self.period_s = 1.0 / float(dev.rate_hz)
        self.state_timeout_s = float(dev.state_timeout_s)
        #: The silence of the device that is an ERROR [s of wall time].
        self._silence_timeout_s = (float(self.config.sim.stall_timeout_s) if self._sim_time
                                   else self.state_timeout_s)
        self._command_wait_s = float(self.config.sim.command_wait_s)
        self.torque_limit_nm = float(dev.torque_limit_nm)
        self.slew = CommandSlew(self.n, self.torque_limit_nm,
                                float(dev.torque_rate_limit_nm_per_s), self.period_s)
        self.max_stiffness = float(dev.max_stiffness_nm_per_rad)
        self.max_damping = float(dev.max_damping_nms_per_rad)
        #: The backend (set by :meth:`_select_backend`).
        self.device: HandDevice | None = None

        self._lock = threading.Lock()
        self._modes = np.full(self.n, int(JointMode.HOLD), dtype=np.int64)
        self._setpoints = np.zeros(self.n)
        self._stiffness = np.zeros(self.n)
        self._damping = np.zeros(self.n)
        self.state = DriverState.WAITING
        self._error_reason = ''
        self._last_sample: JointSample | None = None
        self._startup_sample: JointSample | None = None  # the newest sample of the probe
        #: ~/reset calls begun: a sample read while one began predates the recovery.
        self._resets = 0
        self._rejected_commands = 0
        self._last_reject_reason = ''
        #: (joint states published, header stamp of the last one [ns])
        self._published_last: tuple[int, int] = (0, 0)
        self._latencies_s: deque[float] = deque(maxlen=2000)
        #: Counts at the previous /diagnostics, for the rates since.
        self._diag_window = RateWindow(time.monotonic())
        #: Header stamp [ns] of the joint state the newest /hand/command answers (its own
        #: stamp), and the condition the device-link thread waits on for it.
        self._command_ref_ns: int | None = None
        self._command_arrived = threading.Condition()
        self._command_waits_timed_out = 0
        #: Exceptions the device-link thread caught (each an ERROR).
        self._link_exceptions = 0
        #: The link thread is arming the device (a ~/reset waits for it).
        self._arming = False
        #: Stamps [ns] of the last three joint states published, oldest first (simulated time).
        self._stamps_ns = (0, 0, 0)
        self._child: subprocess.Popen[bytes] | None = None
        self._running = True

        # The hand's model, latched (transient local) as robot_state_publisher does.
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL,
                             reliability=ReliabilityPolicy.RELIABLE)
        self._description_pub = self.create_publisher(String, '/robot_description', latched)
        self._description_pub.publish(String(data=hand_urdf(self.config)))
        self._js_pub = self.create_publisher(JointState, '/joint_states',
                                              STREAM_HISTORY_DEPTH)
        self._js_msg = JointState()
        self._js_msg.name = list(self.joint_names)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        # /clock jumps, two /clock publishers, wall time beside a simulated clock: logged and
        # in /diagnostics beside the driver's status (dam_common.clock_watch)
        self._clock_watch = ClockWatch(self, 'dam_hand_driver: clock',
                                       float(self.config.sim.stall_timeout_s))
        # /hand/command (500 Hz during a grasp) has a thread and a wait set of its own
        # (dam_common.intake): through the executor each message would cost about a
        # millisecond of interpreter time.
        self._intake = SubscriptionThread(self, 'hand_command')
        self._cmd_sub = self._intake.create_subscription(HandCommand, '/hand/command',
                                                         self._on_command, 10)
        self._reset_srv = self.create_service(Trigger, '~/reset', self._on_reset,
                                              qos_profile=SERVICE_QOS)
        self._diag_timer = create_steady_timer(self, 1.0, self._publish_diagnostics)

        try:
            self._select_backend()
        except BaseException:
            self.destroy_node()  # a stand-in already started goes with it
            raise
        try:
            self._intake.start()
            self._thread = threading.Thread(target=self._loop, name='device_link', daemon=True)
            self._thread.start()
        except BaseException:  # e.g. a stop request: the node is not handed out to stop it
            self.destroy_node()
            raise

    # ---------------------------------------------------------------------------------------
    # Backend

    def _select_backend(self) -> None:
        if self.backend == 'dynamixel':
            self._select_dynamixel()
            return
        self.device = UdpDevice(self.config)
        dev = self.config.device
        addr = f'{dev.host}:{dev.command_port} (states to port {dev.state_port})'
        if self.backend == 'sim':
            self._start_standin('backend sim')
            return
        probe = self._receive_at_start(float(dev.probe_timeout_s))
        if probe is not None:
            self._simulated_device = probe.simulated
            kind = 'simulated' if self._simulated_device else 'hardware'
            if self._sim_time and not self._simulated_device:
                raise HandDriverError(
                    f'a real hand answered at {addr}, and use_sim_time:=true runs on the '
                    f'stand-in\'s clock: start the driver without use_sim_time')
            self.get_logger().info(f'device answered at {addr}: backend {self.backend}, '
                                   f'{kind} device')
            return
        if self.backend == 'hardware':
            self.get_logger().error(
                f'no state frame from the hand at {addr} within {dev.probe_timeout_s} s; '
                f'backend hardware never falls back to the simulator: waiting for the device')
            return
        self._start_standin(f'no device answered at {addr} within {dev.probe_timeout_s} s')

    def _select_dynamixel(self) -> None:
        """Open the Dynamixel bus: the configured port, or the emulated bus started here."""
        port = self._port
        if not port:
            port = self._start_standin('no Dynamixel port configured (dynamixel.port, port)',
                                       bus='dynamixel')

        def clock_ns() -> int:
            return self.get_clock().now().nanoseconds

        with SHUTDOWN.uninterrupted():
            self.device = DynamixelDevice(self.config, port, clock_hint_ns=clock_ns,
                                          simulated=self._simulated_device,
                                          sim_time=self._sim_time)
        for cap in self.device.rate_report:
            self.get_logger().warning(f'Dynamixel bus rate: {cap}')
        dxl = self.config.dynamixel
        self.get_logger().info(
            f'Dynamixel bus on {port} at {dxl.baud_rate} bit/s: {len(dxl.servos)} servos '
            f'answered with their configured models; bus cycle {dxl.rate_hz:g} Hz; torque off '
            f'until ACTIVE')

    def _start_standin(self, why: str, bus: str = 'udp') -> str:
        """Start the stand-in (``bus``: its UDP device link, or an emulated Dynamixel bus);
        returns the emulated bus's port (empty for UDP)."""
        exe = standin_executable(why)
        self._simulated_device = True
        port_file = new_port_file() if bus == 'dynamixel' else ''
        cmd = standin_command(exe, self.config.source, self._overlays, self.config.object.name,
                              self._gui, self._sim_time, port_file)
        # A session of its own: Ctrl-C in the terminal reaches the driver only, which stops the
        # stand-in itself (a signal in the stand-in's first milliseconds, before it handles
        # signals, would end it with a traceback); it dies with the driver however that dies.
        self._child = subprocess.Popen(cmd, stdin=subprocess.DEVNULL,
                                       preexec_fn=die_with_parent, start_new_session=True)
        self.get_logger().warning(
            f'{why}: RUNNING ON THE SIMULATOR - started the stand-in sim_bridge '
            f'(PID {self._child.pid})')
        deadline = time.monotonic() + STANDIN_START_TIMEOUT_S
        if bus == 'dynamixel':
            return await_port_file(self._child, port_file, deadline)
        while time.monotonic() < deadline and self._child.poll() is None:
            if self._receive_at_start(0.1) is not None:
                return ''
        if self._child.poll() is not None:
            raise HandDriverError(f'the stand-in exited with code {self._child.returncode} '
                                  f'before sending a state frame')
        self.get_logger().error(f'the stand-in sent no state frame within '
                                f'{STANDIN_START_TIMEOUT_S} s')
        return ''

    def _receive_at_start(self, timeout_s: float) -> JointSample | None:
        """A sample within ``timeout_s`` [s], or ``None``; in short waits, so that a stop
        request (SIGINT, SIGTERM) ends the start-up at once
        (:class:`~dam_common.shutdown.StartupInterrupted`)."""
        assert self.device is not None
        deadline = time.monotonic() + timeout_s
        while True:
            SHUTDOWN.raise_if_requested()
            left = deadline - time.monotonic()
            sample = self.device.receive(min(0.05, max(left, 0.0)))
            if sample is not None:
                # The device link answers it: a stand-in on simulated time sends no newer
                # frame before this one is answered.
                self._startup_sample = sample
            if sample is not None or left <= 0.05:
                return sample

    def _stop_standin(self) -> None:
        """Stop the stand-in and wait for it (:func:`dam_hand_driver.standin.stop_standin`)."""
        child, self._child = self._child, None
        if child is not None:
            stop_standin(child, self.get_logger())

    # ---------------------------------------------------------------------------------------
    # Control loop (own thread)

    def _activate(self, sample: JointSample) -> None:
        """Clean start: every joint HOLDs its measured position; the slew of torque commands
        starts afresh (from the measured torques); the device's actuators come on."""
        assert self.device is not None
        self._arming = True
        try:
            self.device.arm(sample)
        except Exception as exc:  # noqa: BLE001 - a port that went away raises anything
            self._arming = False
            self._enter_error(f'the device could not be switched on: {exc}')
            return
        with self._lock:
            self._arming = False
            gave_up = self.state is not DriverState.WAITING  # a ~/reset gave up meanwhile
            if not gave_up:
                self._modes[:] = int(JointMode.HOLD)
                self._setpoints[:] = 0.0
                self._stiffness[:] = 0.0
                self._damping[:] = 0.0
                self.slew.reset()
                self.state = DriverState.ACTIVE
                self._error_reason = ''
        if gave_up:
            self.device.disarm()
            return
        q = sample.position
        self.get_logger().info(f'device link active: holding the measured posture '
                               f'{np.round(q, 3).tolist()} rad; torque commands ramp from '
                               f'the measured torques')

    def _enter_error(self, reason: str) -> None:
        with self._lock:
            if self.state is DriverState.ERROR:
                return
            self.state = DriverState.ERROR
            self._error_reason = reason
        if self.device is not None:
            try:
                self.device.disarm()
            except Exception as exc:  # noqa: BLE001 - the device may be gone
                self.get_logger().warning(f'could not switch the device off: {exc!r}')
        self.get_logger().error(f'ERROR: {reason}; /joint_states and torque commands stopped, '
                                f'call ~/reset to recover')

    def _schedule_link_thread(self) -> None:
        """SCHED_FIFO for this (the device-link) thread only, and only for a real hand."""
        if self._simulated_device:
            self._scheduling = 'normal (simulated device: no physical deadline)'
            return
        refused = set_thread_priority(self.thread_priority)
        self._scheduling = (f'normal ({refused})' if refused else
                            f'SCHED_FIFO {self.thread_priority}' if self.thread_priority else
                            'normal')
        if refused:
            self.get_logger().warning(
                f'{refused}: the device link runs with normal scheduling, /joint_states may '
                f'jitter on a busy machine (thread_priority:=0 silences this)')

    def _silence(self, now: float) -> str | None:
        """Why the device counts as gone (``None``: it does not), no frame having come."""
        child = self._child
        if self._sim_time and child is not None and child.poll() is not None:
            return f'the stand-in (PID {child.pid}) exited with code {child.returncode}'
        assert self.device is not None
        last = self.device.last_sample_time
        if last is None or now - last <= self._silence_timeout_s:
            return None
        what = ('sim.stall_timeout_s, wall time: the simulated clock stands still'
                if self._sim_time else 'device.state_timeout_s')
        detail = self.device.last_failure
        return (f'no state frame for {now - last:.3f} s ({what}, {self._silence_timeout_s} s)'
                + (f'; last read: {detail}' if detail else ''))

    def _loop(self) -> None:
        self._schedule_link_thread()
        device = self.device
        assert device is not None
        while self._running:
            try:
                if not self._cycle(device):
                    return
            except Exception as exc:  # noqa: BLE001 - the link thread never dies
                if not self._running:
                    return
                self._link_fault(exc)

    def _link_fault(self, exc: Exception) -> None:
        """An exception in the device-link thread: an ERROR naming it (the traceback logged
        once, for a bug report); the thread goes on, so that ``~/reset`` can recover."""
        self._link_exceptions += 1
        if self._link_exceptions == 1:
            self.get_logger().error('device link: ' + ''.join(
                traceback.format_exception(type(exc), exc, exc.__traceback__)).rstrip())
        self._enter_error(f'device link: {type(exc).__name__}: {exc}')
        time.sleep(0.05)  # a fault that repeats does not spin

    def _cycle(self, device: HandDevice) -> bool:
        """One turn of the device-link loop; ``False`` when the node is shutting down."""
        sample, self._startup_sample = self._startup_sample, None
        resets = self._resets
        if sample is None:
            sample = device.receive(min(0.01, self.state_timeout_s / 4.0))
        now = time.monotonic()
        if sample is not None and self._resets != resets:
            return True  # read before the recovery of a ~/reset: its fault is gone
        if sample is None:
            lost = device.link_lost
            if lost:  # the port failed: no use waiting for the state timeout
                self._enter_error(lost)
                return True
            if self.state is not DriverState.ACTIVE:
                return True
            why = self._silence(now)
            if why is not None:
                # This thread may itself have been held up (interpreter lock, CPU):
                # samples that arrived meanwhile are waiting in the socket.
                sample = device.receive(0.0)
                if sample is None:
                    self._enter_error(device.link_lost or why)
            elif self._sim_time and now - (device.last_sample_time or now) \
                    > _RESEND_AFTER_S:
                # The stand-in waits for this answer: it may have been lost.
                device.resend()
            if sample is None:
                return True
            now = time.monotonic()
        self._last_sample = sample
        if sample.fault and self.state is not DriverState.ERROR:
            self._enter_error(sample.fault)
        if self.state is DriverState.WAITING:
            self._activate(sample)
        if self.state is not DriverState.ACTIVE:
            return True
        if self._sim_time:
            # Simulated time: the joint state first, so that the commander computes its
            # answer while the stand-in steps; then the answer to the previous one.
            if not self._publish_or_stop(sample):
                return False
            self._await_command()
            self._answer(sample, now)
            return True
        self._answer(sample, now)
        return self._publish_or_stop(sample)

    def _answer(self, sample: JointSample, received: float) -> None:
        try:
            self._send_command(sample)
        except Exception as exc:  # noqa: BLE001 - the loop must survive any bug
            if self._running:  # (stopping: the stand-in may have closed the port first)
                self.get_logger().error(f'command not sent: {exc!r}',
                                        throttle_duration_sec=_LOG_THROTTLE_S)
        self._latencies_s.append(time.monotonic() - received)

    def _publish_or_stop(self, sample: JointSample) -> bool:
        """Publish the joint state; ``False`` when the node is shutting down."""
        if not self.context.ok():
            return False  # shutting down: the publishers are gone
        try:
            self._publish_joint_states(sample)
        except Exception as exc:  # noqa: BLE001 - e.g. the context went away meanwhile
            if not self.context.ok():
                return False
            self.get_logger().error(f'/joint_states not published: {exc!r}',
                                    throttle_duration_sec=_LOG_THROTTLE_S)
        return True

    def _await_command(self) -> None:
        """Simulated time: wait for the command that answers the previous joint state, if
        the commander streams (its newest command answered the one before), at most
        ``sim.command_wait_s`` of wall time. A commander that stops streaming costs one such
        wait; one that never streamed (none, or a script at its own rate) costs none."""
        before_previous, previous, _newest = self._stamps_ns
        with self._command_arrived:
            ref = self._command_ref_ns
            if ref is None or ref < before_previous or ref >= previous:
                return
            deadline = time.monotonic() + self._command_wait_s
            while self._running and (self._command_ref_ns or 0) < previous:
                left = deadline - time.monotonic()
                if left <= 0.0:
                    self._command_waits_timed_out += 1
                    return
                self._command_arrived.wait(min(left, 0.05))

    def _send_command(self, sample: JointSample) -> None:
        """Answer ``sample`` with the newest command, slew-limited."""
        assert self.device is not None
        with self._lock:
            modes = self._modes.copy()
            target = self._setpoints.copy()
            stiffness = self._stiffness.copy()
            damping = self._damping.copy()
        setpoints = self.slew.step(modes, target, stiffness, damping, sample.position,
                                   sample.velocity, sample.effort)
        self.device.send(sample, modes, setpoints, stiffness, damping)

    def _publish_joint_states(self, sample: JointSample) -> None:
        q, dq, tau = sample.position, sample.velocity, sample.effort
        msg = self._js_msg  # one message, refilled: publish() serialises it at once
        if self._sim_time:  # the device's clock is the simulated time: the state's own
            stamp_ns = int(sample.stamp_ns)
            msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
            self._stamps_ns = (self._stamps_ns[1], self._stamps_ns[2], stamp_ns)
        else:
            msg.header.stamp = self.get_clock().now().to_msg()
        # array.array('d') is taken as is by the generated setters (no per-element checks).
        msg.position = array.array('d', q.tobytes())
        msg.velocity = array.array('d', dq.tobytes())
        msg.effort = array.array('d', tau.tobytes())
        self._js_pub.publish(msg)
        # One assignment: /diagnostics reads the count and the stamp that belong together.
        self._published_last = (self._published_last[0] + 1,
                                msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec)

    # ---------------------------------------------------------------------------------------
    # ROS callbacks

    def _on_command(self, msg: HandCommand) -> None:
        try:
            items = validate_command(msg, self._index, self.torque_limit_nm, self._lower,
                                     self._upper, self.max_stiffness, self.max_damping)
            why = self.device.command_error(items) if self.device is not None else None
            if why is not None:
                raise CommandRejected(why)
        except CommandRejected as exc:
            self._rejected_commands += 1
            self._last_reject_reason = str(exc)
            self.get_logger().warning(f'rejected /hand/command: {exc}',
                                      throttle_duration_sec=_LOG_THROTTLE_S)
            return
        with self._lock:
            for j, mode, sp, k, d in items:
                self._modes[j] = int(mode)
                self._setpoints[j] = sp if mode is not JointMode.HOLD else 0.0
                self._stiffness[j] = k
                self._damping[j] = d
        if self._sim_time:
            stamp = msg.header.stamp
            with self._command_arrived:
                self._command_ref_ns = stamp.sec * 1_000_000_000 + stamp.nanosec
                self._command_arrived.notify()

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        assert self.device is not None
        rearm = self.device.needs_rearm() if self.state is DriverState.ACTIVE else ''
        if self.state is DriverState.ACTIVE and not rearm:
            response.success = True
            response.message = 'already ACTIVE'
            return response
        if rearm:
            self.get_logger().warning(f'~/reset while ACTIVE: {rearm}: arming again')
        self._resets += 1
        self.device.restart_sequence()  # the device may have restarted its sequence numbers
        try:
            done = self.device.recover()
        except Exception as exc:  # noqa: BLE001 - the node stays up whatever the device does
            why = str(exc) if isinstance(exc, HandDriverError) else f'{type(exc).__name__}: {exc}'
            with self._lock:
                self.state = DriverState.ERROR
                self._error_reason = f'reset failed: {why}'
            self.get_logger().warning(f'~/reset: still in ERROR: {why}')
            response.success = False
            response.message = f'still in ERROR: reset failed: {why}'
            return response
        if done:
            self.get_logger().info(f'~/reset: {done}')
        with self._lock:
            self.state = DriverState.WAITING
        # A good read within a few state timeouts (on simulated time, the stall timeout: a
        # failing read of the emulated bus takes its long packet timeout), and as long as
        # the link thread is arming the hand (its transactions have their own timeouts).
        wait_s = max(0.5, 5.0 * self.state_timeout_s, self._silence_timeout_s)
        deadline = time.monotonic() + wait_s
        while self.state is DriverState.WAITING and (time.monotonic() < deadline
                                                     or self._arming):
            time.sleep(0.01)
        with self._lock:  # one decision with the link thread's: the answer is the state
            if self.state is DriverState.WAITING:
                self.state = DriverState.ERROR
                self._error_reason = (f'reset failed: no state from the device within '
                                      f'{wait_s:.2f} s')
            state, reason = self.state, self._error_reason
        prefix = f'{done}; ' if done else ''
        if state is DriverState.ACTIVE:
            response.success = True
            response.message = (f'{prefix}device link ACTIVE again: holding the measured '
                                f'posture')
            return response
        response.success = False
        response.message = f'{prefix}still in ERROR: {reason}'
        return response

    def _publish_diagnostics(self) -> None:
        now = time.monotonic()
        device = self.device
        received = device.samples_received if device is not None else 0
        published, last_stamp_ns = self._published_last
        sample = self._last_sample
        device_ns = int(sample.stamp_ns) if sample is not None else 0
        failures = device.read_failures if device is not None else 0
        # Device time per wall time over the last period: the real-time factor of a stand-in
        # on simulated time (at most 1.0; lower when a period's work does not fit in a period).
        rates = self._diag_window.advance(now, received, published, device_ns, failures)
        failing = device.failing_reads if device is not None else 0
        tripped = bool(sample is not None and sample.watchdog_tripped)
        simulated = bool(sample is not None and sample.simulated)
        latency_p50_us, latency_max_us = latency_summary_us(self._latencies_s)
        last = device.last_sample_time if device is not None else None
        status = DiagnosticStatus()
        status.name = 'dam_hand_driver: device link'
        status.hardware_id = device.hardware_id if device is not None else ''
        state = self.state
        level, status.message = link_status(
            state, self._error_reason, rates, self.period_s, self._sim_time, tripped, failing,
            device.last_failure if device is not None else '', simulated)
        status.level = _DIAGNOSTIC_LEVELS[level]
        collector = getattr(self, 'garbage_collector', None)  # set by run_node
        gc_pause_max_s = collector.max_pause_s if collector is not None else 0.0
        values = {
            'state': state.value,
            'backend': self.backend + (' (simulator running)' if simulated else ''),
            'standin_pid': str(self._child.pid) if self._child is not None else '',
            'state_rate_hz': f'{rates.state_rate_hz:.1f}',
            'joint_states_rate_hz': f'{rates.joint_states_rate_hz:.1f}',
            'joint_states_published': str(published),
            'joint_states_last_stamp_ns': str(last_stamp_ns),
            'target_rate_hz': f'{1.0 / self.period_s:g}',
            'use_sim_time': str(self._sim_time),
            'real_time_factor': f'{rates.real_time_factor:.3f}',
            'command_waits_timed_out': str(self._command_waits_timed_out),
            # The scheduled garbage collections (dam_common.collector): how long the longest
            # held the interpreter lock, i.e. stopped the device-link thread.
            'gc_collections': str(collector.collections if collector is not None else 0),
            'gc_pause_max_ms': f'{gc_pause_max_s * 1e3:.2f}',
            'link_thread_scheduling': self._scheduling,
            'state_age_s': f'{now - last:.4f}' if last is not None else 'never',
            'loop_latency_p50_us': f'{latency_p50_us:.0f}',
            'loop_latency_max_us': f'{latency_max_us:.0f}',
            'device_watchdog_tripped': str(tripped),
            'link_thread_exceptions': str(self._link_exceptions),
            'hand_commands_rejected': str(self._rejected_commands),
            # Publishers of /hand/command whose QoS or type cannot match (logged once).
            'hand_command_incompatible_qos': str(self._intake.incompatible_qos),
            'hand_command_incompatible_type': str(self._intake.incompatible_type),
            'last_command_rejection': self._last_reject_reason,
        }
        if device is not None:
            values['device_backend'] = device.kind
            values.update(device.diagnostics())
        status.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status = [status, self._clock_watch.status()]
        self._diag_pub.publish(msg)

    def destroy_node(self) -> None:
        """Stop the link thread, the stand-in (by PID) and close the socket."""
        signal_standin(self._child)  # first: both shut down at the same time
        self._running = False
        if hasattr(self, '_command_arrived'):
            with self._command_arrived:
                self._command_arrived.notify_all()
        intake = getattr(self, '_intake', None)
        if intake is not None:
            intake.stop()
        thread = getattr(self, '_thread', None)
        if thread is not None and thread.is_alive():
            thread.join(timeout=2.0)
        self._stop_standin()
        device = getattr(self, 'device', None)
        if device is not None:
            device.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    run_node(HandDriverNode, 'hand_driver', args,
             startup_errors=(HandDriverError, OSError),
             switch_interval_s=SWITCH_INTERVAL_S, scheduled_gc_period_s=GC_PERIOD_S)
