"""What every DAM node shares in its ROS layer: ``run_node`` and the common parameters.

:func:`run_node` is the whole life of a node process: start-up errors as one line, SIGINT and
SIGTERM at any moment as a clean exit, an executor loop that survives a failing callback,
services that always answer, and a warning for parameter overrides that match nothing.
"""

from __future__ import annotations

import gc
import inspect
import re
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import rclpy
from rcl_interfaces.msg import IntegerRange, ParameterDescriptor
from rclpy.exceptions import ParameterException
from rclpy.executors import (
    ExternalShutdownException,
    MultiThreadedExecutor,
    SingleThreadedExecutor,
)
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions

from dam_common.collector import ScheduledCollector
from dam_common.config import DamConfig
from dam_common.echo import brief_repr, brief_text
from dam_common.errors import DamCommonError
from dam_common.parameter_services import harden_parameter_services, list_parameters_hint
from dam_common.shutdown import ShutdownRequest, StartupInterrupted, catch_signals
from dam_common.sim_time import fix_use_sim_time

CONFIG_FILE_DESCRIPTION = ('DAM configuration file (YAML); empty: DAM_CONFIG or the installed '
                           'config/dam.yaml')
#: Longest time a stop request waits for the executor loop [s].
SPIN_PERIOD_S = 0.05
#: History depth of the 500 Hz streams' publishers (``/joint_states``, ``/hand/command``)
#: [messages]: one second, kept for reliable subscribers that fall behind (a recorder that the
#: kernel stops for up to 50 ms when the real-time budget runs out). With the usual 10 the
#: publisher overwrites what such a subscriber has not yet acknowledged (20 ms at 500 Hz), and
#: the subscriber's middleware reports those messages lost.
STREAM_HISTORY_DEPTH = 500
#: Longest time a node may finish its work after a stop request (``begin_shutdown``) [s].
FINISH_TIMEOUT_S = 1.0
#: Fields that say whether a service call succeeded, and the ones that say why not.
_OK_FIELDS = ('ok', 'success', 'successful')
_REASON_FIELDS = ('message', 'reason')


def declare_config_file(node: Node) -> str:
    """Declare the read-only ``config_file`` parameter on ``node`` and return its value.

    Pass the value, or ``None`` when it is empty, to :func:`dam_common.config.load_config`.
    """
    return str(node.declare_parameter(
        'config_file', '',
        ParameterDescriptor(description=CONFIG_FILE_DESCRIPTION, read_only=True)).value)


def declare_config_overlay(node: Node) -> tuple[str, ...]:
    """Declare the read-only ``config_overlay`` parameter on ``node``; the overlay files.

    The value is a YAML file holding part of a configuration (the ``contact`` values a
    calibration fitted, ``docs/analysis.md``), merged over ``config_file`` by
    :func:`dam_common.config.load_config`; empty (the default): no overlay.
    """
    value = str(node.declare_parameter(
        'config_overlay', '',
        ParameterDescriptor(description='configuration overlay (YAML, part of a '
                                        'configuration) merged over config_file; empty: none',
                            read_only=True)).value)
    return (value,) if value else ()


def declare_object(node: Node, config: DamConfig) -> DamConfig:
    """Declare the read-only ``object`` parameter on ``node``; ``config`` with that object.

    The value names an object of the configuration's ``object.library``; empty (the
    default) keeps ``object.default``.

    Raises
    ------
    ConfigError
        The name is not in the library (the message lists the names).
    """
    name = str(node.declare_parameter(
        'object', '',
        ParameterDescriptor(
            description='column object of the configuration\'s object.library (known: '
                        f'{", ".join(sorted(config.objects))}); empty: object.default '
                        f'({config.object.name})',
            read_only=True)).value)
    return config.with_object(name)


def declare_thread_priority(node: Node, default: int = 50,
                            what: str = 'the timed device thread') -> int:
    """Declare the read-only ``thread_priority`` parameter on ``node`` and return its value.

    The priority (1-99) of the ``SCHED_FIFO`` policy ``what`` asks for, as ``ros2_control``'s
    controller manager does; ``0`` keeps the normal policy. See :mod:`dam_common.realtime`.
    """
    return int(node.declare_parameter(
        'thread_priority', default,
        ParameterDescriptor(
            description=f'SCHED_FIFO priority of {what} (1-99); 0: normal scheduling. Needs '
                        'the rtprio permission; without it the node warns and runs with '
                        'normal scheduling',
            integer_range=[IntegerRange(from_value=0, to_value=99, step=1)],
            read_only=True)).value)


