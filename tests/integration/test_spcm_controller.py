"""spcm_controller over DDS: real controller, fixture plant and check_lift_server processes."""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path

import numpy as np
import pytest

from ros_testing import (
    RosClient,
    fixture_command,
    installed_executable,
    node_process,
    thread_policies,
)

# Real-time runs on a shared 2-core machine: a test that fails is run once more (the rerun is
# reported as R in pytest's summary); a deterministic failure fails twice.
pytestmark = [pytest.mark.integration, pytest.mark.flaky(reruns=1)]

REPO = Path(__file__).resolve().parents[2]
CONTROLLER = installed_executable('dam_spcm_controller', 'spcm_controller')
# Short motions keep a full grasp at a few seconds on the synthetic plant. The plant is massless
# with viscous friction b = 0.1 N*m*s/rad: a controller damping above b makes it alternate from
# step to step (the configured 0.2 is for the simulated hand's drive inertia).
FAST = ['-p', 'trajectory_duration:=1.0', '-p', 'approach_speed:=0.5', '-p', 'damping:=0.02']
INSIDE = (7.0, math.radians(10.0))  # k_theta [N*m/rad], delta_theta_p [rad]: lift guaranteed
OUTSIDE = (0.5, math.radians(40.0))  # outside the sufficient region at alpha = 5 deg
BEYOND_TORQUE = (63.0, math.radians(10.0))  # guaranteed by eq. 18 with 3 N*m on finger 1


def controller_command(*ros_args: str) -> list[str]:
    return [str(CONTROLLER), '--ros-args', *FAST, *ros_args]


class Harness:
    """Client node: action client, /hand/command and /dam/status recorders."""

    def __init__(self) -> None:
        from rclpy.action import ActionClient

        from dam_interfaces.action import DamGrasp
        from dam_interfaces.msg import DamStatus, HandCommand

        self.ros = RosClient()
        self.node = self.ros.node
        self.commands: list[tuple[float, HandCommand]] = []
        self.statuses: list[DamStatus] = []
        self.node.create_subscription(HandCommand, '/hand/command', self._on_command, 100)
        self.node.create_subscription(DamStatus, '/dam/status', self.statuses.append, 100)
        self.action = ActionClient(self.node, DamGrasp, '/dam_grasp')
        self.feedback: list = []

    def _on_command(self, msg) -> None:
        self.commands.append((time.monotonic(), msg))

    def wait_ready(self, check_lift: bool = True) -> None:
        assert self.action.wait_for_server(timeout_sec=30.0), '/dam_grasp did not appear'
        assert self.ros.spin_until(lambda: len(self.statuses) > 0, 30.0), 'no /dam/status'
        from sensor_msgs.msg import JointState

        states: list = []
        sub = self.node.create_subscription(JointState, '/joint_states', states.append, 10)
        assert self.ros.spin_until(lambda: len(states) > 0, 30.0), 'no /joint_states'
        self.node.destroy_subscription(sub)
        if not check_lift:
            return
        from dam_interfaces.srv import CheckLift

        client = self.node.create_client(CheckLift, '/check_lift')
        assert client.wait_for_service(timeout_sec=30.0), '/check_lift did not appear'
        self.node.destroy_client(client)

    def send(self, k: list[float] | None, dp: list[float] | None):
        """Send a goal (``None``: the field left as default-constructed); return the goal
        handle (accepted or not)."""
        from dam_interfaces.action import DamGrasp

        goal = DamGrasp.Goal()
        if k is not None:
            goal.k_theta = k
        if dp is not None:
            goal.delta_theta_p = dp
        future = self.action.send_goal_async(goal, feedback_callback=self.feedback.append)
        assert self.ros.spin_until(future.done, 15.0), 'no goal response'
        return future.result()

    def result(self, handle, timeout: float = 30.0):
        future = handle.get_result_async()
        assert self.ros.spin_until(future.done, timeout), 'no result in time'
        return future.result()

    def wait_phase(self, handle, phase: str, timeout: float) -> None:
        """Spin until feedback shows ``phase``; on failure report the goal's result."""
        result = handle.get_result_async()
        if self.ros.spin_until(lambda: phase in self.phases() or result.done(), timeout) \
                and phase in self.phases():
            return
        detail = result.result().result.message if result.done() else 'still running'
        raise AssertionError(f'phase {phase} not reached: {self.phases()}; {detail}')

    def phases(self) -> list[str]:
        seen: list[str] = []
        for fb in self.feedback:
            if not seen or seen[-1] != fb.feedback.phase:
                seen.append(fb.feedback.phase)
        return seen

    def set_parameter(self, name: str, value):
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter

        request = SetParameters.Request()
        request.parameters = [Parameter(name, value=value).to_parameter_msg()]
        return self.ros.call(SetParameters, '/spcm_controller/set_parameters', request).results[0]

    def close(self) -> None:
        self.action.destroy()
        self.ros.close()


