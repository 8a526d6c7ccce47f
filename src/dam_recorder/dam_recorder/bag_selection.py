"""Which part of a bag ``bag plot`` and ``bag export`` show: one grasp, or a time window.

A bag recorded by hand (not an episode) may hold several grasps, with long quiet stretches
between them. The grasps are found from ``/dam/status``
(:func:`dam_recorder.bag_info.grasps_from_status`); ``--episode N`` picks the N-th (1-based,
the numbering ``bag info`` prints), ``--start``/``--end`` a window [s from the bag's first
message]. Without either, a bag of one grasp (an episode) is shown whole, and of several the
last grasp is shown and the others are named (:attr:`Selection.notes`).

A grasp's window runs from :data:`BEFORE_S` before its first active phase (not before the end
of the grasp before it) to :data:`AFTER_S` after its end phase (not past the start of the
next one); one whose end the bag lacks runs to the bag's end. No rclpy.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

from dam_common.words import counted
from dam_recorder.bag_info import Grasp
from dam_recorder.errors import BagReadError

#: Time shown before a grasp's first active phase [s].
BEFORE_S = 1.0
#: Time shown after a grasp's end phase [s] (the classification, the hold).
AFTER_S = 3.0


@dataclass(frozen=True)
class Selection:
    """The part of a bag to show.

    Attributes
    ----------
    start_ns, end_ns : int
        The window [ns since the epoch], both ends included.
    grasp : int or None
        The 1-based number of the grasp shown (``None``: a time window or the whole bag).
    grasp_count : int
        Grasps in the bag.
    outcome : str or None
        The shown grasp's outcome name from ``/dam/status`` (``None`` without one grasp).
    description : str
        One line: what is shown.
    notes : list of str
        What else the bag holds, and how to choose it.
    """

    start_ns: int
    end_ns: int
    grasp: int | None
    grasp_count: int
    outcome: str | None
    description: str
    notes: list[str] = field(default_factory=list)

    def contains(self, time_ns: int) -> bool:
        """Whether ``time_ns`` lies in the window."""
        return self.start_ns <= time_ns <= self.end_ns


def grasp_line(number: int, grasp: Grasp, bag_start_ns: int) -> str:
    """``2: 12.345 s to 40.100 s, FAILURE`` [s from the bag start]."""
    t0 = (grasp.start_ns - bag_start_ns) * 1e-9
    t1 = '-' if grasp.end_ns is None else f'{(grasp.end_ns - bag_start_ns) * 1e-9:.3f}'
    return f'{number}: {t0:.3f} s to {t1} s, {grasp.outcome}'


def grasp_window(grasps: Sequence[Grasp], index: int, bag_start_ns: int,
                 bag_end_ns: int) -> tuple[int, int]:
    """The window [ns] of ``grasps[index]`` (0-based; see the module)."""
    grasp = grasps[index]
    start = grasp.start_ns - int(BEFORE_S * 1e9)
    if index > 0 and grasps[index - 1].end_ns is not None:
        start = max(start, grasps[index - 1].end_ns)
    if grasp.end_ns is None:
        end = bag_end_ns
    else:
        end = grasp.end_ns + int(AFTER_S * 1e9)
        if index + 1 < len(grasps):
            end = min(end, grasps[index + 1].start_ns)
    return max(start, bag_start_ns), min(end, bag_end_ns)


def select(grasps: Sequence[Grasp], bag_start_ns: int, bag_end_ns: int, *,
           episode: int | None = None, start_s: float | None = None,
           end_s: float | None = None) -> Selection:
    """The part of the bag to show (see the module).

    Parameters
    ----------
    grasps : the grasps ``/dam/status`` shows, in time order.
    bag_start_ns, bag_end_ns : the bag's first and last message [ns since the epoch].
    episode : the grasp to show, 1-based; exclusive with ``start_s``/``end_s``.
    start_s, end_s : a window [s from the bag's first message]; either may be left out.

    Raises
    ------
    BagReadError
        ``episode`` with a window, a grasp number the bag does not hold, a window that is
        empty, not finite or outside the bag.
    """
    duration_s = (bag_end_ns - bag_start_ns) * 1e-9
    count = len(grasps)
    listing = [grasp_line(i, g, bag_start_ns) for i, g in enumerate(grasps, 1)]
    if episode is not None and (start_s is not None or end_s is not None):
        raise BagReadError('--episode and --start/--end choose the same thing: give one')
    if episode is not None:
        if not 1 <= episode <= count:
            held = (f'grasps 1 to {count}: ' + '; '.join(listing)) if count else 'no grasp'
            raise BagReadError(f'--episode {episode}: the bag holds {held}')
        start, end = grasp_window(grasps, episode - 1, bag_start_ns, bag_end_ns)
        return Selection(start, end, episode, count, grasps[episode - 1].outcome,
                         f'grasp {listing[episode - 1]} (of {count})')
    if start_s is not None or end_s is not None:
        low = 0.0 if start_s is None else start_s
        high = duration_s if end_s is None else end_s
        for name, value in (('--start', low), ('--end', high)):
            if not math.isfinite(value):
                raise BagReadError(f'{name} {value}: not a finite time')
        if high < 0.0 or low > duration_s:
            raise BagReadError(f'--start {low:g} s to --end {high:g} s lies outside the bag '
                               f'(0 s to {duration_s:.3f} s)')
        if not low < high:
            raise BagReadError(f'--start {low:g} s is not before --end {high:g} s')
        start = bag_start_ns + int(round(max(low, 0.0) * 1e9))
        end = bag_start_ns + int(round(min(high, duration_s) * 1e9))
        inside = [i for i, g in enumerate(grasps) if start <= g.start_ns <= end]
        outcome = grasps[inside[0]].outcome if len(inside) == 1 else None
        notes = ([f'the window holds {len(inside)} of the bag\'s {counted(count, "grasp")}']
                 if count else [])
        return Selection(start, end, None, count, outcome,
                         f'{(start - bag_start_ns) * 1e-9:.3f} s to '
                         f'{(end - bag_start_ns) * 1e-9:.3f} s', notes)
    if count <= 1:
        return Selection(bag_start_ns, bag_end_ns, 1 if count else None, count,
                         grasps[0].outcome if count else None, 'the whole bag')
    start, end = grasp_window(grasps, count - 1, bag_start_ns, bag_end_ns)
    notes = [f'the bag holds {counted(count, "grasp")}; shown: the last. The others:',
             *[f'  {line}' for line in listing[:-1]],
             'choose one with --episode N, or a window with --start S --end S']
    return Selection(start, end, count, count, grasps[-1].outcome,
                     f'grasp {listing[-1]} (of {count})', notes)
