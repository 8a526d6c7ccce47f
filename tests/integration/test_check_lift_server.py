"""The installed check_lift_server and check_lift client, as real processes over DDS."""

from __future__ import annotations

import math
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import linprog

from dam_analysis.analysis import LiftAnalyzer
from dam_common.config import load_config
from ros_testing import RosClient, installed_executable, node_process
from spcm_reference import PlanarFinger, ReferenceBranch, follow_branch, theta_s_near_fold

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG = load_config(REPO_ROOT / 'config' / 'dam.yaml')
SERVER = installed_executable('dam_analysis', 'check_lift_server')
CLIENT = installed_executable('dam_analysis', 'check_lift')


@pytest.fixture(scope='module')
def analyzer() -> LiftAnalyzer:
    return LiftAnalyzer(CONFIG)


@pytest.fixture(scope='module')
def references() -> list[ReferenceBranch]:
    """Each finger's SPCM branch and fold, solved independently of dam_analysis."""
    return [follow_branch(PlanarFinger.from_config(CONFIG, i))
            for i in range(CONFIG.hand.n_fingers)]


@pytest.fixture(scope='module')
def server() -> Iterator[object]:
    with node_process([SERVER]) as proc:
        yield proc


@pytest.fixture(scope='module')
def client(server: object) -> Iterator[RosClient]:
    ros = RosClient()
    yield ros
    ros.close()


def _request(k_theta: list[float], delta_theta_p: list[float], friction_angle: float):
    from dam_interfaces.srv import CheckLift

    req = CheckLift.Request()
    req.k_theta = k_theta
    req.delta_theta_p = delta_theta_p
    req.friction_angle = friction_angle
    return req


def _call(client: RosClient, req):
    from dam_interfaces.srv import CheckLift

    return client.call(CheckLift, '/check_lift', req)


def _finger_forces_problem(analyzer: LiftAnalyzer, k_theta: float, delta_theta_p: float):
    """Per finger: compliant-joint Jacobian J_i = a x (p_C - p_s) (3,), torque
    tau_i = -k_i delta_theta_si [N*m] and the inward normal n_in = -n_CB (3,), from the SPCM
    states of the core (eqs. 1-4) and the configuration."""
    ratios = CONFIG.hand.stiffness_ratios
    out = []
    for fc, finger, ratio in zip(analyzer.spcm(delta_theta_p), CONFIG.hand.fingers, ratios,
                                 strict=True):
        axis = np.asarray(finger.joint_axis, dtype=float)
        jac = np.cross(axis, fc.contact_point - np.asarray(finger.base_position_m))
        tau = -k_theta * ratio / ratios[0] * fc.delta_theta_s
        out.append((axis, jac, tau, -fc.normal_object))
    return out


def _lp_worst_case_margin(analyzer: LiftAnalyzer, k_theta: float, delta_theta_p: float,
                          alpha: float) -> float:
    """Eq. 18's worst case as one linear program (HiGHS): min c_z^T sum f_i subject to
    J_i^T f_i = tau_i and f_i inside the L-faced cone of eq. 7, written by its faces
    m_k = v^k x v^(k+1) (f^T m_k >= 0), minus m_B g [N]."""
    parts = _finger_forces_problem(analyzer, k_theta, delta_theta_p)
    n, faces = len(parts), CONFIG.contact.cone_faces
    a_eq, b_eq, a_ub = np.zeros((n, 3 * n)), np.zeros(n), []
    for i, (axis, jac, tau, n_in) in enumerate(parts):
        a_eq[i, 3 * i:3 * i + 3], b_eq[i] = jac, tau
        tangent = np.cross(axis, -n_in)
        span = [math.cos(alpha) * n_in + math.sin(alpha) * (
            math.cos(phi) * tangent + math.sin(phi) * axis)
            for phi in 2.0 * math.pi * np.arange(faces) / faces]
        for k in range(faces):
            m = np.cross(span[k], span[(k + 1) % faces])
            row = np.zeros(3 * n)
            row[3 * i:3 * i + 3] = -m if m @ n_in > 0.0 else m
            a_ub.append(row)
    cost = np.zeros(3 * n)
    cost[2::3] = 1.0
    res = linprog(cost, A_ub=np.array(a_ub), b_ub=np.zeros(len(a_ub)), A_eq=a_eq, b_eq=b_eq,
                  bounds=[(None, None)] * (3 * n), method='highs')
    assert res.status == 0, res.message
    return float(res.fun) - CONFIG.object_weight_n