#: A stack parameter that starts no check_lift_server (the controller waits for it in vain).
NO_CHECK_LIFT = '--no-check-lift-server'


@pytest.fixture
def stack(request) -> Iterator[tuple[Harness, object, object]]:
    """Plant, check_lift_server and controller; ``request.param``: the controller's extra ROS
    arguments, and :data:`NO_CHECK_LIFT` to leave the analysis server out."""
    extra = list(getattr(request, 'param', []))
    with_check_lift = NO_CHECK_LIFT not in extra
    extra = [a for a in extra if a != NO_CHECK_LIFT]
    env = {'PYTHONPATH': os.pathsep.join([str(REPO / 'src' / 'dam_analysis'),
                                          os.environ.get('PYTHONPATH', '')])}
    with ExitStack() as es:
        plant = es.enter_context(node_process(fixture_command('spcm_plant_node.py'), env))
        if with_check_lift:
            es.enter_context(node_process(
                [str(installed_executable('dam_analysis', 'check_lift_server'))]))
        ctl = es.enter_context(node_process(controller_command(*extra)))
        harness = Harness()
        es.callback(harness.close)
        harness.wait_ready(with_check_lift)
        yield harness, ctl, plant
        assert ctl.alive(), ctl.output()


def _torques(msg) -> list[float]:
    from dam_interfaces.msg import HandCommand

    return [s for m, s in zip(msg.mode, msg.setpoint, strict=True) if m == HandCommand.MODE_TORQUE]


def _compliant(msg) -> list[tuple[int, float, float, float]]:
    """(mode, setpoint, stiffness, damping) of the compliant joints of a HandCommand."""
    out = []
    for i, name in enumerate(msg.name):
        if name.endswith('_compliant_joint'):
            k = msg.stiffness[i] if len(msg.stiffness) else 0.0
            d = msg.damping[i] if len(msg.damping) else 0.0
            out.append((msg.mode[i], msg.setpoint[i], k, d))
    return out


def test_full_grasp_second_goal_and_parameters(stack) -> None:
    from action_msgs.msg import GoalStatus

    from dam_interfaces.action import DamGrasp

    h, ctl, _plant = stack
    handle = h.send([INSIDE[0]], [INSIDE[1]])
    assert handle.accepted
    h.wait_phase(handle, 'APPROACH', 10.0)
    # A second goal while one runs ends at once, ABORTED with OUTCOME_REJECTED and the
    # reason in its result (what `ros2 action send_goal` prints); a parameter change is refused.
    second = h.send([INSIDE[0]], [INSIDE[1]])
    assert second.accepted
    refused_goal = h.result(second, 5.0)
    assert refused_goal.status == GoalStatus.STATUS_ABORTED
    assert refused_goal.result.outcome == DamGrasp.Result.OUTCOME_REJECTED
    assert refused_goal.result.outcome_name == 'REJECTED'
    assert 'already running' in refused_goal.result.message
    refused = h.set_parameter('envelope_torque', 0.1)
    assert not refused.successful and 'grasp is running' in refused.reason
    res = h.result(handle, 40.0)
    # SUCCEEDED exactly when the outcome is SUCCESS; any other outcome ends ABORTED.
    success = res.result.outcome == DamGrasp.Result.OUTCOME_SUCCESS
    expected_status = GoalStatus.STATUS_SUCCEEDED if success else GoalStatus.STATUS_ABORTED
    assert res.status == expected_status, (res.result.outcome_name, res.result.message)
    # The last feedback shows the phase the grasp ended in with its outcome beside it
    # (it may reach us just after the result).
    h.ros.spin_until(lambda: h.feedback and h.feedback[-1].feedback.outcome != 0, 2.0)
    last = h.feedback[-1].feedback
    assert (last.phase, last.outcome, last.outcome_name) == (
        'DONE', res.result.outcome, res.result.outcome_name), last
    phases = h.phases()
    for phase in ('APPROACH', 'ROLLING_UP', 'ENVELOPE', 'CLASSIFYING', 'DONE'):
        assert phase in phases, phases
    assert all(f.feedback.outcome == 0 for f in h.feedback[:-1])  # decided at the end only
    # /dam/status never shows an end phase without the outcome (a failed grasp ended 'DONE'
    # with outcome 3, a number, beside it), and it ends with the result's.
    h.ros.spin_until(lambda: h.statuses and h.statuses[-1].outcome != 0, 2.0)
    ends = [st for st in h.statuses if st.phase in ('DONE', 'ABORTED', 'FAILED')]
    assert ends and all(st.outcome == res.result.outcome for st in ends), \
        [(st.phase, st.outcome) for st in ends]
    assert (h.statuses[-1].phase, h.statuses[-1].outcome_name) == (
        'DONE', res.result.outcome_name)
    # no IDLE tick between CHECK_LIFT and APPROACH (nor anywhere else)
    assert phases[:2] == ['CHECK_LIFT', 'APPROACH'] and 'IDLE' not in phases, phases
    assert phases.index('APPROACH') < phases.index('ROLLING_UP') < phases.index('ENVELOPE')
    checked = [f.feedback for f in h.feedback if f.feedback.lift_checked]
    assert checked and all(fb.lift_guaranteed for fb in checked)
    assert res.result.outcome in (DamGrasp.Result.OUTCOME_SUCCESS,
                                  DamGrasp.Result.OUTCOME_LIFTED_DAM_FAILED,
                                  DamGrasp.Result.OUTCOME_FAILURE)
    assert res.result.outcome_name in ('SUCCESS', 'LIFTED_DAM_FAILED', 'FAILURE')
    assert res.result.message.startswith('grasp done')
    assert res.result.duration > 1.0  # at least the 1 s trajectory
    # Idle again: the same parameter change is accepted; a bad value is refused.
    assert h.set_parameter('envelope_torque', 0.1).successful
    bad = h.set_parameter('envelope_torque', 5.0)  # above torque_limit 0.6 N*m
    assert not bad.successful and 'torque_limit' in bad.reason
    assert not h.set_parameter('trajectory_duration', 1000.0).successful  # outside its range
    assert not h.set_parameter('status_rate', 50.0).successful  # read-only
    assert h.set_parameter('require_lift_guarantee', True).successful
    assert ctl.alive()


