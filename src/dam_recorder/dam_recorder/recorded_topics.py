"""The recorder's account of each recorded topic (the core, no rclpy).

Every message the recorder's subscriptions receive ends up in exactly one count of its topic:
written, dropped from the full backlog (``shed``), not written when the stop's time ran out
(``unwritten_at_stop``) or paused; before that, messages that never reached it are counted
from the publisher's sequence numbers (``dropped``, ``before_subscription``) or by the
middleware (``lost``). :func:`losses_text` is the closing line's account of them, and of the
selected topics the bag does not hold.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from dam_recorder.completeness import ACTION_STATUS_TOPIC, EPISODE_TOPIC, header_stamp_ns

#: A header stamp is a message's log time when it is at most this far after the receipt
#: (clocks of two machines differ a little) [ns] ...
HEADER_LEAD_LIMIT_NS = 1_000_000_000
#: ... and at most this far before it [ns] (a receipt that late is no delivery delay).
HEADER_LAG_LIMIT_NS = 300_000_000_000
#: What a bag's log times are (custom_data ``dam_recorder.log_time``).
LOG_TIME_TEXT = ('header stamp for messages that start with a std_msgs/Header (else, and for '
                 'a stamp of 0 or far from the receipt, the receive time); receive time for '
                 'the others; with use_sim_time on the simulated clock')
#: Topics whose messages the backlog never drops and that are written first: the goal's
#: events and statuses (what labels an episode).
PROTECTED_TOPICS = frozenset({EPISODE_TOPIC, ACTION_STATUS_TOPIC})


@dataclass
class RecordedTopic:
    """A topic being recorded, and the recorder's counts of its messages.

    The taker's thread writes ``queued``, ``shed``; the executor's thread everything else
    (each attribute has one writer, so the other thread reads a count that is at most a
    message old).
    """

    name: str
    topic_id: int
    end: Any  #: the topic's :class:`~dam_recorder.cdr_end.CdrEnd`
    lost: int = 0
    paused: int = 0
    trimmed: int = 0
    malformed: int = 0
    dropped: int = 0
    #: Publishers that joined with a QoS the subscription cannot match (nothing of theirs is
    #: recorded).
    incompatible: int = 0
    #: The topic appeared after the recording began (found by a later discovery).
    appeared_late: bool = False
    #: Messages its publisher sent before the recorder had subscribed (a late topic).
    before_subscription: int = 0
    #: Gaps in the publication sequence numbers count as dropped while the topic has one
    #: publisher (rclpy does not say which publisher sent a message).
    one_publisher: bool = False
    last_sequence: int | None = None
    #: ``shed`` as it was when the message of ``last_sequence`` was queued.
    last_shed: int = 0
    #: A sequence number of the topic was seen.
    followed: bool = False
    #: What an episode reads from a message (None: nothing).
    facts: Any = None
    #: Never dropped from the backlog, written first (:data:`PROTECTED_TOPICS`).
    protected: bool = False
    #: Its messages start with a ``std_msgs/Header``: logged at their header stamp.
    stamped: bool = False
    #: Of those, messages logged at their receipt instead (a header stamp of 0, from the
    #: future, or older than :data:`HEADER_LAG_LIMIT_NS`).
    logged_at_receipt: int = 0
    #: Messages put into the backlog (the taker's thread) and taken out of it (the
    #: executor's): their difference is what the backlog holds of the topic.
    queued: int = 0
    dequeued: int = 0
    #: Dropped because the backlog was full (the taker's thread counts), and how many of them
    #: the executor's thread has passed on to the episodes.
    shed: int = 0
    shed_noted: int = 0
    #: In the backlog when the stop's time ran out: not written.
    unwritten_at_stop: int = 0
    #: Messages were still queued in the middleware when the stop's time ran out (not taken,
    #: not counted).
    not_taken: bool = False


def header_log_time_ns(recorded: RecordedTopic, data: bytes, receipt_ns: int) -> int:
    """A message's log time (:data:`LOG_TIME_TEXT`): its header stamp when ``recorded`` is
    stamped and the stamp is plausible (not 0, at most :data:`HEADER_LEAD_LIMIT_NS` after
    the receipt and :data:`HEADER_LAG_LIMIT_NS` before it), else ``receipt_ns`` (counted in
    ``logged_at_receipt``). All times [ns]."""
    if recorded.stamped:
        header = header_stamp_ns(data)
        if header and receipt_ns - HEADER_LAG_LIMIT_NS <= header <= \
                receipt_ns + HEADER_LEAD_LIMIT_NS:
            return header
        recorded.logged_at_receipt += 1
    return receipt_ns


def _counts(recorded: Iterable[RecordedTopic], attribute: str) -> dict[str, int]:
    return {r.name: getattr(r, attribute) for r in recorded if getattr(r, attribute)}


def counts_json(recorded: Iterable[RecordedTopic], attribute: str) -> str:
    """JSON ``{topic: count}`` of the topics whose ``attribute`` is not 0 (custom_data)."""
    return json.dumps(_counts(recorded, attribute), sort_keys=True)


def lost_anything(recorded: Iterable[RecordedTopic], not_recorded: Mapping[str, str]) -> bool:
    """Something selected is not in the bag(s)."""
    return any(r.lost or r.dropped or r.shed or r.unwritten_at_stop or r.not_taken
               or r.before_subscription or r.incompatible for r in recorded) \
        or bool(not_recorded)


def losses_text(recorded: Iterable[RecordedTopic], unwritten: int, backlog: str,
                not_recorded: Mapping[str, str]) -> str:
    """The closing line's account of every message and topic not in the bag(s):
    ``unwritten`` messages lost to write errors, the per-topic counts, the ``backlog``
    description and the topics not recorded with their reasons."""
    recorded = list(recorded)

    def per_topic(attribute: str) -> str:
        counts = _counts(recorded, attribute)
        total = sum(counts.values())
        return f'{total}' + (' (' + ', '.join(f'{n} {c}' for n, c in sorted(
            counts.items())) + ')' if total else '')
    not_taken = sorted(r.name for r in recorded if r.not_taken)
    parts = [
        f'not written {unwritten} (write errors)',
        f'not written at the stop {per_topic("unwritten_at_stop")}',
        f'dropped from the full backlog {per_topic("shed")}',
        f'dropped on the way {per_topic("dropped")}',
        f'reported lost by the middleware {per_topic("lost")}',
        f'before the subscription {per_topic("before_subscription")}',
        f'backlog {backlog}',
    ]
    if not_taken:
        parts.append('still queued in the middleware at the stop (not counted): '
                     + ', '.join(not_taken))
    parts.append(f'topics not recorded {len(not_recorded)}' + (
        ' (' + '; '.join(f'{n}: {why}' for n, why in sorted(not_recorded.items())) + ')'
        if not_recorded else ''))
    return '; '.join(parts)
