"""Lift-off: whether and when the object left the table, from its table contacts (pure).

The stand-in's ground truth of "lifted" is that the object **left the table** during the
grasp (a lift-off, the event eq. 18 promises: "the object leaves the table"), whatever its
shape and whatever it did after: a polygon that rolls on the table raises its centroid by up
to its circumradius minus its apothem (1.35 mm for the 18 mm hexagonal bar turned by 25 deg)
while it still touches, an object that left the table may have risen by less than
``classification.lift_height_m``, and a column that left it may tip out of the plane
afterwards until one end rests on the table again. So the rule reads the object-table
contacts, not the rise, and whether the object was still off the table at the end is a
separate fact.

Samples
    ``(t_i, n_i)``: the simulated time [s] and the number of object-table contact points
    closer than :data:`TOUCH_DISTANCE_M` (:meth:`~dam_sim_bridge.world.HandWorld.
    object_table_contacts`), taken by the world after every :meth:`~dam_sim_bridge.world.
    HandWorld.step` call: every device cycle (2 ms) in the lockstep trial and in the stand-in
    device. A sample with ``n_i > 0`` touches.
Off-table run
    Consecutive samples that do not touch; it starts at its first sample ``t_a`` and its
    length is ``t_b - t_a``, ``t_b`` its last sample.
Lift-off
    The first off-table run at least :data:`LIFT_OFF_MIN_S` (50 ms) long; the **lift-off
    time** is its start ``t_a``. A bounce, a shorter run, is no lift-off.
Lifted
    A lift-off happened since the record began (the world's reset; a lockstep trial begins
    it again at the goal). It stays true when the object falls back or an end of it comes to
    rest on the table.
Off the table at the end
    At the end of the record (the end of the grasp), the object is off the table and has been
    for at least :data:`AT_END_WINDOW_S` (0.1 s): no sample of the last 0.1 s touches.

:class:`LiftOffTracker` applies the rule sample by sample (the world keeps one,
:attr:`~dam_sim_bridge.world.HandWorld.lift_off`), :func:`lift_off_of_samples` to a recorded
series.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

#: A contact point of the object and the table closer than this touches [m]. Bullet reports
#: manifold points up to about 0.7 mm apart; a resting object's are within 1e-5 m of zero.
TOUCH_DISTANCE_M = 1.0e-4
#: Shortest off-table run that is a lift-off [s]; a shorter one is a bounce.
LIFT_OFF_MIN_S = 0.05
#: The object is off the table at the end when it has been off it this long then [s].
AT_END_WINDOW_S = 0.1
#: Slack of the time comparisons [s] (sample times are sums of physics steps).
_TIME_SLACK_S = 1e-9


@dataclass(frozen=True)
class LiftOffState:
    """The rule's verdict after the last sample.

    Attributes
    ----------
    table_contacts
        Object-table contact points of the last sample (0 before any sample).
    off_table_s
        Length of the off-table run the last sample belongs to [s]; 0 when it touches.
    lift_off_time
        Start of the first lift-off [s, the samples' clock]; NaN when none.
    off_table_at_end
        Off the table for at least :data:`AT_END_WINDOW_S` at the last sample.
    samples
        Samples taken.
    """

    table_contacts: int
    off_table_s: float
    lift_off_time: float
    off_table_at_end: bool
    samples: int

    @property
    def lifted(self) -> bool:
        """A lift-off happened (the object may have fallen back since)."""
        return not math.isnan(self.lift_off_time)

    @property
    def on_table(self) -> bool:
        """The last sample touches (or there was none)."""
        return self.samples == 0 or self.table_contacts > 0


class LiftOffTracker:
    """Applies the lift-off rule (module docstring) to samples as they come.

    Parameters
    ----------
    lift_off_min_s
        Shortest off-table run that is a lift-off [s] (> 0).
    at_end_window_s
        Off-table time at the last sample that makes the object off the table at the end
        [s] (> 0).

    Raises
    ------
    ValueError
        A length that is not a positive finite number.
    """

    def __init__(self, lift_off_min_s: float = LIFT_OFF_MIN_S,
                 at_end_window_s: float = AT_END_WINDOW_S) -> None:
        for name, value in (('lift_off_min_s', lift_off_min_s),
                            ('at_end_window_s', at_end_window_s)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ValueError(f'{name} must be a positive number of seconds, got {value!r}')
        self.lift_off_min_s = float(lift_off_min_s)
        self.at_end_window_s = float(at_end_window_s)
        self.reset()

    def reset(self) -> None:
        """Forget every sample: a new record begins (the world was reset, or a grasp
        starts)."""
        self._samples = 0
        self._last_t = -math.inf
        self._contacts = 0
        self._off_since = math.nan  # start of the current off-table run
        self._lift_off = math.nan

    def update(self, time_s: float, table_contacts: int) -> None:
        """Take the sample ``(time_s, table_contacts)``.

        Parameters
        ----------
        time_s
            Simulated time of the sample [s]; not before the previous sample's.
        table_contacts
            Object-table contact points (>= 0).

        Raises
        ------
        ValueError
            A time that is not finite or goes back, or a negative contact count.
        """
        t = float(time_s)
        if not math.isfinite(t) or t < self._last_t:
            raise ValueError(f'sample time {time_s!r} s is not finite or before the previous '
                             f'sample ({self._last_t!r} s)')
        n = int(table_contacts)
        if n < 0:
            raise ValueError(f'table_contacts must be >= 0, got {table_contacts!r}')
        self._samples += 1
        self._last_t = t
        self._contacts = n
        if n > 0:
            self._off_since = math.nan
            return
        if math.isnan(self._off_since):
            self._off_since = t
        if (math.isnan(self._lift_off)
                and t - self._off_since >= self.lift_off_min_s - _TIME_SLACK_S):
            self._lift_off = self._off_since

    @property
    def off_table_s(self) -> float:
        """Length of the current off-table run [s]; 0 when the last sample touches."""
        return 0.0 if math.isnan(self._off_since) else self._last_t - self._off_since

    @property
    def lift_off_time(self) -> float:
        """Start of the first lift-off [s]; NaN when none yet."""
        return self._lift_off

    @property
    def lifted(self) -> bool:
        """A lift-off happened since the record began."""
        return not math.isnan(self._lift_off)

    @property
    def off_table_at_end(self) -> bool:
        """Off the table for at least ``at_end_window_s`` at the last sample."""
        return (not math.isnan(self._off_since)
                and self.off_table_s >= self.at_end_window_s - _TIME_SLACK_S)

    @property
    def table_contacts(self) -> int:
        """Contact points of the last sample (0 before any)."""
        return self._contacts

    def state(self) -> LiftOffState:
        """The verdict after the last sample."""
        return LiftOffState(table_contacts=self._contacts, off_table_s=self.off_table_s,
                            lift_off_time=self._lift_off,
                            off_table_at_end=self.off_table_at_end, samples=self._samples)


def lift_off_of_samples(samples: Iterable[tuple[float, int]],
                        lift_off_min_s: float = LIFT_OFF_MIN_S,
                        at_end_window_s: float = AT_END_WINDOW_S) -> LiftOffState:
    """The rule applied to a whole record of ``(time [s], table contacts)`` samples.

    Raises
    ------
    ValueError
        As :meth:`LiftOffTracker.update`, naming the bad sample.
    """
    tracker = LiftOffTracker(lift_off_min_s, at_end_window_s)
    for t, n in samples:
        tracker.update(t, n)
    return tracker.state()
