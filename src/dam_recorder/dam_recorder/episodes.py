"""Per-grasp episodes: each ``/dam_grasp`` goal becomes one bag (the core, no rclpy).

The recorder keeps the last ``pre_roll`` seconds of every recorded topic in memory. When a goal
starts (the controller's STARTED event on ``/dam/episode``) an episode bag opens with that
pre-roll; messages go on into it until ``post_roll`` seconds after the goal's end (the ENDED
event). Then the bag is closed with the episode's metadata in ``custom_data`` and its directory
is renamed after the goal's start time and outcome (``2026_11_29-18_05_12_success``), with
``_incomplete`` appended when the bag lacks part of the episode
(:mod:`~dam_recorder.completeness`: ``2026_11_29-18_05_12_success_incomplete``). Episodes
may overlap (a goal refused while another runs): every open episode gets every message.

Episode metadata (``custom_data`` of ``metadata.yaml``, strings):

``dam_episode.summary``
    JSON object: ``goal_id`` (32 hex digits), ``accepted_ns`` and ``ended_ns`` (the
    controller's stamps of the two events [ns]), ``goal`` (``k_theta``, ``delta_theta_p`` as
    the client sent them), ``k_theta`` [N*m/rad] and ``delta_theta_p`` [rad] per finger as run,
    ``friction_angle`` [rad] (the one ``/check_lift`` assumed), ``check_lift`` (the answer's
    fields, or null without an answer), ``outcome``, ``outcome_name``, ``message``,
    ``duration_s``, ``pre_roll_s``, ``post_roll_s``. Non-finite numbers are
    written as the strings ``"nan"``, ``"inf"`` and ``"-inf"`` (JSON has no such numbers).
``dam_episode.config``
    The controller's configuration file, as text.
``dam_episode.version``
    The software version the controller reported.
``dam_episode.config_source``
    Where the controller's configuration came from (a path on the controller's machine).
``dam_episode.complete``, ``dam_episode.missing``
    ``"true"`` or ``"false"``, and the JSON list of what the bag lacks
    (:mod:`~dam_recorder.completeness`); while the episode is being written ``"false"`` with
    one item of kind ``open`` (what a recorder killed meanwhile leaves).
``dam_recorder.lost_messages``, ``dam_recorder.dropped_messages``, ``dam_recorder.backlog``
    The recorder's counts of this episode's messages, and its backlog while the episode was
    open (:mod:`~dam_recorder.backlog`).
``dam_recorder.backlog_dropped_messages``, ``dam_recorder.stop_unwritten_messages``
    Messages per topic the recorder dropped from its full backlog, and those received before
    it was stopped that it had no time left to write (at most: counted for every episode open
    at the stop).
``dam_recorder.unwritten_messages``
    After a write error: the episode's messages that are not on disk (its bag counts them).

A write error in one episode's bag (:class:`~dam_recorder.errors.BagWriteError`) is raised
once every open episode has had the message, or once every episode is closed: an episode
whose bag failed is closed with what is on disk and keeps its ``_recording`` name when the
file system refuses the rename.
"""

from __future__ import annotations

import json
import math
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from rosbags.interfaces import Qos

from dam_common.words import counted
from dam_recorder.backlog import BACKLOG_KEY, Backlog
from dam_recorder.bag_reading import DROPPED_KEY, SHED_KEY, STOP_UNWRITTEN_KEY
from dam_recorder.bag_writer import BagWriter
from dam_recorder.completeness import (
    INCOMPLETE_SUFFIX,
    EpisodeAccount,
    Facts,
    Missing,
    completeness_custom_data,
)
from dam_recorder.errors import BagWriteError, ConfigurationError

#: ``custom_data`` keys of an episode.
SUMMARY_KEY = 'dam_episode.summary'
CONFIG_KEY = 'dam_episode.config'
VERSION_KEY = 'dam_episode.version'
CONFIG_SOURCE_KEY = 'dam_episode.config_source'
#: Outcome name of an episode whose goal had not ended when the recorder stopped.
UNFINISHED = 'UNKNOWN'
#: Suffix of an episode directory while it is being written.
OPEN_SUFFIX = 'recording'
#: An episode closes once every message received up to this long after its post-roll has
#: been handed over [ns] (a receive stamp is taken a moment before the message is queued).
CLOSE_MARGIN_NS = 100_000_000
#: What an open episode's metadata says (a recorder killed meanwhile leaves it so).
OPEN_MISSING = (Missing('open', '', 'the episode was still being recorded: the recorder did '
                        'not close it'),)
