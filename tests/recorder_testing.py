"""A recorder in episode mode beside stream publishers, with the goal events published here as
the controller publishes them: the harness of the recorder's episode integration tests."""

from __future__ import annotations

import contextlib
import time
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import NamedTuple

from ros_testing import (
    NodeProcess,
    RosClient,
    fixture_command,
    installed_executable,
    node_process,
)


def wait_for_output(proc: NodeProcess, texts: Sequence[str], timeout: float = 60.0) -> None:
    """Wait until ``proc`` has printed every one of ``texts`` (it must stay alive) [s]."""
    deadline = time.monotonic() + timeout
    while not all(t in proc.output() for t in texts):
        assert proc.alive(), proc.output()
        assert time.monotonic() < deadline, f'no {texts} within {timeout} s:\n{proc.output()}'
        time.sleep(0.05)


class GoalEvents:
    """Publishes /dam/episode events as the controller does (reliable, volatile)."""

    def __init__(self, client: RosClient) -> None:
        from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

        from dam_interfaces.msg import GraspEpisode

        self.client = client
        self.type = GraspEpisode
        self.pub = client.node.create_publisher(GraspEpisode, '/dam/episode', QoSProfile(
            depth=10, reliability=ReliabilityPolicy.RELIABLE,
            durability=DurabilityPolicy.VOLATILE))
        self.started: dict[str, float] = {}

    def send(self, goal_id: str, event: int) -> None:
        """Publish the STARTED (0) or ENDED (1, a success) event of ``goal_id``."""
        msg = self.type(event=event, goal_id=goal_id, object='cylinder')
        msg.header.stamp = self.client.node.get_clock().now().to_msg()
        if event == self.type.EVENT_STARTED:
            self.started[goal_id] = time.monotonic()
            msg.config_yaml = 'task: {}\n'
        else:
            msg.outcome, msg.outcome_name, msg.message = 1, 'SUCCESS', 'fixture grasp done'
            msg.duration = time.monotonic() - self.started[goal_id]
        self.pub.publish(msg)


class EpisodeRecording(NamedTuple):
    """What :func:`episode_recording` runs: the recorder, the stream publishers (in the
    order given), the test's client node and its goal events."""

    recorder: NodeProcess
    streams: list[NodeProcess]
    client: RosClient
    events: GoalEvents


@contextlib.contextmanager
def episode_recording(out: Path, topics: Sequence[str], pre_roll: str, post_roll: str,
                      streams: Sequence[Sequence[str]], prefix: Sequence[str] = (),
                      ros_args: Sequence[str] = (), start_timeout_s: float = 60.0,
                      match_timeout_s: float = 30.0) -> Iterator[EpisodeRecording]:
    """A recorder in episode mode into ``out`` recording ``topics`` (``pre_roll``,
    ``post_roll`` [s] as given on its command line; started after ``prefix``, e.g. ``nice``,
    with ``ros_args`` at the end), one ``tests/fixtures/stream_publisher.py`` per item of
    ``streams`` (its arguments), and a client publishing the goal events: yielded once the
    recorder records every topic (within ``start_timeout_s``) and both of its subscriptions
    of /dam/episode match the events' publisher (within ``match_timeout_s``). Everything is
    stopped at the end of the ``with`` block."""
    command = [*prefix, str(installed_executable('dam_recorder', 'recorder')), '--episodes',
               '-o', str(out), '--pre-roll', pre_roll, '--post-roll', post_roll, *topics,
               *ros_args]
    with node_process(command) as recorder, contextlib.ExitStack() as stack:
        publishers = [stack.enter_context(node_process(fixture_command(
            'stream_publisher.py', *args))) for args in streams]
        client = RosClient()
        try:
            events = GoalEvents(client)
            wait_for_output(recorder, [f'recording {t} ' for t in topics], start_timeout_s)
            # The recorder's own subscription and its taker's both match.
            assert client.spin_until(lambda: events.pub.get_subscription_count() >= 2,
                                     match_timeout_s)
            yield EpisodeRecording(recorder, publishers, client, events)
        finally:
            client.close()