BAD_GOALS = [
    ([math.nan], [0.2], 'k_theta'),
    ([-1.0], [0.2], 'positive'),
    ([1.0, 2.0], [0.2], 'expected 1 or 3'),
    ([1.0], [0.1, 0.2], 'expected 1 or 3'),
    ([1.0], [math.radians(80.0)], 'delta_theta_p_max'),
    ([1.0], [0.0], 'must be positive'),
    ([150.0], [0.2], 'max_stiffness_nm_per_rad'),  # beyond what the device accepts
]


def test_bad_goals_end_with_their_reason(stack) -> None:
    """A malformed goal is accepted and ends at once: ABORTED, OUTCOME_REJECTED, the field and
    the value in the result's message (a plain rejection could not carry the reason)."""
    from action_msgs.msg import GoalStatus

    from dam_interfaces.action import DamGrasp
    from dam_interfaces.msg import HandCommand

    h, ctl, _plant = stack
    n_commands = len(h.commands)
    for k, dp, words in BAD_GOALS:
        handle = h.send(k, dp)
        assert handle.accepted, (k, dp)
        res = h.result(handle, 5.0)
        assert res.status == GoalStatus.STATUS_ABORTED, (k, dp)
        assert res.result.outcome == DamGrasp.Result.OUTCOME_REJECTED, (k, dp)
        assert res.result.message.startswith('goal refused') and words in res.result.message, \
            (k, dp, res.result.message)
        assert ctl.alive()
    # The hand was never commanded. (The controller's one start-up command may arrive late
    # on a loaded machine: it holds every joint, it moves nothing.)
    moving = [m for _t, m in h.commands[n_commands:]
              if any(mode != HandCommand.MODE_HOLD for mode in m.mode)]
    assert not moving, f'{len(moving)} commands were sent for refused goals'
    # Bad joint states (unknown names, NaN) are dropped with a log; the node stays up.
    from sensor_msgs.msg import JointState

    pub = h.node.create_publisher(JointState, '/joint_states', 10)
    wrong = JointState(name=['elbow'], position=[0.0], velocity=[0.0], effort=[0.0])
    names = [f'finger{i}_{r}_joint' for i in (1, 2, 3)
             for r in ('compliant', 'locked', 'position')]
    nan = JointState(name=names, position=[math.nan] * 9, velocity=[0.0] * 9,
                     effort=[0.0] * 9)
    for _ in range(5):
        pub.publish(wrong)
        pub.publish(nan)
        h.ros.spin_until(lambda: False, 0.05)
    assert h.ros.spin_until(lambda: 'dropped /joint_states' in ctl.output(), 10.0), \
        ctl.output()[-2000:]
    assert 'position of finger1_compliant_joint is nan' in ctl.output() or \
        'joint names missing' in ctl.output()
    assert ctl.alive()
    # The node still serves a good goal afterwards.
    good = h.send([INSIDE[0]], [INSIDE[1]])
    assert good.accepted
    h.wait_phase(good, 'APPROACH', 10.0)
    good.cancel_goal_async()
    h.result(good, 20.0)


