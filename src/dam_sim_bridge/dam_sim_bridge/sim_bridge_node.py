"""``sim_bridge``: the PyBullet stand-in of the DAM hand, served over the device link.

Run it with ``ros2 run dam_sim_bridge sim_bridge [--gui] [--ros-args -p ...]``. A
:class:`~dam_sim_bridge.sim_device.SimDevice` runs the world in its own thread and speaks the
UDP device link (``docs/device_protocol.md``) on ``device.host`` / ``device.command_port`` /
``device.state_port``; the driver (``dam_hand_driver hand_driver``) is its client.

With ``use_sim_time:=true`` (what the scripts and a driver started with it give the stand-in)
the stand-in is the suite's clock: it publishes ``/clock``, its device clock is the simulated
time, and it steps the physics one device period only once the driver has answered the newest
state frame, paced to at most real time; a loaded machine slows the grasp down and changes
nothing else (``docs/simulation_grasp.md``, "Simulated time"). Without it the device runs in
real time, as a hand with a hardware clock does, and misses no deadline of its own: a driver
that is late misses them. The node adds what only a simulator has:

Topics
------
/sim/object_pose : geometry_msgs/PoseStamped
    Ground-truth pose of the object (its centroid), frame ``world``, at ``pose_rate_hz``.
/sim/object_table_contact : dam_interfaces/ObjectTableContact
    Ground truth of lift-off beside the pose (the same stamp): the object's table contacts and
    the world's lift-off rule (:mod:`dam_sim_bridge.lift_off`): on the table, how long off it,
    lifted (a lift-off, 50 ms off, happened since the reset), off the table at the end (off it
    for the last 0.1 s). The rule is sampled every device cycle; a reset of the world starts it
    again.
/clock : rosgraph_msgs/Clock
    Simulated time, at ``pose_rate_hz`` of wall time, with ``use_sim_time`` or
    ``publish_clock``.

Services
--------
~/reset : std_srvs/Trigger
    Put the world back in its initial state (hand open, all joints HOLD, object at rest).
~/set_friction_angle : dam_interfaces/SetFrictionAngle
    Finger-object friction angle [rad]; the coefficient becomes ``tan(alpha)``. A negative
    angle (the request's default, ``FRICTION_ANGLE_FROM_CONFIG``) puts back the configured
    ``contact.friction_angle_deg``; NaN, inf and angles from pi/2 on are rejected. The answer
    gives the angle in force and the coefficient read back from the simulator.

Parameters
----------
config_file : string, read-only
    DAM configuration file; empty: ``DAM_CONFIG`` or the installed ``config/dam.yaml``.
config_overlay : string, read-only
    A YAML file holding part of a configuration, merged over ``config_file`` (the driver
    passes its own, so that emulated servos and driver agree on e.g. the zero offsets).
object : string, read-only
    The column object on the table, a name of the configuration's ``object.library`` (empty:
    ``object.default``); its convex mesh is a prism of the cross-section.
gui : bool, read-only
    Open the PyBullet window (also ``--gui`` on the command line); refused without a display.
use_sim_time : bool, fixed at start-up
    Run in simulated time (above) and publish ``/clock``.
publish_clock : bool, read-only
    Publish ``/clock`` from the simulated time; default ``use_sim_time`` (so ``ros2 param get``
    says true whenever the node publishes ``/clock``); true also publishes it in real-time
    mode; false with ``use_sim_time`` true is refused at start-up.
pose_rate_hz : double [Hz], in [1, 1000]
    Rate of ``/sim/object_pose``, ``/sim/object_table_contact`` (and ``/clock``); may be
    changed at run time.
bus : string, read-only, ``udp`` (default) or ``dynamixel``
    ``dynamixel``: serve the world as nine emulated Dynamixel servos on a pseudo-terminal
    (:class:`~dam_sim_bridge.dynamixel_standin.DynamixelStandIn`, the ``dynamixel:`` section of
    the configuration) instead of the UDP device link; the driver's ``backend:=dynamixel``
    starts it so when no port is configured. With ``use_sim_time`` the world steps one bus
    period per read of Present Position (the host's bus cycle is the clock).
port_file : string, read-only
    ``bus:=dynamixel``: write the pseudo-terminal's path into this file once it serves.
port_link : string, read-only
    ``bus:=dynamixel``: a symbolic link to the pseudo-terminal (a fixed name for tools).
watchdog_feed : string, read-only, ``addressed`` (default) or ``any``
    ``bus:=dynamixel``: which instruction packets feed a servo's Bus Watchdog (the e-manual
    leaves it open): ``addressed``, packets with its ID, plain broadcasts, and sync and bulk
    packets that list its ID; ``any``, every instruction packet on the bus. Another value is
    refused at start-up.
fault_crc_error_ids, fault_silent_ids : int[], ``bus:=dynamixel``, may be set at run time
    Servos (by ID) whose status packets get a wrong CRC, or that stop answering.
fault_status_delay_s : double [s] in [0, 1], ``bus:=dynamixel``, may be set at run time
    Every status packet is sent this late.
fault_hardware_error : int[], ``bus:=dynamixel``, may be set at run time
    Pairs ``[id, bits, ...]``: set these Hardware Error Status bits on the servo (bit 5
    overload, 2 overheating, 0 input voltage, 3 motor encoder, 4 electrical shock): its torque
    goes off and every status packet carries the alert bit, until a reboot.
thread_priority : int, read-only, in [0, 99], default 0
    ``SCHED_FIFO`` priority of the simulated device's thread only (0: normal scheduling, the
    default: a simulation has no physical deadline, and real-time threads of a physics that
    fills a core use up the kernel's real-time budget, which then stops every real-time thread
    of the machine). Without the permission the node warns once and runs on.
"""

