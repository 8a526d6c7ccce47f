"""The parts of the Dynamixel X-series control table the suite uses, and what its values mean
(no I/O).

Addresses, the blocks of the bus cycle and the servo check, the Hardware Error Status bits and
the Bus Watchdog's trip value (ROBOTIS e-manual, X series, Protocol 2.0: the addresses are
shared by the models of :data:`dam_common.dynamixel_config.MODELS`), and the timing facts of
the SDK's transactions that the driver and ``dynamixel_setup`` both depend on.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

# Control table addresses (X series, shared by the supported models).
ADDR_ID = 7
ADDR_BAUD_RATE = 8
ADDR_RETURN_DELAY_TIME = 9
ADDR_OPERATING_MODE = 11
ADDR_CURRENT_LIMIT = 38
ADDR_TORQUE_ENABLE = 64
ADDR_HARDWARE_ERROR = 70
ADDR_BUS_WATCHDOG = 98
ADDR_GOAL_CURRENT = 102
ADDR_GOAL_POSITION = 116
ADDR_REALTIME_TICK = 120
ADDR_PRESENT_CURRENT = 126
ADDR_PRESENT_VELOCITY = 128
ADDR_PRESENT_POSITION = 132
#: The block one sync read takes per cycle: Realtime Tick .. Present Position.
STATE_START, STATE_LENGTH = ADDR_REALTIME_TICK, 16
#: The block one sync write gives per cycle: Goal Current .. Goal Position.
GOAL_START, GOAL_LENGTH = ADDR_GOAL_CURRENT, 18
#: The servo check's block: Torque Enable .. Goal Position (64-119).
CHECK_START, CHECK_LENGTH = ADDR_TORQUE_ENABLE, ADDR_GOAL_POSITION + 4 - ADDR_TORQUE_ENABLE
#: Bus Watchdog (98) of a servo whose watchdog tripped (-1): its goals are read-only.
WATCHDOG_TRIPPED = 255
#: The Alert bit of a status packet's error byte: the servo has a hardware error.
ALERT_BIT = 0x80
#: Hardware Error Status bits (address 70).
HARDWARE_ERROR_BITS = {0: 'input voltage error', 2: 'overheating error',
                       3: 'motor encoder error', 4: 'electrical shock error',
                       5: 'overload error'}
_KNOWN_BITS = sum(1 << b for b in HARDWARE_ERROR_BITS)

#: Tries of one start-up, arming or recovery transaction before a servo counts as silent.
TRANSACTION_TRIES = 3
#: The SDK's packet timeout without the transfer time [ms]: twice its USB latency timer
#: (16 ms) plus 2 ms. After a failed transaction the input is drained until the line has
#: been quiet this long: an answer later than the SDK waited must not be taken for the next
#: transaction's (the SDK matches status packets by ID only).
QUIET_MS = 2.0 * 16.0 + 2.0
#: A drain ends after this many quiet times even if bytes keep coming.
DRAIN_LIMIT = 8


def stale_error_bits(bits: int | np.ndarray) -> int | np.ndarray:
    """Bits that no Hardware Error Status has: an answer of an earlier transaction, which the
    SDK took for this one (it matches status packets by ID only)."""
    return bits & ~_KNOWN_BITS


def hardware_error_names(bits: int) -> str:
    """``overload error, overheating error`` for Hardware Error Status ``bits``."""
    names = [name for bit, name in HARDWARE_ERROR_BITS.items() if bits & (1 << bit)]
    unknown = bits & ~_KNOWN_BITS
    if unknown:
        names.append(f'unknown bits 0x{unknown:02x}')
    return ', '.join(names) if names else 'none'


def id_ranges(ids: Sequence[int]) -> str:
    """``1-3, 5, 7-9`` for IDs 1, 2, 3, 5, 7, 8, 9."""
    parts: list[str] = []
    ordered = sorted(set(ids))
    k = 0
    while k < len(ordered):
        end = k
        while end + 1 < len(ordered) and ordered[end + 1] == ordered[end] + 1:
            end += 1
        parts.append(str(ordered[k]) if end == k else f'{ordered[k]}-{ordered[end]}')
        k = end + 1
    return ', '.join(parts)