@pytest.mark.parametrize('stack', [['-p', 'require_lift_guarantee:=true']], indirect=True)
def test_require_lift_guarantee_refuses_pair_outside_region(stack) -> None:
    from action_msgs.msg import GoalStatus

    from dam_interfaces.action import DamGrasp

    h, _ctl, _plant = stack
    handle = h.send([OUTSIDE[0]], [OUTSIDE[1]])
    assert handle.accepted
    res = h.result(handle, 20.0)
    assert res.status == GoalStatus.STATUS_ABORTED
    assert res.result.outcome == DamGrasp.Result.OUTCOME_ABORTED
    assert 'sufficient-lift region' in res.result.message
    assert any(f.feedback.lift_checked and not f.feedback.lift_guaranteed for f in h.feedback)
    # Guaranteed by eq. 18, but with about 3 N*m on finger 1, more than the hand gives.
    h.feedback.clear()
    handle = h.send([BEYOND_TORQUE[0]], [BEYOND_TORQUE[1]])
    assert handle.accepted
    res = h.result(handle, 20.0)
    assert res.status == GoalStatus.STATUS_ABORTED
    assert 'more compliant torque than the hand gives (0.6 N*m)' in res.result.message
    assert any(f.feedback.lift_checked and f.feedback.lift_guaranteed for f in h.feedback)
    # The inside pair starts (reaches APPROACH), then is cancelled.
    h.feedback.clear()
    handle = h.send([INSIDE[0]], [INSIDE[1]])
    assert handle.accepted
    h.wait_phase(handle, 'APPROACH', 10.0)
    handle.cancel_goal_async()
    assert h.result(handle, 20.0).status == GoalStatus.STATUS_CANCELED


def test_cancel_mid_grasp_ramps_torque_to_zero(stack) -> None:
    from action_msgs.msg import GoalStatus

    from dam_interfaces.action import DamGrasp

    h, _ctl, _plant = stack
    handle = h.send([INSIDE[0]], [INSIDE[1]])
    assert handle.accepted
    h.wait_phase(handle, 'ROLLING_UP', 15.0)
    from dam_interfaces.msg import HandCommand

    # impedance on the device (the default): equilibrium and gains, no torque commands
    rolling = _compliant(h.commands[-1][1])
    assert len(rolling) == 3
    k_i = [INSIDE[0], INSIDE[0] / 2, INSIDE[0] / 2]
    for (mode, _theta_0, k, d), k_expected in zip(rolling, k_i, strict=True):
        assert mode == HandCommand.MODE_IMPEDANCE and k == pytest.approx(k_expected)
        assert d == pytest.approx(0.02)  # the damping parameter (FAST)
    assert not _torques(h.commands[-1][1])
    cancel = handle.cancel_goal_async()
    res = h.result(handle, 20.0)
    assert h.ros.spin_until(cancel.done, 10.0)
    assert len(cancel.result().goals_canceling) == 1
    assert res.status == GoalStatus.STATUS_CANCELED
    assert res.result.outcome == DamGrasp.Result.OUTCOME_ABORTED
    h.ros.spin_until(lambda: False, 0.3)
    last = h.commands[-1][1]
    assert _torques(last) and all(t == 0.0 for t in _torques(last)), list(last.setpoint)
    # The status tells the joints' measured effort (zero: the plant applies the zero torque)
    # from the estimate -K dtheta_s (the old compliant_torque), which the zero torque leaves
    # where the deflection stands.
    h.ros.spin_until(lambda: False, 0.2)
    status = h.statuses[-1]
    assert list(status.compliant_effort_measured) == [0.0, 0.0, 0.0], status
    assert list(status.compliant_torque_estimate) == list(status.compliant_torque), status


@pytest.mark.skipif(not os.path.isdir('/proc'), reason='reads /proc')
def test_controller_threads_never_run_real_time(stack) -> None:
    """The controller is no real-time loop (the device runs the impedance law): every thread
    keeps the normal policy, so that it never uses up the kernel's real-time budget."""
    _h, ctl, _plant = stack
    assert set(thread_policies(ctl.pid)) == {(0, 0)}


def _grasp_until(h: Harness, phase: str, timeout: float, refused: tuple[str, object]):
    """Send the INSIDE goal, wait for ``phase`` and check that setting the parameter
    ``refused`` = (name, value) is refused while the grasp runs; return the goal handle."""
    handle = h.send([INSIDE[0]], [INSIDE[1]])
    assert handle.accepted
    h.wait_phase(handle, phase, timeout)
    answer = h.set_parameter(*refused)
    assert not answer.successful and 'grasp is running' in answer.reason
    return handle


@pytest.mark.parametrize('stack', [['-p', 'impedance_on_device:=false']], indirect=True)
def test_impedance_in_the_controller_sends_torques(stack) -> None:
    """impedance_on_device false: the controller closes the loop itself (MODE_TORQUE, no
    gains); the parameter is refused while a grasp runs and accepts only a bool."""
    from action_msgs.msg import GoalStatus

    h, _ctl, _plant = stack
    handle = _grasp_until(h, 'ROLLING_UP', 15.0, refused=('impedance_on_device', True))
    h.ros.spin_until(lambda: False, 0.3)
    grasp = [m for _, m in h.commands if len(_torques(m)) == 3]  # APPROACH and ROLLING_UP
    assert len(grasp) > 100
    # the synthetic plant lags the closing equilibrium: the approach needs a real torque
    assert max(abs(t) for m in grasp for t in _torques(m)) > 1e-3
    assert all(len(m.stiffness) == 0 and len(m.damping) == 0 for m in grasp)
    handle.cancel_goal_async()
    assert h.result(handle, 20.0).status == GoalStatus.STATUS_CANCELED
    assert not h.set_parameter('impedance_on_device', 1.0).successful
    assert h.set_parameter('impedance_on_device', True).successful


