"""An action client of /dam_grasp with observers of the stand-in's ground truth, shared by the
grasp integration tests."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator
from pathlib import Path

import yaml

from ros_testing import RosClient, free_udp_ports, installed_executable, node_process

REPO_ROOT = Path(__file__).resolve().parents[1]


def config_with_free_ports(directory: Path) -> Path:
    """The shipped configuration written to ``directory/dam.yaml`` with device ports that no
    other run on the machine uses."""
    data = yaml.safe_load((REPO_ROOT / 'config' / 'dam.yaml').read_text(encoding='utf-8'))
    data['device']['state_port'], data['device']['command_port'] = free_udp_ports(2)
    path = directory / 'dam.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


#: How far the live grasp's ground-truth rise may lie from the lockstep trial's [m]: the
#: controller's commands reach the world at the same device cycle on both paths; what differs
#: is the driver's torque slew (it runs on the state the command answers, one cycle later
#: than in the lockstep trial) and the moment the rise is read (the result's arrival).
RISE_TOLERANCE_M = 0.5e-3
#: Times the reset world runs before the goal in the lockstep references [s]: a live goal
#: arrives at any moment after the world's reset, and the final seat of a lifted cylinder in
#: the hand has two configurations (about 8.1 and 9.8 mm) that this moment selects even in
#: lockstep (one physics step of difference is enough), while the outcome stays the same.
HOLDS_BEFORE_S = (0.0, 0.001, 0.05, 0.25, 0.5, 1.0)


def lockstep_reference(config_file: Path, k_theta: float, delta_theta_p: float,
                       object_name: str = '') -> tuple[str, list[float]]:
    """(outcome name, rises of the object when the controller is done [m]) of the lockstep
    trials started after each of :data:`HOLDS_BEFORE_S`; their outcomes agree."""
    from dam_common.config import load_config
    from dam_experiments.experiment import run_experiment
    from dam_sim_bridge.world import HandWorld

    config = load_config(config_file).with_object(object_name)
    outcomes, rises = set(), []
    with HandWorld(config) as world:
        for hold in HOLDS_BEFORE_S:
            result = run_experiment(config, k_theta, delta_theta_p, world=world,
                                    latency_cycles=2, hold_before=hold)
            outcomes.add(result.outcome.name)
            rises.append(float(result.lift_final))
    assert len(outcomes) == 1, f'k_theta {k_theta:g} is on an outcome boundary: {outcomes}'
    return outcomes.pop(), rises


def assert_as_in_lockstep(result, rise: float, expected: tuple[str, list[float]],
                          what: str) -> None:
    """The live ``result``'s outcome is the lockstep trials' and its ground-truth ``rise``
    [m] lies within :data:`RISE_TOLERANCE_M` of one of theirs (see :data:`HOLDS_BEFORE_S`)."""
    outcome, lockstep_rises = expected
    assert result.outcome_name == outcome, f'{what}: {result.outcome_name} ({result.message})'
    nearest = min(lockstep_rises, key=lambda r: abs(r - rise))
    assert abs(rise - nearest) < RISE_TOLERANCE_M, (
        f'{what}: rise {rise * 1e3:.3f} mm live, in lockstep '
        f'{[round(r * 1e3, 3) for r in lockstep_rises]} mm')


class Grasper:
    """Action client of /dam_grasp plus observers of the ground truth and the commands."""

    def __init__(self) -> None:
        from geometry_msgs.msg import PoseStamped
        from rclpy.action import ActionClient
        from sensor_msgs.msg import JointState

        from dam_interfaces.action import DamGrasp
        from dam_interfaces.msg import HandCommand

        self.client = RosClient()
        node = self.client.node
        self.poses: list[tuple[float, float]] = []  # (monotonic time, object z [m])
        self.command: HandCommand | None = None
        self.joint_state: JointState | None = None
        self.feedback_phases: list[str] = []
        node.create_subscription(
            PoseStamped, '/sim/object_pose',
            lambda m: self.poses.append((time.monotonic(), m.pose.position.z)), 50)
        self._watches: list = []
        self._watch_types = (HandCommand, JointState)
        self.watch(True)
        self.action = ActionClient(node, DamGrasp, '/dam_grasp')
        self.goal_type = DamGrasp.Goal

    def watch(self, on: bool) -> None:
        """Follow /hand/command and /joint_states (500 Hz each: a fifth of a core for this
        process on a machine that the real-time nodes keep busy) only when a test needs them."""
        node = self.client.node
        for sub in self._watches:
            node.destroy_subscription(sub)
        self._watches = []
        if on:
            command_type, joint_state_type = self._watch_types
            self._watches = [
                node.create_subscription(command_type, '/hand/command',
                                         lambda m: setattr(self, 'command', m), 10),
                node.create_subscription(joint_state_type, '/joint_states',
                                         lambda m: setattr(self, 'joint_state', m), 10)]

    def z(self) -> float:
        return self.poses[-1][1]

    def z_between(self, t0: float, t1: float) -> list[float]:
        return [z for t, z in self.poses if t0 <= t <= t1]

    def send(self, k_theta: float, delta_theta_p: float):
        def on_feedback(msg) -> None:
            phase = msg.feedback.phase
            if not self.feedback_phases or self.feedback_phases[-1] != phase:
                self.feedback_phases.append(phase)

        self.feedback_phases = []
        future = self.action.send_goal_async(
            self.goal_type(k_theta=[k_theta], delta_theta_p=[delta_theta_p]),
            feedback_callback=on_feedback)
        assert self.client.wait_future(future, 10.0), 'no answer to the goal'
        handle = future.result()
        assert handle.accepted
        return handle

    def result(self, handle, timeout: float = 30.0):
        future = handle.get_result_async()
        if not self.client.wait_future(future, timeout):
            controller = getattr(self, 'controller', None)
            log = controller.output()[-4000:] if controller is not None else ''
            raise AssertionError(f'no result within {timeout} s (goal status '
                                 f'{handle.status}); controller log:\n{log}')
        return future.result()

    def reset_world(self) -> None:
        """Let go (the controller's ~/release: every joint ends in HOLD and the controller
        stops commanding), put the object back on the table and open the hand; the driver's
        ~/reset brings it back should it be in ERROR (it answers 'already ACTIVE' otherwise)."""
        from std_srvs.srv import Trigger

        assert self.client.call(Trigger, '/hand_driver/reset', Trigger.Request()).success
        self.client.spin_until(lambda: False, 0.2)
        # the release takes a few seconds of simulated time; on a loaded machine the stand-in
        # runs well below real time (a CI rehearsal at load 4+ took over 30 s of wall time)
        released = self.client.call(Trigger, '/spcm_controller/release', Trigger.Request(),
                                    timeout=120.0)
        assert released.success, released.message
        reset = self.client.call(Trigger, '/hand_driver_sim/reset', Trigger.Request())
        assert reset.success, reset.message
        self.client.spin_until(lambda: False, 0.3)
        driver = self.client.call(Trigger, '/hand_driver/reset', Trigger.Request())
        assert driver.success, driver.message
        self.client.spin_until(lambda: False, 0.3)

    def close(self) -> None:
        self.action.destroy()
        self.client.close()


@contextlib.contextmanager
def grasp_stack(config_file: Path, object_name: str = '', sim_time: bool = True,
                backend: str = 'sim') -> Iterator[Grasper]:
    """The stand-in (started by the driver, ``backend:=sim``, or as the emulated Dynamixel
    bus with ``backend='dynamixel'``), the driver, the analysis
    server and the controller as separate processes with ``config_file``, the driver and the
    controller given ``object:=object_name``, every node ``use_sim_time:=sim_time`` (as the
    scripts start them on the stand-in); a :class:`Grasper` once joint states and the object
    pose flow and the action server is up. Every process must still be alive at the end."""
    from std_srvs.srv import Trigger

    env = {'DAM_CONFIG': str(config_file)}
    selected = ['-p', f'object:={object_name}'] if object_name else []
    clock = ['-p', f'use_sim_time:={str(sim_time).lower()}']
    with node_process([installed_executable('dam_hand_driver', 'hand_driver'),
                       '--ros-args', '-p', f'backend:={backend}', *selected, *clock],
                      env=env) as driver, \
            node_process([installed_executable('dam_analysis', 'check_lift_server'),
                          '--ros-args', *clock], env=env) as analysis, \
            node_process([installed_executable('dam_spcm_controller', 'spcm_controller'),
                          '--ros-args', *selected, *clock], env=env) as controller:
        grasper = Grasper()
        try:
            ready = False
            for _ in range(4):  # a stand-in stalled at start-up leaves the driver in ERROR:
                ready = grasper.client.spin_until(  # then ~/reset, as its log says
                    lambda: bool(grasper.poses) and grasper.joint_state is not None, 10.0)
                if ready:
                    break
                grasper.client.call(Trigger, '/hand_driver/reset', Trigger.Request())
            assert ready, driver.output()
            grasper.watch(False)
            assert grasper.action.wait_for_server(timeout_sec=30.0), controller.output()
            grasper.controller = controller
            grasper.analysis = analysis
            grasper.driver = driver
            yield grasper
        finally:
            grasper.close()
            for proc in (controller, analysis, driver):
                assert proc.alive(), proc.output()
