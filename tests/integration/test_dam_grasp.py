"""A real DAM grasp end to end: simulated stand-in, driver, /check_lift server and controller as
separate processes over DDS and the UDP device link; the ground truth comes from the
simulator's /sim/object_pose.

One stack serves the scenarios; each starts from a reset world (object on the table, hand
open):

1. ``k_theta = 0.5`` (below both analysis regions at 10 deg): the object stays on the table and
   the result is not SUCCESS;
2. ``k_theta = 10`` (inside the sufficient region at 10 deg, ``k* = 6.35``): the object rises
   by well over 5 mm, stays up while the hand holds it, and the result is SUCCESS;
3. after a world reset, a grasp cancelled mid-way: the controller commands zero torque on the
   compliant joints and the simulated joints report zero torque;
4. the ROS path against the lockstep path (``run_experiment``, what ``sweep`` runs): for three
   pairs with different outcomes (those of 1 and 2, and a LIFTED_DAM_FAILED one), each grasped
   with two CPU-burning processes beside the suite, the action's outcome is that of the
   lockstep trial of the same pair and the ground-truth rise within
   ``grasp_testing.RISE_TOLERANCE_M`` of it.

The suite runs on the stand-in's simulated time (``docs/simulation_grasp.md``, "Simulated
time"), so a loaded machine slows a grasp down and changes nothing else: every scenario runs
once, no retries.
"""

from __future__ import annotations

import math
import os
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from grasp_testing import Grasper as _Grasper
from grasp_testing import (
    assert_as_in_lockstep,
    config_with_free_ports,
    grasp_stack,
    lockstep_reference,
)
from std_srvs.srv import Trigger

from ros_testing import cpu_burners, installed_executable

# No reruns: on simulated time the outcome may not depend on the machine's load.
# Live = lockstep, outcome for outcome, beside two CPU burners: beside another worker's
# stack as well (more than the two burners the suite promises) a starved controller saw its
# joint states arrive over 0.1 s behind /clock and aborted ('silent'); so alone
# (scripts/test.sh, marker exclusive).
pytestmark = [pytest.mark.integration, pytest.mark.exclusive]

REPO_ROOT = Path(__file__).resolve().parents[2]
DELTA_THETA_P = math.radians(10.0)
LIFT_M = 0.005


@pytest.fixture(scope='module')
def config_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return config_with_free_ports(tmp_path_factory.mktemp('dam_grasp'))


@pytest.fixture(scope='module')
def stack(config_file: Path) -> Iterator[_Grasper]:
    with grasp_stack(config_file) as grasper:
        yield grasper


#: (k_theta [N*m/rad], delta_theta_p [deg]) at the configured friction angle (5 deg) whose
#: ROS outcome is compared with the lockstep trial's, chosen for three different lockstep
#: outcomes away from their class boundaries: FAILURE (too soft, the object stays down; the
#: pair of test 1), SUCCESS (test 2), and LIFTED_DAM_FAILED (the joints say lifted, the
#: object is not caged and stays down).
LOCKSTEP_PAIRS = ((0.5, 10.0), (10.0, 10.0), (0.5, 40.0))


@pytest.fixture(scope='module')
def lockstep(config_file: Path) -> dict[tuple[float, float], tuple[str, list[float]]]:
    """(outcome name, ground-truth rises [m]) of the lockstep trials of each pair of
    LOCKSTEP_PAIRS (``grasp_testing.lockstep_reference``), with the stack's configuration."""
    return {(k, d): lockstep_reference(config_file, k, math.radians(d))
            for k, d in LOCKSTEP_PAIRS}


def _assert_as_in_lockstep(lockstep, pair: tuple[float, float], result, rise: float) -> None:
    assert_as_in_lockstep(result, rise, lockstep[pair], f'k_theta {pair[0]:g}, '
                                                        f'delta_theta_p {pair[1]:g} deg')


def _done_result(grasper: _Grasper, k_theta: float) -> tuple[object, float, float, float]:
    """Reset the world, run a grasp to its end; (result, z before [m], z at the end [m],
    end time)."""
    _reset_world(grasper)
    z_before = grasper.z()
    with cpu_burners(2):
        handle = grasper.send(k_theta, DELTA_THETA_P)
        answer = grasper.result(handle, 90.0)
    t_end = time.monotonic()
    grasper.client.spin_until(lambda: False, 0.3)
    return answer.result, z_before, grasper.z(), t_end