from __future__ import annotations

import math
import os
import sys
import threading

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Header
from std_srvs.srv import Trigger

from dam_common.clock import create_steady_timer
from dam_common.collector import PERIOD_S as GC_PERIOD_S
from dam_common.config import load_config
from dam_common.echo import brief_repr
from dam_common.node import (
    STREAM_HISTORY_DEPTH,
    declare_config_file,
    declare_config_overlay,
    declare_object,
    declare_thread_priority,
    run_node,
)
from dam_common.realtime import SWITCH_INTERVAL_S, set_thread_priority
from dam_common.ros_args import strip_ros_args
from dam_common.service_qos import SERVICE_QOS
from dam_common.shutdown import SHUTDOWN
from dam_interfaces.msg import ObjectTableContact
from dam_interfaces.srv import SetFrictionAngle
from dam_sim_bridge.dynamixel_bus import WATCHDOG_FEED_ADDRESSED, WATCHDOG_FEEDS
from dam_sim_bridge.dynamixel_standin import DynamixelStandIn
from dam_sim_bridge.errors import SimBridgeError
from dam_sim_bridge.lift_off import LiftOffState
from dam_sim_bridge.sim_device import SimDevice
from dam_sim_bridge.world import HandWorld
from dam_sim_bridge.world_options import WorldOptions

_POSE_RATE_RANGE = (1.0, 1000.0)
#: The stand-in's ground truth of lift-off, published beside ``/sim/object_pose``.
TABLE_CONTACT_TOPIC = '/sim/object_table_contact'
_BUSES = ('udp', 'dynamixel')
_FAULT_PARAMETERS = ('fault_crc_error_ids', 'fault_silent_ids', 'fault_status_delay_s',
                     'fault_hardware_error')
_HARDWARE_ERROR_BITS = 0b111101  # the bits an X series servo has


