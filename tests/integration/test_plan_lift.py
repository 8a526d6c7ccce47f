"""/plan_lift of the installed check_lift_server, and the plan_lift client, over DDS."""

from __future__ import annotations

import math
import subprocess
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from dam_analysis.planner import LiftPlanner, ranges_from_request
from dam_common.config import load_config
from ros_testing import RosClient, installed_executable, node_process

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG = load_config(REPO_ROOT / 'config' / 'dam.yaml')
SERVER = installed_executable('dam_analysis', 'check_lift_server')
CLIENT = installed_executable('dam_analysis', 'plan_lift')
FIELDS = ('friction_angle_min', 'friction_angle_max', 'mass_min', 'mass_max',
          'position_tolerance', 'k_theta_max', 'delta_theta_p_min', 'delta_theta_p_max',
          'min_margin')
ANSWER = ('found', 'k_theta', 'delta_theta_p', 'worst_case_margin', 'position_error_bound',
          'best_k_theta', 'best_delta_theta_p', 'best_worst_case_margin', 'csm_k_theta',
          'csm_delta_theta_p', 'csm_margin', 'csm_in_domain', 'k_theta_cap', 'method')


@pytest.fixture(scope='module')
def server() -> Iterator[object]:
    with node_process([SERVER]) as proc:
        yield proc


@pytest.fixture(scope='module')
def client(server: object) -> Iterator[RosClient]:
    ros = RosClient()
    yield ros
    ros.close()


@pytest.fixture(scope='module')
def planner() -> LiftPlanner:
    return LiftPlanner(CONFIG)


def _call(client: RosClient, **fields: float):
    from dam_interfaces.srv import PlanLift

    request = PlanLift.Request()
    for name, value in fields.items():
        setattr(request, name, value)
    return client.call(PlanLift, '/plan_lift', request, timeout=60.0)


def _expected(planner: LiftPlanner, **fields: float):
    from dam_interfaces.srv import PlanLift

    request = PlanLift.Request()
    for name, value in fields.items():
        setattr(request, name, value)
    ranges, _ = ranges_from_request(planner, *(getattr(request, f) for f in FIELDS))
    return planner.plan(ranges)


def _same(response, plan) -> None:
    for name in ANSWER:
        got, want = getattr(response, name), getattr(plan, name)
        if isinstance(want, (bool, str)):
            assert got == want, name
        else:
            assert got == pytest.approx(float(want), nan_ok=True), name


def test_a_default_constructed_request_plans_for_the_configuration(client: RosClient,
                                                                   planner: LiftPlanner) -> None:
    """``ros2 service call /plan_lift dam_interfaces/srv/PlanLift "{}"``."""
    response = _call(client)
    assert response.ok, response.message
    assert response.found and response.k_theta > 0.0
    _same(response, _expected(planner))
    assert response.message.startswith('guaranteed over the ranges: k_theta ')
    assert ('[from the configuration: friction_angle = 5 deg, mass = 0.04 kg, k_theta_max = '
            '100 N*m/rad, min_margin = 0.01 N, object = cylinder]') in response.message


def test_the_issue_s_ranges_cross_dds_as_the_core_answers_them(client: RosClient,
                                                               planner: LiftPlanner) -> None:
    fields = {'friction_angle_min': math.radians(3.0), 'friction_angle_max': math.radians(6.0),
              'mass_min': 0.03, 'mass_max': 0.05, 'position_tolerance': 1e-3}
    response = _call(client, **fields)
    assert response.ok and response.found, response.message
    _same(response, _expected(planner, **fields))
    assert response.position_error_bound > 0.0
    assert 'alpha_max = 6 deg' in response.method and '5 positions' in response.method
    # 30 deg: no guarantee, the reason and the CSM's pair
    response = _call(client, friction_angle_min=math.radians(30.0))
    assert response.ok and not response.found
    assert 'holds for no stiffness there' in response.message
    assert math.isnan(response.k_theta) and response.csm_margin > 0.0


