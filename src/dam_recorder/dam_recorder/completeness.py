"""Whether an episode bag holds its whole episode, and what it lacks (the core, no rclpy).

An episode (:mod:`dam_recorder.episodes`) is labelled by what its bag proves. While it is
written, every message that goes into it is accounted for here (:class:`EpisodeAccount`),
with the few facts the recorder reads from it (:data:`Facts`): the header stamp of a message
of a counted topic, the counts publishers report on ``/diagnostics``, the goal events on
``/dam/episode`` and the goal statuses of the ``/dam_grasp`` action. When the episode closes,
:meth:`EpisodeAccount.judge` lists what is missing (:class:`Missing`); an episode with
anything missing is *incomplete*: its directory name ends in ``_incomplete`` and its
``custom_data`` says so (:data:`COMPLETE_KEY`, :data:`MISSING_KEY`).

What a complete episode's bag holds (each rule names the kind of :class:`Missing` it gives):

``result``
    The goal's result: the recorder got the ENDED event (else the outcome is unknown).
``start_event``, ``end_event``
    The goal's STARTED and ENDED events on ``/dam/episode``, in the bag.
``final_status``
    A status of the goal in a final state (succeeded, canceled, aborted) on
    ``/dam_grasp/_action/status``, when that topic is recorded (every goal the controller
    runs is accepted, so every episode's goal gets one).
``short``
    A counted topic (:data:`COUNTED_TOPICS`: the publisher reports on ``/diagnostics`` how
    many it has published and the header stamp of the last one): between the first and the
    last report of the episode (those at least :data:`COUNT_EDGE_NS` inside its window), the
    bag holds every message the publisher counted, by their header stamps.
``stopped``
    A topic that streams (it had at least :data:`STREAM_MIN_BEFORE` messages before the goal
    started) goes on to the end of the episode's window: its last message is at most
    ``max(STOP_MIN_NS, STOP_PERIODS * period)`` before it, the period being the median time
    between its messages. A counted topic is judged by its publisher's reports instead (a
    publisher may stop publishing, as the driver does in ERROR): its reports go on to the end
    (at most ``max(COUNTER_STALE_MIN_NS, COUNTER_STALE_PERIODS * period)`` before it), else
    it stopped. Topics that follow the grasp (:data:`GOAL_BOUND_TOPICS`) stop when it ends
    and are judged by their counts only.
``dropped``
    No message of the episode's window was dropped on the way: no gap in the publisher's
    sequence numbers (topics with one publisher) and none reported lost by the middleware.
``backlog_dropped``
    The recorder dropped none of the topic's messages because its backlog was full (a
    recorder starved of CPU time keeps at most ``max_backlog_bytes`` in memory).
``not_written``
    Every message received before the recorder was asked to stop was written (a recorder
    far behind writes for ``stop_write_time`` after SIGINT or SIGTERM, then counts the rest).
"""

from __future__ import annotations

import bisect
import json
import struct
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

from dam_common.words import counted
from dam_recorder.errors import EpisodeError

#: ``custom_data`` keys: ``"true"`` or ``"false"``; the JSON list of :class:`Missing`.
COMPLETE_KEY = 'dam_episode.complete'
MISSING_KEY = 'dam_episode.missing'
#: Suffix of an incomplete episode's directory name (``..._success_incomplete``).
INCOMPLETE_SUFFIX = '_incomplete'

EPISODE_TOPIC = '/dam/episode'
ACTION_STATUS_TOPIC = '/dam_grasp/_action/status'
DIAGNOSTICS_TOPIC = '/diagnostics'
#: Topics whose publisher reports its count on ``/diagnostics``: topic -> key prefix
#: (``<prefix>_published``, ``<prefix>_last_stamp_ns``). Their messages start with a
#: ``std_msgs/Header``.
COUNTED_TOPICS: dict[str, str] = {'/joint_states': 'joint_states',
                                  '/hand/command': 'hand_commands'}
#: Topics published while a grasp runs (or holds its result): they stop when it ends.
GOAL_BOUND_TOPICS = frozenset({'/hand/command', '/dam_grasp/_action/feedback'})
#: The types whose messages an episode reads facts from: topic -> type.
FACT_TYPES = {DIAGNOSTICS_TOPIC: 'diagnostic_msgs/msg/DiagnosticArray',
              EPISODE_TOPIC: 'dam_interfaces/msg/GraspEpisode',
              ACTION_STATUS_TOPIC: 'action_msgs/msg/GoalStatusArray'}