def failure_response(response: Any, reason: str) -> Any:
    """Mark a service ``response`` as failed where its type can say so (``ok``, ``success`` or
    ``successful`` false; ``message`` or ``reason`` set, cut to
    :data:`~dam_common.echo.TEXT_LIMIT` characters); return it."""
    for name in _OK_FIELDS:
        if hasattr(response, name):
            setattr(response, name, False)
    for name in _REASON_FIELDS:
        if hasattr(response, name):
            setattr(response, name, brief_text(reason))
    return response


def guard_service_callbacks(node: Node) -> None:
    """Wrap the callback of every service ``node`` has now so that an exception becomes an
    answer (:func:`failure_response`) and an error in the log instead of a request left without
    answer and an executor that stops."""
    for service in node.services:
        service.callback = _guarded(node, service.srv_name, service.callback)


def _guarded(node: Node, srv_name: str, callback: Callable[..., Any]) -> Callable[..., Any]:
    def report(exc: Exception, response: Any) -> Any:
        node.get_logger().error(f'{srv_name}: the request raised {brief_repr(exc)}; answered '
                                'as failed')
        return failure_response(response, f'internal error while answering: {brief_repr(exc)}')

    if inspect.iscoroutinefunction(callback):
        async def guarded_async(request: Any, response: Any) -> Any:
            try:
                return await callback(request, response)
            except Exception as exc:  # noqa: BLE001 - every request gets an answer
                return report(exc, response)
        return guarded_async

    def guarded(request: Any, response: Any) -> Any:
        try:
            return callback(request, response)
        except Exception as exc:  # noqa: BLE001 - every request gets an answer
            return report(exc, response)
    return guarded


def unmatched_overrides(node: Node) -> list[str]:
    """Names of parameter overrides (``-p``, ``--params-file``) that no declared parameter of
    ``node`` takes: misspelled or meant for another node."""
    overrides = getattr(node, '_parameter_overrides', {})  # rclpy keeps them there
    return sorted(name for name in overrides if not node.has_parameter(name))


def _params_files(args: Sequence[str] | None) -> list[str]:
    argv = list(sys.argv if args is None else args)
    return [argv[i + 1] for i, a in enumerate(argv[:-1]) if a == '--params-file']


def _rcl_error_text(exc: BaseException, args: Sequence[str] | None) -> str:
    """One line for an rcl error at start-up, naming the parameter file when it is the cause."""
    first = str(exc).strip().splitlines()[0] if str(exc).strip() else repr(exc)
    first = re.sub(r',\s*at\s+\S+:\d+.*$', '', first)  # rcl's source location
    files = _params_files(args)
    if files and re.search(r'param|yaml|pars', str(exc), re.IGNORECASE):
        return f'cannot read the parameter file {", ".join(map(repr, files))}: {first}'
    return f'invalid ROS arguments: {first}'


def spin_until_shutdown(node: Node, shutdown: ShutdownRequest, executor_threads: int = 1
                        ) -> None:
    """Run ``node``'s callbacks until a stop request or an external shutdown.

    A callback that raises is reported in the log and the node goes on serving: one bad
    message, request or timer tick does not end it. On a stop request a node with a
    ``begin_shutdown()`` method (returning a future, or ``None``) is given up to
    :data:`FINISH_TIMEOUT_S` of further spinning to finish what it owes its clients (e.g.
    the result of an action goal). With ``executor_threads`` > 1 the callbacks run on that
    many threads (a ``MultiThreadedExecutor``): callbacks of different callback groups run
    side by side, so a long one in a group of its own does not hold up the others.
    """
    executor = (SingleThreadedExecutor(context=node.context) if executor_threads <= 1 else
                MultiThreadedExecutor(num_threads=executor_threads, context=node.context))
    executor.add_node(node)

    def spin_once() -> bool:
        try:
            executor.spin_once(timeout_sec=SPIN_PERIOD_S)
        except ExternalShutdownException:
            return False
        except Exception as exc:  # noqa: BLE001 - the node stays up
            if not node.context.ok():
                return False
            node.get_logger().error(f'a callback raised {brief_repr(exc)}; the node goes on')
        return True

    try:
        while not shutdown.requested and node.context.ok():
            if not spin_once():
                return
        begin = getattr(node, 'begin_shutdown', None)
        pending = begin() if callable(begin) and node.context.ok() else None
        if pending is None:
            return
        deadline = time.monotonic() + FINISH_TIMEOUT_S
        while not pending.done() and time.monotonic() < deadline and spin_once():
            pass
        flush = time.monotonic() + 0.1  # the answers that follow from it go out
        while time.monotonic() < flush and spin_once():
            pass
    finally:
        executor.remove_node(node)