@pytest.mark.parametrize('stack', [['-p', 'envelope_constant_torque:=true']], indirect=True)
def test_envelope_constant_torque_closes_with_the_paper_torque(stack) -> None:
    """envelope_constant_torque: ENVELOPE puts the compliant joints in MODE_TORQUE and ramps
    them to envelope_torque * ratio_i / max ratio (paper Fig. 6(d)); refused while running."""
    from dam_common.config import load_config
    from dam_interfaces.msg import HandCommand

    cfg = load_config()
    ratios = np.asarray(cfg.hand.stiffness_ratios, dtype=float)
    expected = cfg.controller.envelope_torque_nm * ratios / ratios.max()
    h, _ctl, _plant = stack
    handle = _grasp_until(h, 'ENVELOPE', 30.0, refused=('envelope_constant_torque', False))
    h.ros.spin_until(lambda: False, 0.5)  # past the torque ramp
    last = _compliant(h.commands[-1][1])
    assert [mode for mode, *_ in last] == [HandCommand.MODE_TORQUE] * 3, last
    np.testing.assert_allclose([sp for _, sp, _, _ in last], expected, rtol=1e-9)
    h.result(handle, 40.0)
    assert not h.set_parameter('envelope_constant_torque', 'yes').successful
    assert h.set_parameter('envelope_constant_torque', False).successful


@pytest.mark.parametrize('stack', [[], ['-p', 'use_sim_time:=true']], indirect=True,
                         ids=['wall_clock', 'use_sim_time_without_clock'])
def test_plant_silence_aborts_with_zero_torque(stack, request) -> None:
    """On the wall clock the silence is caught after state_timeout (0.1 s). With use_sim_time
    the grasp runs on the joint states' stamps and the simulated clock; with no /clock at all
    (nothing simulates) a silence still ends the grasp, after sim.stall_timeout_s of wall
    time."""
    from action_msgs.msg import GoalStatus
    from std_srvs.srv import Trigger

    from dam_common.config import load_config

    sim_time = 'use_sim_time_without_clock' in request.node.callspec.id
    bound = float(load_config().sim.stall_timeout_s) if sim_time else 0.1
    h, _ctl, _plant = stack
    handle = h.send([INSIDE[0]], [INSIDE[1]])
    assert handle.accepted
    h.wait_phase(handle, 'ROLLING_UP', 15.0)
    assert h.ros.call(Trigger, '/plant/stop', Trigger.Request()).success
    t_stop = time.monotonic()
    res = h.result(handle, bound + 10.0)
    took = time.monotonic() - t_stop
    assert bound <= took < bound + 1.0, took  # plus DDS and polling
    assert res.status == GoalStatus.STATUS_ABORTED
    assert 'joint_states silent' in res.result.message
    assert ('of wall time' in res.result.message) == sim_time, res.result.message
    h.ros.spin_until(lambda: False, 0.3)
    last_t, last = h.commands[-1]
    assert last_t > t_stop  # the zero-torque command came after the plant went silent
    assert _torques(last) and all(t == 0.0 for t in _torques(last)), list(last.setpoint)
    assert any(s.phase == 'FAILED' for s in h.statuses)
    # The next goal ends the FAILED status at once (it cannot run: the plant is silent).
    seen = len(h.statuses)
    again = h.result(h.send([INSIDE[0]], [INSIDE[1]]), bound + 10.0)
    assert again.status == GoalStatus.STATUS_ABORTED
    h.ros.spin_until(lambda: False, 0.2)
    later = [st.phase for st in h.statuses[seen:]]
    assert 'CHECK_LIFT' in later and later[-1] != 'FAILED', later


def test_default_goal_grasps_with_the_configured_pair(stack) -> None:
    """A default-constructed goal (`ros2 action send_goal /dam_grasp ... "{}"`) grasps with
    the configured task pair: the stiffness sent to the hand is k_theta_i of the config."""
    from dam_common.config import load_config
    from dam_interfaces.msg import HandCommand

    cfg = load_config()
    ratios = np.asarray(cfg.hand.stiffness_ratios, dtype=float)
    h, _ctl, _plant = stack
    handle = h.send(None, None)
    assert handle.accepted
    h.wait_phase(handle, 'APPROACH', 10.0)
    assert h.ros.spin_until(
        lambda: any(m == HandCommand.MODE_IMPEDANCE for _, c in h.commands[-1:]
                    for m, *_ in _compliant(c)), 5.0)
    stiffness = [k for _, c in h.commands[-1:] for _m, _s, k, _d in _compliant(c)]
    np.testing.assert_allclose(stiffness, cfg.task.k_theta_nm_per_rad * ratios, rtol=1e-12)
    checked = [f.feedback for f in h.feedback if f.feedback.lift_checked]
    assert checked, 'the configured pair was checked with /check_lift'
    handle.cancel_goal_async()
    h.result(handle, 20.0)


