"""The verdict on an episode whose recorder was killed with it open (the core, no rclpy).

A recorder killed (SIGKILL, power cut) while an episode is open leaves its directory named
``<stem>_recording`` and its ``custom_data`` marking it open (one :class:`Missing` of kind
``open``, :data:`~dam_recorder.episodes.OPEN_MISSING`). Once :mod:`dam_recorder.recovery` has
made its files whole, :func:`judge_open_episode` labels it by what the bag proves, as the
recorder would have on closing it (:meth:`~dam_recorder.completeness.EpisodeAccount.judge`):

- every message of the bag goes into an :class:`~dam_recorder.completeness.EpisodeAccount`
  at its log time, with the facts the recorder reads from it: the header stamp of a counted
  topic's message, the publishers' counts on ``/diagnostics``, the goal events on
  ``/dam/episode`` and the goal statuses on ``/dam_grasp/_action/status`` (decoded with the
  types the bag's own definitions describe); the recorder's per-topic counts of dropped
  messages, messages dropped from its backlog and losses the middleware reported are taken
  from ``custom_data`` as last written (a lower bound: it is rewritten only when a file or a
  topic is added);
- the goal is the one whose STARTED event opened the episode (:func:`episode_goal`), its
  window is the bag's first to its last message;
- the outcome and ``dam_episode.summary`` come from the goal's ENDED event when the bag holds
  it (:func:`~dam_recorder.episode_messages.summary_from_event`, which reads a message
  ``rosbags`` decoded as well as an ``rclpy`` one), else they are ``UNKNOWN``
  (:func:`~dam_recorder.episodes.unfinished_summary`); ``pre_roll_s`` and ``post_roll_s`` are
  what the bag holds before the goal's start and after its end;
- one more :class:`Missing` of kind ``killed`` (:data:`KILLED_KIND`) says that the recorder
  died with the episode open: what it had received but not written out is not in the bag
  (the last ``chunk_interval`` and the messages an open episode holds back,
  :data:`~dam_recorder.episodes.HOLD_BACK_NS`). A recovered killed episode is never complete.

:func:`relabel` then names the directory ``<stem>_<outcome lower>_incomplete`` (a free name,
as the recorder picks it); ``bag info`` shows the outcome and INCOMPLETE with the reasons.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from dam_recorder.bag_reading import DROPPED_KEY, LOST_KEY, SHED_KEY, typestore_of
from dam_recorder.completeness import (
    COUNTED_TOPICS,
    DIAGNOSTICS_TOPIC,
    EPISODE_TOPIC,
    EVENT_ENDED,
    EVENT_STARTED,
    FACT_TYPES,
    INCOMPLETE_SUFFIX,
    MISSING_KEY,
    EpisodeAccount,
    Facts,
    Missing,
    completeness_custom_data,
    diagnostic_counts,
    header_stamp_ns,
)
from dam_recorder.episode_messages import start_info, summary_from_event
from dam_recorder.episodes import (
    HOLD_BACK_NS,
    OPEN_SUFFIX,
    SUMMARY_KEY,
    UNFINISHED,
    episode_stem,
    json_safe,
    unfinished_summary,
)
from dam_recorder.errors import RecoveryError

#: Kind of the :class:`Missing` item every recovered killed episode gets.
KILLED_KIND = 'killed'
#: An open episode's directory: ``<stem>_recording``, or with the goal id's first 8 digits
#: (and a number) when that name was taken (the recorder's free name).
_OPEN_NAME = re.compile(rf'^(?P<stem>.+)_{OPEN_SUFFIX}(_[0-9a-f]{{8}}(_\d+)?)?$')
_GOAL_ID = re.compile(r'^[0-9a-f]{32}$')


@dataclass(frozen=True)
class EpisodeVerdict:
    """What a killed episode's bag proves (:func:`judge_open_episode`).

    Attributes
    ----------
    goal_id : str
        The goal's id (32 hex digits; ``''`` when the bag names none).
    outcome : str
        The outcome name (``UNKNOWN`` without the goal's ENDED event in the bag).
    got_result : bool
        The bag holds the goal's ENDED event.
    missing : tuple of Missing
        What the bag lacks, the ``killed`` item last (never empty).
    summary : dict or None
        ``dam_episode.summary`` (``None`` when no goal id is known: no summary can name it).
    custom_data : dict
        The ``custom_data`` entries to write: summary, complete, missing, and the STARTED
        event's configuration and version where ``custom_data`` lacks them.
    stem : str or None
        The episode's name without its state (``YYYY_MM_DD-HH_MM_SS``), from the directory
        name; ``None`` when the name is not an open episode's (it is then kept).
    undecodable : dict
        Messages per fact topic that could not be decoded (their facts are not counted, as
        the recorder does not count what it cannot read).
    """

    goal_id: str
    outcome: str
    got_result: bool
    missing: tuple[Missing, ...]
    summary: dict[str, Any] | None
    custom_data: dict[str, str]
    stem: str | None
    undecodable: dict[str, int]


def is_open_episode(bag_dir: Path, custom_data: Mapping[str, str]) -> bool:
    """Whether ``bag_dir`` is an episode its recorder left open: ``custom_data`` lists an item
    of kind ``open``, or the directory is named as an open episode (``..._recording``)."""
    if _OPEN_NAME.match(bag_dir.name):
        return True
    try:
        items = json.loads(custom_data.get(MISSING_KEY, '[]'))
    except (TypeError, ValueError):
        return False
    return isinstance(items, list) and any(isinstance(i, dict) and i.get('kind') == 'open'
                                           for i in items)


def open_stem(name: str) -> str | None:
    """The stem of an open episode's directory name (``None`` for another name)."""
    match = _OPEN_NAME.match(name)
    return match.group('stem') if match else None


def episode_goal(started: Iterable[tuple[str, int, int]], stem: str | None,
                 custom_data: Mapping[str, str]) -> str:
    """The goal the episode was opened for.

    Parameters
    ----------
    started : iterable of (goal id, log time [ns], event stamp [ns])
        The STARTED events in the bag, in time order.
    stem : str or None
        The directory's stem: the recorder names an episode by the earlier of the STARTED
        event's receipt and stamp (:func:`~dam_recorder.episodes.episode_stem`).
    custom_data : mapping
        The bag's ``custom_data``: a ``dam_episode.summary`` there names the goal.

    Returns
    -------
    str
        The goal id named by the summary, else that of the STARTED event that names the
        directory, else of the first STARTED event (``''`` without any). (On a simulated
        clock the name is the wall-clock time: the first STARTED event is taken; an episode
        that has another goal's STARTED event in its pre-roll then gets that goal.)
    """
    try:
        named = json.loads(custom_data.get(SUMMARY_KEY, '{}')).get('goal_id')
    except (TypeError, ValueError, AttributeError):
        named = None
    if isinstance(named, str) and _GOAL_ID.match(named):
        return named
    events = list(started)
    for goal_id, log_ns, stamp in events:
        if stem is not None and stem in {episode_stem(min(log_ns, stamp or log_ns)),
                                         episode_stem(log_ns)}:
            return goal_id
    return events[0][0] if events else ''


def _counts(custom_data: Mapping[str, str], key: str) -> dict[str, int]:
    """A ``{topic: count}`` entry of ``custom_data`` (empty when absent or malformed)."""
    try:
        data = json.loads(custom_data.get(key, '{}'))
    except (TypeError, ValueError):
        return {}
    if not isinstance(data, dict):
        return {}
    return {str(k): v for k, v in data.items() if isinstance(v, int) and v > 0}


def _facts(topic: str, msg: Any) -> Facts:
    """What the recorder reads from a decoded message of a fact topic."""
    if topic == DIAGNOSTICS_TOPIC:
        return diagnostic_counts((s.name, {kv.key: kv.value for kv in s.values})
                                 for s in msg.status)
    if topic == EPISODE_TOPIC:
        return (('event', (str(msg.goal_id), int(msg.event))),)
    return [('status', (bytes(bytearray(s.goal_info.goal_id.uuid)).hex(), int(s.status)))
            for s in msg.status_list]


@dataclass
class _Read:
    """The bag's messages as the account needs them."""

    messages: list[tuple[str, int, Facts]]  # (topic, log time [ns], facts), in time order
    events: list[tuple[str, int, int, int, Any]]  # (goal, event, log time, stamp, message)
    undecodable: dict[str, int]  # messages of a fact topic that could not be decoded


def _read(bag_dir: Path) -> _Read:
    from rosbags.rosbag2 import Reader

    read = _Read([], [], {})
    try:
        with Reader(bag_dir) as reader:
            store = typestore_of(reader.connections)
            for connection, time_ns, data in reader.messages():
                topic, facts = connection.topic, ()
                if topic in COUNTED_TOPICS:
                    header = header_stamp_ns(data)
                    facts = () if header is None else (('stamp', header),)
                elif FACT_TYPES.get(topic) == connection.msgtype:
                    try:
                        msg = store.deserialize_cdr(data, connection.msgtype)
                        facts = _facts(topic, msg)
                    except Exception:  # noqa: BLE001 - as the recorder: a message it cannot read
                        read.undecodable[topic] = read.undecodable.get(topic, 0) + 1
                        msg = None
                    if topic == EPISODE_TOPIC and msg is not None:
                        read.events.append((str(msg.goal_id), int(msg.event), int(time_ns),
                                            int(msg.header.stamp.sec) * 1_000_000_000
                                            + int(msg.header.stamp.nanosec), msg))
                read.messages.append((topic, int(time_ns), facts))
    except RecoveryError:
        raise
    except Exception as exc:  # noqa: BLE001 - rosbags raises many kinds; all mean unreadable
        raise RecoveryError(f'{bag_dir}: cannot read the recovered bag to judge its episode: '
                            f'{" ".join(str(exc).split()) or type(exc).__name__}') from None
    return read


def judge_open_episode(bag_dir: Path, custom_data: Mapping[str, str],
                       topics: Iterable[tuple[str, bool]]) -> EpisodeVerdict:
    """Judge the episode in the whole (recovered) bag ``bag_dir`` (see the module).

    Parameters
    ----------
    bag_dir : Path
        The bag directory; its files and ``metadata.yaml`` must be readable.
    custom_data : mapping
        Its ``custom_data`` (the recorder's counts, the episode's start info).
    topics : iterable of (name, latched)
        Every topic the episode recorded, those without messages included; ``latched``: its
        publishers offered transient local durability (its last message goes into every
        episode, whatever its age).

    Raises
    ------
    RecoveryError
        If the bag cannot be read (the message names it and the cause).
    """
    topics = list(topics)
    read = _read(bag_dir)
    stem = open_stem(bag_dir.name)
    goal_id = episode_goal(((g, t, s) for g, e, t, s, _ in read.events if e == EVENT_STARTED),
                           stem, custom_data)
    started = [(t, s, m) for g, e, t, s, m in read.events if g == goal_id and e == EVENT_STARTED]
    ended = [(t, s, m) for g, e, t, s, m in read.events if g == goal_id and e == EVENT_ENDED]
    first_ns = read.messages[0][1] if read.messages else 0
    last_ns = max((t for _, t, _ in read.messages), default=0)
    # As the recorder: the goal starts at the earlier of the event's receipt and its stamp.
    start_ns = min(started[0][0], started[0][1] or started[0][0]) if started else first_ns
    account = EpisodeAccount(goal_id, start_ns)
    latched = {name for name, is_latched in topics if is_latched}
    for topic, time_ns, facts in read.messages:
        account.add(topic, time_ns, facts, topic in latched)
    for topic, count in _counts(custom_data, DROPPED_KEY).items():
        account.dropped(topic, count)
    for topic, count in _counts(custom_data, SHED_KEY).items():
        account.shed(topic, count)
    got_result = bool(ended)
    missing = account.judge(first_ns, last_ns, [name for name, _ in topics], got_result,
                            _counts(custom_data, LOST_KEY))
    end_s = round((last_ns - first_ns) * 1e-9, 3) if read.messages else None
    missing.append(Missing(
        KILLED_KIND, '', f'the recorder was killed with the episode open: what it had received '
        f'after the last chunk it wrote out is not in the bag (up to chunk_interval; while '
        f'the goal runs up to {HOLD_BACK_NS / 1e9:g} s more, which an open episode holds '
        f'back; ' + (f'the bag ends at {end_s:.3f} s)' if read.messages
                     else 'the bag holds no message)'),
        until_ns=last_ns if read.messages else None, until_s=end_s, end_s=end_s))
    summary: dict[str, Any] | None = None
    if ended:
        summary = summary_from_event(ended[0][2])
        end_ns = min(ended[0][0], summary['ended_ns'] or ended[0][0])
        summary['post_roll_s'] = round(max(0, last_ns - end_ns) * 1e-9, 3)
    elif goal_id:
        summary = unfinished_summary(goal_id, started[0][1] if started else 0)
        summary['message'] = ('the recorder was killed before the goal ended, or before it '
                              'wrote the ENDED event out')
        summary['post_roll_s'] = 0.0
    entries = completeness_custom_data(missing)
    if summary is not None:
        summary.setdefault('accepted_ns', (started[0][1] or started[0][0]) if started else 0)
        summary['pre_roll_s'] = round(max(0, start_ns - first_ns) * 1e-9, 3)
        entries[SUMMARY_KEY] = json.dumps(json_safe(summary), sort_keys=True, allow_nan=False)
    if started:
        for key, value in start_info(started[0][2]).items():
            if key not in custom_data:
                entries[key] = value
    outcome = str(summary.get('outcome_name') or UNFINISHED) if summary else UNFINISHED
    return EpisodeVerdict(goal_id, outcome, got_result, tuple(missing), summary, entries, stem,
                          read.undecodable)


def free_dir(parent: Path, name: str, goal_id: str) -> Path:
    """``parent/name``, or when that exists ``name_<goal id's first 8>`` and then
    ``name_<...>_2``, ``_3``, ...: the first free one (as the recorder names episodes;
    without a goal id ``name_2``, ``name_3``, ...)."""
    path = parent / name
    base = f'{name}_{goal_id[:8]}' if goal_id else name
    if path.exists() and goal_id:
        path = parent / base
    index = 2
    while path.exists():
        path = parent / f'{base}_{index}'
        index += 1
    return path


def relabel(bag_dir: Path, verdict: EpisodeVerdict) -> Path:
    """Rename ``bag_dir`` to ``<stem>_<outcome lower>_incomplete`` (a free name); a directory
    not named as an open episode keeps its name. Returns the directory's path.

    Raises
    ------
    RecoveryError
        If the file system refuses the rename (the message names both paths).
    """
    if verdict.stem is None:
        return bag_dir
    target = free_dir(bag_dir.parent, f'{verdict.stem}_{verdict.outcome.lower()}'
                      f'{INCOMPLETE_SUFFIX}', verdict.goal_id)
    try:
        bag_dir.rename(target)
    except OSError as exc:
        raise RecoveryError(f'cannot rename {bag_dir} to {target.name}: '
                            f'{exc.strerror or exc}') from None
    return target
