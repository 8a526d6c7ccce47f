"""The object in a bag: the stand-in's ground truth and the controller's estimate (no rclpy).

What ``bag info`` and ``bag plot`` say about the object, from three topics:

``/sim/object_pose`` (``geometry_msgs/PoseStamped``, the stand-in only)
    The rise: ``position.z`` above the first pose read [mm], at the end and its largest.
``/sim/object_table_contact`` (``dam_interfaces/ObjectTableContact``, the stand-in only)
    Whether the object **left the table (stand-in)** during the grasp, by the stand-in's
    lift-off rule (``dam_sim_bridge.lift_off``: off the table for 50 ms; a bounce does not
    count): a message at or before the end of the grasp (the episode's end, else the last
    message read) says ``lifted``, which the stand-in keeps from the lift-off to the world's
    next reset. The lift-off is placed at the receive time of the first message of the
    off-table stretch that first says ``lifted`` (when the stretch fell between two messages,
    at the message before), to one message period (10 ms at the default 100 Hz); when the
    first message read already says ``lifted``, the lift-off came before it and has no
    time. **Off the table at the end**: the last message at or before the end of the grasp
    says ``off_table_at_end``: off the table for the last 0.1 s.
``/dam/episode`` (``dam_interfaces/GraspEpisode``)
    The **controller's estimate**, from its joints alone, in the ENDED event: the fields
    ``object_rise`` [m], ``object_left_table`` and ``object_orientation`` where the recorded
    message has them (older messages have none: no estimate).

:class:`ObjectCollector` takes the messages as a reading loop meets them and gives
:class:`ObjectTruth` and :class:`ObjectEstimate`; :func:`object_lines` puts both in words.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

OBJECT_POSE_TOPIC = '/sim/object_pose'
TABLE_CONTACT_TOPIC = '/sim/object_table_contact'
EPISODE_TOPIC = '/dam/episode'
#: The topics :class:`ObjectCollector` reads.
OBJECT_TOPICS = (OBJECT_POSE_TOPIC, TABLE_CONTACT_TOPIC, EPISODE_TOPIC)
#: ``GraspEpisode.EVENT_ENDED``.
_EVENT_ENDED = 1


@dataclass(frozen=True)
class ObjectTruth:
    """The stand-in's ground truth of the object in a bag (or a window of it).

    Attributes
    ----------
    rise_final_mm, rise_max_mm
        Rise of ``position.z`` above the first pose at the last pose, and its largest [mm];
        None without poses.
    contact_recorded
        Whether ``/sim/object_table_contact`` messages were read.
    lifted
        The object left the table by the end of the grasp, a lift-off (None: not recorded).
    lift_off_s
        When the object left the table [s from the bag's first message] (None: no lift-off,
        one before the first message read, or not recorded).
    off_table_at_end
        Off the table for the last 0.1 s at the end of the grasp (None: not recorded).
    off_table_s
        Stretches off the table, ``(start, end)`` [s from the bag's first message], from the
        first to the last message of each.
    """

    rise_final_mm: float | None
    rise_max_mm: float | None
    contact_recorded: bool
    lifted: bool | None
    lift_off_s: float | None
    off_table_at_end: bool | None
    off_table_s: tuple[tuple[float, float], ...] = ()


@dataclass(frozen=True)
class ObjectEstimate:
    """The controller's estimate of the object, from its ENDED event.

    Attributes
    ----------
    rise_mm
        ``object_rise`` [mm] (None: not in the message, or NaN: not classified).
    left_table
        ``object_left_table`` (None: not in the message).
    orientation
        ``object_orientation`` in words (None: not in the message).
    """

    rise_mm: float | None
    left_table: bool | None
    orientation: str | None


def _orientation_text(value: Any) -> str | None:
    """An orientation as the message holds it: an angle [rad] in degrees, a quaternion, or
    numbers as they are."""
    if value is None:
        return None
    if all(hasattr(value, axis) for axis in ('x', 'y', 'z', 'w')):
        return (f'quaternion (x {float(value.x):.4g}, y {float(value.y):.4g}, '
                f'z {float(value.z):.4g}, w {float(value.w):.4g})')
    if isinstance(value, (int, float)):
        angle = float(value)
        return f'{math.degrees(angle):.1f} deg' if math.isfinite(angle) else None
    try:
        numbers = [float(v) for v in value]
    except (TypeError, ValueError):
        return str(value)
    return '[' + ', '.join(f'{v:.4g}' for v in numbers) + ']' if numbers else None


class ObjectCollector:
    """Collects the object's messages (:data:`OBJECT_TOPICS`) in time order.

    Parameters
    ----------
    start_ns
        Time 0 of the times it reports [ns since the epoch]: the bag's first message.
    """

    def __init__(self, start_ns: int) -> None:
        self.start_ns = int(start_ns)
        self._heights: list[float] = []
        # receive time, on_table, lifted, off_table_at_end
        self._contacts: list[tuple[int, bool, bool, bool]] = []
        self._ended: Any = None

    def add(self, topic: str, time_ns: int, message: Any) -> None:
        """Take one message (others than :data:`OBJECT_TOPICS` are ignored)."""
        if topic == OBJECT_POSE_TOPIC:
            self._heights.append(float(message.pose.position.z))
        elif topic == TABLE_CONTACT_TOPIC:
            if hasattr(message, 'off_table_at_end'):
                lifted, at_end = bool(message.lifted), bool(message.off_table_at_end)
            else:  # the message's first form: lifted_off (off 50 ms now), lifted (0.1 s)
                lifted, at_end = bool(message.lifted_off), bool(message.lifted)
            self._contacts.append((int(time_ns), bool(message.on_table), lifted, at_end))
        elif topic == EPISODE_TOPIC and int(message.event) == _EVENT_ENDED:
            self._ended = message

    def _seconds(self, time_ns: int) -> float:
        return (time_ns - self.start_ns) * 1e-9

    def truth(self, end_ns: int | None = None) -> ObjectTruth:
        """The ground truth at the end of the grasp ``end_ns`` [ns since the epoch] (None:
        the last message): ``lifted`` and ``off_table_at_end`` from the messages up to it, the
        off-table stretches from all."""
        rise_final = rise_max = None
        if self._heights:
            z0 = self._heights[0]
            rise_final = (self._heights[-1] - z0) * 1e3
            rise_max = (max(self._heights) - z0) * 1e3
        contacts = self._contacts
        if not contacts:
            return ObjectTruth(rise_final, rise_max, False, None, None, None)
        spans: list[tuple[float, float]] = []
        starts: list[int] = []  # per message: the start of its off-table stretch, or its time
        for time_ns, on_table, _lifted, _at_end in contacts:
            if on_table:
                starts.append(time_ns)
                continue
            if not starts or contacts[len(starts) - 1][1]:  # the first off the table
                spans.append((self._seconds(time_ns), self._seconds(time_ns)))
                starts.append(time_ns)
            else:
                starts.append(starts[-1])
            spans[-1] = (spans[-1][0], self._seconds(time_ns))
        before = [c for c in contacts if end_ns is None or c[0] <= end_ns]
        if not before:
            return ObjectTruth(rise_final, rise_max, True, None, None, None, tuple(spans))
        first = next((i for i, c in enumerate(before) if c[2]), None)
        lift_off: float | None = None
        if first is not None and first > 0:
            # in the stretch of the first message saying lifted, else just before it
            at = first if not before[first][1] else first - 1
            lift_off = self._seconds(starts[at])
        return ObjectTruth(rise_final, rise_max, True, first is not None, lift_off,
                           before[-1][3], tuple(spans))

    def estimate(self) -> ObjectEstimate | None:
        """The controller's estimate of the last ENDED event; None without an ENDED event,
        when its message has no ``object_rise``, or when that is NaN (the grasp was not
        classified: the message's other estimate fields are then placeholders)."""
        msg = self._ended
        if msg is None:
            return None
        rise = getattr(msg, 'object_rise', None)
        if rise is None or not math.isfinite(float(rise)):
            return None
        left = getattr(msg, 'object_left_table', None)
        return ObjectEstimate(float(rise) * 1e3, None if left is None else bool(left),
                              _orientation_text(getattr(msg, 'object_orientation', None)))


def object_lines(truth: ObjectTruth, estimate: ObjectEstimate | None) -> list[str]:
    """``truth`` and ``estimate`` in words, labelled by where they come from: where both give
    a rise, both first on one line (``object rise: 8.09 mm (stand-in), 9.80 mm estimated from
    the joints``: one grasp printed as two different rises read as a contradiction); then the
    rise and whether the object left the table (the stand-in's ground truth, one line each),
    then the controller's estimate."""
    source = f'stand-in ground truth, {OBJECT_POSE_TOPIC}'
    lines = []
    if truth.rise_final_mm is not None and estimate is not None \
            and estimate.rise_mm is not None:
        lines.append(f'object rise: {truth.rise_final_mm:.2f} mm (stand-in), '
                     f'{estimate.rise_mm:.2f} mm estimated from the joints')
    if truth.rise_final_mm is None:
        lines.append(f'object rise ({source}): not recorded')
    else:
        lines.append(f'object rise ({source}, from the first pose): at the end '
                     f'{truth.rise_final_mm:.2f} mm, highest {truth.rise_max_mm:.2f} mm')
    where = f'left the table (stand-in ground truth, {TABLE_CONTACT_TOPIC})'
    if not truth.contact_recorded or truth.lifted is None:
        lines.append(f'{where}: not recorded')
    else:
        when = ('' if not truth.lifted else ', before the first message read'
                if truth.lift_off_s is None else f', at {truth.lift_off_s:.2f} s')
        lines.append(f'{where}: {"yes" if truth.lifted else "no"}{when}; off the table at the '
                     f'grasp\'s end: {"yes" if truth.off_table_at_end else "no"}')
    label = 'controller\'s estimate (from the joints, /dam/episode)'
    if estimate is None:
        lines.append(f'{label}: none recorded')
    else:
        words = ['rise ' + ('not estimated' if estimate.rise_mm is None
                            else f'{estimate.rise_mm:.2f} mm')]
        if estimate.left_table is not None:
            words.append(f'left the table {"yes" if estimate.left_table else "no"}')
        if estimate.orientation is not None:
            words.append(f'orientation {estimate.orientation}')
        lines.append(f'{label}: ' + ', '.join(words))
    return lines
