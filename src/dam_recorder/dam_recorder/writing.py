"""The recorder's writing pipeline, from the taker's thread to the bag (the core, no rclpy).

:class:`BagWriting` is what :mod:`~dam_recorder.recorder_node` hands every taken message to.
The taker's thread puts each message into a backlog (:meth:`BagWriting.intake`: the urgent
one for the goal's events and statuses, never dropped; the inbox for the rest, dropped and
counted beyond ``max_backlog_bytes``); the executor's thread writes the backlog
(:meth:`BagWriting.write_inbox`) into the one bag (:class:`~dam_recorder.bag_writer.BagWriter`)
or the episodes (:class:`~dam_recorder.episodes.EpisodeRecorder`), each message cut at its
CDR end and logged at its log time. It counts what it could not record on the way: gaps in a
publisher's sequence numbers, the middleware's loss reports, the messages dropped from the
full backlog and those left when the stop's writing time ran out; it keeps the backlog's
delay (:mod:`~dam_recorder.backlog`) and the first write error
(:mod:`~dam_recorder.write_failure`), and closes the bag with the closing line.

Only the executor's thread touches the bags (sqlite3 connections belong to the thread that
opened them); the taker's thread only appends to the backlog and counts.
"""

from __future__ import annotations

import json
import time
from collections import deque
from collections.abc import Callable
from typing import Any, Protocol

from dam_common.echo import brief_repr
from dam_common.shutdown import SHUTDOWN
from dam_common.words import counted
from dam_recorder.backlog import BACKLOG_KEY, Backlog
from dam_recorder.bag_reading import (
    DROPPED_KEY,
    NOT_RECORDED_KEY,
    SHED_KEY,
    STOP_UNWRITTEN_KEY,
)
from dam_recorder.bag_writer import BagWriter
from dam_recorder.clock_receipts import ClockReceipts
from dam_recorder.completeness import EPISODE_TOPIC, Facts
from dam_recorder.episodes import EpisodeRecorder
from dam_recorder.errors import BagWriteError, CdrError
from dam_recorder.recorded_topics import (
    LOG_TIME_TEXT,
    RecordedTopic,
    counts_json,
    header_log_time_ns,
    losses_text,
    lost_anything,
)
from dam_recorder.write_failure import WRITE_ERROR_STATUS, WriteFailure

#: Longest time [s] one turn of the executor spends writing the backlog: the executor
#: comes back to its other work (a stop request, services, discovery) at least this often.
WRITE_SLICE_S = 0.05
#: After the stop's writing time, how long closing episodes may write the messages they held
#: back (:data:`~dam_recorder.episodes.HOLD_BACK_NS`) [s]; the rest is counted.
CLOSE_WRITE_S = 0.5
#: A stop with more messages than this waiting to be written is hurried: no wait for
#: messages in flight, and the subscriptions and services are not deleted one by one (each
#: deletion waits for the middleware's threads, which a starved process runs seldom).
HURRIED_BACKLOG = 1000
#: Memory a message in the backlog takes beside its data (the tuple and the middleware's
#: information dictionary) [bytes], for ``max_backlog_bytes``.
MESSAGE_OVERHEAD_BYTES = 400
#: Bytes after a message's CDR end that are its final alignment (kept; more is cut).
MAX_ALIGNMENT_PADDING = 3
#: A message handed to the bag longer than this after its receipt is logged (throttled) [ns].
BACKLOG_WARNING_NS = 1_000_000_000

#: What the taker's thread does with a message: ``(data, info)`` (the middleware's
#: information dictionary: ``received_timestamp`` [ns], ``publication_sequence_number``).
OnMessage = Callable[[bytes, dict[str, Any]], None]


class Logger(Protocol):
    """What the pipeline logs through (the node's logger; ``throttle_duration_sec`` [s])."""

    def info(self, message: str, **kwargs: Any) -> Any: ...

    def warning(self, message: str, **kwargs: Any) -> Any: ...

    def error(self, message: str, **kwargs: Any) -> Any: ...