def test_too_little_stiffness_does_not_lift(stack: _Grasper, lockstep, config_file) -> None:
    from dam_interfaces.action import DamGrasp

    result, z0, z_end, _ = _done_result(stack, 0.5)
    phases = stack.feedback_phases
    assert phases[:3] == ["CHECK_LIFT", "APPROACH", "ROLLING_UP"], (phases, result.message)
    assert 'IDLE' not in phases, phases
    assert z_end - z0 < 0.002, f'object rose by {(z_end - z0) * 1e3:.2f} mm'
    assert max(stack.z_between(0.0, math.inf)) - z0 < 0.002
    assert result.outcome != DamGrasp.Result.OUTCOME_SUCCESS, result.message
    assert result.outcome in (DamGrasp.Result.OUTCOME_FAILURE,
                              DamGrasp.Result.OUTCOME_LIFTED_DAM_FAILED), result.message
    _assert_as_in_lockstep(lockstep, (0.5, 10.0), result, z_end - z0)


def test_pair_inside_the_sufficient_region_lifts(stack: _Grasper, lockstep,
                                                 config_file) -> None:
    from dam_interfaces.action import DamGrasp

    result, z_table, z_end, t_end = _done_result(stack, 10.0)  # one try: no retries
    # (the DONE feedback may arrive after the result)
    assert {'ROLLING_UP', 'ENVELOPE'} <= set(stack.feedback_phases), \
        (stack.feedback_phases, result.message)
    assert result.outcome == DamGrasp.Result.OUTCOME_SUCCESS, (result.message,
                                                               stack.controller.output())
    assert 'IDLE' not in stack.feedback_phases, stack.feedback_phases
    assert z_end - z_table > LIFT_M, f'object rose by only {(z_end - z_table) * 1e3:.2f} mm'
    _assert_as_in_lockstep(lockstep, (10.0, 10.0), result, z_end - z_table)
    # it stays up while the hand holds it
    stack.client.spin_until(lambda: False, 2.0)
    held = stack.z_between(t_end, math.inf)
    assert len(held) > 50
    assert min(held) - z_table > LIFT_M, f'dropped to {(min(held) - z_table) * 1e3:.2f} mm'
    # Let go with the one documented call; a world reset afterwards stays as reset (before,
    # the held grasp re-grasped the reset object at once).

    released = stack.client.call(Trigger, '/spcm_controller/release', Trigger.Request(),
                                 timeout=120.0)  # seconds simulated; slower under load
    assert released.success, (released.message, stack.controller.output()[-3000:])
    assert stack.client.call(Trigger, '/hand_driver_sim/reset', Trigger.Request()).success
    stack.client.call(Trigger, '/hand_driver/reset', Trigger.Request())
    t_reset = time.monotonic()
    stack.client.spin_until(lambda: False, 2.0)
    after = stack.z_between(t_reset + 0.5, math.inf)
    assert after and max(abs(z - z_table) for z in after) < 0.001, \
        f'object at {max(after) * 1e3:.2f} mm after the reset (table {z_table * 1e3:.2f} mm)'


def _reset_world(stack: _Grasper) -> None:
    stack.reset_world()


