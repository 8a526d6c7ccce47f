"""A hexagonal column grasped end to end: the stand-in (started by the driver with
``object:=hex_bar``), the driver, the /check_lift server and the controller (``object:=hex_bar``)
as separate processes over DDS and the UDP device link, as ``scripts/run.sh --object hex_bar``
brings them up. The ground truth comes from the stand-in's /sim/object_pose.

1. The stand-in's object is the hexagonal prism of the library: it rests with its centroid at
   half its width across flats (9 mm), not at the cylinder's 10 mm.
2. /check_lift answers for the object a request names, for the default one when it names
   none, and refuses a name outside the library (naming it); the server stays up.
3. A grasp with a pair that lifts the hexagonal bar in the stand-in (k_theta 5 N*m/rad,
   delta_theta_p 40 deg), with two CPU-burning processes beside the suite: the controller asks
   /check_lift about ``hex_bar``, the object rises by well over 5 mm, and the controller's
   joint-only verdict is SUCCESS, the lockstep trial's outcome, with its rise within
   ``grasp_testing.RISE_TOLERANCE_M``.
"""

from __future__ import annotations

import math
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

from ros_testing import cpu_burners

# No reruns: on simulated time the outcome may not depend on the machine's load.
pytestmark = [pytest.mark.integration]

REPO_ROOT = Path(__file__).resolve().parents[2]
OBJECT = 'hex_bar'
K_THETA = 5.0
DELTA_THETA_P = math.radians(40.0)


@pytest.fixture(scope='module')
def config_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return config_with_free_ports(tmp_path_factory.mktemp('column_grasp'))


@pytest.fixture(scope='module')
def stack(config_file: Path) -> Iterator[_Grasper]:
    with grasp_stack(config_file, OBJECT) as grasper:
        yield grasper


def test_the_stand_in_puts_the_hexagonal_bar_on_the_table(stack: _Grasper) -> None:
    from dam_common.config import load_config

    section = load_config(REPO_ROOT / 'config' / 'dam.yaml').with_object(OBJECT).object.section
    assert section.inradius == pytest.approx(0.009)
    # resting on a face: the centroid at the inradius (a cylinder of that width: 10 mm)
    assert stack.z() == pytest.approx(0.009, abs=2e-4)


def test_check_lift_answers_for_the_named_object(stack: _Grasper) -> None:
    from dam_interfaces.srv import CheckLift

    def ask(name: str) -> CheckLift.Response:
        request = CheckLift.Request(k_theta=[K_THETA], delta_theta_p=[DELTA_THETA_P],
                                    object=name)
        return stack.client.call(CheckLift, '/check_lift', request, timeout=30.0)

    named = ask(OBJECT)
    assert named.ok, named.message
    assert named.object == OBJECT
    default = ask('')
    assert default.ok and default.object == 'cylinder', default.message
    assert 'object = cylinder' in default.message
    # the answer depends on the object: its SPCM deflections differ from the cylinder's
    assert abs(named.delta_theta_s[0] - default.delta_theta_s[0]) > math.radians(0.1)
    unknown = ask('pencil')
    assert not unknown.ok
    assert "'pencil'" in unknown.message and 'hex_pencil' in unknown.message, unknown.message
    assert unknown.object == ''
    assert ask(OBJECT).ok  # still up and answering
    assert stack.analysis.alive()


def test_a_hexagonal_bar_is_lifted_and_enveloped(stack: _Grasper, config_file: Path) -> None:
    from dam_interfaces.action import DamGrasp

    expected = lockstep_reference(config_file, K_THETA, DELTA_THETA_P, OBJECT)
    z_table = stack.z()
    with cpu_burners(2):
        handle = stack.send(K_THETA, DELTA_THETA_P)
        answer = stack.result(handle, 90.0)
    result = answer.result
    assert {'CHECK_LIFT', 'ROLLING_UP', 'ENVELOPE'} <= set(stack.feedback_phases), \
        (stack.feedback_phases, result.message)
    stack.client.spin_until(lambda: False, 0.5)
    rise = stack.z() - z_table
    assert rise > 0.005, f'the bar rose by only {rise * 1e3:.2f} mm ({result.message})'
    assert result.outcome == DamGrasp.Result.OUTCOME_SUCCESS, (
        result.message, stack.controller.output()[-3000:])
    assert_as_in_lockstep(result, rise, expected, 'hex_bar k_theta 5, 40 deg')
    log = stack.controller.output()
    assert OBJECT in log, log[-3000:]


def test_the_object_parameter_is_read_only_as_ros2_param_shows_it(stack: _Grasper) -> None:
    """What ``ros2 param get /spcm_controller object`` and ``ros2 param set ... object
    square_bar`` do: the value is the object started with, and a change is refused while the
    node keeps serving."""
    from rcl_interfaces.srv import GetParameters, SetParameters
    from rclpy.parameter import Parameter

    got = stack.client.call(GetParameters, '/spcm_controller/get_parameters',
                            GetParameters.Request(names=['object']))
    assert [v.string_value for v in got.values] == [OBJECT]
    request = SetParameters.Request(
        parameters=[Parameter('object', value='square_bar').to_parameter_msg()])
    result = stack.client.call(SetParameters, '/spcm_controller/set_parameters',
                               request).results[0]
    assert not result.successful and 'read-only' in result.reason, result.reason
    again = stack.client.call(GetParameters, '/spcm_controller/get_parameters',
                              GetParameters.Request(names=['object']))
    assert [v.string_value for v in again.values] == [OBJECT]
    assert stack.controller.alive()
