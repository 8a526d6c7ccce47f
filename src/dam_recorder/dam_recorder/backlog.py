"""How far behind the recorder writes: the backlog (no rclpy).

The backlog of a message is the time from its receipt by the recorder's middleware (its
receive stamp) to the moment the recorder hands it to the bag (an episode then holds it back
on purpose, :data:`~dam_recorder.episodes.HOLD_BACK_NS`: that is not counted). While the
recorder keeps up it is a few milliseconds (the taker's and the writer's periods); it grows
while the process gets too little CPU, and what the reader queues and the publishers' history
cannot hold any more is dropped.
"""

from __future__ import annotations

import json
from dataclasses import dataclass

#: ``custom_data`` key of the backlog (JSON: ``max_s``, ``mean_s``, ``messages``).
BACKLOG_KEY = 'dam_recorder.backlog'


@dataclass
class Backlog:
    """The largest and the mean backlog of the messages counted so far."""

    messages: int = 0
    total_ns: int = 0
    max_ns: int = 0

    def add(self, backlog_ns: int) -> None:
        """Count one message handed to the bag ``backlog_ns`` [ns] after its receipt."""
        self.messages += 1
        self.total_ns += backlog_ns
        if backlog_ns > self.max_ns:
            self.max_ns = backlog_ns

    def as_dict(self) -> dict[str, float | int]:
        """``max_s`` and ``mean_s`` [s] (3 significant decimals of a millisecond), ``messages``."""
        mean = self.total_ns / self.messages if self.messages else 0.0
        return {'max_s': round(self.max_ns * 1e-9, 6), 'mean_s': round(mean * 1e-9, 6),
                'messages': self.messages}

    def json(self) -> str:
        """:meth:`as_dict` as JSON text (the ``custom_data`` value)."""
        return json.dumps(self.as_dict(), sort_keys=True)

    def describe(self) -> str:
        """``max 0.012 s, mean 0.003 s over 1234 messages``."""
        mean = self.total_ns / self.messages if self.messages else 0.0
        return (f'max {self.max_ns * 1e-9:.3f} s, mean {mean * 1e-9:.3f} s over '
                f'{self.messages} messages')
