"""``bag info``: what a bag holds, or what a directory of episode bags holds (no rclpy).

For one bag (:func:`bag_info`): its topics with types, message counts, mean rates [Hz], the
largest gap between consecutive messages per topic and when it began, the recorder's counts of
lost, dropped, paused and trimmed messages and its backlog (``custom_data``), the episode
metadata when it is an episode bag with whether the bag holds the whole episode and what it
lacks (:mod:`dam_recorder.completeness`), and the grasps ``/dam/status`` shows (from the phase
leaving ``IDLE`` to ``DONE``, ``ABORTED`` or ``FAILED``, with the outcome it then reports), and
the object (:mod:`dam_recorder.object_record`): the stand-in's ground truth (its rise, whether
it left the table, whether it was off it at the end of the grasp) and the controller's
estimate, each labelled as such.

For a directory of episode bags (:func:`episodes_info`): one row per episode (name, start,
durations, outcome, whether it is complete, ``k_theta``, ``delta_theta_p``, whether the lift
is guaranteed) read from the metadata only, and the number of episodes per outcome, where an
incomplete episode counts as ``INCOMPLETE`` whatever its outcome.

An episode its recorder has not closed (``..._recording``: still being recorded, or the
recorder was killed) is shown as such, outcome ``OPEN``, with :data:`OPEN_HINT`: ``recover``
makes its bag readable and labels it by what it holds (:mod:`dam_recorder.episode_recovery`).

Times are receive times; "s" columns are seconds since the bag's first message.
"""

from __future__ import annotations

import dataclasses
import os
from collections import Counter
from contextlib import ExitStack
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from dam_recorder.bag_reading import (
    DROPPED_KEY,
    LOST_KEY,
    PAUSED_KEY,
    TRIMMED_KEY,
    BagReader,
    locate,
    read_bag_metadata,
)
from dam_recorder.completeness import INCOMPLETE_SUFFIX, Completeness, describe
from dam_recorder.episode import (
    OUTCOME_NAMES,
    OUTCOME_ORDER,
    Episode,
    parse_episode_name,
)
from dam_recorder.errors import BagReadError
from dam_recorder.object_record import (
    OBJECT_POSE_TOPIC,
    OBJECT_TOPICS,
    TABLE_CONTACT_TOPIC,
    ObjectCollector,
    ObjectEstimate,
    ObjectTruth,
)

STATUS_TOPIC = '/dam/status'
#: Phases of a running grasp, and the phases a grasp ends in.
ACTIVE_PHASES = frozenset({'APPROACH', 'ROLLING_UP', 'ENVELOPE'})
END_PHASES = frozenset({'DONE', 'ABORTED', 'FAILED'})
#: Outcome shown for an episode its recorder has not closed, and what to do about it.
OPEN_OUTCOME = 'OPEN'
OPEN_HINT = ('if its recorder was killed (none writes it any more), `ros2 run dam_recorder '
             'recover DIR` rebuilds the bag and labels the episode by what it holds')


def is_open(completeness: Completeness | None) -> bool:
    """Whether the metadata marks the episode open (an item of kind ``open``: its recorder
    has not closed it)."""
    return completeness is not None and any(m.kind == 'open' for m in completeness.missing)


@dataclass(frozen=True)
class TopicStats:
    """One topic of a bag.

    Attributes
    ----------
    name, type : str
        Topic and type name.
    count : int
        Messages in the bag.
    rate_hz : float or None
        Mean rate, (count - 1) / (last - first) [Hz]; ``None`` below two messages or when all
        share one time.
    first_ns, last_ns : int or None
        Receive times of the first and the last message [ns since the epoch].
    max_gap_ns : int or None
        Largest time between consecutive messages [ns]; ``None`` below two messages.
    max_gap_at_ns : int or None
        Receive time of the message before that gap [ns since the epoch].
    lost, dropped, paused, trimmed : int
        The recorder's counts (``custom_data``) for the topic.
    """

    name: str
    type: str
    count: int
    rate_hz: float | None
    first_ns: int | None
    last_ns: int | None
    max_gap_ns: int | None
    max_gap_at_ns: int | None
    lost: int = 0
    paused: int = 0
    trimmed: int = 0
    dropped: int = 0


@dataclass(frozen=True)
class Grasp:
    """A grasp seen on ``/dam/status``.

    Attributes
    ----------
    start_ns : int
        First status message of the grasp (phase ``APPROACH``, ``ROLLING_UP`` or ``ENVELOPE``
        after any other phase) [ns since the epoch].
    end_ns : int or None
        First status message in an end phase [ns]; ``None`` when the bag ends first.
    end_phase : str
        ``DONE``, ``ABORTED``, ``FAILED``, or the last phase seen when the bag ends first.
    outcome : str
        The outcome name the status messages of the end phase report (the controller enters
        the phase before it has classified the grasp, so the first of them may still say
        ``UNKNOWN``; the first known outcome counts).
    message : str
        The text that comes with that outcome.
    """

    start_ns: int
    end_ns: int | None
    end_phase: str
    outcome: str
    message: str