def _frictionless_margin(analyzer: LiftAnalyzer, k_theta: float, delta_theta_p: float
                         ) -> float:
    """alpha = 0: each force lies along n_in, so f_i = tau_i / (J_i^T n_in) n_in [N]."""
    total = sum(tau / float(jac @ n_in) * n_in[2]
                for _, jac, tau, n_in in _finger_forces_problem(analyzer, k_theta,
                                                                 delta_theta_p))
    return total - CONFIG.object_weight_n


@pytest.mark.parametrize(('k_theta', 'dp_deg', 'alpha_deg'), [
    ([7.0], [10.0], 5.0),            # inside the sufficient region at alpha = 5 deg
    ([0.5], [40.0], 5.0),            # outside it
    ([1.0, 0.6, 0.4], [20.0, 25.0, 30.0], 1.0),
    ([2.0], [30.0], 30.0),           # alpha = 30 deg: never guaranteed
])
def test_answer_is_the_core_answer(client: RosClient, analyzer: LiftAnalyzer,
                                   k_theta: list[float], dp_deg: list[float],
                                   alpha_deg: float) -> None:
    dp = [math.radians(v) for v in dp_deg]
    alpha = math.radians(alpha_deg)
    response = _call(client, _request(k_theta, dp, alpha))
    expected = analyzer.check_lift(k_theta, dp, alpha)
    assert response.ok, response.message
    assert response.lift_guaranteed == expected.lift_guaranteed
    assert response.csm_lift == expected.csm_lift
    np.testing.assert_allclose(response.worst_case_margin, expected.worst_case_margin)
    np.testing.assert_allclose(response.csm_margin, expected.csm_margin)
    np.testing.assert_allclose(response.delta_theta_s, expected.delta_theta_s)
    np.testing.assert_allclose(response.compliant_torque, expected.compliant_torque)
    assert len(response.delta_theta_s) == CONFIG.hand.n_fingers
    # the CSM's path verdict beside the end verdict; the cylinder is never checked for turns
    assert response.csm_path_lift == expected.csm_path_lift
    np.testing.assert_allclose(response.csm_path_margin, expected.csm_path_margin)
    np.testing.assert_allclose(response.csm_path_delta_theta_p,
                               expected.csm_path_delta_theta_p)
    assert response.csm_path_margin >= np.nan_to_num(response.csm_margin, nan=-np.inf)
    assert not response.rolling_checked and math.isnan(response.rolling_margin)


def test_a_section_that_can_turn_is_checked_in_its_turned_poses(client: RosClient) -> None:
    """The hexagonal bar the stand-in rolled +25 deg on the table (alpha 5 deg, k_theta 7,
    delta_theta_p 5 deg): eq. 18 holds at rest, the answer is "may roll" with the pose."""
    request = _request([7.0], [math.radians(5.0)], math.radians(5.0))
    request.object = 'hex_bar'
    response = _call(client, request)
    assert response.ok, response.message
    assert response.worst_case_margin > 0.0 and not response.lift_guaranteed
    assert response.rolling_checked and response.rolling_margin <= 0.0
    assert 20.0 <= abs(math.degrees(response.rolling_turn)) <= 30.0
    assert abs(response.rolling_slide) < 1e-9
    assert 'lift not guaranteed: eq. 18 holds at rest' in response.message
    assert 'may roll' in response.message
    assert response.csm_path_lift  # the CSM lifts it on the way (the stand-in: it hops off)


def test_single_values_expand_with_the_configured_ratios(client: RosClient) -> None:
    dp = math.radians(20.0)
    one = _call(client, _request([0.8], [dp], -1.0))
    full = _call(client, _request([0.8, 0.4, 0.4], [dp, dp, dp], -1.0))
    assert one.ok and full.ok
    np.testing.assert_allclose(one.compliant_torque, full.compliant_torque)
    # tau_s = -K_theta delta_theta_s (paper section 3.2), with k_theta_i from the ratios
    k_i = 0.8 * CONFIG.hand.stiffness_ratios / CONFIG.hand.stiffness_ratios[0]
    np.testing.assert_allclose(one.compliant_torque, -k_i * np.asarray(one.delta_theta_s))