#: How long an open episode holds a message back before it writes it [ns]: an ENDED event that
#: arrives up to this much later than the messages after the post-roll still keeps them out
#: (events and data travel on different topics; a resent event arrives late).
HOLD_BACK_NS = 3_000_000_000


def json_safe(value: Any) -> Any:
    """``value`` with every non-finite float replaced by ``"nan"``, ``"inf"`` or ``"-inf"``
    (recursively through dicts, lists and tuples), so that ``json.dumps`` writes standard JSON."""
    if isinstance(value, float) and not math.isfinite(value):
        return 'nan' if math.isnan(value) else ('inf' if value > 0 else '-inf')
    if isinstance(value, Mapping):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


@dataclass(frozen=True)
class TopicSpec:
    """What an episode bag needs to know of a recorded topic."""

    name: str
    type_name: str
    definition: str
    type_hash: str
    offered_qos: Sequence[Qos]
    latched: bool = False
    #: Written whatever the stop's time (the goal's events and statuses).
    protected: bool = False


#: A message as the episodes keep it: (topic key, receive stamp [ns], data, trimmed, facts).
_Message = tuple[int, int, bytes, bool, 'Facts | None']


@dataclass
class _Episode:
    goal_id: str
    bag: BagWriter
    stem: str
    started_ns: int
    ids: dict[int, int] = field(default_factory=dict)  # topic key -> the bag's topic id
    lost: dict[str, int] = field(default_factory=dict)
    trimmed: dict[str, int] = field(default_factory=dict)
    paused: dict[str, int] = field(default_factory=dict)
    start_info: dict[str, str] = field(default_factory=dict)
    dropped: dict[str, int] = field(default_factory=dict)
    shed: dict[str, int] = field(default_factory=dict)  # dropped from a full backlog
    unwritten_at_stop: dict[str, int] = field(default_factory=dict)
    backlog: Backlog = field(default_factory=Backlog)
    summary: dict[str, Any] | None = None
    close_after_ns: int | None = None
    window_start_ns: int = 0  # messages stamped before are not the episode's
    #: (key, stamp, data, trimmed, facts) taken but not yet written (:data:`HOLD_BACK_NS`)
    held: deque[_Message] = field(default_factory=deque)
    account: EpisodeAccount | None = None
    #: What the bag lacks, once closed (:mod:`~dam_recorder.completeness`)
    missing: tuple[Missing, ...] = OPEN_MISSING


class Closed(NamedTuple):
    """An episode that was closed: its bag directory, the outcome and what the bag lacks
    (empty: complete)."""

    path: Path
    outcome: str
    missing: tuple[Missing, ...]


#: Stamps before 2000-01-01 are no dates: a simulated clock (``use_sim_time``) starts at 0.
_DATE_FROM_NS = 946_684_800 * 1_000_000_000


def episode_stem(start_ns: int) -> str:
    """The name of an episode that starts at ``start_ns`` [ns]: its local date and time,
    ``YYYY_MM_DD-HH_MM_SS``. A stamp of a simulated clock (before 2000) is no date: the
    wall-clock time of the call names the episode instead, as rosbag2 names its bags."""
    seconds = start_ns / 1e9 if start_ns >= _DATE_FROM_NS else time.time()
    return time.strftime('%Y_%m_%d-%H_%M_%S', time.localtime(seconds))


