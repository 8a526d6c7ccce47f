"""Taking serialized messages in a thread of their own, without an executor.

An rclpy executor rebuilds its wait set (every subscription, timer, service and event handler of
the node) in Python for each wait and takes one message per ready subscription per wait: about
0.3 ms of interpreter time per message for the recorder, a third of a core at 1000 messages per
second, and messages pile up (then overflow the reader queue) whenever the process is short of
CPU, e.g. beside a real-time driver on two cores. Here the subscriptions belong to a node that
no executor spins; a thread takes whatever each has queued every ``period_s`` and hands the
serialized bytes and the middleware's message info to a callback: a few tens of microseconds a
message, the recording included.

Losses the middleware reports (the ``message_lost`` event) are read by the same thread every
:data:`LOST_POLL_S`. Its event handler cannot go to the owner's executor: the middleware marks
it ready whenever data is queued, and the executor, which would not take the data, would spin.
rclpy offers no public way to read an event outside a wait set, so the thread marks the handler
ready itself (``EventHandler._ready_to_take_data``, rclpy 7) before it takes the status. The
same thread reads the ``incompatible_qos`` event the same way: a publisher that joins with a
QoS this subscription cannot match (a best-effort publisher to a topic recorded as reliable)
delivers nothing, and the owner is told (``on_incompatible``) instead of losing it silently.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

from rclpy.context import Context
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.qos import QoSProfile, qos_policy_name_from_kind

#: How often the middleware's count of lost messages is read [s].
LOST_POLL_S = 0.5
#: What a callback gets: the serialized message and the middleware's message info
#: (``received_timestamp``, ``source_timestamp`` [ns], ...).
OnMessage = Callable[[bytes, dict[str, Any]], None]


class SerializedTaker:
    """Subscriptions whose serialized messages a thread takes every ``period_s``.

    Parameters
    ----------
    owner : Node
        The node that serves the subscriptions' event handlers (and logs).
    period_s : float
        How long the thread sleeps after it has emptied every queue [s]: the longest a message
        waits in its reader queue while the process gets CPU (the queues must hold what
        arrives meanwhile).
    on_swept : callable, optional
        ``on_swept(start_ns)`` runs in the thread after each pass over every queue, with the
        time [ns since the epoch, system clock: the clock of the receive stamps] at which the
        pass began: every message received before then has been handed to its callback.
    """

    def __init__(self, owner: Node, period_s: float,
                 on_swept: Callable[[int], None] | None = None) -> None:
        self._owner = owner
        self._period_s = float(period_s)
        self._on_swept = on_swept
        # Not on the command line's arguments: a remapping of __node would give it the owner's
        # name. Topic names are absolute, so no remapping is lost.
        self._node = Node(f'{owner.get_name()}_taker', namespace=owner.get_namespace(),
                          context=owner.context, use_global_arguments=False,
                          start_parameter_services=False, enable_rosout=False)
        self._subscriptions: list[tuple[Any, OnMessage]] = []
        self._first_count = 0  # the subscriptions taken first lead the list
        #: The ``first`` subscriptions live in a middleware participant of their own (a
        #: second context): a recorder starved of CPU time receives the data streams late,
        #: and a goal event queued behind them in the same participant came too late.
        self._first_context: Context | None = None
        self._first_node: Node | None = None
        self._lost_handlers: list[tuple[Any, Callable[[int], None]]] = []
        self._incompatible_handlers: list[tuple[Any, Callable[[int, str], None]]] = []
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name='serialized_taker', daemon=True)
        self._thread.start()

    def _own_first_node(self) -> Node:
        if self._first_node is None:
            context = Context()
            context.init(args=None, initialize_logging=False,
                         domain_id=self._owner.context.get_domain_id())
            self._first_context = context
            self._first_node = Node(f'{self._owner.get_name()}_events',
                                    namespace=self._owner.get_namespace(), context=context,
                                    use_global_arguments=False,
                                    start_parameter_services=False, enable_rosout=False)
        return self._first_node

    def subscribe(self, msg_type: type, topic: str, qos: QoSProfile, on_message: OnMessage,
                  on_lost: Callable[[int], None] | None = None,
                  on_incompatible: Callable[[int, str], None] | None = None,
                  first: bool = False) -> None:
        """Subscribe to ``topic``; ``on_message(data, info)`` runs in the taker's thread, and
        so does ``on_lost(count)`` when the middleware reports ``count`` more messages lost,
        and ``on_incompatible(count, policy)`` when ``count`` more publishers offer a QoS this
        subscription cannot match (``policy``: the last incompatible policy's name).
        ``first``: taken before the others in every pass (after the earlier ``first`` ones),
        and in a drain that runs out of time."""
        node = self._node if not first else self._own_first_node()
        subscription = node.create_subscription(
            msg_type, topic, lambda *_args: None, qos, raw=True,
            event_callbacks=SubscriptionEventCallbacks(
                message_lost=lambda _status: None, incompatible_qos=lambda _status: None,
                use_default_callbacks=False))

        def handler(kind: str) -> Any:
            found = [h for h in subscription.event_handlers
                     if kind in str(getattr(h, 'event_type', ''))]
            return found[0] if found and hasattr(found[0], '_ready_to_take_data') else None

        lost, incompatible = handler('MESSAGE_LOST'), handler('INCOMPATIBLE_QOS')
        with self._lock:
            if first:
                self._subscriptions.insert(self._first_count, (subscription, on_message))
                self._first_count += 1
            else:
                self._subscriptions.append((subscription, on_message))
            if on_lost is not None and lost is not None:
                self._lost_handlers.append((lost, on_lost))
            if on_incompatible is not None and incompatible is not None:
                self._incompatible_handlers.append((incompatible, on_incompatible))

    def _read_losses(self) -> None:
        with self._lock:
            handlers = list(self._lost_handlers)
            incompatible = list(self._incompatible_handlers)
        for handler, on_lost in handlers:
            handler._ready_to_take_data = True  # noqa: SLF001 - see the module's docstring
            status = handler.take_data()
            change = int(getattr(status, 'total_count_change', 0) or 0)
            if change > 0:
                on_lost(change)
        for handler, on_incompatible in incompatible:
            handler._ready_to_take_data = True  # noqa: SLF001 - see the module's docstring
            status = handler.take_data()
            change = int(getattr(status, 'total_count_change', 0) or 0)
            if change > 0:
                policy = qos_policy_name_from_kind(status.last_policy_kind)
                on_incompatible(change, policy)

    def _take_all(self, until_stopped: bool = True, deadline: float | None = None
                  ) -> tuple[int, list[str]]:
        """Take what each subscription has queued; stop at ``deadline`` (time.monotonic()).
        Return how many messages, and the topics whose queue was not emptied."""
        with self._lock:
            subscriptions = list(self._subscriptions)
        taken = 0
        left: list[str] = []
        for subscription, on_message in subscriptions:
            if deadline is not None and time.monotonic() >= deadline:
                left.append(subscription.topic_name)
                continue
            while not (until_stopped and self._stop.is_set()):
                with subscription.handle:
                    taken_message = subscription.handle.take_message(subscription.msg_type,
                                                                     True)
                if taken_message is None:
                    break
                taken += 1
                try:
                    on_message(taken_message[0], taken_message[1])
                except Exception as exc:  # noqa: BLE001 - the thread goes on with the others
                    self._owner.get_logger().error(
                        f'{subscription.topic_name}: a message was not recorded: {exc!r}',
                        throttle_duration_sec=5.0)
                if deadline is not None and time.monotonic() >= deadline:
                    left.append(subscription.topic_name)
                    break
        return taken, left

    def _run(self) -> None:
        next_loss_read = time.monotonic()
        while not self._stop.is_set():
            try:
                if time.monotonic() >= next_loss_read:
                    next_loss_read += LOST_POLL_S
                    self._read_losses()
                start_ns = time.time_ns()
                self._take_all()  # everything queued: the wait below batches what comes
                if self._on_swept is not None and not self._stop.is_set():
                    self._on_swept(start_ns)
                self._stop.wait(self._period_s)
            except Exception as exc:  # noqa: BLE001 - e.g. the context is going away
                if self._stop.is_set() or not self._owner.context.ok():
                    return
                self._owner.get_logger().error(f'taking messages failed: {exc!r}',
                                               throttle_duration_sec=5.0)
                time.sleep(self._period_s)

    def drain(self, deadline: float | None = None) -> list[str]:
        """Take what is queued now and read the losses, in the calling thread (the taker's
        thread must be stopped), until ``deadline`` (time.monotonic(); None: all). Return the
        topics whose queue was not emptied by then."""
        _taken, left = self._take_all(until_stopped=False, deadline=deadline)
        self._read_losses()
        return left

    def stop(self) -> None:
        """Stop the thread (it finishes the message in hand first)."""
        self._stop.set()
        if self._thread.is_alive() and self._thread is not threading.current_thread():
            self._thread.join(timeout=5.0)

    def destroy(self) -> None:
        """Stop the thread and destroy the subscriptions."""
        self.stop()
        with self._lock:
            self._subscriptions, self._lost_handlers = [], []
            self._first_count = 0
            self._incompatible_handlers = []
        self._node.destroy_node()
        if self._first_node is not None:
            self._first_node.destroy_node()
            self._first_context.try_shutdown()
            self._first_node = self._first_context = None