def test_negative_friction_angle_means_the_configured_one(client: RosClient) -> None:
    dp = [math.radians(12.0)]
    configured = _call(client, _request([6.5], dp, -1.0))
    explicit = _call(client, _request([6.5], dp, CONFIG.contact.friction_angle_rad))
    assert configured.ok and explicit.ok
    assert configured.worst_case_margin == pytest.approx(explicit.worst_case_margin)
    assert configured.csm_margin == pytest.approx(explicit.csm_margin)


def test_the_answer_names_the_friction_angle_it_assumed(client: RosClient) -> None:
    dp = [math.radians(12.0)]
    assert _call(client, _request([6.5], dp, -1.0)).friction_angle == pytest.approx(
        CONFIG.contact.friction_angle_rad)
    assert _call(client, _request([6.5], dp, 0.3)).friction_angle == 0.3
    rejected = _call(client, _request([6.5], dp, math.pi))
    assert not rejected.ok and math.isnan(rejected.friction_angle)


def test_the_request_defaults_are_the_idl_defaults() -> None:
    from dam_interfaces.srv import CheckLift

    req = CheckLift.Request()
    assert list(req.k_theta) == [] and list(req.delta_theta_p) == []
    assert req.friction_angle == CheckLift.Request.FRICTION_ANGLE_FROM_CONFIG == -1.0


def test_default_constructed_request_answers_for_the_configured_task_pair(
        client: RosClient, analyzer: LiftAnalyzer) -> None:
    from dam_interfaces.srv import CheckLift

    task, alpha = CONFIG.task, CONFIG.contact.friction_angle_rad
    response = _call(client, CheckLift.Request())
    assert response.ok, response.message
    expected = _lp_worst_case_margin(analyzer, task.k_theta_nm_per_rad, task.delta_theta_p_rad,
                                     alpha)
    assert response.worst_case_margin == pytest.approx(expected, abs=1e-9)
    assert response.lift_guaranteed is True  # documented: the configured pair lifts at 5 deg
    explicit = _call(client, _request([task.k_theta_nm_per_rad], [task.delta_theta_p_rad],
                                      alpha))
    assert explicit.ok
    assert response.worst_case_margin == explicit.worst_case_margin
    assert response.csm_margin == explicit.csm_margin
    assert list(response.delta_theta_s) == list(explicit.delta_theta_s)
    assert len(response.delta_theta_s) == CONFIG.hand.n_fingers
    assert ('from the configuration: k_theta = 10 N*m/rad, delta_theta_p = 10 deg, '
            'friction_angle = 5 deg') in response.message


def test_yaml_request_with_only_k_theta_and_delta_theta_p_uses_the_configured_angle(
        client: RosClient, analyzer: LiftAnalyzer) -> None:
    """``{k_theta: [7.0], delta_theta_p: [0.1745]}``: friction_angle is left out."""
    from dam_interfaces.srv import CheckLift

    response = _call(client, CheckLift.Request(k_theta=[7.0], delta_theta_p=[0.1745]))
    assert response.ok, response.message
    configured = _lp_worst_case_margin(analyzer, 7.0, 0.1745, CONFIG.contact.friction_angle_rad)
    frictionless = _frictionless_margin(analyzer, 7.0, 0.1745)
    assert configured == pytest.approx(0.040, abs=1e-3)  # the numbers
    assert frictionless == pytest.approx(0.693, abs=1e-3)
    assert response.worst_case_margin == pytest.approx(configured, abs=1e-9)
    assert response.lift_guaranteed is True
    assert 'friction_angle = 5 deg' in response.message


@pytest.mark.parametrize('left_out', ['k_theta', 'delta_theta_p'])
def test_a_field_left_out_takes_its_configured_value(client: RosClient, left_out: str) -> None:
    from dam_interfaces.srv import CheckLift

    task = CONFIG.task
    given = {'k_theta': [3.0], 'delta_theta_p': [math.radians(14.0)]}
    configured = {'k_theta': [task.k_theta_nm_per_rad],
                  'delta_theta_p': [task.delta_theta_p_rad]}
    assert given[left_out] != configured[left_out]
    partial = _call(client, CheckLift.Request(
        **{name: value for name, value in given.items() if name != left_out}))
    full = _call(client, CheckLift.Request(**{**given, left_out: configured[left_out]}))
    assert partial.ok and full.ok, (partial.message, full.message)
    assert partial.worst_case_margin == full.worst_case_margin
    assert partial.csm_margin == full.csm_margin
    assert list(partial.compliant_torque) == list(full.compliant_torque)
    assert f'{left_out} = ' in partial.message


