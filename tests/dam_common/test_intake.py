"""SubscriptionThread: a subscription served by a thread of its own, over real DDS."""

from __future__ import annotations

import threading
import time
import uuid
from collections.abc import Iterator
from contextlib import contextmanager

import pytest

rclpy = pytest.importorskip('rclpy')
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from std_msgs.msg import Int64  # noqa: E402

from dam_common.intake import SubscriptionThread  # noqa: E402

#: DDS in this process: one pytest-xdist worker for all of them (scripts/test.sh).
pytestmark = pytest.mark.xdist_group('dds')


@pytest.fixture
def context() -> Iterator[rclpy.Context]:
    ctx = rclpy.Context()
    rclpy.init(context=ctx)
    try:
        yield ctx
    finally:
        rclpy.try_shutdown(context=ctx)


def _topic() -> str:
    return f'/dam_test_intake_{uuid.uuid4().hex[:8]}'


def _publish_until_matched(node, topic: str, count: int) -> None:
    pub = node.create_publisher(Int64, topic, count)
    deadline = time.monotonic() + 10.0
    while pub.get_subscription_count() == 0:
        assert time.monotonic() < deadline, f'no subscriber on {topic}'
        time.sleep(0.01)
    time.sleep(0.2)  # the reader's side of the match
    for i in range(count):
        pub.publish(Int64(data=i))
        time.sleep(0.001)


def _wait(predicate, timeout: float = 10.0) -> bool:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if predicate():
            return True
        time.sleep(0.01)
    return predicate()


@contextmanager
def _numbers_intake(context, on_message, depth: int
                    ) -> Iterator[tuple[SubscriptionThread, object, str]]:
    """A started intake of Int64 on a fresh topic, its owner's talker node and the topic;
    stopped and destroyed afterwards."""
    owner = rclpy.create_node('intake_owner', context=context)
    talker = rclpy.create_node('intake_talker', context=context)
    topic = _topic()
    intake = SubscriptionThread(owner, 'numbers')
    intake.create_subscription(Int64, topic, on_message, depth)
    intake.start()
    try:
        yield intake, talker, topic
    finally:
        intake.stop()
        talker.destroy_node()
        owner.destroy_node()


def test_every_message_reaches_the_callback_in_order_in_the_intake_thread(context) -> None:
    owner = rclpy.create_node('intake_owner', context=context)
    talker = rclpy.create_node('intake_talker', context=context)
    topic = _topic()
    got: list[int] = []
    threads: set[str] = set()

    def on_message(msg: Int64) -> None:
        got.append(msg.data)
        threads.add(threading.current_thread().name)

    intake = SubscriptionThread(owner, 'numbers')
    intake.create_subscription(Int64, topic, on_message, 300)
    intake.start()
    try:
        # The subscription is the owner's in the graph (``ros2 node info /intake_owner`` lists
        # it; a side node without parameter services made ``ros2 param list`` time out), and
        # no executor of the owner sees it.
        assert intake.node_name == 'intake_owner'
        assert _wait(lambda: topic in dict(owner.get_subscriber_names_and_types_by_node(
            'intake_owner', owner.get_namespace())))
        assert not any(name.startswith('intake_owner_') for name in owner.get_node_names())
        assert list(owner.subscriptions) == []
        _publish_until_matched(talker, topic, 300)
        assert _wait(lambda: len(got) == 300), len(got)
        assert got == list(range(300))
        assert threads == {'numbers_thread'}  # not the caller's thread, no executor needed
    finally:
        intake.stop()
        talker.destroy_node()
        owner.destroy_node()


def test_the_owners_remapping_applies_and_the_owners_executor_takes_nothing(context) -> None:
    remapped = _topic()
    owner = rclpy.create_node('intake_owner', context=context,
                              cli_args=['--ros-args', '-r', f'/joint_states:={remapped}'])
    talker = rclpy.create_node('intake_talker', context=context)
    got: list[int] = []
    intake = SubscriptionThread(owner, 'states')
    sub = intake.create_subscription(Int64, '/joint_states', lambda m: got.append(m.data), 50)
    assert sub.topic_name == remapped
    intake.start()
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(owner)  # the owner's executor spins beside it: the messages stay ours
    try:
        _publish_until_matched(talker, remapped, 50)
        deadline = time.monotonic() + 10.0
        while len(got) < 50 and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.01)
        assert got == list(range(50))
    finally:
        executor.shutdown()
        intake.stop()
        talker.destroy_node()
        owner.destroy_node()


