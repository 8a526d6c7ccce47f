"""The recorder's episode bookkeeping: goal events open and end episodes (the core, no rclpy).

Each ``/dam/episode`` event reaches the recorder twice: from its subscription, and taken with
the recorded messages (:attr:`~dam_recorder.writing.BagWriting.on_taken_event`, at the
message's log time); :class:`EpisodeEvents` handles whichever comes first (a starved executor
may take its subscription's late, while the event is in the bag). It closes the episodes
whose post-roll is over once every message of it has been handed over, logs each closed one
(``episode OUTCOME: PATH`` alone on its line: scripts read the path from it) and, at the
stop, closes them all with the closing line.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from dam_common.words import counted
from dam_recorder.completeness import describe
from dam_recorder.episode_messages import (
    EPISODE_TOPIC,
    stamp_ns,
    start_info,
    summary_from_event,
)
from dam_recorder.episodes import Closed, EpisodeRecorder
from dam_recorder.errors import BagWriteError
from dam_recorder.writing import BagWriting, Logger


class EpisodeEvents:
    """Goal events into episodes, and the episodes closed and logged.

    Parameters
    ----------
    episodes : EpisodeRecorder
        The episodes (also :attr:`~dam_recorder.writing.BagWriting.episodes`).
    writing : BagWriting
        The writing pipeline: what it has handed over, its write errors, its stop.
    logger : Logger
        Where the episodes are logged.
    now_ns : callable
        The node's clock now [ns]: the receipt of an event from the subscription.
    read_event : callable
        A ``/dam/episode`` message from its serialized data (raises on another type).
    """

    def __init__(self, episodes: EpisodeRecorder, writing: BagWriting, logger: Logger,
                 now_ns: Callable[[], int], read_event: Callable[[bytes], Any]) -> None:
        self.episodes = episodes
        self._writing = writing
        self._log = logger
        self._now_ns = now_ns
        self._read_event = read_event
        #: (goal id, event) of the goal events handled (each comes twice, see on_event).
        self._handled: set[tuple[str, int]] = set()

    def on_event(self, msg: Any, received_ns: int | None = None) -> None:
        """A goal event, from the subscription (received now) or taken with the recorded
        messages (at ``received_ns``, its log time), whichever comes first: a starved
        executor may take its subscription's late, while the event is in the bag."""
        if self._writing.stopped or self._writing.write_failure is not None:
            return
        key = (str(msg.goal_id), int(msg.event))
        if key in self._handled:
            return
        self._handled.add(key)
        now = self._now_ns() if received_ns is None else received_ns
        if msg.event == msg.EVENT_STARTED:
            try:
                path = self.episodes.started(msg.goal_id, now,
                                             stamp_ns(msg.header.stamp), start_info(msg))
            except BagWriteError as exc:
                self._writing.on_write_error(exc)
                return
            self._log.info(f'episode of goal {msg.goal_id[:8]}: recording into {path}')
        elif msg.event == msg.EVENT_ENDED:
            summary = summary_from_event(msg)
            if not self.episodes.ended(msg.goal_id, now, summary,
                                       ended_ns=summary['ended_ns']):
                self._log.warning(
                    f'goal {msg.goal_id[:8]} ended ({msg.outcome_name}) but it started before '
                    'the recorder did: no episode')
        else:
            self._log.warning(f'{EPISODE_TOPIC}: unknown event {msg.event}, ignored')

    def on_taken(self, data: bytes, stamp: int) -> None:
        """A ``/dam/episode`` message as it is written, at its log time ``stamp`` [ns]."""
        try:
            msg = self._read_event(data)
        except Exception:  # noqa: BLE001 - another type on the topic: the facts say so
            return
        self.on_event(msg, stamp)

    def close_due(self) -> None:
        """Close the episodes whose post-roll has been handed over (a timer)."""
        if self._writing.stopped or self._writing.write_failure is not None:
            return  # (after a write error the episodes are closed as the node ends)
        try:
            for closed in self.episodes.poll(self._writing.taken_until_ns()):
                self._log_episode(closed)
        except BagWriteError as exc:
            self._writing.on_write_error(exc)

    def _log_episode(self, closed: Closed) -> None:
        # 'episode OUTCOME: PATH' alone on its line: scripts read the path from it.
        if closed.missing:
            self._log.warning(f'episode {closed.outcome}: {closed.path}')
            self._log.warning(f'{closed.path.name} is INCOMPLETE, the bag lacks: '
                              + '; '.join(describe(closed.missing)))
        else:
            self._log.info(f'episode {closed.outcome}: {closed.path}')

    def close_all(self) -> None:
        """The stop: close every open episode (writing what they held back until the
        pipeline's close deadline), log them and the closing line with every loss."""
        writing = self._writing
        before = len(self.episodes.finished)
        try:
            self.episodes.close_all(writing.taken_until_ns(), writing.close_deadline())
        except BagWriteError as exc:  # (close_all closes every episode all the same)
            writing.on_write_error(exc)
        for name, count in self.episodes.held_unwritten.items():
            if name in writing.recorded:
                writing.recorded[name].unwritten_at_stop += count
        for closed in self.episodes.finished[before:]:
            self._log_episode(closed)
        incomplete = sum(1 for c in self.episodes.finished if c.missing)
        unwritten = self.episodes.unwritten_count()
        text = (f'{counted(len(self.episodes.finished), "episode")} recorded in '
                f'{self.episodes.out_dir} ({incomplete} incomplete); '
                f'{writing.losses(unwritten)}')
        log = self._log.warning if incomplete or unwritten or writing.lost() \
            else self._log.info
        log(text)