#: ``/dam/episode`` event codes (``GraspEpisode.EVENT_*``).
EVENT_STARTED, EVENT_ENDED = 0, 1
#: Final states of a goal (``action_msgs/GoalStatus.STATUS_*``).
FINAL_STATUSES = {4: 'SUCCEEDED', 5: 'CANCELED', 6: 'ABORTED'}

#: Messages before the goal's start that make a topic a stream.
STREAM_MIN_BEFORE = 3
#: A stream stopped when its last message is longer than this before the window's end [ns]...
STOP_MIN_NS = 1_000_000_000
#: ...and longer than this many of its periods.
STOP_PERIODS = 10
#: Counts reported closer than this to either end of the window are not compared [ns]: the
#: messages they count and the report travel on different topics.
COUNT_EDGE_NS = 1_000_000_000
#: A publisher's reports stopped when the last is longer than this before the window's end
#: [ns], and longer than this many of their periods.
COUNTER_STALE_MIN_NS = 3_000_000_000
COUNTER_STALE_PERIODS = 3

#: What the recorder reads from a message, as ``(kind, value)`` pairs:
#: ``('stamp', ns)`` the header stamp of a counted topic's message;
#: ``('count', (topic, published, last_stamp_ns))`` a publisher's report;
#: ``('event', (goal_id, event))`` a ``/dam/episode`` event;
#: ``('status', (goal_id, status))`` a goal status of the action.
Facts = Sequence[tuple[str, Any]]


def header_stamp_ns(data: bytes | memoryview) -> int | None:
    """The header stamp [ns] of a CDR-serialized message that starts with a
    ``std_msgs/Header`` (``None`` for a buffer too short to hold one)."""
    if len(data) < 12:
        return None
    sec, nanosec = struct.unpack_from('<iI' if data[1] & 1 else '>iI', data, 4)
    return sec * 1_000_000_000 + nanosec


def diagnostic_counts(statuses: Iterable[tuple[str, Mapping[str, str]]]) -> Facts:
    """The publishers' counts in a ``/diagnostics`` message, from its statuses as
    (name, {key: value}): one ``('count', (topic, published, last_stamp_ns))`` per counted
    topic reported (:data:`COUNTED_TOPICS`); values that are not integers are ignored."""
    facts = []
    for _name, values in statuses:
        for topic, prefix in COUNTED_TOPICS.items():
            try:
                count = int(values[f'{prefix}_published'])
                stamp = int(values[f'{prefix}_last_stamp_ns'])
            except (KeyError, ValueError):
                continue
            facts.append(('count', (topic, count, stamp)))
    return facts


@dataclass(frozen=True)
class Missing:
    """One thing an episode's bag lacks.

    Attributes
    ----------
    kind : str
        ``result``, ``start_event``, ``end_event``, ``final_status``, ``short``, ``stopped``,
        ``dropped``, ``backlog_dropped``, ``not_written`` (see the module), ``unwritten``
        (a write error, set by :mod:`~dam_recorder.episodes`) or ``killed`` (the recorder
        died with the episode open, set by :mod:`~dam_recorder.episode_recovery`).
    topic : str
        The topic it concerns.
    detail : str
        What is missing, in words (times in seconds since the bag's first message).
    expected, recorded, short : int or None
        Messages expected (as counted, or from the topic's rate), in the bag, and missing.
    until_ns : int or None
        ``stopped``: the topic's last message [ns since the epoch]; ``short``: the last
        report compared.
    until_s, end_s : float or None
        ``until_ns`` and the end of the episode's window [s since the bag's first message].
    basis : str
        What ``expected`` rests on: ``publisher count``, ``rate`` (the topic's own median
        rate, an estimate), ``sequence numbers``, ``middleware report`` or ``recorder count``.
    """

    kind: str
    topic: str
    detail: str
    expected: int | None = None
    recorded: int | None = None
    short: int | None = None
    until_ns: int | None = None
    until_s: float | None = None
    end_s: float | None = None
    basis: str = ''


