"""What the servo check of the Dynamixel backend concludes from its reads (no I/O).

Every :data:`~dam_hand_driver.dynamixel_device.CHECK_EVERY` bus cycles, and at once after a
status packet with the Alert bit, the driver reads Torque Enable .. Goal Position of every
servo (:data:`~dam_hand_driver.dynamixel_table.CHECK_START`). :class:`ServoCheck` turns these
reads into faults, each counting only when two reads in a row show it (one read can be an
answer of an earlier transaction, or a write still on its way):

- a Hardware Error Status bit;
- torque off on an armed servo without a hardware error (it restarted);
- a tripped Bus Watchdog (address 98 reads 255: the servo refuses its goals);
- goals other than the ones the driver wrote last (a Sync Write has no answer: a servo that
  refuses its goals is seen only by reading them back).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import NamedTuple

import numpy as np

from dam_hand_driver.dynamixel_goals import ServoTable
from dam_hand_driver.dynamixel_table import WATCHDOG_TRIPPED, hardware_error_names, id_ranges


class CheckRead(NamedTuple):
    """One read of the check block, (n,) int64 per field, joint order."""

    torque_enable: np.ndarray
    hardware_error: np.ndarray  #: Hardware Error Status bits
    bus_watchdog: np.ndarray
    goal_current: np.ndarray  #: signed [units]
    goal_position: np.ndarray  #: signed [counts]


class ServoCheck:
    """The faults the reads show, two in a row.

    Parameters
    ----------
    table
        The servos.
    bus_watchdog_s
        ``dynamixel.bus_watchdog_s`` [s], for the messages.
    """

    def __init__(self, table: ServoTable, bus_watchdog_s: float) -> None:
        self.table = table
        self.bus_watchdog_s = float(bus_watchdog_s)
        n = len(table.ids)
        self.hardware_errors = np.zeros(n, dtype=np.int64)  #: Hardware Error Status
        self.torque_lost = np.zeros(n, dtype=bool)  #: torque off while armed (restarted)
        self.watchdog_tripped = np.zeros(n, dtype=bool)  #: tripped while armed
        self.watchdog_trips = np.zeros(n, dtype=np.int64)  #: trips seen since start
        self.goals_refused = np.zeros(n, dtype=bool)  #: goals other than the ones written
        self._refused_detail = [''] * n
        # What the read before showed (a fault counts when two reads in a row show it).
        self._errors_before = np.zeros(n, dtype=np.int64)
        self._off_before = np.zeros(n, dtype=bool)
        self._tripped_before = np.zeros(n, dtype=bool)
        self._refused_before = np.zeros(n, dtype=bool)

    def clear(self) -> None:
        """Forget what was seen (torque is about to come on, or the servos were recovered):
        the trip counts and the hardware errors stay."""
        for flags in (self.torque_lost, self.watchdog_tripped, self.goals_refused,
                      self._off_before, self._tripped_before, self._refused_before):
            flags[:] = False
        self._errors_before[:] = 0

    def update(self, read: CheckRead, armed: bool,
               written: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Take one read.

        Parameters
        ----------
        read
            The check block of every servo.
        armed
            Torque is on (a servo off, a tripped watchdog and refused goals count only then).
        written
            (Goal Current, Goal Position) the driver wrote last, (n,) each; ``None``: no
            goals written since arming (nothing to compare).
        """
        bits = read.hardware_error
        self.hardware_errors = bits & self._errors_before
        self._errors_before = bits
        off = (read.torque_enable == 0) & (bits == 0)
        tripped = read.bus_watchdog == WATCHDOG_TRIPPED
        n = len(self.table.ids)
        if armed:
            self.torque_lost = off & self._off_before
            now_tripped = tripped & self._tripped_before
            self.watchdog_trips += now_tripped & ~self.watchdog_tripped
            self.watchdog_tripped = now_tripped
        else:
            self.torque_lost = np.zeros(n, dtype=bool)
            self.watchdog_tripped = np.zeros(n, dtype=bool)
        self._off_before, self._tripped_before = off, tripped
        refused = np.zeros(n, dtype=bool)
        if armed and written is not None:
            current, position = written
            refused = (read.goal_current != current) | (read.goal_position != position)
            for j in np.flatnonzero(refused):
                self._refused_detail[j] = (
                    f'Goal Current {int(read.goal_current[j])}, Goal Position '
                    f'{int(read.goal_position[j])}; written {int(current[j])}, '
                    f'{int(position[j])}')
        self.goals_refused = refused & self._refused_before
        self._refused_before = refused

    def fault(self) -> str:
        """The faults, each naming its servos (empty: none); servos with the same fault are
        named together (``servos ID 1-9: Bus Watchdog tripped ...``)."""
        faults = []
        errors = self.hardware_errors
        for bits in sorted({int(b) for b in errors if b}):
            faults.append(f'{self.servos(np.flatnonzero(errors == bits))}: hardware error '
                          f'({hardware_error_names(bits)})')
        lost = np.flatnonzero(self.torque_lost)
        if lost.size:
            faults.append(f'{self.servos(lost)}: torque went off (restarted: power dip or '
                          f'reboot)')
        tripped = np.flatnonzero(self.watchdog_tripped)
        if tripped.size:
            trips = int(self.watchdog_trips[tripped].max())
            faults.append(f'{self.servos(tripped)}: Bus Watchdog tripped (no packet from the '
                          f'host for {self.bus_watchdog_s:g} s, trip {trips}; goals read-only '
                          f'until ~/reset)')
        faults += [f'{self.servos([j])}: does not follow its goals (it holds '
                   f'{self._refused_detail[j]})'
                   for j in np.flatnonzero(self.goals_refused & ~self.watchdog_tripped)]
        return '; '.join(faults)

    def servos(self, indices: Sequence[int] | np.ndarray) -> str:
        """``servo ID 3 (finger1_position_joint)`` for one, ``servos ID 1-4, 6`` for more."""
        js = [int(j) for j in indices]
        if len(js) == 1:
            return f'servo {self.table.label(js[0])}'
        return f'servos ID {id_ranges([self.table.ids[j] for j in js])}'

