"""A fast subscription: its callback runs in a thread of its own, on a wait set of its own.

An rclpy executor rebuilds its wait set in Python before every wait, from every subscription,
timer, service, client, guard condition and action entity of its nodes, and wraps each callback
in a task: taking one ``/joint_states`` message at 500 Hz through the executor of a node with an
action server, parameter services and timers costs most of a core, and even an executor of its
own about half a core, on this project's two-core reference machine. Beside the real-time
stand-in and driver that load delays everything else (the middleware's threads, the recorder).

:class:`SubscriptionThread` creates the high-rate subscription on the owner node itself but
keeps it out of the owner's list of subscriptions, so that no executor waits on it. Its thread
waits on a wait set that holds only that subscription and a guard condition (to stop), takes
every message queued and calls the callback at once, as ``rclpy.wait_for_message`` does for one
message (with the same ``rclpy_implementation`` wait set).

The subscription belongs to the owner in the ROS graph: ``ros2 node info /<owner>`` lists it
and ``ros2 topic info -v`` names the owner as the subscriber; the topic name is resolved with
the owner's expansion and remapping rules (``--ros-args -r joint_states:=...``). (It was on a
side node ``<owner>_<suffix>`` without parameter services: ``ros2 param list`` timed out on it
and ``ros2 node info`` of the owner listed no subscriber.)

The callback runs concurrently with the owner's executor: it must protect the state it shares
(the controller takes its lock).

No executor sees the subscription, so its QoS events are served by the same thread: a
publisher that offers an incompatible QoS (a best-effort publisher to a reliable subscription:
none of its messages would arrive) or an incompatible type is logged once per topic by the
owner's logger, naming the policy, and counted (:attr:`incompatible_qos`,
:attr:`incompatible_type`), which the owners report in ``/diagnostics``.
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from typing import Any

from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.guard_condition import GuardCondition
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_policy_name_from_kind
from rclpy.subscription import Subscription
from rclpy.type_support import check_is_valid_msg_type

from dam_common.echo import brief_repr

#: The longest one wait lasts before the thread looks at the context again [s].
POLL_S = 0.1
#: How long :meth:`SubscriptionThread.stop` waits for the thread [s].
JOIN_TIMEOUT_S = 2.0


class SubscriptionThread:
    """One subscription of ``owner`` served by a thread and a wait set of its own.

    Parameters
    ----------
    owner : Node
        The node the subscription belongs to: its context, remapping rules and logger are
        used.
    suffix : str
        Names the thread (``<suffix>_thread``) and the intake in messages
        (``<owner>_<suffix>``).

    Notes
    -----
    :meth:`create_subscription`, then :meth:`start`; :meth:`stop` before the owner is
    destroyed. A thread takes the scheduling policy of the thread that starts it; start this
    before :func:`~dam_common.realtime.set_process_priority` is called, which then covers it.
    """

    def __init__(self, owner: Node, suffix: str = 'intake') -> None:
        self._owner = owner
        self._name = f'{owner.get_name()}_{suffix}'
        self._wake = GuardCondition(None, None, owner.context)
        self._subscription: Subscription | None = None
        self._callback: Callable[[Any], None] | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f'{suffix}_thread', daemon=True)
        self._stopped = False
        self._topic = ''
        #: Publishers seen offering an incompatible QoS (the middleware's total count).
        self.incompatible_qos = 0
        #: Publishers seen offering an incompatible type.
        self.incompatible_type = 0
        self._warned: set[str] = set()
        #: How many times the thread found the queue empty after taking (and calling back
        #: for) every message in it: once this grows, every message that arrived before has
        #: been handed to the callback.
        self.drained = 0

    @property
    def node_name(self) -> str:
        """The owner's name (what ``ros2 topic info -v`` shows as the subscriber)."""
        return self._owner.get_name()

    def create_subscription(self, msg_type: type, topic: str,
                            callback: Callable[[Any], None], qos: QoSProfile | int
                            ) -> Subscription:
        """Subscribe to ``topic`` (resolved by the owner's rules); ``callback(msg)`` runs in
        this object's thread, once per message, in the order they arrived.

        Raises
        ------
        RuntimeError
            A second subscription (one per thread).
        """
        if self._subscription is not None:
            raise RuntimeError('a SubscriptionThread serves one subscription')
        resolved = self._owner.resolve_topic_name(topic)
        self._topic = resolved
        events = SubscriptionEventCallbacks(incompatible_qos=self._on_incompatible_qos,
                                            incompatible_type=self._on_incompatible_type,
                                            use_default_callbacks=False)
        profile = qos if isinstance(qos, QoSProfile) else QoSProfile(depth=int(qos))
        check_is_valid_msg_type(msg_type)  # imports the type support
        with self._owner.handle:
            handle = _rclpy.Subscription(self._owner.handle, msg_type, resolved,
                                         profile.get_c_qos_profile())
        try:
            self._subscription = Subscription(
                handle, msg_type, resolved, lambda _msg: None,
                MutuallyExclusiveCallbackGroup(), profile, False, event_callbacks=events)
        except Exception:
            handle.destroy_when_not_in_use()
            raise
        self._callback = callback
        return self._subscription

    def start(self) -> None:
        """Start serving the subscription."""
        self._thread.start()

    def _run(self) -> None:
        sub, callback = self._subscription, self._callback
        if sub is None or callback is None:
            return
        context = self._owner.context
        events = list(sub.event_handlers)
        wait_set = _rclpy.WaitSet(1, 1, 0, 0, 0, len(events), context.handle)
        timeout_ns = int(POLL_S * 1e9)
        try:
            while not self._stop.is_set() and context.ok():
                with sub.handle, self._wake.handle:
                    wait_set.clear_entities()
                    wait_set.add_subscription(sub.handle)
                    wait_set.add_guard_condition(self._wake.handle)
                    for handler in events:
                        handler.add_to_wait_set(wait_set)
                    wait_set.wait(timeout_ns)
                    for handler in events:
                        if handler.is_ready(wait_set):
                            event = handler.take_data()
                            if event is not None:
                                self._call(handler.callback, event)
                    while not self._stop.is_set():
                        taken = sub.handle.take_message(sub.msg_type, sub.raw)
                        if taken is None:
                            self.drained += 1
                            break
                        self._call(callback, taken[0])
        except Exception as exc:  # noqa: BLE001 - e.g. the context went away meanwhile
            if context.ok() and not self._stop.is_set():
                self._owner.get_logger().error(f'{self._name} stopped: {brief_repr(exc)}')

    def _on_incompatible_qos(self, event: Any) -> None:
        self.incompatible_qos = int(event.total_count)
        if 'qos' not in self._warned:
            self._warned.add('qos')
            policy = qos_policy_name_from_kind(event.last_policy_kind)
            self._owner.get_logger().warning(
                f'a publisher on {self._topic} offers a QoS incompatible with this '
                f'subscription ({policy}): none of its messages arrive (counted in '
                f'/diagnostics; logged once per topic)')

    def _on_incompatible_type(self, event: Any) -> None:
        self.incompatible_type = int(event.total_count)
        if 'type' not in self._warned:
            self._warned.add('type')
            self._owner.get_logger().warning(
                f'a publisher on {self._topic} offers another message type: none of its '
                f'messages arrive (counted in /diagnostics; logged once per topic)')

    def _call(self, callback: Callable[[Any], None], msg: Any) -> None:
        try:
            callback(msg)
        except Exception as exc:  # noqa: BLE001 - one bad message must not end the intake
            self._owner.get_logger().error(
                f'a {self._name} callback raised {brief_repr(exc)}; the intake goes on',
                throttle_duration_sec=1.0)

    def stop(self) -> None:
        """Stop the thread (waits up to :data:`JOIN_TIMEOUT_S`) and destroy the subscription
        (before the owner is destroyed). Idempotent."""
        if self._stopped:
            return
        self._stopped = True
        self._stop.set()
        try:
            self._wake.trigger()
        except Exception:  # noqa: BLE001 - a context already shut down wakes the wait anyway
            pass
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=JOIN_TIMEOUT_S)
        self._wake.destroy()
        if self._subscription is not None:
            self._subscription.destroy()