@dataclass(frozen=True)
class BagInfo:
    """The answer of ``bag info`` for one bag.

    Attributes
    ----------
    path : Path
        The bag directory.
    storage : str
        Storage identifier (``mcap``, ``sqlite3``).
    files : list of str
        Storage files, relative to the bag directory.
    start_ns, end_ns : int or None
        Receive times of the first and the last message [ns since the epoch] (``None``
        without messages).
    message_count : int
        Messages read from the files.
    topics : list of TopicStats
        One per topic, sorted by name.
    lost, paused, trimmed : dict
        The recorder's counts per topic (``custom_data``), topics not in the bag included.
    episode : Episode or None
        The episode metadata.
    grasps : list of Grasp
        The grasps ``/dam/status`` shows, in time order.
    dropped : dict
        Messages that never reached the recorder, per topic (``custom_data``).
    completeness : Completeness or None
        Whether the episode bag holds its whole episode; ``None`` when not recorded.
    backlog : dict or None
        The recorder's backlog (``max_s``, ``mean_s``, ``messages``).
    object_truth : ObjectTruth or None
        The stand-in's ground truth of the object (rise, left the table during the grasp, off
        the table at its end: :mod:`dam_recorder.object_record`); None when the bag has neither
        ``/sim/object_pose`` nor ``/sim/object_table_contact``.
    object_estimate : ObjectEstimate or None
        The controller's estimate of the object from its ENDED event, where recorded.
    """

    path: Path
    storage: str
    files: list[str]
    start_ns: int | None
    end_ns: int | None
    message_count: int
    topics: list[TopicStats]
    lost: dict[str, int]
    paused: dict[str, int]
    trimmed: dict[str, int]
    episode: Episode | None
    grasps: list[Grasp]
    dropped: dict[str, int] = dataclasses.field(default_factory=dict)
    completeness: Completeness | None = None
    backlog: dict[str, float] | None = None
    object_truth: ObjectTruth | None = None
    object_estimate: ObjectEstimate | None = None

    @property
    def duration_ns(self) -> int:
        """From the first to the last message [ns] (0 without messages)."""
        if self.start_ns is None or self.end_ns is None:
            return 0
        return self.end_ns - self.start_ns


@dataclass(frozen=True)
class EpisodeRow:
    """One episode bag of a directory.

    Attributes
    ----------
    name : str
        Directory name.
    start_ns : int or None
        First message [ns since the epoch] (``None`` when unreadable or empty).
    bag_duration_s : float or None
        From the first to the last message [s].
    grasp_duration_s : float or None
        From goal acceptance to the end [s] (the summary's ``duration_s``: on the grasp's
        clock, simulated time with the stand-in, when ``grasp_wall_s`` is there; else on the
        wall clock).
    outcome : str
        The summary's outcome name; without a summary the directory name's suffix in upper
        case, ``OPEN`` for an episode its recorder has not closed; ``ERROR`` when the bag
        cannot be read.
    k_theta : tuple of float
        As run [N*m/rad]; for a goal that never ran (refused), as the client sent it.
    delta_theta_p : tuple of float
        As run [rad]; likewise.
    lift_guaranteed : bool or None
        ``/check_lift``'s answer; ``None`` without one.
    error : str or None
        Why the bag could not be read.
    complete : bool or None
        Whether the bag holds the whole episode (``None``: the metadata does not say; then the
        name's ``_incomplete`` suffix tells).
    missing : list of str
        What it lacks, one line per item.
    kind : str
        ``'episode'`` (episode metadata, or an episode's name), or ``'bag'``: an ordinary bag
        (no outcome: ``outcome`` is ``'-'``).
    message_count, topic_count : int or None
        The bag's messages and topics (``None`` when unreadable).
    grasp_wall_s : float or None
        From goal acceptance to the end on the wall clock [s] (the summary's
        ``wall_duration_s``; ``None``: not reported, ``grasp_duration_s`` is that).
    """

    name: str
    start_ns: int | None
    bag_duration_s: float | None
    grasp_duration_s: float | None
    outcome: str
    k_theta: tuple[float, ...] = ()
    delta_theta_p: tuple[float, ...] = ()
    lift_guaranteed: bool | None = None
    error: str | None = None
    complete: bool | None = None
    missing: tuple[str, ...] = ()
    kind: str = 'episode'
    message_count: int | None = None
    topic_count: int | None = None
    grasp_wall_s: float | None = None