def test_just_below_the_branch_end_is_answered_with_a_solution(
        client: RosClient, references: list[ReferenceBranch]) -> None:
    dp = references[0].fold_delta_theta_p - math.radians(1e-3)
    response = _call(client, _request([7.0], [dp], -1.0))
    assert response.ok, response.message
    expected = [theta_s_near_fold(ref, dp)[0] - ref.states[0][0] for ref in references]
    np.testing.assert_allclose(response.delta_theta_s, expected, rtol=0.0, atol=1e-9)
    assert math.isfinite(response.csm_margin)
    assert 'branch ends' not in response.message


@pytest.mark.parametrize('beyond', ['end + 1e-3 deg', '65 deg'])
def test_beyond_the_branch_end_is_ok_and_no_lift(client: RosClient, server,
                                                 references: list[ReferenceBranch],
                                                 beyond: str) -> None:
    end = references[0].fold_delta_theta_p
    dp = end + math.radians(1e-3) if beyond == 'end + 1e-3 deg' else math.radians(65.0)
    response = _call(client, _request([7.0], [dp], -1.0))
    assert response.ok is True, response.message
    assert response.lift_guaranteed is False and response.csm_lift is False
    assert math.isnan(response.worst_case_margin) and math.isnan(response.csm_margin)
    assert len(response.delta_theta_s) == CONFIG.hand.n_fingers
    assert np.all(np.isnan(response.delta_theta_s))
    assert np.all(np.isnan(response.compliant_torque))
    assert f'delta_theta_p = {math.degrees(dp):.5f} deg' in response.message
    assert f'branch ends at {math.degrees(end):.5f} deg' in response.message
    assert 'fold' in response.message
    assert server.alive()


@pytest.mark.parametrize(('k_theta', 'dp', 'alpha', 'pattern'), [
    ([float('nan')], [0.3], 0.1, r'k_theta.*nan'),
    ([float('inf')], [0.3], 0.1, r'k_theta.*inf'),
    ([0.0], [0.3], 0.1, r'k_theta.*positive.*0\.0'),
    ([-2.0], [0.3], 0.1, r'k_theta.*positive.*-2\.0'),
    ([1.0, 2.0], [0.3], 0.1, r'k_theta.*1 or 3 values.*2'),
    ([-2.0], [], 0.1, r'k_theta.*positive.*-2\.0'),  # dp from the configuration, k bad
    ([1.0], [-0.1], -1.0, r'delta_theta_p.*>= 0.*-0\.1'),
    ([1.0], [0.1, 0.2], 0.1, r'delta_theta_p.*1 or 3 values'),
    ([1.0], [-0.1], 0.1, r'delta_theta_p.*>= 0.*-0\.1'),
    ([1.0], [math.radians(80.0)], 0.1,  # 4 significant digits, in rad and deg
     r'delta_theta_p: \[1\.396(, 1\.396)*\] rad \(\[80(, 80)*\] deg\) exceeds '
     r'delta_theta_p_max 1\.134 rad \(65 deg\)$'),
    ([1.0], [float('nan')], 0.1, r'delta_theta_p.*nan'),
    ([1.0], [0.3], math.pi / 2, r'friction_angle.*90'),
    ([1.0], [0.3], 2.0, r'friction_angle: 2 rad \(114\.6 deg\)'),
    ([1.0], [0.3], float('nan'), r'friction_angle.*nan'),
    ([1.0], [0.3], float('-inf'), r'friction_angle.*inf'),
])
def test_bad_requests_are_rejected_with_the_field_and_value(
        client: RosClient, server, k_theta: list[float], dp: list[float], alpha: float,
        pattern: str) -> None:
    import re

    response = _call(client, _request(k_theta, dp, alpha))
    assert response.ok is False
    assert re.search(pattern, response.message), response.message
    assert list(response.delta_theta_s) == []
    # every number of a rejected answer is NaN: 0.0 would read "on the boundary"
    assert math.isnan(response.worst_case_margin) and math.isnan(response.csm_margin)
    assert server.alive()