def test_a_raising_callback_is_logged_and_the_intake_goes_on(context) -> None:
    got: list[int] = []

    def on_message(msg: Int64) -> None:
        if msg.data % 2:
            raise ValueError(f'odd {msg.data}')
        got.append(msg.data)

    with _numbers_intake(context, on_message, 20) as (_intake, talker, topic):
        _publish_until_matched(talker, topic, 20)
        assert _wait(lambda: len(got) == 10), got
        assert got == list(range(0, 20, 2))


def test_stop_ends_the_thread_at_once_and_removes_the_subscription(context) -> None:
    owner = rclpy.create_node('intake_owner', context=context)
    intake = SubscriptionThread(owner, 'numbers')
    topic = _topic()
    intake.create_subscription(Int64, topic, lambda _m: None, 1)
    intake.start()

    def subscribed() -> bool:
        return topic in dict(owner.get_subscriber_names_and_types_by_node(
            'intake_owner', owner.get_namespace()))

    assert _wait(subscribed)
    started = time.monotonic()
    intake.stop()
    assert time.monotonic() - started < 0.5  # woken by its guard condition, not a time-out
    assert not intake._thread.is_alive()
    intake.stop()  # idempotent
    assert _wait(lambda: not subscribed())
    owner.destroy_node()


def test_one_subscription_per_thread(context) -> None:
    owner = rclpy.create_node('intake_owner', context=context)
    intake = SubscriptionThread(owner)
    intake.create_subscription(Int64, _topic(), lambda _m: None, 1)
    with pytest.raises(RuntimeError, match='one subscription'):
        intake.create_subscription(Int64, _topic(), lambda _m: None, 1)
    intake.stop()
    owner.destroy_node()


def test_an_incompatible_publisher_is_logged_once_per_topic_and_counted(context,
                                                                        capfd) -> None:
    """A best-effort publisher to the intake's reliable subscription delivers nothing: the
    side node's QoS events are served by the intake thread, so this is said (once) and
    counted, as an executor would say it for an ordinary subscription."""
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    owner = rclpy.create_node('intake_qos_owner', context=context)
    talker = rclpy.create_node('intake_qos_talker', context=context)
    topic = _topic()
    got: list[int] = []
    intake = SubscriptionThread(owner, 'qos')
    intake.create_subscription(Int64, topic, lambda m: got.append(m.data),
                               QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    intake.start()
    try:
        best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
        first = talker.create_publisher(Int64, topic, best_effort)
        assert _wait(lambda: intake.incompatible_qos >= 1), 'no incompatible-QoS event'
        second = talker.create_publisher(Int64, topic, best_effort)
        assert _wait(lambda: intake.incompatible_qos >= 2), intake.incompatible_qos
        for i in range(20):
            first.publish(Int64(data=i))
            second.publish(Int64(data=i))
        time.sleep(0.3)
        assert got == []  # nothing arrives: the log line is all the user is told
    finally:
        intake.stop()
        talker.destroy_node()
        owner.destroy_node()
    err = capfd.readouterr().err
    assert err.count('offers a QoS incompatible with this subscription') == 1, err
    assert 'RELIABILITY' in err and topic in err, err


def test_drained_grows_only_once_every_queued_message_was_handed_over(context) -> None:
    """``drained`` tells a watchdog that a starved thread has caught up: while the callback
    is held up, messages queue and the count stays; once it grows, every message that was
    queued before has reached the callback."""
    got: list[int] = []
    hold = threading.Event()

    def on_message(msg: Int64) -> None:
        hold.wait(30.0)  # the first message holds the thread up
        got.append(msg.data)

    try:
        with _numbers_intake(context, on_message, 100) as (intake, talker, topic):
            _publish_until_matched(talker, topic, 50)
            time.sleep(0.3)  # well beyond the thread's wait (POLL_S): held in the callback
            before = intake.drained
            assert got == []
            hold.set()
            assert _wait(lambda: intake.drained > before)
            assert got == list(range(50))  # all of them, handed over before the count grew
    finally:
        hold.set()  # a failed assertion leaves the thread held: let it end