@dataclass(frozen=True)
class EpisodesInfo:
    """The answer of ``bag info`` for a directory of bags: its path and one
    :class:`EpisodeRow` per bag, in name (so time) order; episodes and ordinary bags are told
    apart by :attr:`EpisodeRow.kind`."""

    path: Path
    rows: list[EpisodeRow]

    @property
    def episodes(self) -> list[EpisodeRow]:
        """The rows of episode bags (and of bags that cannot be read)."""
        return [r for r in self.rows if r.kind == 'episode']

    @property
    def bags(self) -> list[EpisodeRow]:
        """The rows of ordinary bags (no episode metadata, no episode's name)."""
        return [r for r in self.rows if r.kind == 'bag']

    @property
    def totals(self) -> dict[str, int]:
        """Episodes per outcome, every episode by the outcome it names (an incomplete one too:
        :attr:`incomplete_totals` says how many of each are incomplete), in
        :data:`OUTCOME_ORDER` (other names after). Ordinary bags have no outcome and are not
        counted."""
        return _in_order(Counter(r.outcome for r in self.episodes))

    @property
    def incomplete_totals(self) -> dict[str, int]:
        """Incomplete episodes per outcome they name, in the order of :attr:`totals`."""
        return _in_order(Counter(r.outcome for r in self.episodes if r.complete is False))

    @property
    def errors(self) -> list[str]:
        """The messages of the episodes that could not be read."""
        return [r.error for r in self.rows if r.error]


def _in_order(counts: Counter[str]) -> dict[str, int]:
    """``counts`` in :data:`OUTCOME_ORDER`, other names after, sorted."""
    order = [o for o in OUTCOME_ORDER if o in counts]
    order += sorted(o for o in counts if o not in OUTCOME_ORDER)
    return {o: counts[o] for o in order}


def topic_stats(name: str, type_name: str, times_ns: np.ndarray) -> TopicStats:
    """Count, mean rate and largest gap of one topic from its receive times [ns]."""
    times = np.sort(np.asarray(times_ns, dtype=np.int64))
    count = int(times.size)
    if count == 0:
        return TopicStats(name, type_name, 0, None, None, None, None, None)
    first, last = int(times[0]), int(times[-1])
    if count < 2:
        return TopicStats(name, type_name, 1, None, first, last, None, None)
    gaps = np.diff(times)
    worst = int(np.argmax(gaps))
    rate = (count - 1) / ((last - first) * 1e-9) if last > first else None
    return TopicStats(name, type_name, count, rate, first, last, int(gaps[worst]),
                      int(times[worst]))


def grasps_from_status(phases: list[tuple[int, str, int, str]]) -> list[Grasp]:
    """The grasps in a sequence of ``/dam/status`` messages.

    Parameters
    ----------
    phases : list of (time [ns], phase, outcome code, message)
        The status messages in time order.
    """
    grasps: list[Grasp] = []
    start: int | None = None
    last_phase = ''
    settling = False  # in the end phase of the last grasp, its outcome not yet reported
    for time_ns, phase, outcome, message in phases:
        name = OUTCOME_NAMES[outcome] if 0 <= outcome < len(OUTCOME_NAMES) else str(outcome)
        if start is None and phase in ACTIVE_PHASES:
            start = time_ns
            settling = False
        elif start is not None and phase in END_PHASES:
            grasps.append(Grasp(start, time_ns, phase, name, message))
            start = None
            settling = outcome == 0
        elif settling and phase == last_phase and outcome != 0:
            grasps[-1] = replace(grasps[-1], outcome=name, message=message)
            settling = False
        elif phase != last_phase:
            settling = False
        last_phase = phase
    if start is not None:
        grasps.append(Grasp(start, None, last_phase, 'UNKNOWN', 'the bag ends during the grasp'))
    return grasps