def test_fuzz_thousands_of_requests_then_a_valid_one(client: RosClient, server,
                                                     analyzer: LiftAnalyzer) -> None:
    from dam_interfaces.srv import CheckLift

    rng = np.random.default_rng(2026)
    specials = [float('nan'), float('inf'), float('-inf'), 0.0, -0.0, -1.0, 1e308, -1e308,
                5e-324, 1e-12, math.pi, 100.0]
    cli = client.node.create_client(CheckLift, '/check_lift')
    assert cli.wait_for_service(timeout_sec=30.0)
    futures = []
    n_requests = 3000
    ok_count = 0
    for i in range(n_requests):
        req = CheckLift.Request()
        for field in ('k_theta', 'delta_theta_p'):
            length = int(rng.choice([0, 1, 2, 3, 4, 50]))
            values = rng.uniform(-2.0, 3.0, size=length)
            mask = rng.random(length) < 0.2
            values[mask] = rng.choice(specials, size=int(mask.sum()))
            setattr(req, field, values.tolist())
        req.friction_angle = float(rng.choice(specials + [float(rng.uniform(-1, 2))]))
        futures.append(cli.call_async(req))
        # At most 8 in flight: the service's request queue keeps the last 10 (default QoS).
        if len(futures) >= 8 or i == n_requests - 1:
            for future in futures:
                assert client.wait_future(future, 10.0), \
                    'the server stopped answering during the fuzz run'
                response = future.result()
                ok_count += int(response.ok)
                if not response.ok:
                    assert response.message, 'a rejection must say why'
            futures.clear()
    client.node.destroy_client(cli)
    assert server.alive(), server.output()
    assert ok_count < n_requests  # most random requests are malformed
    dp = [math.radians(10.0)]
    response = _call(client, _request([7.0], dp, math.radians(5.0)))
    assert response.ok, response.message
    expected = analyzer.check_lift([7.0], dp, math.radians(5.0))
    assert response.worst_case_margin == pytest.approx(expected.worst_case_margin)


def test_params_file_and_parameter_validation(tmp_path: Path) -> None:
    from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
    from rcl_interfaces.srv import SetParameters

    from dam_interfaces.srv import CheckLift

    params = tmp_path / 'params.yaml'
    alpha = math.radians(30.0)
    params.write_text(f'/**:\n  ros__parameters:\n'
                      f'    default_friction_angle: {alpha!r}\n')
    with node_process([SERVER, '--ros-args', '-r', '__ns:=/paramtest',
                       '--params-file', str(params)]) as proc:
        ros = RosClient()
        try:
            req = _request([2.0], [math.radians(20.0)],
                           CheckLift.Request.FRICTION_ANGLE_FROM_CONFIG)
            via_default = ros.call(CheckLift, '/paramtest/check_lift', req)
            req.friction_angle = alpha
            explicit = ros.call(CheckLift, '/paramtest/check_lift', req)
            assert via_default.ok and explicit.ok
            assert via_default.worst_case_margin == explicit.worst_case_margin
            assert via_default.lift_guaranteed is False  # alpha = 30 deg: never guaranteed

            def set_angle(value: float):
                set_req = SetParameters.Request()
                set_req.parameters = [Parameter(
                    name='default_friction_angle',
                    value=ParameterValue(type=ParameterType.PARAMETER_DOUBLE,
                                         double_value=value))]
                return ros.call(SetParameters, '/paramtest/check_lift_server/set_parameters',
                                set_req).results[0]

            refused = set_angle(2.0)
            assert refused.successful is False
            assert refused.reason
            accepted = set_angle(math.radians(1.0))
            assert accepted.successful is True, accepted.reason
            req.friction_angle = CheckLift.Request.FRICTION_ANGLE_FROM_CONFIG
            after = ros.call(CheckLift, '/paramtest/check_lift', req)
            req.friction_angle = math.radians(1.0)
            explicit_1deg = ros.call(CheckLift, '/paramtest/check_lift', req)
            assert after.worst_case_margin == explicit_1deg.worst_case_margin
        finally:
            ros.close()
        assert proc.alive()


def _run_client(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(CLIENT), *args], capture_output=True, text=True, timeout=60)