class BagWriting:
    """The backlog of taken messages, their writing into the bag or the episodes, and the
    account of what could not be written.

    Parameters
    ----------
    recorded : dict[str, RecordedTopic]
        The recorded topics by name (the owner adds to it as topics are found; shared).
    not_recorded : callable
        The selected topics the recording does not hold, each with the reason (for the
        metadata and the closing line).
    logger : Logger
        Where the pipeline logs.
    now_ns : callable
        The node's clock now [ns] (a receipt with ``use_sim_time`` before any ``/clock``).
    max_backlog_bytes : int
        Most memory the messages waiting to be written may take [bytes].
    stop_write_s : float
        After a stop request, how long the backlog is written [s] (``stop_write_time``).
    use_sim_time : bool
        Log times on the simulated clock (the ``/clock`` receipts, :attr:`clock_receipts`).
    discovery_period_s : float
        How often the owner looks for new topics [s] (named when a late topic lost messages).

    Attributes
    ----------
    writer : BagWriter or None
        The one bag (not episode mode), set by the owner once opened; None once closed.
    episodes : EpisodeRecorder or None
        Episode mode: the episodes, set by the owner once made.
    on_taken_event : callable or None
        Episode mode: called with a ``/dam/episode`` message's data and log time [ns] as it
        is written (the goal event, in case its subscription is taken late).
    paused : bool
        ``~/pause``: messages are counted as paused, not written.
    stopped : bool
        The node is closing: nothing more is written.
    write_failure : WriteFailure or None
        The first write error of a bag (then the recorder stops, status 74).
    """

    def __init__(self, recorded: dict[str, RecordedTopic],
                 not_recorded: Callable[[], dict[str, str]], logger: Logger,
                 now_ns: Callable[[], int], *, max_backlog_bytes: int, stop_write_s: float,
                 use_sim_time: bool, discovery_period_s: float) -> None:
        self.recorded = recorded
        self._not_recorded = not_recorded
        self._log = logger
        self._now_ns = now_ns
        self.max_backlog_bytes = max_backlog_bytes
        self.stop_write_s = stop_write_s
        self.use_sim_time = use_sim_time
        self._discovery_period_s = discovery_period_s
        self.writer: BagWriter | None = None
        self.episodes: EpisodeRecorder | None = None
        self.on_taken_event: Callable[[bytes, int], None] | None = None
        self.paused = False
        self.stopped = False
        self.write_failure: WriteFailure | None = None
        #: What the taker's thread took, for the executor's thread to write: ('message',
        #: recorded, data, info, shed), ('lost', recorded, count) or ('swept', ns). Only the
        #: executor's thread touches the writer.
        self.inbox: deque[tuple[Any, ...]] = deque()
        #: Messages of the protected topics and the middleware's loss reports: written before
        #: the inbox, never dropped.
        self._urgent: deque[tuple[Any, ...]] = deque()
        #: Bytes put into the inbox (the taker's thread) and taken out (the executor's).
        self._inbox_in_bytes = 0
        self._inbox_out_bytes = 0
        self._shed_total = 0  # (the taker's thread)
        self._shed_noted_total = 0
        #: The /clock receipts (use_sim_time): log times are receive times on that clock.
        self.clock_receipts = ClockReceipts()
        #: use_sim_time: the first /clock has come (until then messages are held), or never
        #: came while recording (then they are stamped with their receive time).
        self._clock_started = False
        self._no_clock = False
        self._before_clock = 0
        self._releasing = False  # writing the messages held for the first /clock
        self._to_release = 0  # of those, how many are still to be written
        #: When the writing of the backlog ends after a stop request (time.monotonic()).
        self.stop_deadline: float | None = None
        self.stop_requested_at: float | None = None
        #: The stop came with a backlog (:data:`HURRIED_BACKLOG`): the middleware entities are
        #: left to the end of the process.
        self.hurried = False
        #: When the taker last took a message (time.monotonic()).
        self.last_message = time.monotonic()
        self.backlog = Backlog()
        #: Every message received before this [ns] has been handed over (episode mode).
        self.taken_ns = 0

    # -- the taker's thread ------------------------------------------------------------------

    def intake(self, recorded: RecordedTopic) -> OnMessage:
        """What the taker's thread does with a message of ``recorded``: into the backlog
        (the urgent one for a protected topic), or dropped and counted when the backlog holds
        ``max_backlog_bytes`` already."""
        inbox = self._urgent if recorded.protected else self.inbox
        limit = self.max_backlog_bytes

        def on_message(data: bytes, info: dict[str, Any]) -> None:  # the taker's thread
            self.last_message = time.monotonic()
            size = len(data) + MESSAGE_OVERHEAD_BYTES
            if not recorded.protected:
                if self._inbox_in_bytes - self._inbox_out_bytes + size > limit:
                    recorded.shed += 1
                    self._shed_total += 1
                    return
                self._inbox_in_bytes += size
            recorded.queued += 1
            # (with the topic's count of dropped ones so far: the gap they leave in the
            # sequence numbers is the recorder's drop, not one on the way)
            inbox.append(('message', recorded, data, info, recorded.shed))
        return on_message

    def lost_reported(self, recorded: RecordedTopic, change: int) -> None:
        """The middleware reports ``change`` more messages of ``recorded`` lost (written to
        the account before the backlog)."""
        self._urgent.append(('lost', recorded, change))

    def swept(self, taken_ns: int) -> None:
        """Every message received before ``taken_ns`` [ns] has been taken (episode mode)."""
        self.inbox.append(('swept', taken_ns))

    def on_incompatible(self, recorded: RecordedTopic, change: int, policy: str) -> None:
        """The taker's thread: ``change`` more publishers of the topic offer a QoS its
        subscription cannot match. Logged once per topic, counted in the bag's custom data
        (``dam_recorder.incompatible_publishers``)."""
        first = recorded.incompatible == 0
        recorded.incompatible += change
        if first:
            self._log.warning(
                f'{recorded.name}: a publisher joined offering a QoS this recording cannot '
                f'take ({policy}; the topic is recorded as its first publishers offered it): '
                f'none of its messages are recorded (counted in the bag\'s custom data '
                f'dam_recorder.incompatible_publishers; logged once per topic)')

    # -- the executor's thread ---------------------------------------------------------------

    def waiting(self) -> int:
        """Messages taken and not yet written (both backlogs)."""
        return sum(r.queued - r.dequeued for r in self.recorded.values())

    def write_inbox(self, final: bool = False) -> None:
        """Write what the taker took (in the executor's thread): the urgent messages first,
        then the backlog, for at most :data:`WRITE_SLICE_S` a turn (``final``: until the
        stop's deadline, then the rest is counted, :meth:`_give_up`).

        With ``use_sim_time``, messages that arrive before the first ``/clock`` are held (in
        order) and written once it comes, stamped with its time: a bag on simulated time never
        starts in 1970. When the recorder stops (``final``) without a ``/clock`` ever, they
        are written with their receive time (system clock)."""
        inbox = self.inbox
        if self.use_sim_time and not self._clock_started:
            if self.clock_receipts.started:
                self._clock_started = True
                held = self.waiting()
                self._before_clock = held
                self._to_release = held
                if held:
                    first = self.clock_receipts.at(0) or 0
                    self._log.info(
                        f'{counted(held, "message")} arrived before the first /clock: '
                        f'written now, stamped with its time ({first * 1e-9:.3f} s; counted in '
                        f'dam_recorder.before_clock_messages)')
            elif final:
                self._no_clock = True
                held = self.waiting()
                if held:
                    self._log.warning(
                        f'no /clock came while recording (use_sim_time): '
                        f'{counted(held, "message")} written with '
                        f'{"its" if held == 1 else "their"} receive time (system clock)')
            else:
                return  # held until the clock runs
        writer = self.writer if self.episodes is None else self.episodes
        urgent = self._urgent
        while urgent and not self.stopped:
            self._write_item(writer, urgent.popleft())
        if final and self.stop_deadline is None:
            self.stop_deadline = time.monotonic() + self.stop_write_s
        deadline = self.stop_deadline if final else time.monotonic() + WRITE_SLICE_S
        stop_request = SHUTDOWN if not final else None
        while inbox and not self.stopped:
            # Every message: a starved process may wait long for its next time slice.
            if time.monotonic() >= deadline or (stop_request is not None
                                                and stop_request.requested):
                break
            while urgent:  # (an event that came meanwhile goes first)
                self._write_item(writer, urgent.popleft())
            item = inbox.popleft()
            if item[0] == 'message':
                item[1].dequeued += 1
                self._inbox_out_bytes += len(item[2]) + MESSAGE_OVERHEAD_BYTES
            self._write_item(writer, item)
        if self._shed_total != self._shed_noted_total:
            self._note_shed()
        if final:
            while urgent and not self.stopped:
                self._write_item(writer, urgent.popleft())
            if inbox:
                self._give_up()

    def _write_item(self, writer: Any, item: tuple[Any, ...]) -> None:
        if item[0] == 'message':
            if item[1].protected:
                item[1].dequeued += 1
            self._releasing = self._to_release > 0
            self._to_release = max(self._to_release - 1, 0)
            try:
                self._write(writer, item[1], item[2], item[3], item[4])
            except BagWriteError as exc:
                self.on_write_error(exc)
        elif item[0] == 'swept':
            self.taken_ns = item[1]
        else:
            self._on_lost(item[1], item[2])

    def _note_shed(self) -> None:
        """Log what the taker dropped from the full backlog since the last look, and count it
        in the open episodes."""
        self._shed_noted_total = self._shed_total
        names = []
        for recorded in self.recorded.values():
            new = recorded.shed - recorded.shed_noted
            if new > 0:
                recorded.shed_noted += new
                names.append(f'{recorded.name} {recorded.shed}')
                if self.episodes is not None:
                    self.episodes.note_shed(recorded.topic_id, new)
        if names:
            self._log.warning(
                f'the backlog is full (max_backlog_bytes {self.max_backlog_bytes}): messages '
                f'dropped and counted ({", ".join(names)} in all; never the goal events); the '
                f'recorder gets too little CPU time', throttle_duration_sec=5.0)

    def _give_up(self) -> None:
        """The stop's time ran out: count what is left in the backlog per topic as not
        written (dam_recorder.stop_unwritten_messages, and in the open episodes)."""
        self.inbox.clear()
        left = []
        for recorded in self.recorded.values():
            if recorded.protected:
                continue
            count = recorded.queued - recorded.dequeued
            if count <= 0:
                continue
            recorded.dequeued = recorded.queued
            recorded.unwritten_at_stop += count
            left.append(f'{recorded.name} {count}')
            if self.episodes is not None:
                self.episodes.note_unwritten_at_stop(recorded.topic_id, count)
        if left:
            self._log.warning(
                f'stop: {self.stop_write_s:g} s of writing after the stop request did not '
                f'reach the end of the backlog: not written, counted ({", ".join(left)})')

    def _receipt_ns(self, received: int) -> int:
        """The receive time of a message received at ``received`` [ns, system clock]: that
        time, or with ``use_sim_time`` the simulated time at the receipt
        (:mod:`~dam_recorder.clock_receipts`)."""
        if self.use_sim_time and not self._no_clock:
            stamp = self.clock_receipts.at(received) if received else None
            return stamp if stamp is not None else self._now_ns()
        return received or time.time_ns()

    def taken_until_ns(self) -> int:
        """Every message received before this [ns] has been handed to the episodes (with
        use_sim_time: on the simulated clock, as the messages' log times)."""
        if self.use_sim_time and not self._no_clock:
            at = self.clock_receipts.at(self.taken_ns) if self.taken_ns else None
            return at or 0
        return self.taken_ns

    def _write(self, writer: Any, recorded: RecordedTopic, data: bytes,
               info: dict[str, Any], shed: int = 0) -> None:
        received = info.get('received_timestamp', 0)
        stamp = header_log_time_ns(recorded, data, self._receipt_ns(received))
        self._follow_sequence(recorded, info.get('publication_sequence_number'), stamp, shed)
        if self.paused:
            recorded.paused += 1
            if self.episodes is not None:
                self.episodes.note_paused(recorded.topic_id)
            return
        # (Messages held for the first /clock waited for it, not for CPU time.)
        backlog = time.time_ns() - received if received and not self._releasing else None
        if backlog is not None:
            self.backlog.add(backlog)
            if backlog > BACKLOG_WARNING_NS:
                self._log.warning(
                    f'writing {backlog * 1e-9:.2f} s behind the receipt of the messages '
                    f'({recorded.name}): the recorder gets too little CPU time',
                    throttle_duration_sec=5.0)
        try:
            cut = recorded.end.trim(data)
            if len(data) - len(cut) <= MAX_ALIGNMENT_PADDING:
                cut = data  # the final alignment: part of a CDR message, kept as received
        except CdrError as exc:
            if not recorded.malformed:
                self._log.warning(f'{recorded.name}: {exc}; written as received')
            recorded.malformed += 1
            cut = data
        trimmed = len(cut) != len(data)
        recorded.trimmed += trimmed
        if self.episodes is not None:
            if recorded.name == EPISODE_TOPIC and self.on_taken_event is not None:
                self.on_taken_event(cut, stamp)
            writer.write(recorded.topic_id, stamp, cut, trimmed, self._read_facts(recorded, cut),
                         backlog)
        else:
            writer.write(recorded.topic_id, stamp, cut)

    def _read_facts(self, recorded: RecordedTopic, data: bytes) -> Facts | None:
        if recorded.facts is None:
            return None
        try:
            return recorded.facts(data)
        except Exception as exc:  # noqa: BLE001 - a message the recorder cannot read
            self._log.warning(f'{recorded.name}: cannot read the message: '
                              f'{brief_repr(exc)}',
                              throttle_duration_sec=5.0)
            return None

    def _follow_sequence(self, recorded: RecordedTopic, sequence: int | None, stamp: int,
                         shed: int = 0) -> None:
        """Count the messages missing before this one by its publisher's sequence number
        (``shed``: the topic's count of messages the recorder dropped, up to this one; those
        are no gap on the way)."""
        if not sequence:
            return
        shed_between, recorded.last_shed = shed - recorded.last_shed, shed
        last, recorded.last_sequence = recorded.last_sequence, sequence
        first, recorded.followed = not recorded.followed, True
        if last is None:
            # Only the topic's first message tells what came before the subscription: a
            # sequence followed anew (a second publisher came and went) does not.
            if first and recorded.appeared_late and recorded.one_publisher and sequence > 1:
                # Published before the topic was found and subscribed to: a volatile topic
                # keeps nothing for a late subscriber.
                recorded.before_subscription = sequence - 1
                self._log.warning(
                    f'{recorded.name} appeared while recording: its publisher sent '
                    f'{counted(sequence - 1, "message")} before the recorder had found and '
                    f'subscribed to it (discovery_period {self._discovery_period_s:g} s); '
                    f'{"it is" if sequence == 2 else "they are"} not in the bag (counted in '
                    f'its custom data '
                    f'dam_recorder.before_subscription_messages)')
            return
        if sequence <= last:  # another publisher's: gaps mean nothing until the graph says one
            recorded.one_publisher = False
        elif sequence > last + 1 + shed_between and recorded.one_publisher:
            gap = sequence - last - 1 - shed_between
            recorded.dropped += gap
            if self.episodes is not None:
                self.episodes.note_dropped(recorded.topic_id, gap, stamp)
            self._log.warning(
                f'{recorded.name}: {counted(gap, "message")} of its publisher never reached '
                f'the recorder (sequence {last} to {sequence}; {recorded.dropped} in all)',
                throttle_duration_sec=2.0)

    def _on_lost(self, recorded: RecordedTopic, change: int) -> None:
        recorded.lost += change
        if self.episodes is not None:
            self.episodes.note_lost(recorded.topic_id, change)
        self._log.warning(f'{recorded.name}: the middleware reports '
                          f'{counted(change, "message")} lost ({recorded.lost} in all)')

    # -- flushing, write errors, closing -----------------------------------------------------

    def flush(self) -> None:
        """Write out what waits in memory (every ``chunk_interval``)."""
        try:
            if self.writer is not None and not self.writer.closed:
                self.writer.flush()
            if self.episodes is not None and not self.stopped:
                self.episodes.flush()
        except BagWriteError as exc:
            self.on_write_error(exc)

    def on_write_error(self, exc: BagWriteError) -> None:
        """The first write error: log it once, stop (the executor ends the node, which closes
        what is open, and ``main`` exits with :data:`WRITE_ERROR_STATUS`). Later ones (other
        episode bags on the same file system) are counted by their bags, not logged."""
        if self.write_failure is not None:
            return
        self.write_failure = exc.failure
        self._log.error(
            f'{exc}: recording stopped; the bag is closed with the messages on disk, every '
            f'message not written is counted (dam_recorder.unwritten_messages); the recorder '
            f'exits with status {WRITE_ERROR_STATUS}')
        SHUTDOWN.request()

    def begin_stop(self) -> int:
        """A stop request, now: the backlog is written for ``stop_write_s`` at most from now
        on. Returns the messages waiting (more than :data:`HURRIED_BACKLOG`: hurried)."""
        self.stop_requested_at = time.monotonic()
        self.stop_deadline = self.stop_requested_at + self.stop_write_s
        backlog = self.waiting()
        self.hurried = backlog > HURRIED_BACKLOG
        return backlog

    def close_deadline(self) -> float | None:
        """Until when closing episodes write what they held back (None: no limit)."""
        if self.stop_deadline is None:
            return None
        if self.hurried:
            return time.monotonic()  # what was held back is counted, not written
        return self.stop_deadline + CLOSE_WRITE_S

    def close_writer(self) -> None:
        """Close the one bag (summary, index and ``metadata.yaml``) and log the closing line
        with every loss; nothing in episode mode."""
        writer, self.writer = self.writer, None
        if writer is None:
            return
        try:
            writer.close()
        except BagWriteError as exc:
            self.on_write_error(exc)
        count = sum(t.message_count for t in writer.topics)
        unwritten = sum(writer.unwritten.values())
        text = (f'closed {writer.bag_dir}: {counted(count, "message")} on '
                f'{counted(len(writer.topics), "topic")} in '
                f'{counted(len(writer.files), "file")}; {self.losses(unwritten)}')
        if writer.failure is None:
            (self._log.warning if self.lost() else self._log.info)(text)
            return
        where = 'metadata.yaml says so' if writer.metadata_current else (
            'metadata.yaml could not be written: run recover on the bag')
        self._log.warning(f'{text} ({writer.failure.errno_name}; {where})')

    def losses(self, unwritten: int) -> str:
        """The closing line's account of the losses (``unwritten``: messages not on disk)."""
        return losses_text(self.recorded.values(), unwritten, self.backlog.describe(),
                           self._not_recorded())

    def lost(self) -> bool:
        """Anything was lost, or a selected topic is not recorded."""
        return lost_anything(self.recorded.values(), self._not_recorded())

    def custom_data(self) -> dict[str, str]:
        """The recorder's counts in a bag's ``custom_data`` (strings)."""
        def counts(attribute: str) -> str:
            return counts_json(self.recorded.values(), attribute)
        return {'dam_recorder.lost_messages': counts('lost'),
                'dam_recorder.paused_messages': counts('paused'),
                'dam_recorder.trimmed_messages': counts('trimmed'),
                'dam_recorder.incompatible_publishers': counts('incompatible'),
                'dam_recorder.before_subscription_messages': counts('before_subscription'),
                'dam_recorder.before_clock_messages': str(self._before_clock),
                DROPPED_KEY: counts('dropped'), SHED_KEY: counts('shed'),
                STOP_UNWRITTEN_KEY: counts('unwritten_at_stop'),
                'dam_recorder.not_taken_topics': json.dumps(
                    sorted(r.name for r in self.recorded.values() if r.not_taken)),
                NOT_RECORDED_KEY: json.dumps(self._not_recorded(), sort_keys=True),
                'dam_recorder.logged_at_receipt_messages': counts('logged_at_receipt'),
                'dam_recorder.log_time': LOG_TIME_TEXT,
                BACKLOG_KEY: self.backlog.json()}
