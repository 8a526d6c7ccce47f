"""The Dynamixel driver on simulated time (the emulated bus it starts itself), end to end:
failing reads are a WARN in ``/diagnostics`` until the stall timeout makes them an ERROR, as on
wall time. A module of its own: no other driver may publish ``/diagnostics`` meanwhile."""

from __future__ import annotations

import pytest
from dynamixel_testing import DriverClient
from grasp_testing import config_with_free_ports

from ros_testing import installed_executable, node_process

pytestmark = [pytest.mark.integration]


def test_failing_reads_are_a_warn_on_simulated_time_before_the_error(
        tmp_path_factory: pytest.TempPathFactory) -> None:
    """On simulated time (the emulated bus the driver starts), a failing read takes the long
    packet timeout of the emulated bus: /diagnostics says WARN while reads fail, then ERROR
    after ``sim.stall_timeout_s``, as on wall time."""
    config = config_with_free_ports(tmp_path_factory.mktemp('dynamixel_sim_time'))
    command = [installed_executable('dam_hand_driver', 'hand_driver'), '--ros-args', '-p',
               'backend:=dynamixel', '-p', 'use_sim_time:=true']
    with node_process(command, env={'DAM_CONFIG': str(config)}) as driver:
        client = DriverClient()
        try:
            assert client.wait_state('ACTIVE', 60.0), driver.output()[-3000:]
            assert client.set_fault('fault_silent_ids', [3]).results[0].successful
            levels = []

            def warned() -> bool:
                message = client.diag.get('message', '')
                levels.append((client.state(), message))
                return client.state() == 'ACTIVE' and (
                    'failed reads' in message or 'reads failing' in message)

            assert client.client.spin_until(warned, 10.0), levels[-5:]
            assert 'ID 3 (finger1_position_joint)' in client.diag['message']
            # Until the ERROR, every report is a WARN: none says OK between two failed reads.
            reports: list[str] = []

            def errored() -> bool:
                if client.diag and client.state() == 'ACTIVE':
                    reports.append(client.diag['message'])
                    client.diag = {}
                return client.state() == 'ERROR'

            assert client.client.spin_until(errored, 30.0), client.diag
            assert reports and not [r for r in reports if r.startswith('ACTIVE')], reports
            assert client.set_fault('fault_silent_ids', []).results[0].successful
            reset = client.reset()
            assert reset.success, reset.message
        finally:
            client.client.close()
