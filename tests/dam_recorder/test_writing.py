"""The recorder's writing pipeline on its own (no rclpy): the backlog, its limit, the order of
writing, the gaps in sequence numbers and the account at the stop."""

from __future__ import annotations

import time
from typing import Any

from dam_recorder.recorded_topics import RecordedTopic
from dam_recorder.writing import MESSAGE_OVERHEAD_BYTES, BagWriting


class _Whole:
    """A CDR end that keeps every message as it is."""

    def trim(self, data: bytes) -> bytes:
        return data


class _Writer:
    """The bag: what was written, in order (topic id, log time [ns], data)."""

    def __init__(self) -> None:
        self.written: list[tuple[int, int, bytes]] = []

    def write(self, topic_id: int, stamp: int, data: bytes) -> None:
        self.written.append((topic_id, stamp, data))


class _Log:
    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []

    def info(self, message: str, **_kwargs: Any) -> None:
        self.lines.append(('info', message))

    def warning(self, message: str, **_kwargs: Any) -> None:
        self.lines.append(('warning', message))

    def error(self, message: str, **_kwargs: Any) -> None:
        self.lines.append(('error', message))


def _pipeline(max_backlog_bytes: int = 10**9, stop_write_s: float = 2.0
              ) -> tuple[BagWriting, dict[str, RecordedTopic], _Writer, _Log]:
    recorded = {'/a': RecordedTopic('/a', 1, _Whole()),
                '/dam/episode': RecordedTopic('/dam/episode', 2, _Whole(), protected=True)}
    log = _Log()
    writing = BagWriting(recorded, dict, log, time.time_ns,
                         max_backlog_bytes=max_backlog_bytes, stop_write_s=stop_write_s,
                         use_sim_time=False, discovery_period_s=0.5)
    writing.writer = _Writer()
    return writing, recorded, writing.writer, log


def _info(received_ns: int, sequence: int) -> dict[str, Any]:
    return {'received_timestamp': received_ns, 'publication_sequence_number': sequence}


def test_a_full_backlog_drops_and_counts_but_never_a_goal_event() -> None:
    size = 100
    writing, recorded, writer, log = _pipeline(
        max_backlog_bytes=2 * (size + MESSAGE_OVERHEAD_BYTES))
    take_a, take_event = writing.intake(recorded['/a']), writing.intake(recorded['/dam/episode'])
    now = time.time_ns()
    for i in range(1, 5):
        take_a(bytes(size), _info(now + i, i))
    for i in range(1, 4):
        take_event(b'event%d' % i, _info(now + 10 + i, i))
    assert (recorded['/a'].queued, recorded['/a'].shed) == (2, 2)
    assert writing.waiting() == 5
    writing.write_inbox()
    # The goal events first, then the backlog; the two dropped ones are no gap on the way.
    assert [w[0] for w in writer.written] == [2, 2, 2, 1, 1]
    assert writing.waiting() == 0
    assert recorded['/a'].dropped == 0 and recorded['/dam/episode'].shed == 0
    assert any('the backlog is full' in m and '/a 2' in m for _level, m in log.lines)
    # Room again: the next message is taken.
    take_a(bytes(size), _info(now + 20, 5))
    assert recorded['/a'].queued == 3


def test_a_gap_in_the_sequence_numbers_counts_as_dropped() -> None:
    writing, recorded, writer, log = _pipeline()
    take = writing.intake(recorded['/a'])
    now = time.time_ns()
    for sequence in (1, 2, 6, 7):
        take(b'x', _info(now + sequence, sequence))
    recorded['/a'].one_publisher = True
    writing.write_inbox()
    assert len(writer.written) == 4
    assert recorded['/a'].dropped == 3
    assert any(m.startswith('/a: 3 messages of its publisher never reached the recorder '
                            '(sequence 2 to 6; 3 in all)') for _level, m in log.lines), log.lines