@pytest.mark.parametrize('stack', [[NO_CHECK_LIFT]], indirect=True)
def test_cancel_before_the_hand_moved_is_immediate_and_silent(stack) -> None:
    """/check_lift absent: the goal waits for it (check_lift_timeout 2 s). A cancel meanwhile
    ends the goal CANCELED at once, and not a single command reaches the hand."""
    from action_msgs.msg import GoalStatus

    from dam_interfaces.action import DamGrasp
    from dam_interfaces.msg import HandCommand

    h, _ctl, _plant = stack
    h.ros.spin_until(lambda: False, 0.5)  # past the controller's one start-up HOLD command
    t_goal = time.monotonic()
    handle = h.send([INSIDE[0]], [INSIDE[1]])
    assert handle.accepted
    h.ros.spin_until(lambda: False, 0.1)
    result = handle.get_result_async()
    t_cancel = time.monotonic()
    cancel = handle.cancel_goal_async()
    assert h.ros.spin_until(result.done, 5.0)
    elapsed = time.monotonic() - t_cancel
    assert cancel.done() and len(cancel.result().goals_canceling) == 1
    res = result.result()
    assert res.status == GoalStatus.STATUS_CANCELED
    assert res.result.outcome == DamGrasp.Result.OUTCOME_ABORTED
    assert 'before the hand moved' in res.result.message
    # the controller polls every 20 ms; the rest is two DDS round trips on this machine
    assert elapsed < 0.1, f'CANCELED {elapsed:.3f} s after the cancel request'
    h.ros.spin_until(lambda: False, 2.5)  # past the check_lift timeout
    # (the start-up command, if it came this late, holds every joint: it moves nothing)
    moving = [m for t, m in h.commands
              if t >= t_goal and any(mode != HandCommand.MODE_HOLD for mode in m.mode)]
    assert not moving, f'{len(moving)} commands were sent for a cancelled goal'


def test_release_lets_go_and_stops_commanding(stack) -> None:
    """~/release after DONE: compliant torques ramp to zero, the position joints open back to
    the pre-shape angle, every joint ends in HOLD and no command follows."""
    from action_msgs.msg import GoalStatus
    from std_srvs.srv import Trigger

    from dam_common.config import load_config
    from dam_interfaces.msg import HandCommand

    cfg = load_config()
    h, ctl, _plant = stack
    # Refused while nothing has been grasped? No: an idle hand may be opened too. Refused while
    # a grasp runs.
    handle = h.send([INSIDE[0]], [INSIDE[1]])
    assert handle.accepted
    h.wait_phase(handle, 'APPROACH', 10.0)
    busy = h.ros.call(Trigger, '/spcm_controller/release', Trigger.Request())
    assert not busy.success and 'cancel its goal first' in busy.message
    res = h.result(handle, 40.0)
    assert 'DONE' in h.phases(), (res.result.message, h.phases())
    h.ros.spin_until(lambda: False, 0.3)
    held = h.commands[-1][1]
    assert any(m == HandCommand.MODE_IMPEDANCE for m, *_ in _compliant(held))  # still holding
    # The result's duration is on the grasp's clock (steady here), its wall time beside it.
    assert 1.0 < res.result.duration <= res.result.wall_duration + 1e-3, res.result
    # A goal while the hand holds this grasp is refused with the reason, and the hand keeps
    # holding (it would start closed around the object and report its rise as its own).
    n_held = len(h.commands)
    again = h.send([INSIDE[0]], [INSIDE[1]])
    refused = h.result(again, 5.0)
    assert refused.status == GoalStatus.STATUS_ABORTED
    assert refused.result.outcome_name == 'REJECTED', refused.result.message
    assert 'still holds the previous grasp' in refused.result.message and \
        '/spcm_controller/release' in refused.result.message, refused.result.message
    h.ros.spin_until(lambda: False, 0.2)
    assert len(h.commands) > n_held and all(
        any(mode == HandCommand.MODE_IMPEDANCE for mode, *_ in _compliant(m))
        for _t, m in h.commands[n_held:]), 'the hand stopped holding'
    t_release = time.monotonic()
    answer = h.ros.call(Trigger, '/spcm_controller/release', Trigger.Request(), timeout=30.0)
    assert answer.success, answer.message
    h.ros.spin_until(lambda: False, 0.3)  # the last commands may follow the answer here
    during = [m for t, m in h.commands if t >= t_release]
    assert during, 'no release command'
    torques = [_torques(m) for m in during if len(_torques(m)) == 3]
    assert torques, 'the compliant joints did not go to torque mode to unload'
    peak = [max(abs(v) for v in t) for t in torques]
    assert peak[-1] == 0.0 and all(np.diff(peak) <= 1e-12), peak
    position = [i for i, n in enumerate(during[-1].name) if n.endswith('_position_joint')]
    opening = [m for m in during if all(m.mode[i] == HandCommand.MODE_POSITION
                                        for i in position)]
    assert opening, 'the position joints were not moved'
    goal = cfg.hand.initial_position_angle_rad
    assert all(abs(opening[-1].setpoint[i] - goal) < 0.01 for i in position)
    last = during[-1]
    assert all(m == HandCommand.MODE_HOLD for m in last.mode), list(last.mode)
    n_after = len(h.commands)
    h.ros.spin_until(lambda: False, 0.5)
    assert len(h.commands) == n_after, 'commands after the release'
    assert any(s.phase == 'RELEASING' for s in h.statuses)
    assert h.ros.spin_until(lambda: h.statuses[-1].phase == 'IDLE', 2.0)
    # The grasp's outcome went with it: releasing and IDLE show none (IDLE showed the
    # previous outcome still set).
    assert all(st.outcome == 0 for st in h.statuses if st.phase == 'RELEASING')
    assert (h.statuses[-1].outcome, h.statuses[-1].outcome_name) == (0, 'UNKNOWN')
    # A new grasp starts from there.
    again = h.send([INSIDE[0]], [INSIDE[1]])
    assert again.accepted
    h.wait_phase(again, 'APPROACH', 10.0)
    again.cancel_goal_async()
    assert h.result(again, 20.0).status == GoalStatus.STATUS_CANCELED
    assert ctl.alive()