def test_cancel_mid_grasp_zeroes_the_torque(stack: _Grasper) -> None:
    from dam_interfaces.action import DamGrasp
    from dam_interfaces.msg import HandCommand

    _reset_world(stack)
    stack.watch(True)
    handle = stack.send(10.0, DELTA_THETA_P)
    assert stack.client.spin_until(lambda: 'ROLLING_UP' in stack.feedback_phases, 15.0), \
        stack.feedback_phases
    stack.client.spin_until(lambda: False, 0.5)
    cancel = handle.cancel_goal_async()
    assert stack.client.wait_future(cancel, 5.0)
    answer = stack.result(handle, 10.0)
    assert answer.result.outcome == DamGrasp.Result.OUTCOME_ABORTED, answer.result.message
    stack.client.spin_until(lambda: False, 0.5)  # the ramp (0.2 s) is over
    cmd = stack.command  # the last: the controller stops publishing once relaxed
    assert cmd is not None
    count = len(stack.poses)
    stack.command = None
    stack.client.spin_until(lambda: len(stack.poses) > count + 10, 2.0)
    assert stack.command is None, 'the controller still publishes after relaxing'
    compliant = [i for i, name in enumerate(cmd.name) if name.endswith('_compliant_joint')]
    assert len(compliant) == 3
    for i in compliant:
        assert cmd.mode[i] == HandCommand.MODE_TORQUE and cmd.setpoint[i] == 0.0, cmd
    js = stack.joint_state
    efforts = dict(zip(js.name, js.effort, strict=True))
    for i in compliant:
        assert efforts[cmd.name[i]] == pytest.approx(0.0, abs=1e-4), efforts
    stack.watch(False)


def test_a_lifted_dam_failed_pair_ends_as_in_lockstep(stack: _Grasper, lockstep,
                                                      config_file) -> None:
    """The third of LOCKSTEP_PAIRS (the first two are tests 1 and 2)."""
    k_theta, delta_deg = LOCKSTEP_PAIRS[2]
    _reset_world(stack)
    z_before = stack.z()
    with cpu_burners(2):
        result = stack.result(stack.send(k_theta, math.radians(delta_deg)), 90.0).result
    stack.client.spin_until(lambda: False, 0.3)
    _assert_as_in_lockstep(lockstep, LOCKSTEP_PAIRS[2], result, stack.z() - z_before)


def _dam_grasp(*args: str, env: dict[str, str] | None = None,
               timeout: float = 60.0) -> subprocess.CompletedProcess[str]:
    full_env = dict(os.environ)
    full_env.update(env or {})
    return subprocess.run([str(installed_executable('dam_spcm_controller', 'dam_grasp')),
                           *args], capture_output=True, text=True, timeout=timeout,
                          env=full_env, check=False)


def test_dam_grasp_executable_exit_codes(stack: _Grasper) -> None:
    """2 on a rejected goal, 3 after --cancel-after (ABORTED), 1 with no server (0 on
    SUCCESS is checked by hand: see docs/simulation_grasp.md); --release opens the hand (0),
    goes with no goal option (2) and needs the controller (1)."""
    # 80 deg is a displacement the command line allows (below 90 deg) but the controller
    # refuses (above the configured delta_theta_p_max_deg, 65 deg)
    rejected = _dam_grasp('--k-theta', '7', '--delta-theta-p', '80deg')
    assert rejected.returncode == 2, rejected.stdout + rejected.stderr
    assert 'goal refused' in rejected.stderr and 'delta_theta_p' in rejected.stderr

    _reset_world(stack)
    cancelled = _dam_grasp('--k-theta', '10', '--delta-theta-p', '10deg', '--cancel-after',
                           '1.0')
    assert cancelled.returncode == 3, cancelled.stdout + cancelled.stderr
    assert 'cancelling' in cancelled.stdout and 'result: ABORTED' in cancelled.stdout

    # --release: the hand opened without the ros2 CLI (a new user of the wheels has none)
    released = _dam_grasp('--release')
    assert released.returncode == 0, released.stdout + released.stderr
    assert 'release: done: released: every joint holds the open posture' in released.stdout
    both = _dam_grasp('--release', '--k-theta', '7')
    assert both.returncode == 2 and '--release sends no goal: --k-theta' in both.stderr, \
        both.stderr

    other_domain = str((int(os.environ.get('ROS_DOMAIN_ID', '0')) + 17) % 100 + 1)
    lonely = _dam_grasp('--k-theta', '7', '--delta-theta-p', '10deg', '--server-timeout',
                        '1', env={'ROS_DOMAIN_ID': other_domain})
    assert lonely.returncode == 1, lonely.stdout + lonely.stderr
    assert 'no action server' in lonely.stderr
    lonely = _dam_grasp('--release', '--server-timeout', '1',
                        env={'ROS_DOMAIN_ID': other_domain})
    assert lonely.returncode == 1, lonely.stdout + lonely.stderr
    assert 'no /spcm_controller/release service within 1 s' in lonely.stderr