@dataclass(frozen=True)
class Completeness:
    """``dam_episode.complete`` and ``dam_episode.missing`` of an episode bag."""

    complete: bool
    missing: tuple[Missing, ...] = ()


def completeness_custom_data(missing: Sequence[Missing]) -> dict[str, str]:
    """The ``custom_data`` entries of an episode with ``missing``."""
    return {COMPLETE_KEY: 'false' if missing else 'true',
            MISSING_KEY: json.dumps([{k: v for k, v in asdict(m).items() if v is not None}
                                     for m in missing], sort_keys=True)}


def completeness_from_custom_data(custom_data: Mapping[str, Any]) -> Completeness | None:
    """The completeness stored in a bag's ``custom_data``; ``None`` when it has none (a bag
    of an older recorder, or no episode).

    Raises
    ------
    EpisodeError
        If the values are malformed (the message names the key and the value).
    """
    if COMPLETE_KEY not in custom_data:
        return None
    flag = custom_data[COMPLETE_KEY]
    if flag not in ('true', 'false'):
        raise EpisodeError(f'{COMPLETE_KEY}: expected "true" or "false", got {flag!r}')
    text = custom_data.get(MISSING_KEY, '[]')
    try:
        items = json.loads(text) if isinstance(text, str) else None
    except ValueError:
        items = None
    if not isinstance(items, list) or not all(isinstance(i, dict) for i in items):
        raise EpisodeError(f'{MISSING_KEY}: expected a JSON list of objects, got '
                           f'{str(text)[:60]!r}')
    names = set(Missing.__dataclass_fields__)
    missing = []
    for i, item in enumerate(items):
        if not {'kind', 'topic', 'detail'} <= set(item) or not set(item) <= names:
            raise EpisodeError(f'{MISSING_KEY}[{i}]: expected the keys kind, topic, detail '
                               f'(and {", ".join(sorted(names - {"kind", "topic", "detail"}))}),'
                               f' got {sorted(item)}')
        missing.append(Missing(**item))
    if (flag == 'true') == bool(missing):
        raise EpisodeError(f'{COMPLETE_KEY} is {flag} but {MISSING_KEY} lists '
                           f'{counted(len(missing), "item")}')
    return Completeness(flag == 'true', tuple(missing))


@dataclass
class _TopicAccount:
    stamps: list[int] = field(default_factory=list)  # receive stamps [ns]
    header_stamps: list[int] = field(default_factory=list)  # counted topics
    counts: list[tuple[int, int, int]] = field(default_factory=list)  # (received, count, last)
    latched: bool = False
    dropped: int = 0
    shed: int = 0  # dropped from the recorder's full backlog
    unwritten: int = 0  # taken, but not written when the stop's time ran out