@pytest.mark.parametrize('stack', [['-p', 'torque_ramp_time:=3.0']], indirect=True)
def test_release_answers_failure_when_joint_states_go_silent(stack) -> None:
    """The plant stops publishing while the hand is released (a 3 s unloading ramp): the
    release ends with success false and the reason, within a bounded time."""
    from std_srvs.srv import Trigger

    h, ctl, _plant = stack
    client = h.node.create_client(Trigger, '/spcm_controller/release')
    assert client.wait_for_service(timeout_sec=10.0)
    release = client.call_async(Trigger.Request())
    assert h.ros.spin_until(lambda: h.statuses[-1].phase == 'RELEASING', 5.0)
    assert h.ros.call(Trigger, '/plant/stop', Trigger.Request()).success
    assert h.ros.wait_future(release, 5.0), 'the release did not answer'
    answer = release.result()
    assert not answer.success and 'went silent' in answer.message, answer.message
    assert h.ros.spin_until(lambda: h.statuses[-1].phase != 'RELEASING', 2.0)
    assert ctl.alive()


#: The SIGINT test's torque ramp [s]: longer than the first client's --cancel-timeout.
_SLOW_RAMP_S = 1.5


@pytest.mark.parametrize('stack', [['-p', f'torque_ramp_time:={_SLOW_RAMP_S}']], indirect=True)
def test_grasp_client_cancels_its_goal_on_sigint(stack) -> None:
    """Ctrl-C on dam_grasp cancels the goal and exits 3: with the CANCELED result when it
    comes within --cancel-timeout; past that (a ramp longer than the timeout) at the timeout,
    saying that the controller accepted the cancel, which then ends the goal by itself."""
    import signal
    import subprocess

    h, ctl, _plant = stack

    def interrupted(*options: str) -> str:
        """Run dam_grasp, SIGINT it in ROLLING_UP; its output."""
        seen = len(h.statuses)
        client = subprocess.Popen(
            [str(installed_executable('dam_spcm_controller', 'dam_grasp')), '--k-theta',
             str(INSIDE[0]), '--delta-theta-p', f'{INSIDE[1]}rad', *options],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            stdin=subprocess.DEVNULL)
        try:
            assert h.ros.spin_until(
                lambda: any(s.phase == 'ROLLING_UP' for s in h.statuses[seen:]), 20.0), \
                [s.phase for s in h.statuses[seen:]]
            client.send_signal(signal.SIGINT)
            out, _ = client.communicate(timeout=20.0)
        finally:
            if client.poll() is None:
                client.kill()
                client.wait()
        assert client.returncode == 3, out
        assert 'cancelling' in out and 'Traceback' not in out, out
        assert h.ros.spin_until(lambda: h.statuses[-1].phase == 'ABORTED', 10.0), \
            [s.phase for s in h.statuses[-5:]]
        return out

    out = interrupted('--cancel-timeout', '0.5')
    assert 'accepted the cancel' in out and 'CANCELED' not in out, out
    out = interrupted()
    assert 'result: CANCELED' in out, out
    assert ctl.alive()


