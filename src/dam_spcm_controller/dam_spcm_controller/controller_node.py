"""``spcm_controller``: the ROS node around :class:`~dam_spcm_controller.sequence.DamSequence`.

Run it with ``ros2 run dam_spcm_controller spcm_controller [--ros-args -p name:=value]``.

Topics and services
-------------------
/joint_states : sensor_msgs/JointState, subscribed
    Measured angles [rad], velocities [rad/s] and torques [N*m], reordered by joint name.
    Messages with missing names, wrong array lengths or NaN/inf are dropped (throttled log).
    Taken in a thread of its own, outside the node's executor
    (:mod:`dam_common.intake`; the node's remapping rules apply), the control step included.
/hand/command : dam_interfaces/HandCommand, published
    One command per received joint state while a grasp runs or its result is held (DONE keeps
    the envelope commands); ABORTED/FAILED ramp the torque to zero and stop publishing with
    the command that reached zero (the driver keeps it: zero torque on the compliant joints,
    the others held), so that the hand may be commanded by others between grasps; one
    hold-measured command at the first valid joint state after start-up. The header stamp is
    that of the joint state the command answers.
/dam/status : dam_interfaces/DamStatus, published at ``status_rate`` and on phase change.
    ``compliant_torque`` (the old name) and ``compliant_torque_estimate`` are the estimate
    ``-k_theta_i delta_theta_s`` from the joint angles; ``compliant_effort_measured`` is the
    compliant joints' effort in the newest ``/joint_states``. The feedback carries the same.
/dam_grasp : dam_interfaces/action/DamGrasp, action server.
    Goals follow the ``/check_lift`` conventions. Every goal is accepted and answered at once;
    one that cannot run (invalid; a grasp or a release running; the hand still holding the
    previous grasp's DONE, which ``~/release`` lets go) ends ABORTED at once with
    OUTCOME_REJECTED and the reason (also logged). Goals are not queued.
/check_lift : dam_interfaces/srv/CheckLift, called before each grasp.

Parameters
----------
See :data:`~dam_spcm_controller.controller_parameters.DOUBLE_PARAMETERS`; plus
``config_file`` (read-only), ``object`` (read-only, a name
of the configuration's ``object.library``, empty: ``object.default``: the object the outcome is
classified for and ``/check_lift`` is asked about; give the stand-in the same),
``require_lift_guarantee``
(bool) and ``impedance_on_device`` (bool, default ``controller.impedance_on_device`` of the
configuration, true): the compliant joints are commanded in MODE_IMPEDANCE (per-finger
``k_theta_i``, ``theta_0``, the ``damping`` parameter) and the device runs the impedance law at
its physics rate; false: this node computes the torque every joint state and sends
MODE_TORQUE; ``envelope_constant_torque`` (bool, default false): ENVELOPE applies the constant
``envelope_torque`` to the compliant joints as in the paper's Fig. 6(d) instead of keeping the
SPCM impedance (in simulation the constant torque pushes the lifted object out of the hand:
``docs/simulation_grasp.md``). All but ``config_file`` and ``object`` may be changed while no
grasp runs. The controller never asks for real-time scheduling: on a real hand the deadline
is the driver's device-link thread's, and the impedance law runs on the device.

Time
----
With ``use_sim_time:=false`` the grasp's timing (trajectory, phase timeouts, ramps,
``state_timeout``) runs on the steady clock. With ``use_sim_time:=true`` (the stand-in's
simulated time, fixed at start-up) it runs on the stamps of ``/joint_states`` (the stand-in's
simulated time): a machine that holds the suite up slows the grasp down and changes nothing
else. ``state_timeout`` is then simulated time (the time ``/clock`` advanced, its jumps taken
out, since the newest joint state came: a ``/clock`` jump is no silence), and a silence of
``sim.stall_timeout_s`` of wall time (a stand-in or driver that died stops the simulated
clock) fails the grasp all the same. The result's ``duration`` is on the grasp's clock (the
same simulated time, or steady), ``wall_duration`` on the steady clock.

Diagnostics
-----------
/diagnostics : diagnostic_msgs/DiagnosticArray, 1 Hz: status ``dam_spcm_controller: commands``
with ``hand_commands_published`` (commands published since start) and
``hand_commands_last_stamp_ns`` (the header stamp of the last one [ns]), so that a recording
can be checked for completeness; status ``dam_spcm_controller: clock``
(:class:`dam_common.clock_watch.ClockWatch`, jump bound ``sim.stall_timeout_s``): WARN while
``/clock`` has two publishers, this node is on wall time while ``/clock`` is published, or
``/joint_states`` are stamped on another clock, and for 10 s after a ``/clock`` jump; each is
logged too, and a joint-state silence that fails a grasp names them.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, SetParametersResult
from rclpy.action import ActionServer, CancelResponse, GoalResponse
from rclpy.action.server import ServerGoalHandle
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.task import Future
from sensor_msgs.msg import JointState
from std_srvs.srv import Trigger

from dam_analysis.analysis import LiftAnalyzer, unreachable_object
from dam_analysis.errors import DamAnalysisError, NoSolutionError
from dam_common.clock import create_steady_timer
from dam_common.clock_watch import ClockWatch
from dam_common.config import load_config
from dam_common.echo import brief_repr
from dam_common.intake import SubscriptionThread
from dam_common.node import (
    STREAM_HISTORY_DEPTH,
    declare_config_file,
    declare_object,
    run_node,
)
from dam_common.service_qos import SERVICE_QOS, action_server_qos
from dam_common.shutdown import SHUTDOWN
from dam_interfaces.action import DamGrasp
from dam_interfaces.msg import DamStatus, HandCommand
from dam_interfaces.srv import CheckLift
from dam_spcm_controller.classification import (
    Classification,
    ClassifierSettings,
    HandGeometry,
    Outcome,
    classify_from_joints,
)
from dam_spcm_controller.commands import JointCommand, JointMode, zero_torque_command
from dam_spcm_controller.controller_parameters import (
    BOOL_PARAMETERS,
    DOUBLE_PARAMETERS,
    READ_ONLY,
    changed_values,
    sequence_overrides,
)
from dam_spcm_controller.episode import EpisodeEvents
from dam_spcm_controller.errors import InputError, StateError
from dam_spcm_controller.goal_checks import check_goal, guarantee_refusal
from dam_spcm_controller.joint_history import JointHistory
from dam_spcm_controller.object_estimate import FitInterrupted
from dam_spcm_controller.release import ReleaseMotion
from dam_spcm_controller.sequence import DamSequence, Phase, SequenceParams

#: JointMode of the core -> HandCommand.mode on the wire.
_WIRE_MODE = {JointMode.HOLD: HandCommand.MODE_HOLD,
              JointMode.POSITION: HandCommand.MODE_POSITION,
              JointMode.TORQUE: HandCommand.MODE_TORQUE,
              JointMode.IMPEDANCE: HandCommand.MODE_IMPEDANCE}

_OUTCOME = {Outcome.SUCCESS: DamGrasp.Result.OUTCOME_SUCCESS,
            Outcome.LIFTED_DAM_FAILED: DamGrasp.Result.OUTCOME_LIFTED_DAM_FAILED,
            Outcome.FAILURE: DamGrasp.Result.OUTCOME_FAILURE}
_OUTCOME_NAME = {DamGrasp.Result.OUTCOME_UNKNOWN: 'UNKNOWN',
                 DamGrasp.Result.OUTCOME_SUCCESS: 'SUCCESS',
                 DamGrasp.Result.OUTCOME_LIFTED_DAM_FAILED: 'LIFTED_DAM_FAILED',
                 DamGrasp.Result.OUTCOME_FAILURE: 'FAILURE',
                 DamGrasp.Result.OUTCOME_ABORTED: 'ABORTED',
                 DamGrasp.Result.OUTCOME_REJECTED: 'REJECTED'}


def _phase_name(phase: Phase) -> str:
    return phase.name


#: (steady clock, the grasp's clock) at a goal's arrival [s]: its result's wall_duration and
#: duration are counted from them.
_Start = tuple[float, float]

#: How long the action server keeps a goal's result after the goal ended [s] (rclpy: 900).
#: Every goal kept stays in the action's status array, which each status change publishes to
#: every client: with 15 minutes, a burst of 50 goals from five default-profile clients of one
#: node right after another burst lost a third of its goal answers (measured), as in issue
#: #32; with 10 s the same burst 7 s later got every answer. Clients ask for the result when
#: the goal is accepted (rclpy, rclcpp, ``ros2 action send_goal``, ``dam_grasp``): they get it
#: the moment the goal ends; one that asks later than this after the end gets no result.
RESULT_KEPT_S = 10.0

#: How long a new goal waits for a fresh joint state before it is refused [s].
_START_STATE_WAIT_S = 1.0


class SpcmControllerNode(Node):
    """Runs DAM grasps requested on ``/dam_grasp`` against ``/joint_states``."""

    def __init__(self) -> None:
        super().__init__('spcm_controller')
        config_file = declare_config_file(self)
        #: Simulated time: the grasp runs on the stamps of /joint_states (fixed at start-up).
        self._sim_time = bool(self.get_parameter('use_sim_time').value)
        self._config = declare_object(self, load_config(config_file or None))
        #: Why the analysis cannot answer for the object ('' when it can): then every goal is
        #: refused, also when /check_lift is not there to say so (the object is fixed at
        #: start-up; building the analysis takes a few tenths of a second).
        self._unanalysable = ''
        try:
            LiftAnalyzer(self._config)
        except NoSolutionError as exc:
            self._unanalysable = unreachable_object(self._config, exc)
        self._base_params = SequenceParams.from_config(self._config)
        self._layout = self._base_params.layout
        self._geometry = HandGeometry.from_config(self._config)
        self._classifier = ClassifierSettings.from_config(self._config)
        defaults = {name: float(getattr(self._base_params, attr))
                    for name, (attr, *_rest) in DOUBLE_PARAMETERS.items() if attr}
        defaults['state_timeout'] = float(self._config.controller.state_timeout_s)
        defaults['check_lift_timeout'] = 2.0
        defaults['status_rate'] = 20.0
        for name, (_attr, description, lo, hi) in DOUBLE_PARAMETERS.items():
            self.declare_parameter(name, defaults[name], ParameterDescriptor(
                description=description, read_only=name in READ_ONLY,
                floating_point_range=[FloatingPointRange(from_value=lo, to_value=hi,
                                                         step=0.0)]))
        bool_defaults = {
            'require_lift_guarantee': False,
            'impedance_on_device': bool(self._config.controller.impedance_on_device),
            'envelope_constant_torque': False}
        for name, description in BOOL_PARAMETERS.items():
            self.declare_parameter(name, bool_defaults[name],
                                   ParameterDescriptor(description=description))
        self._values = {name: float(self.get_parameter(name).value) for name in DOUBLE_PARAMETERS}
        #: The bool parameters (require_lift_guarantee, impedance_on_device,
        #: envelope_constant_torque) by name.
        self._flags: dict[str, bool] = {}
        for name in BOOL_PARAMETERS:
            value = self.get_parameter(name).value
            if not isinstance(value, bool):
                raise InputError(f'{name} must be a bool, got {value!r}')
            self._flags[name] = value
        self._params = self._make_params(self._values)  # raises on an inconsistent start-up set

        self._lock = threading.RLock()
        self._seq = DamSequence(self._params)
        self._busy = False  # a goal is accepted and not finished
        self._publishing = False  # commands follow each joint state
        self._hold_sent = False
        self._last_state_time: float | None = None  # steady clock [s]
        self._last_control_time = 0.0  # the grasp's time of the newest joint state [s]
        #: On simulated time: the clock without its jumps when the newest joint state came [s].
        self._last_state_clock = 0.0
        self._stall_timeout_s = float(self._config.sim.stall_timeout_s)
        self._commands_published = (0, 0)  # (count, header stamp of the last one [ns])
        #: ``_intake.drained`` when a silence was first seen (None: none seen)
        self._silence_seen_at: int | None = None
        self._last_pos = np.zeros(self._layout.n_joints)
        self._last_eff = np.zeros(self._layout.n_joints)
        self._last_cmd: JointCommand | None = None
        self._last_phase = self._seq.phase
        self._status_message = ''
        self._outcome = DamGrasp.Result.OUTCOME_UNKNOWN
        self._state_timed_out = False
        self._shutting_down = False
        self._bad_state_count = 0
        self._goal_handle: ServerGoalHandle | None = None  # the running goal
        self._run_done: Future | None = None  # resolved when the running grasp has ended
        self._cancel_sent = False
        self._feedback = DamGrasp.Feedback()
        self._release: ReleaseMotion | None = None  # letting go (~/release) when set
        self._release_done: Future | None = None

        self._command_pub = self.create_publisher(HandCommand, '/hand/command',
                                                  STREAM_HISTORY_DEPTH)
        self._status_pub = self.create_publisher(DamStatus, '/dam/status', 10)
        self._diag_pub = self.create_publisher(DiagnosticArray, '/diagnostics', 10)
        self._diag_timer = create_steady_timer(self, 1.0, self._publish_diagnostics)
        # /clock jumps, a second /clock publisher, joint states on another clock: logged and
        # on /diagnostics; a jump is no silence of the joint states (see _silence).
        self._clock_watch = ClockWatch(self, 'dam_spcm_controller: clock',
                                       self._stall_timeout_s)
        self._pre_phase = ''  # CHECK_LIFT while a goal waits for its /check_lift answer
        self._episodes = EpisodeEvents(self, str(self._config.source), self._config.object.name)
        # /joint_states (500 Hz) has a thread and a wait set of its own: through this node's
        # executor, with its action server, services and timers, each message would cost
        # about a millisecond of interpreter time.
        self._intake = SubscriptionThread(self, 'joint_states')
        self._state_sub = self._intake.create_subscription(
            JointState, '/joint_states', self._on_joint_state, 10)
        self._watchdog = create_steady_timer(self, 0.01, self._on_watchdog)
        self._status_timer = create_steady_timer(self, 1.0 / self._values['status_rate'],
                                                 self._on_status_timer)
        self._check_lift = self.create_client(CheckLift, '/check_lift')
        self._action = ActionServer(
            self, DamGrasp, '/dam_grasp', execute_callback=self._execute,
            goal_callback=self._on_goal, cancel_callback=self._on_cancel,
            result_timeout=RESULT_KEPT_S,
            **action_server_qos())  # every goal and cancel request answered, however many
        # A callback group of its own: the release awaits the motion, and an awaiting callback
        # holds its group (the default one would starve /joint_states meanwhile).
        self._release_srv = self.create_service(Trigger, '~/release', self._on_release,
                                                qos_profile=SERVICE_QOS,
                                                callback_group=MutuallyExclusiveCallbackGroup())
        self.add_on_set_parameters_callback(self._on_set_parameters)
        try:
            self._intake.start()
            obj = self._config.object
            self.get_logger().info(f'spcm_controller ready ({self._config.source}); object '
                                   f'{obj.name} ({obj.section.describe()}); joints '
                                   f'{list(self._layout.joint_names)}; '
                                   f'{"simulated" if self._sim_time else "steady"} time')
            if self._unanalysable:
                self.get_logger().warning(f'{self._unanalysable}: every grasp goal will be '
                                          f'refused')
        except BaseException:  # e.g. a stop request: the node is not handed out to stop it
            self._intake.stop()
            raise

    # ------------------------------------------------------------------------------------
    # Parameters

    def _make_params(self, values: dict[str, float], flags: dict[str, bool] | None = None
                     ) -> SequenceParams:
        flags = self._flags if flags is None else flags
        return replace(self._base_params, **sequence_overrides(values, flags))

    def _on_set_parameters(self, params: list[Parameter]) -> SetParametersResult:
        with self._lock:
            if self._busy:
                return SetParametersResult(
                    successful=False,
                    reason=f'a grasp is running (phase {_phase_name(self._seq.phase)}); '
                           'parameters can only be changed while idle')
            try:
                values, flags = changed_values(
                    self._values, self._flags, ((p.name, p.value) for p in params))
                new_params = self._make_params(values, flags)
            except InputError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
            self._values = values
            self._flags = flags
            self._params = new_params
        return SetParametersResult(successful=True)

    # ------------------------------------------------------------------------------------
    # Joint states and commands

    def _control_time(self, msg: JointState, wall: float) -> float:
        """The grasp's time of ``msg`` [s]: its stamp on simulated time, else ``wall``."""
        if self._sim_time:
            stamp = msg.header.stamp
            return stamp.sec + stamp.nanosec * 1e-9
        return wall

    def _silence(self) -> tuple[float, str] | None:
        """How long /joint_states have been silent and on which clock, when longer than
        allowed (``state_timeout``; on simulated time also ``sim.stall_timeout_s`` of wall
        time); ``None`` while they are fresh."""
        last = self._last_state_time
        if last is None:
            return math.inf, 'never received'
        wall = time.monotonic() - last
        timeout = self._values['state_timeout']
        if not self._sim_time:
            return (wall, 's') if wall > timeout else None
        if wall > self._stall_timeout_s:
            return wall, f's of wall time (sim.stall_timeout_s {self._stall_timeout_s:g} s)'
        # The simulated time that passed since the newest joint state came, on the clock
        # without its jumps: a jump (a second /clock publisher, a simulator or a bag that
        # starts its time over) is named as one, never taken for a silence.
        sim = self._clock_watch.steady_now_s() - self._last_state_clock
        return (sim, 's of simulated time') if sim > timeout else None

    def _confirmed_silence(self) -> tuple[float, str] | None:
        """:meth:`_silence`, once the joint-state thread has emptied its queue since the
        silence was first seen and it still holds; ``None`` until then.

        A starved process takes its joint states late: its clock (``/clock``, 100 Hz) may run
        ahead of the joint states (500 Hz) still queued for the thread, which is no silence.
        A publisher that really stopped is confirmed within the thread's next wait
        (:data:`dam_common.intake.POLL_S` of wall time at most).
        """
        silence = self._silence()
        if silence is None:
            self._silence_seen_at = None
            return None
        drained = self._intake.drained
        if self._silence_seen_at is None:
            self._silence_seen_at = drained
            return None
        if drained <= self._silence_seen_at:
            return None  # the thread has not looked at its queue since: wait for it
        return silence

    def _on_joint_state(self, msg: JointState) -> None:
        wall = time.monotonic()
        now = self._control_time(msg, wall)
        stamp = msg.header.stamp
        self._clock_watch.stamp_seen('/joint_states', stamp.sec * 1_000_000_000 + stamp.nanosec)
        try:
            index = self._layout.index_of(list(msg.name))
            n = len(msg.name)
            for field in ('position', 'velocity', 'effort'):
                if len(getattr(msg, field)) != n:
                    raise InputError(f'{field} has {len(getattr(msg, field))} entries for '
                                     f'{n} names')
            pos = np.asarray(msg.position, dtype=np.float64)[index]
            vel = np.asarray(msg.velocity, dtype=np.float64)[index]
            eff = np.asarray(msg.effort, dtype=np.float64)[index]
            for field, arr in (('position', pos), ('velocity', vel), ('effort', eff)):
                if not np.isfinite(arr).all():
                    j = int(np.flatnonzero(~np.isfinite(arr))[0])
                    raise InputError(f'{field} of {self._layout.joint_names[j]} is '
                                     f'{arr[j]!r}')
        except InputError as exc:
            self._bad_state_count += 1
            self.get_logger().warning(
                f'dropped /joint_states message ({self._bad_state_count} so far): {exc}',
                throttle_duration_sec=1.0)
            return
        with self._lock:
            self._last_state_time = wall
            self._last_control_time = now
            if self._sim_time:
                self._last_state_clock = self._clock_watch.steady_now_s()
            self._last_pos = pos
            self._last_eff = eff
            if self._release is not None:
                self._step_release(now, pos, msg)
                return
            if self._state_timed_out:
                return  # the grasp already failed; the zero-torque command stands
            try:
                cmd = self._seq.step(now, pos, vel, eff)
            except InputError as exc:
                self.get_logger().warning(f'control step refused: {exc}',
                                          throttle_duration_sec=1.0)
                return
            publish = self._publishing or not self._hold_sent
            self._hold_sent = True
            if self._seq.phase in (Phase.ABORTED, Phase.FAILED) and self._seq.relaxed:
                self._publishing = False  # this command is the relaxed one: the last
            self._last_cmd = cmd
            phase_changed = self._seq.phase is not self._last_phase
            self._last_phase = self._seq.phase
        if publish:
            self._publish_command(cmd, msg.header.stamp)
        if phase_changed:
            self._publish_status()
        self._advance(feedback=phase_changed)

    def destroy_node(self) -> None:
        """Stop the /joint_states intake thread, then destroy the node."""
        intake = getattr(self, '_intake', None)
        if intake is not None:
            intake.stop()
        super().destroy_node()

    def begin_shutdown(self) -> Future | None:
        """Called by ``run_node`` on SIGINT/SIGTERM before the node is destroyed: a grasp in
        progress is aborted (its torques ramp to zero, as on a cancel) so that its client gets
        the result ABORTED, 'the controller is shutting down'. Returns the future that resolves
        when the goal has ended (``None``: nothing to finish)."""
        with self._lock:
            done = self._run_done
            if done is None or done.done():
                return None
            self._shutting_down = True
            self._seq.fail('the controller is shutting down')
        self.get_logger().warning('shutting down during a grasp: aborting it')
        return done

    # ------------------------------------------------------------------------------------
    # Release (~/release): let go of the object and open the hand

    async def _on_release(self, _request: Trigger.Request, response: Trigger.Response
                          ) -> Trigger.Response:
        with self._lock:
            if self._busy:
                response.success = False
                response.message = ('the hand is being released already'
                                    if self._release is not None else
                                    f'a grasp is running (phase {_phase_name(self._seq.phase)}):'
                                    ' cancel its goal first')
                return response
            self._busy = True  # no goal starts while the release waits for a joint state
        if not await self._fresh_state(_START_STATE_WAIT_S):
            with self._lock:
                self._busy = False
            response.success = False
            response.message = (f'no /joint_states within {_START_STATE_WAIT_S:g} s: cannot '
                                'release')
            return response
        with self._lock:
            held = self._last_cmd if self._publishing or self._seq.phase is Phase.DONE \
                else None
            self._release = ReleaseMotion(self._params, held, self._last_control_time,
                                          self._last_pos)
            release_start = self._last_control_time
            self._release_done = Future()
            self._publishing = True
            self._state_timed_out = False
            self._silence_seen_at = None
            self._outcome = DamGrasp.Result.OUTCOME_UNKNOWN  # the grasp is over: releasing
            done = self._release_done
        self.get_logger().info('releasing: torques to zero, then opening the hand')
        self._publish_status()
        timeout = self._release_timeout()

        def poll() -> None:
            if done.done():
                return
            if self._last_control_time - release_start > timeout or \
                    self._confirmed_silence() is not None:
                self._end_release(False)

        timer = create_steady_timer(self, 0.01, poll)
        try:
            ok = bool(await done)
        finally:
            self.destroy_timer(timer)
        response.success = ok
        response.message = ('released: every joint holds the open posture; the controller '
                            'sends no command until the next goal' if ok else
                            '/joint_states went silent during the release: it stopped, the '
                            'hand keeps its last command')
        if ok:  # one call site per severity (rclpy refuses a change at one site)
            self.get_logger().info(response.message)
        else:
            self.get_logger().error(response.message)
        return response

    def _release_timeout(self) -> float:
        """Longest time a release may take [s]: ramp, the widest opening, a margin."""
        lay = self._layout
        widest = float(lay.upper[lay.position].max() - lay.lower[lay.position].min())
        return self._values['torque_ramp_time'] + 2.0 * widest / \
            self._values['approach_speed'] + 2.0

    def _step_release(self, now: float, pos: np.ndarray, msg: JointState) -> None:
        """One step of the release; called with the lock held."""
        release = self._release
        assert release is not None
        cmd = release.step(now, pos)
        self._last_cmd = cmd
        self._publish_command(cmd, msg.header.stamp)
        if release.done:
            self._end_release(True)

    def _end_release(self, ok: bool) -> None:
        with self._lock:
            done = self._release_done
            self._release = None
            self._release_done = None
            self._publishing = False  # the last command (all HOLD) stands at the driver
            self._busy = False
            if self._seq.phase.terminal:
                self._seq.reset()
            self._status_message = 'released' if ok else 'release stopped'
        if done is not None and not done.done():
            done.set_result(ok)
        self._publish_status()

    def _publish_command(self, cmd: JointCommand, stamp=None) -> None:
        """Publish ``cmd``; ``stamp`` is that of the joint state it answers (now if None)."""
        msg = HandCommand()
        msg.header.stamp = stamp if stamp is not None else self.get_clock().now().to_msg()
        msg.name = list(self._layout.joint_names)
        msg.mode = [_WIRE_MODE[JointMode(int(m))] for m in cmd.modes]
        msg.setpoint = [float(v) for v in cmd.setpoints]
        if cmd.has_impedance:  # else empty: no joint in MODE_IMPEDANCE
            msg.stiffness = [float(v) for v in cmd.stiffness]
            msg.damping = [float(v) for v in cmd.damping]
        self._command_pub.publish(msg)
        self._commands_published = (self._commands_published[0] + 1,
                                    msg.header.stamp.sec * 1_000_000_000
                                    + msg.header.stamp.nanosec)

    def _publish_diagnostics(self) -> None:
        count, stamp_ns = self._commands_published  # one read: the pair belongs together
        status = DiagnosticStatus()
        status.name = 'dam_spcm_controller: commands'
        status.level = DiagnosticStatus.OK
        status.message = f'phase {_phase_name(self._seq.phase)}'
        status.values = [KeyValue(key='hand_commands_published', value=str(count)),
                         KeyValue(key='hand_commands_last_stamp_ns', value=str(stamp_ns)),
                         KeyValue(key='use_sim_time', value=str(self._sim_time)),
                         # Publishers of /joint_states whose QoS or type cannot match.
                         KeyValue(key='joint_states_incompatible_qos',
                                  value=str(self._intake.incompatible_qos)),
                         KeyValue(key='joint_states_incompatible_type',
                                  value=str(self._intake.incompatible_type))]
        msg = DiagnosticArray()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.status = [status, self._clock_watch.status()]
        self._diag_pub.publish(msg)

    def _on_watchdog(self) -> None:
        with self._lock:
            if not self._seq.phase.active or self._state_timed_out:
                return
            timeout = self._values['state_timeout']
            silence = self._confirmed_silence()
            if silence is None:
                return
            silent, unit = silence
            reason = (f'/joint_states silent for {silent:.3f} {unit} (state_timeout '
                      f'{timeout:g} s) during phase {_phase_name(self._seq.phase)}'
                      f'{self._clock_faults()}')
            self._seq.fail(reason)
            self._state_timed_out = True
            zero = zero_torque_command(self._last_cmd, self._last_pos)
            self._last_cmd = zero
            self._last_phase = self._seq.phase
        self.get_logger().error(reason + '; commanding zero torque')
        self._publish_command(zero)
        self._publish_status()
        self._advance(feedback=True)

    def _clock_faults(self) -> str:
        """'; clock: ...' naming the clock faults that hold or a jump of the last
        ``sim.stall_timeout_s`` [s] (they may explain a silence), else ''."""
        faults = self._clock_watch.conditions
        jump = self._clock_watch.last_jump(self._stall_timeout_s)
        if jump:
            faults.append(f'/clock jumped {jump}')
        return f'; clock: {"; ".join(faults)}' if faults else ''

    # ------------------------------------------------------------------------------------
    # Status and progress of the running goal

    def _on_status_timer(self) -> None:
        self._publish_status()
        self._advance(feedback=True)

    def _advance(self, feedback: bool) -> None:
        """Forward a cancel request, publish feedback, resolve the run when it has ended."""
        handle = self._goal_handle
        done = self._run_done
        if handle is None or done is None or done.done():
            return
        with self._lock:
            seq = self._seq
            if handle.is_cancel_requested and not self._cancel_sent:
                self._cancel_sent = True
                if seq.cancel():
                    feedback = True
            phase = seq.phase
            fb = self._feedback
            fb.phase = self._shown_phase()
            fb.progress = float(seq.progress)
            fb.compliant_torque = [float(v) for v in np.nan_to_num(seq.tau_s)]
            fb.compliant_torque_estimate = fb.compliant_torque
            fb.compliant_effort_measured = [
                float(v) for v in self._last_eff[self._layout.compliant]]
            ended = phase is Phase.DONE or (
                phase in (Phase.ABORTED, Phase.FAILED) and (seq.relaxed or self._state_timed_out))
        if feedback:
            handle.publish_feedback(fb)
        if ended:
            done.set_result(phase)

    def _publish_status(self) -> None:
        with self._lock:
            seq = self._seq
            msg = DamStatus()
            msg.header.stamp = self.get_clock().now().to_msg()
            msg.phase = self._shown_phase()
            msg.progress = float(seq.progress)
            msg.finger_names = [self._layout.finger_name(i)
                                for i in range(self._layout.n_fingers)]
            msg.compliant_torque = [float(v) for v in np.nan_to_num(seq.tau_s)]
            msg.compliant_torque_estimate = msg.compliant_torque
            msg.compliant_effort_measured = [
                float(v) for v in self._last_eff[self._layout.compliant]]
            msg.delta_theta_s = [float(v) for v in np.nan_to_num(seq.delta_theta_s)]
            msg.outcome = self._outcome
            msg.outcome_name = _OUTCOME_NAME[self._outcome]
            msg.message = self._status_message
        self._status_pub.publish(msg)

    def _shown_phase(self) -> str:
        """The phase /dam/status and the feedback show (call with the lock held).

        A phase a grasp ends in (DONE, ABORTED, FAILED) is shown only with the grasp's
        outcome beside it: while the goal still decides it, the phase is CLASSIFYING (DONE:
        the classifier fits the final posture) or STOPPING (ABORTED, FAILED: the torque ramps
        to zero).
        """
        if self._release is not None:
            return 'RELEASING'
        if self._pre_phase:
            return self._pre_phase
        phase = self._seq.phase
        if phase.terminal and self._busy and \
                self._outcome == DamGrasp.Result.OUTCOME_UNKNOWN:
            return 'CLASSIFYING' if phase is Phase.DONE else 'STOPPING'
        return _phase_name(phase)

    # ------------------------------------------------------------------------------------
    # Action

    def _validate_goal(self, goal: DamGrasp.Goal) -> tuple[float, float]:
        """(k_theta of finger 1 [N*m/rad], delta_theta_p [rad]) or raise InputError
        (:func:`~dam_spcm_controller.goal_checks.check_goal`; empty: the configured ones)."""
        task = self._config.task
        on_device = self._flags['impedance_on_device']
        return check_goal(goal.k_theta, goal.delta_theta_p, self._layout.stiffness_ratios,
                          task.k_theta_nm_per_rad, task.delta_theta_p_rad,
                          task.delta_theta_p_max_rad,
                          float(self._config.device.max_stiffness_nm_per_rad) if on_device
                          else None)

    def _release_hint(self) -> str:
        """How to let go: ``dam_grasp --release`` knows this node under its default name only."""
        name = self.get_fully_qualified_name()
        command = f'ros2 service call {name}/release std_srvs/srv/Trigger'
        return f'dam_grasp --release or {command}' if name == '/spcm_controller' else command

    def _on_goal(self, _goal: DamGrasp.Goal) -> GoalResponse:
        # Every goal is accepted: one that cannot run is aborted at once with
        # OUTCOME_REJECTED and the reason in its result, which every action client shows
        # (a rejection carries no reason in ROS 2 actions).
        return GoalResponse.ACCEPT

    def _refuse(self, goal_handle: ServerGoalHandle, reason: str, t0: _Start
                ) -> DamGrasp.Result:
        """End a goal that cannot run: ABORTED, OUTCOME_REJECTED, ``reason`` in the result."""
        self.get_logger().warning(f'goal refused: {reason}')
        return self._finish(goal_handle, 'abort', DamGrasp.Result.OUTCOME_REJECTED,
                            f'goal refused: {reason}', t0, owns_run=False)

    def _on_cancel(self, _goal_handle: ServerGoalHandle) -> CancelResponse:
        return CancelResponse.ACCEPT

    async def _poll(self, period_s: float, poll: Callable[[Future], None]) -> Any:
        """The result of a future that ``poll(future)`` resolves; ``poll`` is called now and
        every ``period_s`` [s] of steady time until then."""
        result: Future = Future()

        def tick() -> None:
            if not result.done():
                poll(result)

        timer = create_steady_timer(self, period_s, tick)
        try:
            tick()
            return await result
        finally:
            self.destroy_timer(timer)

    async def _ask_check_lift(self, k: float, dp: float, goal_handle: ServerGoalHandle
                              ) -> CheckLift.Response | None:
        """The /check_lift answer for the pair, or ``None`` if none came within the timeout
        or the goal was cancelled meanwhile."""
        request = CheckLift.Request()
        request.k_theta = [k]
        request.delta_theta_p = [dp]
        request.friction_angle = CheckLift.Request.FRICTION_ANGLE_FROM_CONFIG
        request.object = self._config.object.name
        deadline = time.monotonic() + self._values['check_lift_timeout']
        sent = []

        def poll(answer: Future) -> None:
            if not sent and self._check_lift.service_is_ready():
                call = self._check_lift.call_async(request)
                sent.append(call)
                call.add_done_callback(
                    lambda done: answer.done() or answer.set_result(done.result()))
            if (time.monotonic() >= deadline or goal_handle.is_cancel_requested) \
                    and not answer.done():
                answer.set_result(None)

        return await self._poll(0.02, poll)

    async def _fresh_state(self, wait_s: float, goal_handle: ServerGoalHandle | None = None
                           ) -> bool:
        """Wait up to ``wait_s`` [s] for the joint states to flow: the newest younger than
        ``state_timeout``, or one that came since the wait began; ``False`` also when
        ``goal_handle``'s goal is cancelled meanwhile.

        On simulated time ``/clock`` comes from the stand-in and the joint states from the
        driver: on a loaded machine the clock can run ahead of joint states that still flow,
        which is no silence (a driver in ERROR sends none at all).
        """
        started = time.monotonic()
        deadline = started + wait_s

        def poll(fresh: Future) -> None:
            last = self._last_state_time
            if self._silence() is None or (last is not None and last > started):
                fresh.set_result(True)
            elif time.monotonic() >= deadline or (goal_handle is not None
                                                  and goal_handle.is_cancel_requested):
                fresh.set_result(False)

        return bool(await self._poll(0.01, poll))

    def _finish(self, goal_handle: ServerGoalHandle, status: str, outcome: int, message: str,
                t0: _Start, owns_run: bool = True, estimate: Classification | None = None
                ) -> DamGrasp.Result:
        result = DamGrasp.Result()
        result.outcome = outcome
        result.outcome_name = _OUTCOME_NAME[outcome]
        result.message = message
        wall0, grasp0 = t0
        result.duration = self._grasp_now() - grasp0
        result.wall_duration = time.monotonic() - wall0
        result.object_rise = math.nan if estimate is None else float(estimate.lift_m)
        result.object_left_table = estimate is not None and bool(estimate.lifted)
        result.object_orientation = math.nan if estimate is None else \
            float(estimate.orientation)
        last_feedback = None
        with self._lock:
            self._status_message = message
            if owns_run:
                self._pre_phase = ''
                # The status shows the outcome beside the phase the grasp ended in; a goal
                # that ended before the hand moved leaves the hand IDLE (its result says why).
                moved = self._seq.phase.terminal
                self._outcome = outcome if moved else DamGrasp.Result.OUTCOME_UNKNOWN
                self._busy = False
                last_feedback = self._feedback
                last_feedback.phase = _phase_name(self._seq.phase) if moved else 'ABORTED'
                last_feedback.outcome = outcome
                last_feedback.outcome_name = _OUTCOME_NAME[outcome]
        if last_feedback is not None:  # the end phase with the outcome beside it
            goal_handle.publish_feedback(last_feedback)
        if status == 'succeed':
            goal_handle.succeed()
        elif status == 'canceled':
            goal_handle.canceled()
        else:
            goal_handle.abort()
        self._publish_status()
        self._episodes.ended(goal_handle.goal_id.uuid, goal_handle.request, result)
        # One call site per severity: rclpy refuses a call site whose severity changes
        # ("Logger severity cannot be changed between calls").
        text = f'grasp ended ({status}): {result.outcome_name}: {message}'
        if outcome == DamGrasp.Result.OUTCOME_SUCCESS:
            self.get_logger().info(text)
        else:
            self.get_logger().warning(text)
        return result

    def _grasp_now(self) -> float:
        """Now on the grasp's clock [s]: simulated time without the /clock jumps, or the
        steady clock."""
        return self._clock_watch.steady_now_s() if self._sim_time else time.monotonic()

    async def _execute(self, goal_handle: ServerGoalHandle) -> DamGrasp.Result:
        t0 = (time.monotonic(), self._grasp_now())
        self._episodes.started(goal_handle.goal_id.uuid, goal_handle.request)
        try:
            k, dp = self._validate_goal(goal_handle.request)
        except InputError as exc:
            return self._refuse(goal_handle, str(exc), t0)
        with self._lock:
            busy = self._busy
            if busy:
                activity = ('the hand is being released' if self._release is not None
                            else f'a grasp is already running (phase '
                                 f'{_phase_name(self._seq.phase)})')
            elif self._seq.phase is Phase.DONE and self._publishing:
                # A grasp from a hand that holds the last one's object would start closed
                # around it and report that object's rise as its own.
                busy = True
                activity = (f'the hand still holds the previous grasp (DONE, outcome '
                            f'{_OUTCOME_NAME[self._outcome]}): let go first with '
                            f'{self._release_hint()}')
            else:
                self._busy = True
        if busy:
            return self._refuse(goal_handle, activity, t0)
        ratios = self._layout.stiffness_ratios
        self._episodes.running(goal_handle.goal_id.uuid, k * ratios / ratios[0],
                               [dp] * self._layout.n_fingers)
        try:
            return await self._run_goal(goal_handle, k, dp, t0)
        except Exception as exc:  # noqa: BLE001 - the node must stay up and accept goals
            self.get_logger().error(f'internal error during the grasp: {brief_repr(exc)}')
            with self._lock:
                self._goal_handle = None
                self._run_done = None
                self._seq.fail(f'internal error: {brief_repr(exc)}')
            return self._finish(goal_handle, 'abort', DamGrasp.Result.OUTCOME_ABORTED,
                                f'internal error: {brief_repr(exc)}', t0)

    async def _run_goal(self, goal_handle: ServerGoalHandle, k: float, dp: float, t0: _Start
                        ) -> DamGrasp.Result:
        aborted = DamGrasp.Result.OUTCOME_ABORTED
        with self._lock:
            # The previous grasp's end (DONE, FAILED, ABORTED) is over: a fresh sequence, and
            # the status says what this goal does now.
            self._seq = DamSequence(self._params)
            self._last_phase = self._seq.phase
            self._pre_phase = 'CHECK_LIFT'
            self._outcome = DamGrasp.Result.OUTCOME_UNKNOWN
            self._status_message = (f'grasp k_theta {k:g} N*m/rad, delta_theta_p '
                                    f'{math.degrees(dp):.4g} deg')
        self._publish_status()
        feedback = DamGrasp.Feedback()
        feedback.phase = 'CHECK_LIFT'
        with self._lock:
            self._feedback = feedback  # this goal's, also for its last feedback (_finish)
        if self._unanalysable:
            return self._finish(goal_handle, 'abort', aborted,
                                f'the analysis cannot answer for this grasp, so it is not '
                                f'attempted: {self._unanalysable}', t0)
        answer = await self._ask_check_lift(k, dp, goal_handle)
        self._episodes.checked(goal_handle.goal_id.uuid, answer)
        if goal_handle.is_cancel_requested:
            return self._finish(goal_handle, 'canceled', aborted,
                                'cancelled before the hand moved', t0)
        if answer is not None and answer.ok:
            feedback.lift_checked = True
            feedback.lift_guaranteed = bool(answer.lift_guaranteed)
            feedback.worst_case_margin = float(answer.worst_case_margin)
            feedback.csm_lift = bool(answer.csm_lift)
            feedback.csm_margin = float(answer.csm_margin)
        goal_handle.publish_feedback(feedback)
        if answer is not None and not answer.ok:
            # The analysis cannot answer for this object or pair (e.g. the fingers reach no
            # first contact with it): whatever the hand did then would be claimed without
            # evidence. Refused, with or without require_lift_guarantee.
            return self._finish(goal_handle, 'abort', aborted,
                                f'/check_lift cannot answer for this grasp, so it is not '
                                f'attempted: {answer.message}', t0)
        refusal = guarantee_refusal(answer, k, dp) \
            if self._flags['require_lift_guarantee'] else None
        if refusal is not None:
            return self._finish(goal_handle, 'abort', aborted, refusal, t0)
        fresh = await self._fresh_state(_START_STATE_WAIT_S, goal_handle)
        if goal_handle.is_cancel_requested:
            return self._finish(goal_handle, 'canceled', aborted,
                                'cancelled before the hand moved', t0)
        if not fresh:
            return self._finish(goal_handle, 'abort', aborted,
                                f'no /joint_states within {_START_STATE_WAIT_S:g} s: '
                                'cannot start the grasp (a driver in ERROR stops them: '
                                'see /diagnostics; /hand_driver/reset resumes)', t0)
        with self._lock:
            self._seq = DamSequence(self._params)
            self._last_phase = self._seq.phase
            self._state_timed_out = False
            self._silence_seen_at = None
            try:
                self._seq.start(k, dp)
            except (InputError, StateError) as exc:
                return self._finish(goal_handle, 'abort', aborted, str(exc), t0)
            self._publishing = True
            self._pre_phase = ''
            self._feedback = feedback
            self._cancel_sent = False
            self._run_done = Future()
            self._goal_handle = goal_handle
        run_done = self._run_done
        phase = await run_done
        with self._lock:
            self._goal_handle = None
            self._run_done = None
            pos = self._last_pos.copy()
            eff = self._last_eff.copy()
            history = self._seq.history  # recording ended with DONE: nothing appends now
            reason = self._seq.failure_reason
            timed_out = self._state_timed_out or self._shutting_down
        if phase is Phase.DONE:
            return self._classify_and_finish(goal_handle, pos, eff, history, t0)
        if phase is Phase.ABORTED:
            return self._finish(goal_handle, 'canceled' if goal_handle.is_cancel_requested
                                else 'abort', aborted, 'cancelled: torque ramped to zero', t0)
        outcome = aborted if timed_out else DamGrasp.Result.OUTCOME_FAILURE
        return self._finish(goal_handle, 'abort', outcome, f'failed: {reason}', t0)

    def _classify_and_finish(self, goal_handle: ServerGoalHandle, pos: np.ndarray,
                             eff: np.ndarray, history: JointHistory, t0: _Start
                             ) -> DamGrasp.Result:
        try:
            c = classify_from_joints(self._geometry, self._layout.lower, self._layout.upper,
                                     pos, eff, self._classifier, self._layout.joint_names,
                                     stop=lambda: SHUTDOWN.requested, history=history)
        except FitInterrupted:
            return self._finish(goal_handle, 'abort', DamGrasp.Result.OUTCOME_UNKNOWN,
                                'grasp done, not classified: the controller is stopping', t0)
        except Exception as exc:  # noqa: BLE001 - the node must stay up whatever happens
            return self._finish(goal_handle, 'abort', DamGrasp.Result.OUTCOME_UNKNOWN,
                                f'grasp done, classification failed: {brief_repr(exc)}', t0)
        outcome = _OUTCOME[c.outcome]
        # Goal status SUCCEEDED means the outcome SUCCESS, for every generic action client.
        status = 'succeed' if outcome == DamGrasp.Result.OUTCOME_SUCCESS else 'abort'
        return self._finish(goal_handle, status, outcome, f'grasp done: {c.reason}', t0,
                            estimate=c)


def main(args: list[str] | None = None) -> None:
    # A bad start-up parameter: one clear fatal line and exit status 2.
    run_node(SpcmControllerNode, 'spcm_controller', args,
             startup_errors=(InputError, DamAnalysisError),
             startup_exit_code=2)


if __name__ == '__main__':
    main()
