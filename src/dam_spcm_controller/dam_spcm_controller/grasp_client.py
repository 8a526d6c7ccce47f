"""``dam_grasp``: send one DAM grasp to ``spcm_controller`` and report what happened.

::

    ros2 run dam_spcm_controller dam_grasp [--k-theta 7] [--delta-theta-p 40deg] [--cancel-after S]
    ros2 run dam_spcm_controller dam_grasp --release

Prints the feedback phases as they change (with the ``/check_lift`` answer) and the result.
Exit codes: 0 the outcome is SUCCESS; 3 any other outcome (not lifted, lifted but not
enveloped, aborted, cancelled, or stopped by SIGINT/SIGTERM); 2 the goal was refused (its
reason is printed) or bad arguments; 1 no action server.

``--release`` sends no goal: it asks ``/spcm_controller/release`` (``std_srvs/Trigger``) to let
go of the object the hand holds after a grasp (torques to zero, the hand opened), as
``ros2 service call /spcm_controller/release std_srvs/srv/Trigger`` does, and prints its
answer. Exit codes: 0 released; 3 refused (the answer says why: a grasp or a release is
running, the joint states went silent), no answer within ``--timeout`` or stopped by a signal
(the release goes on in the controller); 1 no such service within ``--server-timeout``; 2 a
goal option given with it. It asks ``/spcm_controller/release``, the default name.

SIGINT (Ctrl-C) or SIGTERM while the goal runs cancels it: the client waits up to
``--cancel-timeout`` seconds in all (the cancel's answer and the end of the goal: the torque
ramp, ``torque_ramp_time`` on the grasp's clock) and exits with 3, printing how the goal ended
or, past the timeout, whether the controller accepted the cancel. The exit follows the signal
within ``--cancel-timeout`` plus the client's own shutdown (tenths of a second).
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from typing import Any

from dam_common.command_line import CommandLineParser
from dam_common.quantities import (
    ANGLE,
    RIGHT_ANGLE,
    argument,
    number_argument,
    parse_quantity,
)
from dam_common.ros_args import strip_ros_args

EXIT_SUCCESS = 0
EXIT_NO_SERVER = 1
EXIT_REJECTED = 2
EXIT_OTHER_OUTCOME = 3

#: The displacement: a positive angle (the position joints curl inward by it); a bare number
#: is radians, as in every command of the suite (:mod:`dam_common.quantities`).
_DELTA_THETA_P = argument(ANGLE, low=0.0, low_inclusive=False, high=RIGHT_ANGLE)
#: Finger 1's stiffness [N*m/rad]: a plain positive number.
_STIFFNESS = number_argument(above=0.0, unit='N*m/rad', what='stiffness')


def parse_angle(text: str) -> float:
    """An angle [rad] from ``'40deg'``, ``'0.7rad'`` or ``'0.7'`` (radians;
    :func:`dam_common.quantities.parse_quantity`)."""
    return parse_quantity(text, ANGLE)


def _positive(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r} is not a number') from None
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f'{text!r} must be a positive number')
    return value


def _parse(argv: Sequence[str]) -> argparse.Namespace:
    p = CommandLineParser(
        prog='dam_grasp', description='Run one DAM grasp on /dam_grasp and print the result.')
    p.add_argument('--k-theta', type=_STIFFNESS, default=None,
                   help='finger-1 compliant-joint stiffness [N*m/rad] (default: the '
                        "controller's configured one)")
    p.add_argument('--delta-theta-p', type=_DELTA_THETA_P, default=None,
                   help='position-joint displacement, e.g. 40deg or 0.7rad (bare: rad; '
                        "default: the controller's configured one)")
    p.add_argument('--cancel-after', type=_positive, default=None, metavar='S',
                   help='cancel the goal this many seconds after it was accepted')
    p.add_argument('--server-timeout', type=_positive, default=10.0, metavar='S',
                   help='how long to wait for the action server [s] (default 10)')
    p.add_argument('--timeout', type=_positive, default=120.0, metavar='S',
                   help='how long to wait for the result, or with --release for its answer '
                        '[s] (default 120)')
    p.add_argument('--cancel-timeout', type=_positive, default=5.0, metavar='S',
                   help='on SIGINT/SIGTERM, how long to wait for the cancel to be confirmed '
                        '[s] (default 5)')
    p.add_argument('--release', action='store_true',
                   help='send no goal: let go of the object the hand holds after a grasp '
                        '(/spcm_controller/release) and open the hand')
    args = p.parse_args(strip_ros_args(list(argv)))  # rclpy's, as ros2 run passes them
    if args.release:
        given = [name for name, value in (('--k-theta', args.k_theta),
                                          ('--delta-theta-p', args.delta_theta_p),
                                          ('--cancel-after', args.cancel_after))
                 if value is not None]
        if given:
            p.error(f'--release sends no goal: {" and ".join(given)} cannot go with it')
    return args


def release(args: argparse.Namespace) -> int:
    """Ask ``/spcm_controller/release`` to let go and open the hand; return the exit code.

    Waits up to ``args.server_timeout`` [s] for the service and ``args.timeout`` [s] for its
    answer (the hand is open when it comes); exit codes as in the module's docstring.
    """
    from std_srvs.srv import Trigger

    from dam_common.service_qos import SERVICE_QOS
    from dam_common.shutdown import catch_signals

    shutdown = catch_signals()
    with _client_node('dam_grasp_release') as (node, executor):
        client = node.create_client(Trigger, '/spcm_controller/release',
                                    qos_profile=SERVICE_QOS)
        if not spin_until_ready(client.service_is_ready, executor, args.server_timeout,
                                shutdown):
            if shutdown.requested:
                return EXIT_OTHER_OUTCOME
            print(f'dam_grasp: no /spcm_controller/release service within '
                  f'{args.server_timeout:g} s (is spcm_controller running?)', file=sys.stderr)
            return EXIT_NO_SERVER
        future = client.call_async(Trigger.Request())
        if not spin_until_done(future, executor, args.timeout, shutdown):
            print('dam_grasp: stopped before the answer came; the release goes on in the '
                  'controller (see /dam/status)' if shutdown.requested else
                  f'dam_grasp: no answer from /spcm_controller/release within '
                  f'{args.timeout:g} s', file=sys.stderr)
            return EXIT_OTHER_OUTCOME
        answer = future.result()
        print(f'release: {"done" if answer.success else "refused"}: {answer.message}',
              flush=True)
        return EXIT_SUCCESS if answer.success else EXIT_OTHER_OUTCOME


def run(args: argparse.Namespace) -> int:
    """Send the goal described by ``args``; return the exit code."""
    from dam_common.shutdown import catch_signals

    shutdown = catch_signals()
    with _client_node('dam_grasp_client') as (node, executor):
        return _send_goal(args, node, executor, shutdown)


def _send_goal(args: argparse.Namespace, node, executor, shutdown) -> int:
    """The goal of :func:`run`, sent from ``node``; return the exit code."""
    from action_msgs.msg import GoalStatus
    from rclpy.action import ActionClient

    from dam_interfaces.action import DamGrasp

    _STATUS = {GoalStatus.STATUS_SUCCEEDED: 'SUCCEEDED', GoalStatus.STATUS_ABORTED: 'ABORTED',
               GoalStatus.STATUS_CANCELED: 'CANCELED'}
    client = ActionClient(node, DamGrasp, '/dam_grasp')

    def spin_until(future, timeout: float, interruptible: bool = True) -> bool:
        return spin_until_done(future, executor, timeout, shutdown if interruptible else None)

    def cancel_on_signal(handle, result_future) -> int:
        """Cancel the goal; wait for its result at most ``--cancel-timeout`` in all (the
        cancel's answer and the torque ramp); say what is known."""
        print(f'[{time.monotonic() - t0:7.2f} s] {shutdown.signal_name or "stop"}: cancelling '
              f'the goal', flush=True)
        give_up = time.monotonic() + args.cancel_timeout
        cancel = handle.cancel_goal_async()
        spin_until(cancel, args.cancel_timeout, interruptible=False)
        if spin_until(result_future, max(give_up - time.monotonic(), 0.0),
                      interruptible=False):
            wrapped = result_future.result()
            print(f'result: {_STATUS.get(wrapped.status, wrapped.status)}, '
                  f'{wrapped.result.outcome_name} ({wrapped.result.message})', flush=True)
        elif cancel.done() and cancel.result().goals_canceling:
            print(f'dam_grasp: the controller accepted the cancel but the goal had not ended '
                  f'within --cancel-timeout {args.cancel_timeout:g} s (its torque ramp runs on '
                  'the grasp\'s clock: slower than wall time on a loaded simulation); it ends '
                  'it without this client (see /dam/status)', file=sys.stderr)
        elif cancel.done():
            print('dam_grasp: the controller refused the cancel (the goal had ended?); no '
                  f'result within --cancel-timeout {args.cancel_timeout:g} s', file=sys.stderr)
        else:
            print(f'dam_grasp: the controller did not answer the cancel within '
                  f'--cancel-timeout {args.cancel_timeout:g} s', file=sys.stderr)
        return EXIT_OTHER_OUTCOME

    last = {'phase': None}

    def on_feedback(msg) -> None:
        fb = msg.feedback
        if fb.phase == last['phase']:
            return
        last['phase'] = fb.phase
        line = f'[{time.monotonic() - t0:7.2f} s] phase {fb.phase:<10} progress {fb.progress:.2f}'
        if fb.outcome:  # the last feedback: the phase the goal ended in, with its outcome
            line += f'  outcome {fb.outcome_name}'
        if fb.lift_checked:
            line += (f'  check_lift: guaranteed={fb.lift_guaranteed} '
                     f'(margin {fb.worst_case_margin:.3g} N), csm={fb.csm_lift} '
                     f'(margin {fb.csm_margin:.3g} N)')
        print(line, flush=True)

    t0 = time.monotonic()
    try:
        if not spin_until_ready(client.server_is_ready, executor, args.server_timeout,
                                shutdown):
            if shutdown.requested:
                return EXIT_OTHER_OUTCOME
            print(f'dam_grasp: no action server /dam_grasp within {args.server_timeout:g} s',
                  file=sys.stderr)
            return EXIT_NO_SERVER
        goal = DamGrasp.Goal()  # a field left empty: the controller's configured value
        if args.k_theta is not None:
            goal.k_theta = [float(args.k_theta)]
        if args.delta_theta_p is not None:
            goal.delta_theta_p = [float(args.delta_theta_p)]
        k_text = 'configured' if args.k_theta is None else f'{args.k_theta:g} N*m/rad'
        dp_text = ('configured' if args.delta_theta_p is None else
                   f'{math.degrees(args.delta_theta_p):.4g} deg')
        print(f'goal: k_theta {k_text}, delta_theta_p {dp_text}', flush=True)
        t0 = time.monotonic()
        send = client.send_goal_async(goal, feedback_callback=on_feedback)
        # The answer to the goal is waited for even after a signal: the goal must be known
        # to be cancelled.
        if not spin_until(send, 10.0, interruptible=False):
            print('dam_grasp: the server did not answer the goal within 10 s', file=sys.stderr)
            return EXIT_NO_SERVER
        handle = send.result()
        if not handle.accepted:
            print('dam_grasp: goal rejected by the server', file=sys.stderr)
            return EXIT_REJECTED
        result_future = handle.get_result_async()
        if args.cancel_after is not None:
            spin_until(result_future, args.cancel_after)
            if not result_future.done() and not shutdown.requested:
                print(f'[{time.monotonic() - t0:7.2f} s] cancelling', flush=True)
                spin_until(handle.cancel_goal_async(), 5.0, interruptible=False)
        if not spin_until(result_future, args.timeout):
            if shutdown.requested:
                return cancel_on_signal(handle, result_future)
            print(f'dam_grasp: no result within {args.timeout:g} s; cancelling',
                  file=sys.stderr)
            spin_until(handle.cancel_goal_async(), 5.0, interruptible=False)
            return EXIT_OTHER_OUTCOME
        wrapped = result_future.result()
        result = wrapped.result
        if result.outcome == DamGrasp.Result.OUTCOME_REJECTED:
            print(f'dam_grasp: {result.message}', file=sys.stderr)
            return EXIT_REJECTED
        print(f'result: {result.outcome_name} ({result.message}); status '
              f'{_STATUS.get(wrapped.status, wrapped.status)}; duration '
              f'{result.duration:.2f} s on the grasp\'s clock ({result.wall_duration:.2f} s '
              'wall)', flush=True)
        if math.isfinite(result.object_rise):
            where = 'left the table' if result.object_left_table else 'on the table'
            turned = (f', turned {math.degrees(result.object_orientation):.1f} deg'
                      if math.isfinite(result.object_orientation)
                      and result.object_orientation != 0.0 else '')
            print(f'object rise: {result.object_rise * 1e3:.1f} mm, {where}{turned} '
                  '(estimated from the joint angles)', flush=True)
        ok = result.outcome == DamGrasp.Result.OUTCOME_SUCCESS
        return EXIT_SUCCESS if ok else EXIT_OTHER_OUTCOME
    finally:
        client.destroy()


@contextlib.contextmanager
def _client_node(name: str) -> Iterator[tuple[Any, Any]]:
    """A node ``name`` in a context of its own with its single-threaded executor; the
    caller's signal handling (:func:`dam_common.shutdown.catch_signals`) is left in place.
    Yields ``(node, executor)``; everything is shut down on leaving."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    context = rclpy.Context()
    rclpy.init(args=[], context=context, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(name, context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    try:
        yield node, executor
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def spin_until_ready(is_ready: Callable[[], bool], executor, timeout_s: float,
                     shutdown) -> bool:
    """Spin ``executor`` until ``is_ready()`` (a server's readiness), ``timeout_s`` [s]
    passed or a stop was requested; return whether it is ready."""
    deadline = time.monotonic() + timeout_s
    while not is_ready():
        if shutdown.requested or time.monotonic() >= deadline:
            return False
        executor.spin_once(timeout_sec=0.05)
    return True


def spin_until_done(future, executor, timeout_s: float, shutdown=None) -> bool:
    """Spin ``executor`` until ``future`` is done, ``timeout_s`` [s] passed or (``shutdown``
    given) a stop was requested; return whether it is done."""
    deadline = time.monotonic() + timeout_s
    while not future.done() and time.monotonic() < deadline:
        if shutdown is not None and shutdown.requested:
            break
        executor.spin_once(timeout_sec=min(0.05, max(deadline - time.monotonic(), 0.0)))
    return future.done()


def main(argv: Sequence[str] | None = None) -> None:
    """Entry point of ``dam_grasp`` (exits with the code of :func:`run`)."""
    try:
        args = _parse(sys.argv[1:] if argv is None else argv)
    except SystemExit as exc:  # argparse: 2 on bad arguments, 0 on --help
        sys.exit(exc.code)
    try:
        code = release(args) if args.release else run(args)
    except KeyboardInterrupt:
        code = EXIT_OTHER_OUTCOME
    sys.exit(code)


if __name__ == '__main__':
    main()