@pytest.mark.parametrize('signum', ['SIGINT', 'SIGTERM'])
def test_a_controller_stopped_mid_grasp_aborts_the_goal_for_its_client(signum: str) -> None:
    """Ctrl-C on the controller during a grasp: the client gets ABORTED with the reason, the
    compliant torques ramp to zero, and the controller exits with status 0."""
    import signal

    from action_msgs.msg import GoalStatus

    from dam_interfaces.action import DamGrasp

    env = {'PYTHONPATH': os.pathsep.join([str(REPO / 'src' / 'dam_analysis'),
                                          os.environ.get('PYTHONPATH', '')])}
    with ExitStack() as es:
        es.enter_context(node_process(fixture_command('spcm_plant_node.py'), env))
        es.enter_context(node_process(
            [str(installed_executable('dam_analysis', 'check_lift_server'))]))
        ctl = es.enter_context(node_process(controller_command()))
        h = Harness()
        es.callback(h.close)
        h.wait_ready()
        handle = h.send([INSIDE[0]], [INSIDE[1]])
        assert handle.accepted
        h.wait_phase(handle, 'ROLLING_UP', 15.0)
        result = handle.get_result_async()
        t_signal = time.monotonic()
        ctl.process.send_signal(getattr(signal, signum))
        assert h.ros.spin_until(result.done, 5.0), ctl.output()[-2000:]
        res = result.result()
        assert res.status == GoalStatus.STATUS_ABORTED
        assert res.result.outcome == DamGrasp.Result.OUTCOME_ABORTED
        assert 'shutting down' in res.result.message
        assert ctl.process.wait(timeout=5.0) == 0
        assert time.monotonic() - t_signal < 2.0
        h.ros.spin_until(lambda: False, 0.3)  # take the commands still queued here
        last = h.commands[-1][1]
        assert _torques(last) and all(t == 0.0 for t in _torques(last)), list(last.setpoint)
        assert 'Traceback' not in ctl.output()



@pytest.mark.parametrize('server', [True, False], ids=['check_lift_up', 'check_lift_down'])
def test_a_goal_the_analysis_cannot_answer_is_refused_at_once(tmp_path: Path,
                                                              server: bool) -> None:
    """An object the loader takes but the analysis cannot answer for (a 2 mm rod: the distal
    links reach no first contact with it) gets no grasp, whatever ``require_lift_guarantee``
    says: ABORTED at once with the analysis' reason, and the hand is never commanded; also
    when /check_lift is not there to say so (the controller went on after its timeout)."""
    import yaml
    from action_msgs.msg import GoalStatus

    from dam_interfaces.action import DamGrasp

    data = yaml.safe_load((REPO / 'config' / 'dam.yaml').read_text(encoding='utf-8'))
    data['object']['library']['thin_rod'] = {'shape': 'circle', 'radius_m': 0.002,
                                             'length_m': 0.1, 'mass_kg': 0.005}
    config = tmp_path / 'dam.yaml'
    config.write_text(yaml.safe_dump(data), encoding='utf-8')
    env = {'DAM_CONFIG': str(config),
           'PYTHONPATH': os.pathsep.join([str(REPO / 'src' / 'dam_analysis'),
                                          os.environ.get('PYTHONPATH', '')])}
    with ExitStack() as es:
        es.enter_context(node_process(fixture_command('spcm_plant_node.py'), env))
        if server:
            es.enter_context(node_process(
                [str(installed_executable('dam_analysis', 'check_lift_server'))], env))
        ctl = es.enter_context(node_process(controller_command('-p', 'object:=thin_rod'), env))
        h = Harness()
        es.callback(h.close)
        h.wait_ready(check_lift=server)
        # The controller holds the posture it finds with one command at its first joint
        # state: that one is not a grasp. It may come before the harness's subscription is
        # matched (the controller started first), so it is waited for, not required.
        h.ros.spin_until(lambda: len(h.commands) > 0, 10.0)
        n_commands = len(h.commands)
        handle = h.send([INSIDE[0]], [INSIDE[1]])
        assert handle.accepted
        res = h.result(handle, 30.0)
        assert res.status == GoalStatus.STATUS_ABORTED, res.result.message
        assert res.result.outcome == DamGrasp.Result.OUTCOME_ABORTED
        assert 'cannot answer' in res.result.message, res.result.message
        assert 'cannot be analysed with this hand' in res.result.message, res.result.message
        assert 'APPROACH' not in h.phases()
        assert len(h.commands) == n_commands, 'the hand was commanded'
        assert ctl.alive(), ctl.output()
        assert 'every grasp goal will be refused' in ctl.output()


if __name__ == '__main__':  # pragma: no cover
    sys.exit(pytest.main([__file__, '-v']))
