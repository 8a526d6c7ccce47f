"""The servo check's conclusions (no I/O): a fault counts when two reads in a row show it, a
tripped watchdog and refused goals only while armed, trips counted once each."""

from __future__ import annotations

import numpy as np
import pytest

from dam_common.config import load_config
from dam_hand_driver.dynamixel_check import CheckRead, ServoCheck
from dam_hand_driver.dynamixel_goals import ServoTable
from dam_hand_driver.dynamixel_table import WATCHDOG_TRIPPED


@pytest.fixture(scope='module')
def table() -> ServoTable:
    return ServoTable.from_config(load_config().dynamixel)


def _read(n: int, **changes: dict[int, int]) -> CheckRead:
    fields = {'torque_enable': np.ones(n, dtype=np.int64),
              'hardware_error': np.zeros(n, dtype=np.int64),
              'bus_watchdog': np.full(n, 5, dtype=np.int64),
              'goal_current': np.full(n, 100, dtype=np.int64),
              'goal_position': np.full(n, 2048, dtype=np.int64)}
    for name, values in changes.items():
        for j, v in values.items():
            fields[name][j] = v
    return CheckRead(**fields)


def test_faults_need_two_reads_in_a_row_and_name_the_servo(table: ServoTable) -> None:
    n = len(table.ids)
    check = ServoCheck(table, 0.1)
    written = (np.full(n, 100), np.full(n, 2048))
    tripped = _read(n, bus_watchdog={0: WATCHDOG_TRIPPED})
    check.update(tripped, armed=True, written=written)
    assert check.fault() == ''  # one read may be an old answer
    check.update(tripped, armed=True, written=written)
    assert check.fault().startswith('servo ID 1 (finger1_compliant_joint): Bus Watchdog '
                                    'tripped (no packet from the host for 0.1 s, trip 1;')
    check.update(tripped, armed=True, written=written)
    assert int(check.watchdog_trips.sum()) == 1  # one trip, however long it lasts
    check.update(_read(n), armed=True, written=written)
    assert check.fault() == ''


def test_refused_goals_and_a_lost_torque_count_only_while_armed(table: ServoTable) -> None:
    n = len(table.ids)
    check = ServoCheck(table, 0.1)
    refused = _read(n, goal_position={4: 2000}, torque_enable={6: 0})
    written = (np.full(n, 100), np.full(n, 2048))
    for _ in range(2):
        check.update(refused, armed=False, written=written)
    assert check.fault() == ''
    check.update(refused, armed=True, written=None)  # nothing written since arming
    check.update(refused, armed=True, written=None)
    assert 'does not follow' not in check.fault()
    check.update(refused, armed=True, written=written)
    check.update(refused, armed=True, written=written)
    fault = check.fault()
    assert ('servo ID 5 (finger2_locked_joint): does not follow its goals (it holds Goal '
            'Current 100, Goal Position 2000; written 100, 2048)') in fault
    assert 'servo ID 7 (finger3_compliant_joint): torque went off' in fault


def test_a_hardware_error_is_named_and_clear_forgets_the_rest(table: ServoTable) -> None:
    n = len(table.ids)
    check = ServoCheck(table, 0.1)
    error = _read(n, hardware_error={2: 0x20}, bus_watchdog={3: WATCHDOG_TRIPPED})
    for _ in range(2):
        check.update(error, armed=True, written=None)
    assert 'servo ID 3 (finger1_position_joint): hardware error (overload error)' in \
        check.fault()
    check.clear()
    assert 'Bus Watchdog' not in check.fault()
    assert int(check.watchdog_trips.sum()) == 1
