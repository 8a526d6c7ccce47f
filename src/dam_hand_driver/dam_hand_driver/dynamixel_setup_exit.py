"""How ``dynamixel_setup`` ends: its exit statuses and the one line on stderr that says why.

The leaf of the command's modules (standard library only): the entry point
(:mod:`dam_hand_driver.dynamixel_setup`, which catches the stop signals before the work loads)
and the work (:mod:`dam_hand_driver.dynamixel_setup_bus`,
:mod:`dam_hand_driver.dynamixel_setup_cli`) both import it, and it imports neither.
"""

from __future__ import annotations

import sys

PROG = 'dynamixel_setup'

#: Exit statuses (:mod:`dam_hand_driver.dynamixel_setup`).
EXIT_OK, EXIT_FAILED, EXIT_USAGE, EXIT_INTERRUPTED = 0, 1, 2, 130


def refuse(line: str) -> None:
    """One line on stderr, ``dynamixel_setup: ...``."""
    sys.stderr.write(f'{PROG}: {" ".join(line.split())}\n')
    sys.stderr.flush()