class EpisodeRecorder:
    """Writes one bag per goal, with pre-roll and post-roll.

    Parameters
    ----------
    out_dir : path
        Directory holding the episode bags (created when the first episode opens).
    open_bag : callable
        ``open_bag(bag_dir, file_stem, custom_data)`` returns a new :class:`BagWriter`
        (storage, compression and split limits are the caller's choice).
    pre_roll_s, post_roll_s : float
        Seconds kept before a goal's start and recorded after its end [s], >= 0.
    custom_data : callable, optional
        Entries (e.g. the recorder's counts) added to every episode's ``custom_data``.

    Raises
    ------
    ConfigurationError
        For a negative or non-finite roll (the value is named).

    Notes
    -----
    All times are the messages' receive stamps [ns since the epoch]; the caller passes the
    events' receive stamps (and their own stamps) to :meth:`started` and :meth:`ended`, and
    to :meth:`poll` how far it has handed messages over. An episode takes the messages by
    their stamps, not by when they are handed over, so messages and events may come late and
    in either order. A latched topic's last message (e.g. ``/robot_description``) is written
    into every episode, stamped at the start of the pre-roll when it is older.
    """

    def __init__(self, out_dir: str | Path,
                 open_bag: Callable[[Path, str, Callable[[], Mapping[str, str]]], BagWriter],
                 pre_roll_s: float = 3.0, post_roll_s: float = 2.0,
                 custom_data: Callable[[], Mapping[str, str]] | None = None) -> None:
        for name, value in (('pre_roll', pre_roll_s), ('post_roll', post_roll_s)):
            if not (math.isfinite(value) and value >= 0.0):
                raise ConfigurationError(f'{name} must be a finite number of seconds >= 0, got '
                                         f'{value!r}')
        self.out_dir = Path(out_dir)
        self._open_bag = open_bag
        self.pre_roll_ns = int(round(pre_roll_s * 1e9))
        self.post_roll_ns = int(round(post_roll_s * 1e9))
        self._custom_data = custom_data
        self._topics: list[TopicSpec] = []
        #: (key, stamp, data, trimmed, facts), by arrival
        self._ring: deque[_Message] = deque()
        self._latched: dict[int, tuple[int, bytes]] = {}
        self._open: dict[str, _Episode] = {}
        self._newest_ns = 0  # the latest stamp handed over
        #: The finished episodes, oldest first.
        self.finished: list[Closed] = []
        self._unwritten_closed = 0  # messages the finished episodes could not write
        #: Messages held back (:data:`HOLD_BACK_NS`) not written when the stop's time ran out,
        #: per topic (the most of any one episode: the episodes hold the same messages).
        self.held_unwritten: dict[str, int] = {}

    # -- topics and messages -----------------------------------------------------------------

    @property
    def open_goals(self) -> list[str]:
        """Goal ids of the episodes being written."""
        return list(self._open)

    def add_topic(self, spec: TopicSpec) -> int:
        """Register a recorded topic; return the key to :meth:`write` its messages with."""
        self._topics.append(spec)
        key = len(self._topics) - 1
        for episode in self._open.values():
            self._add_to(episode, key)
        return key

    def write(self, key: int, stamp_ns: int, data: bytes | memoryview,
              trimmed: bool = False, facts: Facts | None = None,
              backlog_ns: int | None = None) -> None:
        """One message of topic ``key`` received at ``stamp_ns`` [ns] (``trimmed``: cut at its
        CDR end, counted per episode), with what the caller read from it (``facts``, see
        :data:`~dam_recorder.completeness.Facts`) and how long after its receipt it is handed
        over (``backlog_ns``, counted by the open episodes)."""
        data = bytes(data)
        message = (key, stamp_ns, data, trimmed, facts)
        self._ring.append(message)
        self._newest_ns = max(self._newest_ns, stamp_ns)
        horizon = stamp_ns - self.pre_roll_ns
        while self._ring and self._ring[0][1] < horizon:
            self._ring.popleft()
        if self._topics[key].latched:
            self._latched[key] = (stamp_ns, data)
        error: BagWriteError | None = None
        for episode in self._open.values():
            if backlog_ns is not None:
                episode.backlog.add(backlog_ns)
            if stamp_ns < episode.window_start_ns:
                continue  # taken late (a backlog): older than the episode's pre-roll
            try:
                if episode.close_after_ns is None:
                    episode.held.append(message)
                    while episode.held and episode.held[0][1] < stamp_ns - HOLD_BACK_NS:
                        self._write_to(episode, *episode.held.popleft())
                elif stamp_ns <= episode.close_after_ns:
                    self._write_to(episode, *message)
            except BagWriteError as exc:
                error = error or exc
        if error is not None:
            raise error

    def unwritten_count(self) -> int:
        """Messages the episodes (finished and open) could not write (write errors)."""
        return self._unwritten_closed + sum(sum(e.bag.unwritten.values())
                                            for e in self._open.values())

    def note_lost(self, key: int, count: int) -> None:
        """The middleware reports ``count`` messages of topic ``key`` lost."""
        name = self._topics[key].name
        for episode in self._open.values():
            episode.lost[name] = episode.lost.get(name, 0) + int(count)

    def note_dropped(self, key: int, count: int, stamp_ns: int) -> None:
        """``count`` messages of topic ``key`` were dropped on the way (a gap in the
        publisher's sequence numbers, found at a message received at ``stamp_ns`` [ns]): the
        loss of every episode whose window holds that message."""
        name = self._topics[key].name
        for episode in self._open.values():
            if stamp_ns >= episode.window_start_ns and (
                    episode.close_after_ns is None or stamp_ns <= episode.close_after_ns):
                episode.dropped[name] = episode.dropped.get(name, 0) + int(count)
                episode.account.dropped(name, count)

    def note_shed(self, key: int, count: int) -> None:
        """The recorder dropped ``count`` messages of topic ``key`` (its backlog was full):
        the loss of every open episode (they were received while it was open, or in its
        pre-roll)."""
        name = self._topics[key].name
        for episode in self._open.values():
            episode.shed[name] = episode.shed.get(name, 0) + int(count)
            episode.account.shed(name, count)

    def note_unwritten_at_stop(self, key: int, count: int) -> None:
        """``count`` messages of topic ``key`` received before the stop were not written (the
        stop's time ran out): at most that many of every open episode's."""
        name = self._topics[key].name
        for episode in self._open.values():
            episode.unwritten_at_stop[name] = episode.unwritten_at_stop.get(name, 0) + int(count)
            episode.account.unwritten_at_stop(name, count)

    def note_paused(self, key: int) -> None:
        """A message of topic ``key`` arrived while the recorder was paused (not written)."""
        name = self._topics[key].name
        for episode in self._open.values():
            episode.paused[name] = episode.paused.get(name, 0) + 1

    def flush(self) -> None:
        """Write out what the open episodes hold in memory (:meth:`BagWriter.flush`)."""
        for episode in self._open.values():
            episode.bag.flush()

    def split(self) -> list[Path]:
        """Start a new file in every open episode; return the new files."""
        return [episode.bag.split() for episode in self._open.values()]

    # -- goals -------------------------------------------------------------------------------

    def started(self, goal_id: str, stamp_ns: int, accepted_ns: int = 0,
                start_info: Mapping[str, str] | None = None) -> Path:
        """A goal started (its STARTED event arrived at ``stamp_ns`` [ns]): open its episode
        with the pre-roll; return the (provisional) bag directory.

        ``start_info`` holds the entries of the STARTED event that go into ``custom_data``
        (:data:`CONFIG_KEY`, :data:`VERSION_KEY`); ``accepted_ns`` is the event's own stamp.
        A goal id already open is ignored (its directory is returned).
        """
        if goal_id in self._open:
            return self._open[goal_id].bag.bag_dir
        # The earlier of the two: a recorder that takes the event late (a busy machine) still
        # keeps the seconds before the goal; clocks of two machines may differ either way.
        start_ns = min(stamp_ns, accepted_ns) if accepted_ns else stamp_ns
        stem = episode_stem(start_ns)
        bag_dir = self._free_dir(f'{stem}_{OPEN_SUFFIX}', goal_id)
        episode = _Episode(goal_id, None, stem, accepted_ns or stamp_ns,  # type: ignore[arg-type]
                           start_info=dict(start_info or {}),
                           account=EpisodeAccount(goal_id, start_ns))
        # The writer calls custom_data as soon as it writes metadata.yaml, on opening.
        bag = self._open_bag(bag_dir, stem, lambda: self._episode_custom_data(episode))
        episode.bag = bag
        self._open[goal_id] = episode
        for key in range(len(self._topics)):
            self._add_to(episode, key)
        window_start = start_ns - self.pre_roll_ns
        episode.window_start_ns = window_start
        ring_start = self._ring[0][1] if self._ring else stamp_ns
        for key, (latched_ns, data) in self._latched.items():
            if latched_ns < ring_start:  # else it is in the ring
                self._write_to(episode, key, max(latched_ns, window_start), data, False, None)
        for message in self._ring:
            if message[1] >= window_start:
                self._write_to(episode, *message)
        return bag_dir

    def ended(self, goal_id: str, stamp_ns: int, summary: Mapping[str, Any],
              ended_ns: int = 0) -> bool:
        """The goal ended (its ENDED event arrived at ``stamp_ns`` [ns]; ``ended_ns`` is the
        event's own stamp, the earlier of the two counts); the episode takes the messages
        stamped up to ``post_roll`` later and closes (:meth:`poll`). ``summary`` is written as
        :data:`SUMMARY_KEY`. Returns ``False`` when no episode of this goal is open (it started
        before the recorder did)."""
        episode = self._open.get(goal_id)
        if episode is None:
            return False
        episode.summary = dict(summary)
        end_ns = min(stamp_ns, ended_ns) if ended_ns else stamp_ns
        episode.close_after_ns = end_ns + self.post_roll_ns
        self._release_held(episode)
        return True

    def poll(self, taken_ns: int) -> list[Closed]:
        """Close the episodes whose post-roll is over: every message received up to
        :data:`CLOSE_MARGIN_NS` after it has been handed over. ``taken_ns`` [ns]: every
        message received before it has been handed to :meth:`write` (the caller has taken
        everything the middleware had received by then)."""
        due = [g for g, e in self._open.items()
               if e.close_after_ns is not None and taken_ns >= e.close_after_ns + CLOSE_MARGIN_NS]
        return [self._close(goal_id, self._open[goal_id].close_after_ns) for goal_id in due]

    def close_all(self, taken_ns: int | None = None, deadline: float | None = None
                  ) -> list[Closed]:
        """Close every open episode now (the recorder stops; ``taken_ns`` as in :meth:`poll`,
        default: the latest stamp handed over); a goal that has not ended gets the outcome
        :data:`UNFINISHED`. Their windows end at ``taken_ns`` (a post-roll is cut short).
        Messages still held back (:data:`HOLD_BACK_NS`) are written until ``deadline``
        (``time.monotonic()``; None: all); the rest are counted as not written at the stop."""
        end_ns = self._newest_ns if taken_ns is None else taken_ns
        closed: list[Closed] = []
        error: BagWriteError | None = None
        for goal_id, episode in list(self._open.items()):
            try:
                closed.append(self._close(goal_id, min(end_ns, episode.close_after_ns or end_ns),
                                          deadline))
            except BagWriteError as exc:
                error = error or exc
        if error is not None:
            raise error
        return closed

    # -- helpers -----------------------------------------------------------------------------

    def _release_held(self, episode: _Episode, deadline: float | None = None) -> None:
        """Write the held messages inside the episode's window; drop those after its
        post-roll (they arrived before the ENDED event did). Past ``deadline``
        (``time.monotonic()``) the rest are counted as not written at the stop."""
        close_after = episode.close_after_ns
        while episode.held:
            if deadline is not None and time.monotonic() >= deadline:
                left: dict[str, int] = {}
                for message in episode.held:
                    if close_after is None or message[1] <= close_after:
                        if self._topics[message[0]].protected:
                            self._write_to(episode, *message)
                            continue
                        name = self._topics[message[0]].name
                        left[name] = left.get(name, 0) + 1
                episode.held.clear()
                for name, count in left.items():
                    self.held_unwritten[name] = max(self.held_unwritten.get(name, 0), count)
                    episode.unwritten_at_stop[name] = \
                        episode.unwritten_at_stop.get(name, 0) + count
                    episode.account.unwritten_at_stop(name, count)
                return
            message = episode.held.popleft()
            if close_after is None or message[1] <= close_after:
                self._write_to(episode, *message)

    def _write_to(self, episode: _Episode, key: int, stamp_ns: int, data: bytes,
                  trimmed: bool, facts: Facts | None) -> None:
        episode.bag.write(episode.ids[key], stamp_ns, data)
        spec = self._topics[key]
        episode.account.add(spec.name, stamp_ns, facts, spec.latched)
        if trimmed:
            episode.trimmed[spec.name] = episode.trimmed.get(spec.name, 0) + 1

    def _add_to(self, episode: _Episode, key: int) -> None:
        spec = self._topics[key]
        episode.ids[key] = episode.bag.add_topic(spec.name, spec.type_name, spec.definition,
                                                 spec.type_hash, list(spec.offered_qos))

    def _free_dir(self, name: str, goal_id: str) -> Path:
        path = self.out_dir / name
        if path.exists():
            path = self.out_dir / f'{name}_{goal_id[:8]}'
        index = 2
        while path.exists():
            path = self.out_dir / f'{name}_{goal_id[:8]}_{index}'
            index += 1
        return path

    def _episode_custom_data(self, episode: _Episode) -> dict[str, str]:
        data = dict(self._custom_data() if self._custom_data else {})
        # The recorder's counts, of this episode's messages.
        data['dam_recorder.lost_messages'] = json.dumps(episode.lost, sort_keys=True)
        data['dam_recorder.trimmed_messages'] = json.dumps(episode.trimmed, sort_keys=True)
        data['dam_recorder.paused_messages'] = json.dumps(episode.paused, sort_keys=True)
        data[DROPPED_KEY] = json.dumps(episode.dropped, sort_keys=True)
        data[SHED_KEY] = json.dumps(episode.shed, sort_keys=True)
        data[STOP_UNWRITTEN_KEY] = json.dumps(episode.unwritten_at_stop, sort_keys=True)
        data[BACKLOG_KEY] = episode.backlog.json()
        data.update(completeness_custom_data(episode.missing))
        data.update(episode.start_info)
        if episode.summary is not None:
            summary = dict(episode.summary)
            summary.setdefault('accepted_ns', episode.started_ns)
            summary.setdefault('pre_roll_s', self.pre_roll_ns / 1e9)
            summary.setdefault('post_roll_s', self.post_roll_ns / 1e9)
            data[SUMMARY_KEY] = json.dumps(json_safe(summary), sort_keys=True,
                                           allow_nan=False)
        return data

    def _close(self, goal_id: str, window_end_ns: int, deadline: float | None = None
               ) -> Closed:
        """Close the episode of ``goal_id``, its window ending at ``window_end_ns`` [ns]
        (held messages written until ``deadline``, :meth:`_release_held`)."""
        episode = self._open.pop(goal_id)
        error: BagWriteError | None = None
        try:
            self._release_held(episode, deadline)
        except BagWriteError as exc:
            error = exc
        got_result = episode.summary is not None
        if episode.summary is None:
            episode.summary = unfinished_summary(goal_id, episode.started_ns)
        outcome = str(episode.summary.get('outcome_name') or UNFINISHED)
        episode.missing = tuple(episode.account.judge(
            episode.window_start_ns, window_end_ns, [t.name for t in self._topics], got_result,
            episode.lost))
        if episode.bag.failure is not None:
            episode.missing += (Missing(
                'unwritten', '', f'{counted(sum(episode.bag.unwritten.values()), "message")} '
                                 'could not '
                f'be written: {episode.bag.failure.describe()}'),)
        try:
            episode.bag.close()
        except BagWriteError as exc:
            error = error or exc
        name = f'{episode.stem}_{outcome.lower()}'
        final = self._free_dir(name + (INCOMPLETE_SUFFIX if episode.missing else ''), goal_id)
        try:
            episode.bag.bag_dir.rename(final)
        except OSError:
            if episode.bag.failure is None:
                raise
            final = episode.bag.bag_dir  # (the file system refuses: it keeps its name)
        closed = Closed(final, outcome, episode.missing)
        self.finished.append(closed)
        self._unwritten_closed += sum(episode.bag.unwritten.values())
        if error is not None:
            raise error
        return closed


def unfinished_summary(goal_id: str, accepted_ns: int) -> dict[str, Any]:
    """The summary of an episode whose goal had not ended when the recorder stopped."""
    return {'goal_id': goal_id, 'accepted_ns': accepted_ns, 'ended_ns': 0,
            'goal': {'k_theta': [], 'delta_theta_p': []}, 'k_theta': [], 'delta_theta_p': [],
            'friction_angle': math.nan, 'check_lift': None, 'outcome': 0,
            'outcome_name': UNFINISHED, 'duration_s': math.nan,
            'message': 'the recorder stopped before the goal ended'}