def _sim_stamp(seconds: float) -> Time:
    ns = int(round(seconds * 1e9))
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def table_contact_message(ground: LiftOffState, header: Header) -> ObjectTableContact:
    """The ``/sim/object_table_contact`` message of the lift-off rule's verdict ``ground``
    (the world's since its last reset), stamped with ``header``: its contacts, whether it lies
    on the table, how long it has been off it [s], ``lifted`` (a lift-off happened) and
    ``off_table_at_end`` (off it for the last 0.1 s)."""
    contact = ObjectTableContact(
        table_contacts=int(ground.table_contacts), on_table=bool(ground.on_table),
        off_table_s=float(ground.off_table_s), lifted=bool(ground.lifted),
        off_table_at_end=bool(ground.off_table_at_end))
    contact.header = header
    return contact


class SimBridgeNode(Node):
    """Runs the simulated device and publishes the simulator's ground truth.

    Parameters
    ----------
    gui_flag
        ``--gui`` was given on the command line (same as the ``gui`` parameter).

    Raises
    ------
    SimBridgeError
        The world cannot be built (e.g. a GUI was requested without a display).
    OSError
        The device's command port is already in use.
    """

    def __init__(self, gui_flag: bool = False) -> None:
        super().__init__('sim_bridge')
        config_file = declare_config_file(self)
        overlays = declare_config_overlay(self)
        gui = bool(self.declare_parameter(
            'gui', False, ParameterDescriptor(
                description='open the PyBullet window (needs a display)',
                read_only=True)).value) or gui_flag
        self._sim_time = bool(self.get_parameter('use_sim_time').value)
        # Its value is what the node does: with use_sim_time it publishes /clock, so the
        # default follows use_sim_time (it said false while /clock came from this node).
        self._publish_clock = bool(self.declare_parameter(
            'publish_clock', self._sim_time, ParameterDescriptor(
                description='publish /clock from the simulated time (true with '
                            'use_sim_time)', read_only=True)).value)
        if self._sim_time and not self._publish_clock:
            raise SimBridgeError('publish_clock:=false with use_sim_time:=true: in simulated '
                                 'time the stand-in is the clock and publishes /clock (leave '
                                 'publish_clock out)')
        self._pose_rate_hz = float(self.declare_parameter(
            'pose_rate_hz', 100.0, ParameterDescriptor(
                description='rate of /sim/object_pose, /sim/object_table_contact and '
                            '/clock [Hz]',
                floating_point_range=[FloatingPointRange(
                    from_value=_POSE_RATE_RANGE[0], to_value=_POSE_RATE_RANGE[1],
                    step=0.0)])).value)
        self._thread_priority = declare_thread_priority(
            self, default=0, what='the simulated device thread')
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._bus = str(self.declare_parameter(
            'bus', 'udp', ParameterDescriptor(
                description='udp: the UDP device link; dynamixel: nine emulated Dynamixel '
                            'servos on a pseudo-terminal', additional_constraints='udp or '
                            'dynamixel', read_only=True)).value)
        if self._bus not in _BUSES:
            raise SimBridgeError(f'bus {self._bus!r} is not one of {_BUSES}')
        port_file = str(self.declare_parameter(
            'port_file', '', ParameterDescriptor(
                description='bus dynamixel: write the pseudo-terminal path here',
                read_only=True)).value)
        port_link = str(self.declare_parameter(
            'port_link', '', ParameterDescriptor(
                description='bus dynamixel: a symbolic link to the pseudo-terminal',
                read_only=True)).value)
        watchdog_feed = str(self.declare_parameter(
            'watchdog_feed', WATCHDOG_FEED_ADDRESSED, ParameterDescriptor(
                description='bus dynamixel: which instruction packets feed a servo\'s Bus '
                            'Watchdog: addressed (its ID, plain broadcasts, sync and bulk '
                            'packets that list it) or any (every packet on the bus)',
                additional_constraints=' or '.join(WATCHDOG_FEEDS),
                read_only=True)).value)
        if watchdog_feed not in WATCHDOG_FEEDS:
            raise SimBridgeError(f'watchdog_feed {watchdog_feed!r} is not one of '
                                 f'{", ".join(WATCHDOG_FEEDS)}')
        self._declare_fault_parameters()
        self._config = declare_object(self, load_config(config_file or None, overlays))
        with SHUTDOWN.uninterrupted():  # a half-built physics client cannot be destroyed
            world = HandWorld(self._config, WorldOptions.from_config(self._config, gui=gui))
            try:
                if self._bus == 'dynamixel':
                    self._device = DynamixelStandIn(self._config, world,
                                                    sim_time=self._sim_time,
                                                    link_path=port_link or None,
                                                    watchdog_feed=watchdog_feed)
                else:
                    self._device = SimDevice(self._config, world, sim_time=self._sim_time)
            except BaseException:
                world.close()
                raise
        self._thread = threading.Thread(target=self._run_device, name='sim_device',
                                        daemon=True)
        # The ground truth a recording is judged by: as much history as the 500 Hz streams
        # (5 s at the default 100 Hz), so that a recorder that falls behind loses none.
        self._pose_pub = self.create_publisher(PoseStamped, '/sim/object_pose',
                                               STREAM_HISTORY_DEPTH)
        self._contact_pub = self.create_publisher(ObjectTableContact, TABLE_CONTACT_TOPIC,
                                                  STREAM_HISTORY_DEPTH)
        self._clock_pub = (self.create_publisher(Clock, '/clock', 10)
                           if self._publish_clock else None)
        self._timer = create_steady_timer(self, 1.0 / self._pose_rate_hz, self._on_timer)
        self._reset_srv = self.create_service(Trigger, '~/reset', self._on_reset,
                                              qos_profile=SERVICE_QOS)
        self._friction_srv = self.create_service(
            SetFrictionAngle, '~/set_friction_angle', self._on_set_friction_angle,
            qos_profile=SERVICE_QOS)
        self._thread.start()
        dev = self._config.device
        if isinstance(self._device, DynamixelStandIn):
            self._announce_bus(port_file)
            return
        self.get_logger().info(
            f'simulated DAM hand on {dev.host}: commands on UDP port {dev.command_port}, '
            f'states to port {dev.state_port} at {dev.rate_hz:g} Hz '
            f'({self._device.steps_per_cycle} physics steps per cycle, '
            f'{"simulated time: publishing /clock" if self._sim_time else "real time"}), object '
            f'{self._config.object.name} ({self._config.object.section.describe()}), config '
            f'{self._config.source}{", GUI" if gui else ""}')

    # ---------------------------------------------------------------------------------------

    def _announce_bus(self, port_file: str) -> None:
        device = self._device
        assert isinstance(device, DynamixelStandIn)
        dxl = self._config.dynamixel
        assert dxl is not None
        if port_file:
            tmp = f'{port_file}.tmp'
            with open(tmp, 'w', encoding='utf-8') as f:
                f.write(device.port_path + '\n')
            os.replace(tmp, port_file)  # whole or not at all for the reader
        ids = ', '.join(f'{s.servo_id} {s.model}' for s in dxl.servos)
        link = f' (link {device.link_path})' if device.link_path else ''
        clock = ('simulated time: one cycle per read of Present Position, publishing /clock'
                 if self._sim_time else 'real time')
        self.get_logger().info(
            f'simulated DAM hand as an emulated Dynamixel bus on {device.port_path}{link}: '
            f'servos {ids} at {dxl.baud_rate} bit/s; {dxl.rate_hz:g} Hz bus cycle '
            f'({device.steps_per_cycle} physics steps), {clock}; watchdog_feed '
            f'{device.watchdog_feed}; object {self._config.object.name}, config '
            f'{self._config.source}')

    def _declare_fault_parameters(self) -> None:
        # Dynamic typing: `ros2 param set NODE fault_silent_ids "[]"` sends an empty list as a
        # bool array; any empty list clears a fault, and the callback checks the rest.
        descriptor = ParameterDescriptor(
            description='bus dynamixel: servo IDs (fault injection); [] clears',
            additional_constraints='a list of the configured servo IDs',
            dynamic_typing=True)
        for name in ('fault_crc_error_ids', 'fault_silent_ids', 'fault_hardware_error'):
            self.declare_parameter(name, None, descriptor)
        self.declare_parameter('fault_status_delay_s', 0.0, ParameterDescriptor(
            description='bus dynamixel: every status packet this late [s]',
            floating_point_range=[FloatingPointRange(from_value=0.0, to_value=1.0,
                                                     step=0.0)]))

    def _fault_error(self, param: Parameter) -> str | None:
        """Why a fault parameter cannot be set (``None``: it can), and apply it if it can."""
        device = getattr(self, '_device', None)
        if not isinstance(device, DynamixelStandIn):
            return f'{param.name} needs bus:=dynamixel (this stand-in serves the UDP link)'
        dxl = self._config.dynamixel
        assert dxl is not None
        known = {s.servo_id for s in dxl.servos}
        value = param.value
        if param.name == 'fault_status_delay_s':
            device.status_delay_s = float(value)
            return None
        array_types = (Parameter.Type.BOOL_ARRAY, Parameter.Type.BYTE_ARRAY,
                       Parameter.Type.INTEGER_ARRAY, Parameter.Type.DOUBLE_ARRAY,
                       Parameter.Type.STRING_ARRAY)
        if value is None or (param.type_ in array_types and len(value) == 0):
            values: list[int] = []  # any empty list (ros2 param set sends [] as bools)
        elif param.type_ == Parameter.Type.INTEGER_ARRAY:
            values = [int(v) for v in value]
        else:
            return (f'{param.name} takes a list of servo IDs (integers), got '
                    f'{brief_repr(value)}')
        if param.name == 'fault_hardware_error':
            if len(values) % 2:
                return (f'fault_hardware_error takes pairs [id, bits, ...], got '
                        f'{brief_repr(values)}')
            pairs = list(zip(values[::2], values[1::2], strict=True))
            for servo_id, bits in pairs:
                if servo_id not in known:
                    return f'fault_hardware_error: no servo with ID {servo_id} ({sorted(known)})'
                if not 0 < bits <= 255 or bits & ~_HARDWARE_ERROR_BITS:
                    return (f'fault_hardware_error: bits {bits} are not Hardware Error Status '
                            f'bits (0 input voltage, 2 overheating, 3 motor encoder, 4 '
                            f'electrical shock, 5 overload)')
            for servo_id, bits in pairs:
                device.hardware_error(servo_id, bits)
            return None
        unknown = sorted(set(values) - known)
        if unknown:
            return f'{param.name}: no servo with ID {brief_repr(unknown)} (IDs: {sorted(known)})'
        if param.name == 'fault_crc_error_ids':
            device.crc_error_ids = values
        else:
            device.silent_ids = values
        return None

    def _run_device(self) -> None:
        refused = set_thread_priority(self._thread_priority)
        if refused:
            self.get_logger().warning(
                f'{refused}: the simulated device runs with normal scheduling, its state '
                f'frames may be late on a busy machine (thread_priority:=0 silences this)')
        self._device.run()


    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        for param in params:
            if param.name in _FAULT_PARAMETERS:
                if not hasattr(self, '_device'):  # at start-up: taken once the bus runs
                    continue
                why = self._fault_error(param)
                if why is not None:
                    return SetParametersResult(successful=False, reason=why)
        for param in params:
            if param.name == 'pose_rate_hz':
                value = param.value
                if not isinstance(value, float) or not math.isfinite(value) or not (
                        _POSE_RATE_RANGE[0] <= value <= _POSE_RATE_RANGE[1]):
                    return SetParametersResult(
                        successful=False,
                        reason=f'pose_rate_hz must be in [{_POSE_RATE_RANGE[0]:g}, '
                               f'{_POSE_RATE_RANGE[1]:g}] Hz, got {brief_repr(value)}')
        for param in params:
            if param.name == 'pose_rate_hz' and hasattr(self, '_timer'):
                self._pose_rate_hz = float(param.value)
                self._timer.cancel()
                self.destroy_timer(self._timer)
                self._timer = create_steady_timer(self, 1.0 / self._pose_rate_hz, self._on_timer)
        return SetParametersResult(successful=True)

    def _on_timer(self) -> None:
        with self._device.lock:
            pose = self._device.world.object_pose()
            ground = self._device.world.lift_off.state()
            # The device clock runs on across resets of the world; /clock must never go back.
            clock_s = self._device.now() if self._sim_time else pose.sim_time
        stamp = _sim_stamp(clock_s) if self._publish_clock \
            else self.get_clock().now().to_msg()
        msg = PoseStamped()
        msg.header.stamp = stamp
        msg.header.frame_id = 'world'
        p, q = pose.position, pose.quaternion
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = (
            float(p[0]), float(p[1]), float(p[2]))
        (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z,
         msg.pose.orientation.w) = (float(q[0]), float(q[1]), float(q[2]), float(q[3]))
        self._pose_pub.publish(msg)
        self._contact_pub.publish(table_contact_message(ground, msg.header))
        if self._clock_pub is not None:
            self._clock_pub.publish(Clock(clock=stamp))

    def _on_reset(self, request: Trigger.Request, response: Trigger.Response
                  ) -> Trigger.Response:
        try:
            self._device.reset_world()
        except Exception as exc:  # noqa: BLE001 - the node stays up whatever happens
            response.success = False
            response.message = f'reset failed: {exc}'
            self.get_logger().error(response.message)
            return response
        response.success = True
        response.message = 'world reset: hand open, all joints HOLD, object at rest'
        self.get_logger().info(response.message)
        return response

    def _on_set_friction_angle(self, request: SetFrictionAngle.Request,
                               response: SetFrictionAngle.Response
                               ) -> SetFrictionAngle.Response:
        alpha = float(request.friction_angle)
        configured = math.isfinite(alpha) and alpha < 0.0  # the default: back to the config
        if configured:
            alpha = self._config.contact.friction_angle_rad
        try:
            if not math.isfinite(alpha):
                raise ValueError(f'friction_angle: {alpha!r} rad is not a finite angle')
            with self._device.lock:
                self._device.world.set_friction_angle(alpha)
                coefficient = self._device.world.pair_friction()['finger_object']
        except (SimBridgeError, ValueError) as exc:
            response.success = False
            response.message = str(exc)
            self.get_logger().warning(f'rejected friction angle: {exc}')
            return response
        response.success = True
        response.message = (f'friction angle {alpha!r} rad ({math.degrees(alpha):.4g} deg'
                            f'{", the configured one" if configured else ""}), '
                            f'finger-object coefficient {coefficient:.9g}')
        self.get_logger().info(response.message)
        return response

    def destroy_node(self) -> None:
        """Stop the device thread, close the socket and the physics server."""
        device = getattr(self, '_device', None)
        if device is not None:
            device.stop()
            if self._thread.is_alive():
                self._thread.join(timeout=2.0)
            device.close()
        super().destroy_node()


def main(args: list[str] | None = None) -> None:
    argv = sys.argv if args is None else args
    gui_flag = '--gui' in strip_ros_args(argv[1:])
    run_node(lambda: SimBridgeNode(gui_flag=gui_flag), 'sim_bridge', args,
             startup_errors=(SimBridgeError, OSError),
             switch_interval_s=SWITCH_INTERVAL_S, scheduled_gc_period_s=GC_PERIOD_S)