def _pipeline_log(use_sim_time: bool = False) -> tuple[BagWriting, RecordedTopic, _Log]:
    recorded = {'/a': RecordedTopic('/a', 1, _Whole())}
    log = _Log()
    writing = BagWriting(recorded, dict, log, time.time_ns, max_backlog_bytes=10**9,
                         stop_write_s=2.0, use_sim_time=use_sim_time, discovery_period_s=0.5)
    writing.writer = _Writer()
    return writing, recorded['/a'], log


def test_counts_of_one_message_are_in_the_singular() -> None:
    """Every count of messages the writing logs says '1 message' and '2 messages' (it said
    '1 message(s)'), its verb and pronoun agreeing."""
    now = time.time_ns()
    lines = {}
    for count in (1, 2):
        # a gap of `count` in the sequence numbers
        writing, recorded, log = _pipeline_log()
        take = writing.intake(recorded)
        recorded.one_publisher = True
        for sequence in (1, 2 + count):
            take(b'x', _info(now + sequence, sequence))
        writing.write_inbox()
        # a topic found late whose publisher had sent `count` before
        late, topic, late_log = _pipeline_log()
        topic.appeared_late = topic.one_publisher = True
        late.intake(topic)(b'x', _info(now, count + 1))
        late.write_inbox()
        # the middleware's loss report
        writing.lost_reported(recorded, count)
        writing.write_inbox()
        # held for the first /clock, then written when it came
        clocked, topic, clocked_log = _pipeline_log(use_sim_time=True)
        for i in range(count):
            clocked.intake(topic)(b'x', _info(now + i, i + 1))
        clocked.write_inbox()
        clocked.clock_receipts.add(now - 1, 5 * 10**9)
        clocked.write_inbox()
        # held for a /clock that never came
        unclocked, topic, unclocked_log = _pipeline_log(use_sim_time=True)
        for i in range(count):
            unclocked.intake(topic)(b'x', _info(now + i, i + 1))
        unclocked.write_inbox(final=True)
        lines[count] = [m for lg in (log, late_log, clocked_log, unclocked_log)
                        for _level, m in lg.lines]
    one, two = ('\n'.join(lines[1]), '\n'.join(lines[2]))
    assert '(s)' not in one + two, one + two
    assert '/a: 1 message of its publisher never reached the recorder' in one, one
    assert '/a: 2 messages of its publisher never reached the recorder' in two, two
    assert 'its publisher sent 1 message before the recorder' in one, one
    assert '0.5 s); it is not in the bag' in one, one
    assert 'its publisher sent 2 messages before the recorder' in two, two
    assert '0.5 s); they are not in the bag' in two, two
    assert '/a: the middleware reports 1 message lost (1 in all)' in one, one
    assert '/a: the middleware reports 2 messages lost (2 in all)' in two, two
    assert '1 message arrived before the first /clock: written now' in one, one
    assert '2 messages arrived before the first /clock: written now' in two, two
    assert '1 message written with its receive time' in one, one
    assert '2 messages written with their receive time' in two, two


def test_what_the_stop_leaves_unwritten_is_counted_per_topic() -> None:
    writing, recorded, writer, log = _pipeline(stop_write_s=0.0)
    take_a, take_event = writing.intake(recorded['/a']), writing.intake(recorded['/dam/episode'])
    now = time.time_ns()
    for i in range(1, 4):
        take_a(b'x', _info(now + i, i))
    take_event(b'event', _info(now + 9, 1))
    assert writing.begin_stop() == 4 and not writing.hurried
    writing.write_inbox(final=True)
    # No time left to write: the backlog is counted, the goal event written all the same.
    assert [w[0] for w in writer.written] == [2]
    assert recorded['/a'].unwritten_at_stop == 3 and writing.waiting() == 0
    assert any(m.startswith('stop: 0 s of writing') and '/a 3' in m for _level, m in log.lines)
