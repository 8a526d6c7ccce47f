"""The installed check_lift_server and check_lift client, as real processes over DDS."""

from __future__ import annotations

import math
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from dam_analysis.analysis import LiftAnalyzer
from dam_common.config import load_config
from ros_testing import RosClient, installed_executable, node_process

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG = load_config(REPO_ROOT / 'config' / 'dam.yaml')
SERVER = installed_executable('dam_analysis', 'check_lift_server')
CLIENT = installed_executable('dam_analysis', 'check_lift')


@pytest.fixture(scope='module')
def analyzer() -> LiftAnalyzer:
    return LiftAnalyzer(CONFIG)


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


@pytest.mark.parametrize(('k_theta', 'dp', 'alpha', 'pattern'), [
    ([float('nan')], [0.3], 0.1, r'k_theta.*nan'),
    ([float('inf')], [0.3], 0.1, r'k_theta.*inf'),
    ([0.0], [0.3], 0.1, r'k_theta.*positive.*0\.0'),
    ([-2.0], [0.3], 0.1, r'k_theta.*positive.*-2\.0'),
    ([1.0, 2.0], [0.3], 0.1, r'k_theta.*1 or 3 values.*2'),
    ([], [0.3], 0.1, r'k_theta.*empty'),
    ([1.0], [], 0.1, r'delta_theta_p.*empty'),
    ([1.0], [0.1, 0.2], 0.1, r'delta_theta_p.*1 or 3 values'),
    ([1.0], [-0.1], 0.1, r'delta_theta_p.*>= 0.*-0\.1'),
    ([1.0], [math.radians(80.0)], 0.1, r'delta_theta_p.*exceeds'),
    ([1.0], [float('nan')], 0.1, r'delta_theta_p.*nan'),
    ([1.0], [0.3], math.pi / 2, r'friction_angle.*90'),
    ([1.0], [0.3], 2.0, r'friction_angle.*2\.0'),
    ([1.0], [0.3], float('nan'), r'friction_angle.*nan'),
    ([1.0], [0.3], float('-inf'), r'friction_angle.*inf'),
    ([1.0], [math.radians(63.0)], 0.1, r'no SPCM solution.*63'),
])
def test_bad_requests_are_rejected_with_the_field_and_value(
        client: RosClient, server, k_theta: list[float], dp: list[float], alpha: float,
        pattern: str) -> None:
    import re

    response = _call(client, _request(k_theta, dp, alpha))
    assert response.ok is False
    assert re.search(pattern, response.message), response.message
    assert list(response.delta_theta_s) == []
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
    assert 'lift guaranteed (eq. 18) : yes' in inside.stdout
    outside = _run_client('--k-theta', '0.5', '--delta-theta-p', '40deg')
    assert outside.returncode == 0, outside.stderr
    assert 'lift guaranteed (eq. 18) : no' in outside.stdout
    rejected = _run_client('--k-theta', '-1', '--delta-theta-p', '0.3')
    assert rejected.returncode == 2
    assert 'REJECTED' in rejected.stdout and 'k_theta' in rejected.stdout
    bad_angle = _run_client('--k-theta', '1', '--delta-theta-p', 'forty')
    assert bad_angle.returncode == 2
    assert "'forty' is not an angle" in bad_angle.stderr
    missing = _run_client('--k-theta', '1', '--delta-theta-p', '0.3', '--service',
                          '/nobody/here', '--timeout', '1')
    assert missing.returncode == 1
    assert 'not available' in missing.stderr