@pytest.mark.parametrize(('fields', 'words'), [
    ({'friction_angle_min': math.nan}, 'friction_angle_min: non-finite value nan'),
    ({'mass_min': 0.05, 'mass_max': 0.03}, 'mass: empty range'),
    ({'position_tolerance': 0.5},
     'position_tolerance: 0.5 m (500 mm) is outside [0, 0.005] m ([0, 5] mm)'),
    ({'delta_theta_p_max': 2.0}, 'delta_theta_p: '),
    ({'k_theta_max': math.inf}, 'k_theta_max: non-finite value inf'),
])
def test_malformed_requests_are_refused_and_the_server_stays(client: RosClient, server,
                                                             fields: dict, words: str) -> None:
    response = _call(client, **fields)
    assert not response.ok and words in response.message, response.message
    assert math.isnan(response.k_theta) and not response.found
    assert server.alive(), server.output()
    assert _call(client).ok


def test_random_requests_then_a_valid_one(client: RosClient, server,
                                          planner: LiftPlanner) -> None:
    rng = np.random.default_rng(12)
    specials = [math.nan, math.inf, -math.inf, 0.0, -1.0, 1e308, 5e-324, 0.2]
    answered = 0
    for _ in range(60):
        fields = {}
        for name in FIELDS:
            if rng.random() < 0.5:
                fields[name] = float(rng.choice(specials + [float(rng.uniform(-0.1, 1.0))]))
        # tolerances whose position nodes are built already (a new one costs 0.5 s a node)
        fields['position_tolerance'] = float(rng.choice([0.0, 1e-3, math.nan, -1e-3]))
        response = _call(client, **fields)
        answered += 1
        assert response.ok or response.message
    assert answered == 60 and server.alive(), server.output()
    _same(_call(client), _expected(planner))


def test_a_plan_for_a_named_object(client: RosClient) -> None:
    """``object`` selects a column of the library; the plan is that object's, and a name
    outside the library is refused by name."""
    response = _call(client, object='square_bar')
    assert response.ok, response.message
    assert response.object == 'square_bar'
    _same(response, _expected(LiftPlanner(CONFIG.with_object('square_bar'))))
    default = _call(client)
    assert default.object == 'cylinder' and 'object = cylinder]' in default.message
    assert (response.csm_k_theta, response.csm_delta_theta_p) != (
        default.csm_k_theta, default.csm_delta_theta_p)
    unknown = _call(client, object='pencil')
    assert not unknown.ok and "'pencil'" in unknown.message and unknown.object == ''
    assert _call(client).ok


def _run(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(CLIENT), *args], capture_output=True, text=True, timeout=120)