def run_node(make_node: Callable[[], Node], name: str, args: list[str] | None = None,
             startup_errors: tuple[type[BaseException], ...] = (),
             startup_exit_code: int = 1, switch_interval_s: float | None = None,
             scheduled_gc_period_s: float | None = None, executor_threads: int = 1) -> None:
    """The life of a node process: start it, serve until SIGINT or SIGTERM, stop it cleanly.

    - SIGINT and SIGTERM at any moment, from the entry point's first line on (see
      :mod:`dam_common.shutdown`), end the process with status 0 and no traceback: during
      start-up at once (what the node built so far is destroyed), while running between two
      callbacks. ``node.destroy_node()`` (which stops the node's own threads and
      child processes) runs before the ROS context is shut down, so no thread ever publishes
      on a context that is gone.
    - A bad configuration (:class:`~dam_common.errors.DamCommonError`, or one of
      ``startup_errors``), a parameter override of the wrong type or out of its range, or a
      malformed ``--params-file`` is logged as one fatal line ``cannot start: ...`` under the
      logger ``name`` and ends the process with ``startup_exit_code``.
    - Once built, the node's services are guarded (:func:`guard_service_callbacks`), its
      set-parameter services check every request
      (:func:`~dam_common.parameter_services.harden_parameter_services`), ``use_sim_time``
      is fixed (:func:`~dam_common.sim_time.fix_use_sim_time`), and overrides that match no
      parameter are warned about.
    - Every object that exists then is moved out of the garbage collector's sight
      (``gc.freeze``), so later collections scan only what the running node allocates: no
      pause of several milliseconds in the middle of a control cycle. A node with a timed
      thread (the driver's device link, the stand-in's device) passes ``switch_interval_s``
      [s], the longest time another thread may keep that thread from the interpreter
      (``sys.setswitchinterval``; Python's default is 5 ms). A node with a real-time loop
      passes ``scheduled_gc_period_s`` [s]: the automatic collector is off and a full
      collection runs from its executor at that period
      (:class:`~dam_common.collector.ScheduledCollector`, set as the node's
      ``garbage_collector`` attribute), not in the middle of a cycle.
    - ``executor_threads`` > 1 runs the callbacks on that many threads
      (:func:`spin_until_shutdown`); the node then stops its own long callbacks in its
      ``destroy_node``.
    """
    shutdown = catch_signals()
    logger = rclpy.logging.get_logger(name)
    node = None
    try:
        try:
            shutdown.raise_if_requested()
            try:
                rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
                node = make_node()
            except (*startup_errors, DamCommonError, ParameterException) as exc:
                logger.fatal(f'cannot start: {exc}')
                raise SystemExit(startup_exit_code) from None
            except _rclpy.RCLError as exc:
                if shutdown.requested:
                    raise StartupInterrupted(shutdown.signal_name) from None
                logger.fatal(f'cannot start: {_rcl_error_text(exc, args)}')
                raise SystemExit(startup_exit_code) from None
            except Exception:
                if shutdown.requested:  # the interrupt surfaced as another error
                    raise StartupInterrupted(shutdown.signal_name) from None
                raise
            harden_parameter_services(node)
            guard_service_callbacks(node)
            fix_use_sim_time(node)
            for override in unmatched_overrides(node):
                node.get_logger().warning(
                    f'parameter override {override!r} matches no parameter of this node: '
                    f'ignored (misspelled? {list_parameters_hint(node)} lists them)')
        finally:
            shutdown.started()  # from here on a signal asks; it never interrupts
        if switch_interval_s is not None:
            sys.setswitchinterval(switch_interval_s)
        if scheduled_gc_period_s is not None:
            node.garbage_collector = ScheduledCollector(node, scheduled_gc_period_s)
        else:
            gc.freeze()  # no gc.collect() first: a full collection could stall a running thread
        spin_until_shutdown(node, shutdown, executor_threads)
    except StartupInterrupted:
        pass  # stopped while starting: what was built is torn down below, status 0
    finally:
        shutdown.started()
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()  # a no-op where init never ran