def _median_period(stamps: Sequence[int]) -> float | None:
    if len(stamps) < 2:
        return None
    gaps = sorted(b - a for a, b in zip(stamps, stamps[1:], strict=False))
    period = float(gaps[len(gaps) // 2])
    return period if period > 0 else None


class EpisodeAccount:
    """What one episode's bag holds, message by message, and the verdict on it.

    Parameters
    ----------
    goal_id : str
        The goal's id (32 hex digits), as ``/dam/episode`` and the action statuses name it.
    start_ns : int
        When the goal started [ns]: messages before it are the pre-roll.
    """

    def __init__(self, goal_id: str, start_ns: int) -> None:
        self.goal_id = goal_id
        self.start_ns = start_ns
        self._topics: dict[str, _TopicAccount] = {}
        self._events: set[int] = set()
        self._final_status: str | None = None

    def _topic(self, name: str) -> _TopicAccount:
        account = self._topics.get(name)
        if account is None:
            account = self._topics[name] = _TopicAccount()
        return account

    def add(self, topic: str, stamp_ns: int, facts: Facts | None = None,
            latched: bool = False) -> None:
        """A message of ``topic`` received at ``stamp_ns`` [ns] went into the bag, with what
        the recorder read from it (``facts``)."""
        account = self._topic(topic)
        account.stamps.append(stamp_ns)
        account.latched = account.latched or latched
        for kind, value in facts or ():
            if kind == 'stamp':
                account.header_stamps.append(value)
            elif kind == 'count':
                counted, count, last = value
                self._topic(counted).counts.append((stamp_ns, count, last))
            elif kind == 'event' and value[0] == self.goal_id:
                self._events.add(value[1])
            elif kind == 'status' and value[0] == self.goal_id and value[1] in FINAL_STATUSES:
                self._final_status = FINAL_STATUSES[value[1]]

    def dropped(self, topic: str, count: int) -> None:
        """``count`` messages of ``topic`` inside the window were dropped on the way."""
        self._topic(topic).dropped += int(count)

    def shed(self, topic: str, count: int) -> None:
        """``count`` messages of ``topic`` were dropped by the recorder itself: its backlog
        was full (``max_backlog_bytes``)."""
        self._topic(topic).shed += int(count)

    def unwritten_at_stop(self, topic: str, count: int) -> None:
        """``count`` messages of ``topic``, received before the recorder was asked to stop,
        were not written within the time it has to stop (``stop_write_time``)."""
        self._topic(topic).unwritten += int(count)

    @property
    def first_ns(self) -> int | None:
        """The bag's first message [ns] (``None`` without messages)."""
        return min((min(a.stamps) for a in self._topics.values() if a.stamps), default=None)

    def judge(self, window_start_ns: int, window_end_ns: int, recorded_topics: Iterable[str],
              got_result: bool, lost: Mapping[str, int] | None = None) -> list[Missing]:
        """What the bag lacks (empty: the episode is complete), see the module.

        Parameters
        ----------
        window_start_ns, window_end_ns : int
            The window the bag covers [ns]: from the pre-roll's start to the post-roll's end
            (or to when the recorder stopped).
        recorded_topics : iterable of str
            The topics the episode records (those without messages included).
        got_result : bool
            The recorder got the goal's ENDED event (its result).
        lost : mapping, optional
            Messages the middleware reported lost during the episode, per topic.
        """
        recorded = set(recorded_topics)
        first = self.first_ns
        window = _Window(window_start_ns, window_end_ns,
                         first if first is not None else window_start_ns)
        missing: list[Missing] = []
        if not got_result:
            missing.append(Missing('result', EPISODE_TOPIC, 'the recorder got no ENDED event '
                                   'of the goal: its result (outcome) is unknown'))
        where = 'in the bag' if EPISODE_TOPIC in recorded else f'({EPISODE_TOPIC} is not recorded)'
        for code, kind in ((EVENT_STARTED, 'start_event'), (EVENT_ENDED, 'end_event')):
            if code not in self._events:
                name = 'STARTED' if code == EVENT_STARTED else 'ENDED'
                missing.append(Missing(kind, EPISODE_TOPIC, f'no EVENT_{name} of the goal '
                                       f'{where}'))
        if ACTION_STATUS_TOPIC in recorded and self._final_status is None:
            missing.append(Missing('final_status', ACTION_STATUS_TOPIC,
                                   'no final status (succeeded, canceled, aborted) of the goal '
                                   'in the bag'))
        for name in sorted(recorded):
            account = self._topics.get(name, _TopicAccount())
            if name in COUNTED_TOPICS and account.counts:
                missing += self._judge_counted(name, account, window)
            elif name not in GOAL_BOUND_TOPICS and not account.latched:
                missing += self._judge_stream(name, account, window)
            missing += _judge_dropped(name, account, int((lost or {}).get(name, 0)))
            missing += _judge_recorder_losses(name, account)
        return missing

    def _judge_stream(self, name: str, account: _TopicAccount, window: _Window
                      ) -> list[Missing]:
        stamps = sorted(account.stamps)
        before = bisect.bisect_left(stamps, self.start_ns)
        period = _median_period(stamps)
        if before < STREAM_MIN_BEFORE or period is None:
            return []
        last = stamps[-1]
        silent = window.end_ns - last
        if silent <= max(STOP_MIN_NS, STOP_PERIODS * period):
            return []
        short = int(silent // period)
        return [Missing(
            'stopped', name, f'stops at {window.rel(last):.3f} s of {window.end_s:.3f} s: about '
            f'{short} of {len(stamps) + short} messages missing at its rate of '
            f'{1e9 / period:.4g} Hz', expected=len(stamps) + short, recorded=len(stamps),
            short=short, until_ns=last, until_s=window.rel(last), end_s=window.end_s,
            basis='rate')]

    def _judge_counted(self, name: str, account: _TopicAccount, window: _Window
                       ) -> list[Missing]:
        missing: list[Missing] = []
        counts = sorted(account.counts)
        inner = [c for c in counts if window.start_ns + COUNT_EDGE_NS <= c[0]
                 <= window.end_ns - COUNT_EDGE_NS]
        if len(inner) >= 2 and inner[-1][1] >= inner[0][1]:
            (received_a, count_a, stamp_a), (received_b, count_b, stamp_b) = inner[0], inner[-1]
            headers = sorted(account.header_stamps)
            expected = count_b - count_a
            held = bisect.bisect_right(headers, stamp_b) - bisect.bisect_right(headers, stamp_a)
            if held < expected:
                missing.append(Missing(
                    'short', name, f'{expected - held} of the {expected} messages its '
                    f'publisher counted between {window.rel(received_a):.3f} s and '
                    f'{window.rel(received_b):.3f} s are not in the bag', expected=expected,
                    recorded=held, short=expected - held, until_ns=received_b,
                    until_s=window.rel(received_b), end_s=window.end_s,
                    basis='publisher count'))
        report_period = _median_period([c[0] for c in counts]) or 1e9
        last_report = counts[-1][0]
        if window.end_ns - last_report > max(COUNTER_STALE_MIN_NS,
                                             COUNTER_STALE_PERIODS * report_period):
            stamps = sorted(account.stamps)
            last = stamps[-1] if stamps else last_report
            period = _median_period(stamps)
            text = (f'its publisher\'s count on {DIAGNOSTICS_TOPIC} stops at '
                    f'{window.rel(last_report):.3f} s of {window.end_s:.3f} s, its last message '
                    f'is at {window.rel(last):.3f} s')
            short = None
            if period is not None:
                short = int((window.end_ns - last) // period)
                text += f': about {short} messages missing at its rate of {1e9 / period:.4g} Hz'
            missing.append(Missing(
                'stopped', name, text, expected=None if short is None else len(stamps) + short,
                recorded=len(stamps), short=short, until_ns=last, until_s=window.rel(last),
                end_s=window.end_s, basis='rate' if short is not None else 'publisher count'))
        return missing


@dataclass(frozen=True)
class _Window:
    start_ns: int
    end_ns: int
    origin_ns: int  # the bag's first message: times in the text count from it

    def rel(self, ns: int) -> float:
        return round((ns - self.origin_ns) * 1e-9, 3)

    @property
    def end_s(self) -> float:
        return self.rel(self.end_ns)


def _judge_dropped(name: str, account: _TopicAccount, lost: int) -> list[Missing]:
    dropped = max(account.dropped, lost)
    if not dropped:
        return []
    by_sequence = account.dropped >= lost
    how = ("gaps in the publisher's sequence numbers" if by_sequence
           else 'reported lost by the middleware')
    return [Missing('dropped', name, f'{counted(dropped, "message")} '
                                     'dropped on the way to the recorder '
                    f'({how})', expected=len(account.stamps) + dropped,
                    recorded=len(account.stamps), short=dropped,
                    basis='sequence numbers' if by_sequence else 'middleware report')]


def _judge_recorder_losses(name: str, account: _TopicAccount) -> list[Missing]:
    missing = []
    recorded = len(account.stamps)
    if account.shed:
        missing.append(Missing(
            'backlog_dropped', name, f'{counted(account.shed, "message")} '
                                     'dropped by the recorder: its '
            'backlog was full (it got too little CPU time to write what arrived; '
            'max_backlog_bytes)', expected=recorded + account.shed, recorded=recorded,
            short=account.shed, basis='recorder count'))
    if account.unwritten:
        missing.append(Missing(
            'not_written', name, f'{counted(account.unwritten, "message")} received before '
            f'the recorder was stopped {"was" if account.unwritten == 1 else "were"} not '
            'written: its stop time (stop_write_time) ran out',
            expected=recorded + account.unwritten, recorded=recorded, short=account.unwritten,
            basis='recorder count'))
    return missing


def describe(missing: Sequence[Missing]) -> list[str]:
    """One line per missing item: ``topic: detail`` (``detail`` alone for an item of the whole
    bag, without a topic)."""
    return [f'{m.topic}: {m.detail}' if m.topic else m.detail for m in missing]