def bag_info(path: str | os.PathLike[str]) -> BagInfo:
    """Read one bag and describe it (see the module).

    Raises
    ------
    BagReadError
        If ``path`` is no readable bag, or its recorder counts or episode metadata are
        malformed.
    """
    meta = read_bag_metadata(path)
    lost, paused, trimmed, dropped = (meta.counts(k) for k in (LOST_KEY, PAUSED_KEY,
                                                                TRIMMED_KEY, DROPPED_KEY))
    episode = meta.episode()
    completeness = meta.completeness()
    with ExitStack() as stack:
        try:
            bag = stack.enter_context(BagReader(meta.path))
        except BagReadError as exc:
            if not is_open(completeness):
                raise
            cause = str(exc).removeprefix(f'{meta.path}: ').split('; a file without')[0]
            raise BagReadError(f'{meta.path}: an episode its recorder has not closed (still '
                               f'being recorded, or killed): {cause}; {OPEN_HINT}') from None
        types = bag.topics
        for name, type_name in meta.topics.items():
            types.setdefault(name, type_name)  # topics without messages
        times = bag.receive_times()
        status: list[tuple[int, str, int, str]] = []
        if types.get(STATUS_TOPIC) == 'dam_interfaces/msg/DamStatus':
            status = [(m.time_ns, str(m.message.phase), int(m.message.outcome),
                       str(m.message.message)) for m in bag.messages([STATUS_TOPIC])]
        starts = [int(v[0]) for v in times.values() if v.size]
        collector = ObjectCollector(min(starts, default=0))
        for m in bag.messages([t for t in OBJECT_TOPICS if t in bag.topics]):
            collector.add(m.topic, m.time_ns, m.message)
    topics = []
    for name in sorted(types):
        stats = topic_stats(name, types[name], times.get(name, np.zeros(0, np.int64)))
        topics.append(dataclasses.replace(stats, lost=lost.get(name, 0),
                                          paused=paused.get(name, 0),
                                          trimmed=trimmed.get(name, 0),
                                          dropped=dropped.get(name, 0)))
    firsts = [t.first_ns for t in topics if t.first_ns is not None]
    lasts = [t.last_ns for t in topics if t.last_ns is not None]
    return BagInfo(
        path=meta.path, storage=meta.storage, files=meta.files,
        start_ns=min(firsts) if firsts else None, end_ns=max(lasts) if lasts else None,
        message_count=sum(t.count for t in topics), topics=topics, lost=lost, paused=paused,
        trimmed=trimmed, episode=episode, grasps=grasps_from_status(status), dropped=dropped,
        completeness=completeness, backlog=meta.backlog(),
        object_truth=(collector.truth(episode.summary.ended_ns if episode else None)
                      if {OBJECT_POSE_TOPIC, TABLE_CONTACT_TOPIC} & set(types) else None),
        object_estimate=collector.estimate())


def episode_row(bag_dir: Path) -> EpisodeRow:
    """The table row of one episode bag, from its ``metadata.yaml`` alone; a bag that cannot
    be read gives a row with outcome ``ERROR`` and the reason in ``error``."""
    try:
        meta = read_bag_metadata(bag_dir)
        episode = meta.episode()
        completeness = meta.completeness()
    except BagReadError as exc:
        return EpisodeRow(bag_dir.name, None, None, None, 'ERROR', error=str(exc))
    has_messages = meta.message_count > 0
    start = meta.start_ns if has_messages else None
    duration = meta.duration_ns * 1e-9 if has_messages else None
    name = bag_dir.name
    if completeness is not None:
        complete: bool | None = completeness.complete
        missing = tuple(describe(completeness.missing))
        if is_open(completeness):
            missing += (f'({OPEN_HINT})',)
    else:  # a bag without the key: its name may still say
        complete = False if name.endswith(INCOMPLETE_SUFFIX) else None
        missing = ()
    sizes = {'message_count': meta.message_count, 'topic_count': len(meta.topics)}
    if episode is None:
        named = parse_episode_name(name.removesuffix(INCOMPLETE_SUFFIX))
        if named is None and completeness is None:  # an ordinary bag, not an episode
            return EpisodeRow(name, start, duration, None, '-', kind='bag', **sizes)
        outcome = named[1].upper() if named else 'UNKNOWN'
        if is_open(completeness):
            outcome = OPEN_OUTCOME
        return EpisodeRow(name, start, duration, None, outcome, complete=complete,
                          missing=missing, **sizes)
    summary = episode.summary
    check = summary.check_lift
    ran = bool(summary.k_theta or summary.delta_theta_p)  # else refused: what was asked
    return EpisodeRow(name, start, duration, summary.duration_s, summary.outcome_name,
                      summary.k_theta if ran else summary.goal_k_theta,
                      summary.delta_theta_p if ran else summary.goal_delta_theta_p,
                      check.lift_guaranteed if check is not None else None,
                      complete=complete, missing=missing,
                      grasp_wall_s=summary.wall_duration_s, **sizes)


def episodes_info(path: str | os.PathLike[str]) -> EpisodesInfo:
    """Describe every bag in the directory ``path``: episodes and ordinary bags (see
    :class:`EpisodesInfo`).

    Raises
    ------
    BagReadError
        If ``path`` holds no bag directories.
    """
    kind, bags = locate(path)
    if kind != 'episodes':
        raise BagReadError(f'{path}: is one bag, not a directory of episode bags')
    return EpisodesInfo(Path(path), [episode_row(b) for b in bags])
