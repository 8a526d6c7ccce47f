"""plan_lift says on stderr that it waits, every DAM_PROGRESS_S seconds, while its server
works (the example in docs/lift_analysis.md plans for about a minute)."""

from __future__ import annotations

import re
import threading

import pytest

from ros_testing import RosClient, installed_executable, node_process

pytestmark = pytest.mark.integration

#: Longest wait for the client's line or its end on a loaded machine [s]: it only ends a test
#: that would otherwise hang; nothing here is timed.
WAIT_S = 120.0


def test_plan_lift_reports_while_it_waits_for_the_answer() -> None:
    from dam_interfaces.srv import PlanLift

    client = RosClient()
    requests: list[PlanLift.Request] = []

    def answer(request: PlanLift.Request, response: PlanLift.Response) -> PlanLift.Response:
        requests.append(request)
        response.ok = True
        response.object = 'fixture'
        response.message = 'fixture answer'
        return response

    try:
        # The service exists but is not served until the client has said that it waits:
        # however slow the machine, the answer comes after the progress line.
        client.node.create_service(PlanLift, '/plan_lift_fixture', answer)
        exe = installed_executable('dam_analysis', 'plan_lift')
        with node_process([exe, '--service', '/plan_lift_fixture', '--timeout', '600'],
                          env={'DAM_PROGRESS_S': '0.2'}) as proc:
            waiting = 'plan_lift: waiting for the answer of /plan_lift_fixture, '
            assert _wait(lambda: waiting in proc.output(), proc), proc.output()
            assert client.spin_until(lambda: not proc.alive(), WAIT_S), proc.output()
            assert proc.process.returncode == 0, proc.output()
            out = proc.output()
    finally:
        client.close()
    assert len(requests) == 1
    assert re.search(r'^plan_lift: waiting for the answer of /plan_lift_fixture, \d+ s$', out,
                     re.M), out
    assert 'fixture answer' in out


def _wait(predicate, proc) -> bool:  # noqa: ANN001
    """Wait, without serving the service, until ``predicate()`` or the process ended."""
    event = threading.Event()
    for _ in range(int(WAIT_S / 0.05)):
        if predicate() or not proc.alive():
            return predicate()
        event.wait(0.05)
    return predicate()