def test_command_line_client(server: object) -> None:
    done = _run('--friction-angle', '3deg:6deg', '--mass', '30g:50g', '--position-tolerance',
                '1mm')
    assert done.returncode == 0, done.stderr
    assert 'guaranteed (eq. 18)       : k_theta ' in done.stdout
    assert 'contact stiffness model   : k_theta ' in done.stdout
    assert 'method: friction: worst case at alpha_max = 6 deg' in done.stdout
    # the same request in SI units, bare or suffixed: a bare number is SI in every command
    suffixed = _run('--friction-angle', '0.05235987755982988:0.10471975511965977', '--mass',
                    '0.03kg:0.05kg', '--position-tolerance', '0.001')
    assert suffixed.returncode == 0 and suffixed.stdout == done.stdout, suffixed.stderr
    for option, word, meant in (('--friction-angle', '3:6', '3deg'), ('--mass', '30:50', '30g'),
                                ('--position-tolerance', '1', '1mm')):
        implausible = _run(option, word)  # refused before any request, with the meaning
        assert implausible.returncode == 2, implausible.stdout
        assert f'did you mean {meant}?' in implausible.stderr, implausible.stderr
        assert 'REJECTED' not in implausible.stdout
    capped = _run('--friction-angle', '5deg', '--k-theta-max', '3')
    assert capped.returncode == 0, capped.stderr
    assert 'guaranteed (eq. 18)       : none' in capped.stdout
    assert 'is above the cap there' in capped.stdout
    refused = _run('--friction-angle', '89deg:95deg')  # the command line's own bound
    assert refused.returncode == 2 and 'REJECTED' not in refused.stdout
    assert 'friction-angle' in refused.stderr, refused.stderr
    rejected = _run('--position-tolerance', '6mm')  # the server's bound (5 mm)
    assert rejected.returncode == 2 and 'REJECTED' in rejected.stdout
    assert 'position_tolerance' in rejected.stdout, rejected.stdout
    bad = _run('--mass', '0.05:0.03')
    assert bad.returncode == 2 and 'empty range' in bad.stderr
    bad_length = _run('--position-tolerance', 'one')
    assert bad_length.returncode == 2 and "'one' is not a length" in bad_length.stderr
    missing = _run('--service', '/nobody/here', '--timeout', '1')
    assert missing.returncode == 1 and 'not available' in missing.stderr


@pytest.mark.parametrize('signum', ['SIGINT', 'SIGTERM'])
def test_a_signal_during_a_long_plan_stops_the_server_promptly(signum: str) -> None:
    """A plan with a new 2.3 mm tolerance builds 11 position nodes (seconds of work); a
    signal in the middle ends the server within 2 s, cleanly, as at any other moment."""
    import signal
    import time

    from dam_interfaces.srv import PlanLift

    with node_process([SERVER]) as proc:
        ros = RosClient()
        try:
            cli = ros.node.create_client(PlanLift, '/plan_lift')
            assert cli.wait_for_service(timeout_sec=30.0), proc.output()
            request = PlanLift.Request()
            request.position_tolerance = 2.3e-3
            cli.call_async(request)
            ros.spin_until(lambda: False, 1.5)  # the server is building nodes now
            assert proc.alive()
            start = time.monotonic()
            proc.process.send_signal(getattr(signal, signum))
            code = proc.process.wait(timeout=20.0)
            elapsed = time.monotonic() - start
        finally:
            ros.close()
        assert code == 0, proc.output()
        assert elapsed < 2.0, (elapsed, proc.output())
        assert 'Traceback' not in proc.output()


def test_check_lift_answers_while_a_first_plan_builds_its_nodes() -> None:
    """/plan_lift runs on a thread of its own: a plan with a new 2.3 mm tolerance
    (11 position nodes, seconds of work) does not hold up /check_lift, which the controller
    gives 2 s."""
    import time

    from dam_interfaces.srv import CheckLift, PlanLift

    with node_process([SERVER]) as proc:
        ros = RosClient()
        try:
            planner_cli = ros.node.create_client(PlanLift, '/plan_lift')
            assert planner_cli.wait_for_service(timeout_sec=30.0), proc.output()
            assert ros.call(CheckLift, '/check_lift', CheckLift.Request()).ok  # warm
            request = PlanLift.Request()
            request.position_tolerance = 2.3e-3
            plan = planner_cli.call_async(request)
            ros.spin_until(lambda: False, 0.5)
            answered = []
            while not plan.done() and len(answered) < 10:
                start = time.monotonic()
                response = ros.call(CheckLift, '/check_lift', CheckLift.Request(), timeout=10.0)
                answered.append((time.monotonic() - start, response.ok, plan.done()))
            assert ros.wait_future(plan, 60.0) and plan.result().ok, plan.result()
        finally:
            ros.close()
        during = [t for t, ok, plan_done in answered if not plan_done]
        assert len(during) >= 3, answered  # asked while the plan still ran
        assert all(ok for _, ok, _ in answered)
        assert max(during) < 1.0, answered
        assert proc.alive(), proc.output()