def test_command_line_client(server: object) -> None:
    inside = _run_client('--k-theta', '7', '--delta-theta-p', '10deg', '--friction-angle', '5deg')
    assert inside.returncode == 0, inside.stderr
    assert 'lift guaranteed          : yes' in inside.stdout
    outside = _run_client('--k-theta', '0.5', '--delta-theta-p', '40deg')
    assert outside.returncode == 0, outside.stderr
    assert 'lift guaranteed          : no' in outside.stdout
    beyond = _run_client('--k-theta', '1', '--delta-theta-p', '80deg')  # the server refuses
    assert beyond.returncode == 2, beyond.stderr
    assert re.fullmatch(r'REJECTED: delta_theta_p: \[1\.396(, 1\.396)*\] rad \(\[80(, 80)*\] '
                        r'deg\) exceeds delta_theta_p_max 1\.134 rad \(65 deg\)\n',
                        beyond.stdout), beyond.stdout
    words = _run_client('--k-theta', '10Nm/rad')
    assert words.returncode == 2 and 'a stiffness is a plain number in N*m/rad' in words.stderr
    refused = _run_client('--k-theta', '-1', '--delta-theta-p', '0.3')  # before any request
    assert refused.returncode == 2 and 'REJECTED' not in refused.stdout
    assert '--k-theta' in refused.stderr and 'must be greater than 0 N*m/rad' in refused.stderr
    bad_angle = _run_client('--k-theta', '1', '--delta-theta-p', 'forty')
    assert bad_angle.returncode == 2
    assert "'forty' is not an angle" in bad_angle.stderr
    missing = _run_client('--k-theta', '1', '--delta-theta-p', '0.3', '--service',
                          '/nobody/here', '--timeout', '1')
    assert missing.returncode == 1
    assert 'not available' in missing.stderr


def test_command_line_client_defaults_and_beyond_the_branch(
        server: object, references: list[ReferenceBranch]) -> None:
    default = _run_client()
    assert default.returncode == 0, default.stderr
    assert 'k_theta         [N*m/rad]: configured on the server' in default.stdout
    assert 'lift guaranteed          : yes' in default.stdout
    assert ('from the configuration: k_theta = 10 N*m/rad, delta_theta_p = 10 deg, '
            'friction_angle = 5 deg, object = cylinder]') in default.stdout
    assert 'object                   : cylinder' in default.stdout
    turned = _run_client('--object', 'hex_bar', '--k-theta', '7', '--delta-theta-p', '5deg')
    assert turned.returncode == 0, turned.stderr
    assert 'turned on the table      : may rest turned' in turned.stdout
    assert 'CSM on the way (path)    : yes' in turned.stdout
    bar = _run_client('--object', 'square_bar', '--delta-theta-p', '20deg')
    assert bar.returncode == 0, bar.stderr
    assert 'object                   : square_bar' in bar.stdout
    assert bar.stdout != default.stdout
    pencil = _run_client('--object', 'pencil')
    assert pencil.returncode == 2 and 'REJECTED' in pencil.stdout
    assert "'pencil' is not in the object library" in pencil.stdout
    beyond = _run_client('--k-theta', '7', '--delta-theta-p', '65deg')
    assert beyond.returncode == 0, beyond.stderr
    assert ('lift guaranteed          : no   worst-case margin (eq. 18 at rest) none'
            in beyond.stdout)
    end = math.degrees(references[0].fold_delta_theta_p)
    assert f'branch ends at {end:.5f} deg' in beyond.stdout


def test_the_answer_says_what_it_asks_of_the_hand(client: RosClient,
                                                  analyzer: LiftAnalyzer) -> None:
    """The hand's torque limit and the CSM's domain cross DDS with every answer: the
    configured pair stays inside both; k_theta 63 N*m/rad at 10 deg is guaranteed by eq. 18
    with about 3 N*m on finger 1, which the hand does not give, and the message says so."""
    from dam_interfaces.srv import CheckLift

    limit = min(CONFIG.controller.torque_limit_nm, CONFIG.device.torque_limit_nm)
    bound = CONFIG.contact.csm_max_penetration_m
    default = _call(client, CheckLift.Request())
    assert default.ok and default.torque_limit == limit
    assert default.within_torque_limit and default.csm_in_domain
    assert len(default.csm_penetration) == CONFIG.hand.n_fingers
    assert all(0.0 < p <= bound for p in default.csm_penetration)
    assert 'torque:' not in default.message and 'CSM outside' not in default.message

    dp = math.radians(10.0)
    stiff = _call(client, _request([63.0], [dp], -1.0))
    assert stiff.ok and stiff.lift_guaranteed and not stiff.within_torque_limit
    # tau_1 = -k_theta delta_theta_s1 from the SPCM state, by the paper's formula
    tau_1 = _finger_forces_problem(analyzer, 63.0, dp)[0][2]
    assert abs(tau_1) > limit
    assert stiff.compliant_torque[0] == pytest.approx(tau_1)
    assert (f'torque: guaranteed by eq. 18 but not for this hand: finger 1 needs |tau_s| = '
            f'{abs(tau_1):.4g} N*m') in stiff.message
    assert f'more than the {limit:g} N*m it gives' in stiff.message
    assert not stiff.csm_in_domain and max(stiff.csm_penetration) > bound
    assert 'CSM outside its domain of validity' in stiff.message
    core = analyzer.check_lift(63.0, dp)
    assert list(stiff.csm_penetration) == pytest.approx(list(core.csm_penetration))

    rejected = _call(client, _request([-1.0], [dp], -1.0))
    assert not rejected.ok and math.isnan(rejected.torque_limit)
    assert list(rejected.csm_penetration) == [] and not rejected.csm_in_domain


def test_command_line_client_shows_the_hand_s_limits(server: object) -> None:
    inside = _run_client('--k-theta', '7', '--delta-theta-p', '10deg')
    assert inside.returncode == 0, inside.stderr
    assert 'torque within the hand   : yes   limit 0.6 N*m' in inside.stdout
    assert 'inside its domain' in inside.stdout
    assert 'CSM f_n/k_n [um]' in inside.stdout
    stiff = _run_client('--k-theta', '63', '--delta-theta-p', '10deg')
    assert stiff.returncode == 0, stiff.stderr
    assert 'torque within the hand   : no   limit 0.6 N*m' in stiff.stdout
    assert 'OUTSIDE its domain' in stiff.stdout
    assert 'guaranteed by eq. 18 but not for this hand' in stiff.stdout


def test_a_calibration_overlay_round_trips_through_check_lift(tmp_path: Path) -> None:
    """An overlay as calibrate_csm writes it (a soft tangential stiffness and a friction
    angle) changes the served answer to the core's answer with the merged configuration."""
    from dam_interfaces.srv import CheckLift

    overlay = tmp_path / 'csm_calibration.yaml'
    overlay.write_text('contact:\n  contact_stiffness_n_per_m: [100000.0, 20.0, 100000.0]\n'
                       '  series_stiffness_n_per_m: .inf\n  friction_angle_deg: 27.5\n',
                       encoding='utf-8')
    merged = LiftAnalyzer(load_config(REPO_ROOT / 'config' / 'dam.yaml', [overlay]))
    plain = LiftAnalyzer(CONFIG)
    k, dp = 2.0, math.radians(20.0)
    expected = merged.check_lift(k, dp, math.radians(27.5))
    assert expected.csm_margin != pytest.approx(plain.check_lift(k, dp, math.radians(27.5))
                                                .csm_margin, abs=1e-3)
    with node_process([SERVER, '--ros-args', '-r', '__ns:=/overlaytest',
                       '-p', f'config_file:={REPO_ROOT / "config" / "dam.yaml"}',
                       '-p', f'config_overlay:={overlay}']):
        ros = RosClient()
        try:
            req = _request([k], [dp], CheckLift.Request.FRICTION_ANGLE_FROM_CONFIG)
            got = ros.call(CheckLift, '/overlaytest/check_lift', req)
        finally:
            ros.close()
    assert got.ok, got.message
    assert got.friction_angle == pytest.approx(math.radians(27.5))
    assert got.csm_margin == pytest.approx(expected.csm_margin, abs=1e-12)
    assert got.csm_lift == expected.csm_lift


def test_a_bad_overlay_stops_the_server_with_its_name(tmp_path: Path) -> None:
    overlay = tmp_path / 'bad.yaml'
    overlay.write_text('contact:\n  series_stiffness_n_per_m: -1\n', encoding='utf-8')
    proc = subprocess.run([str(SERVER), '--ros-args', '-p', f'config_overlay:={overlay}'],
                          capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode != 0
    assert 'series_stiffness_n_per_m' in proc.stderr + proc.stdout
