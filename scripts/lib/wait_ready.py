"""Wait until the nodes a bring-up started serve, or report the one that died.

Run with the workspace sourced (``source scripts/env.sh``)::

    python scripts/lib/wait_ready.py [--timeout S] [--who NAME] NODE=PID:LOG ...

``NODE`` is one of the suite's nodes; what it must do before it counts as ready:

``check_lift_server``
    ``/check_lift`` answers a default request (the configured pair) with ``ok: true``;
``spcm_controller``
    the ``/dam_grasp`` action server is ready;
``hand_driver``
    ``/joint_states`` is published and ``/diagnostics`` reports the status
    ``dam_hand_driver: device link`` with ``state`` = ``ACTIVE``. A driver that reports
    ``ERROR`` (its device stream stalled while the machine was busy starting the suite) is
    asked once every few seconds to leave it through ``/hand_driver/reset``.

Meanwhile every ``PID`` is polled. Exit status:

0
    every node is ready (one line per node on stdout says so);
1
    a node exited: every ``[FATAL]`` line of its ``LOG`` (else its last lines) on stderr;
2
    ``--timeout`` [s] passed: what is still missing, on stderr;
3
    the arguments are malformed.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

#: The driver's diagnostic status that carries its state.
DRIVER_STATUS_NAME = 'dam_hand_driver: device link'
NODES = ('check_lift_server', 'hand_driver', 'spcm_controller')
#: Lines of a log shown when it has no ``[FATAL]`` line.
_TAIL_LINES = 8
#: Least time between two ``~/reset`` requests to a driver in ERROR [s].
_RESET_INTERVAL_S = 3.0
_POLL_S = 0.05


@dataclass
class Started:
    """A node a bring-up started: its name, its PID and its log file."""

    name: str
    pid: int
    log: Path


@dataclass
class Readiness:
    """What has been seen of the nodes so far."""

    check_lift: bool = False
    grasp_server: bool = False
    joint_states: int = 0  #: /joint_states messages received
    driver_state: str = ''  #: the last ``state`` of the driver's diagnostics ('' never seen)
    driver_message: str = ''  #: its status message
    notes: list[str] = field(default_factory=list)

    def missing(self, names: list[str]) -> list[str]:
        """What the nodes ``names`` still owe, one phrase each (empty: all ready)."""
        out = []
        if 'check_lift_server' in names and not self.check_lift:
            out.append('/check_lift has not answered')
        if 'spcm_controller' in names and not self.grasp_server:
            out.append('the /dam_grasp action server is not ready')
        if 'hand_driver' in names:
            if not self.joint_states:
                out.append('no /joint_states received')
            if self.driver_state != 'ACTIVE':
                seen = (f'{self.driver_state} ({self.driver_message})' if self.driver_state
                        else 'no diagnostics seen')
                out.append(f'the driver is not ACTIVE: {seen}')
        return out


def parse_node(text: str) -> Started:
    """``NODE=PID:LOG`` as a :class:`Started`.

    Raises
    ------
    ValueError
        The text is malformed, the node unknown or the PID not a positive integer.
    """
    name, sep, rest = text.partition('=')
    pid_text, sep2, log = rest.partition(':')
    if not sep or not sep2 or not log:
        raise ValueError(f'expected NODE=PID:LOG, got {text!r}')
    if name not in NODES:
        raise ValueError(f'unknown node {name!r} in {text!r} (known: {", ".join(NODES)})')
    try:
        pid = int(pid_text)
    except ValueError:
        raise ValueError(f'PID {pid_text!r} of {name} is not an integer') from None
    if pid <= 0:
        raise ValueError(f'PID {pid} of {name} is not positive')
    return Started(name, pid, Path(log))


def process_exited(pid: int) -> bool:
    """The process ``pid`` is gone or a zombie its parent has not reaped yet."""
    try:
        stat = Path(f'/proc/{pid}/stat').read_text(encoding='ascii', errors='replace')
    except (FileNotFoundError, ProcessLookupError):
        return True
    return stat.rsplit(')', 1)[-1].split()[0] in ('Z', 'X')


def fatal_lines(log: Path) -> list[str]:
    """The ``[FATAL]`` lines of ``log``, else its last non-empty lines (empty: no log)."""
    try:
        lines = [ln for ln in log.read_text(encoding='utf-8', errors='replace').splitlines()
                 if ln.strip()]
    except OSError:
        return []
    fatal = [ln for ln in lines if '[FATAL]' in ln]
    return fatal or lines[-_TAIL_LINES:]


class Watcher:
    """An rclpy node (in a context of its own) that follows what :class:`Readiness` needs."""

    def __init__(self, names: list[str]) -> None:
        import rclpy
        from diagnostic_msgs.msg import DiagnosticArray
        from rclpy.action import ActionClient
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import qos_profile_sensor_data
        from sensor_msgs.msg import JointState
        from std_srvs.srv import Trigger

        from dam_interfaces.action import DamGrasp
        from dam_interfaces.srv import CheckLift

        self.ready = Readiness()
        self.names = names
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(f'bringup_ready_{int(time.time() * 1e3) % 10**9}',
                                      context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._check_lift = self.node.create_client(CheckLift, '/check_lift')
        self._check_lift_request = CheckLift.Request()
        self._check_lift_future = None
        self._grasp = ActionClient(self.node, DamGrasp, '/dam_grasp')
        self._reset = self.node.create_client(Trigger, '/hand_driver/reset')
        self._reset_request = Trigger.Request()
        self._reset_future = None
        self._last_reset = -math.inf
        self.node.create_subscription(JointState, '/joint_states', self._on_joint_states,
                                      qos_profile_sensor_data)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)

    def _on_joint_states(self, _msg: object) -> None:
        self.ready.joint_states += 1

    def _on_diagnostics(self, msg: object) -> None:
        for status in msg.status:  # type: ignore[attr-defined]
            if status.name == DRIVER_STATUS_NAME:
                values = {kv.key: kv.value for kv in status.values}
                self.ready.driver_state = values.get('state', '')
                self.ready.driver_message = status.message

    def step(self) -> None:
        """Spin a little and move the checks on (service call, action server, reset)."""
        self.executor.spin_once(timeout_sec=_POLL_S)
        r = self.ready
        if 'check_lift_server' in self.names and not r.check_lift:
            if self._check_lift_future is None:
                if self._check_lift.service_is_ready():
                    self._check_lift_future = self._check_lift.call_async(
                        self._check_lift_request)
            elif self._check_lift_future.done():
                answer = self._check_lift_future.result()
                self._check_lift_future = None
                if answer is not None and answer.ok:
                    r.check_lift = True
                elif answer is not None:
                    r.notes.append(f'/check_lift answered ok: false: {answer.message}')
        if 'spcm_controller' in self.names and not r.grasp_server:
            r.grasp_server = self._grasp.server_is_ready()
        if 'hand_driver' in self.names and r.driver_state == 'ERROR':
            self._reset_if_due()

    def _reset_if_due(self) -> None:
        now = time.monotonic()
        if self._reset_future is not None:
            if self._reset_future.done():
                answer = self._reset_future.result()
                self._reset_future = None
                if answer is not None:
                    print(f'    driver in ERROR while starting: ~/reset: {answer.message}',
                          flush=True)
            return
        if now - self._last_reset >= _RESET_INTERVAL_S and self._reset.service_is_ready():
            self._last_reset = now
            self._reset_future = self._reset.call_async(self._reset_request)

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def main(argv: list[str] | None = None) -> int:
    """Wait for the nodes; see the module docstring. Returns the exit status."""
    parser = argparse.ArgumentParser(prog='wait_ready', description=__doc__.splitlines()[0])
    parser.add_argument('nodes', nargs='+', metavar='NODE=PID:LOG')
    parser.add_argument('--timeout', type=float, default=60.0, metavar='S',
                        help='give up after this long [s] (default 60)')
    parser.add_argument('--who', default='wait_ready',
                        help='the name the error lines start with')
    args = parser.parse_args(argv)
    try:
        started = [parse_node(text) for text in args.nodes]
    except ValueError as exc:
        print(f'{args.who}: {exc}', file=sys.stderr)
        return 3
    if not math.isfinite(args.timeout) or args.timeout <= 0.0:
        print(f'{args.who}: --timeout must be a positive number of seconds, got '
              f'{args.timeout!r}', file=sys.stderr)
        return 3
    names = [s.name for s in started]
    t0 = time.monotonic()
    deadline = t0 + args.timeout
    watcher = Watcher(names)
    try:
        while True:
            dead = [s for s in started if process_exited(s.pid)]
            if dead:
                for s in dead:
                    print(f'{args.who}: {s.name} (PID {s.pid}) exited while starting; '
                          f'its log {s.log}:', file=sys.stderr)
                    for line in fatal_lines(s.log) or ['(empty)']:
                        print(f'  {line}', file=sys.stderr)
                return 1
            missing = watcher.ready.missing(names)
            if not missing:
                break
            if time.monotonic() >= deadline:
                print(f'{args.who}: not ready after {args.timeout:g} s: '
                      f'{"; ".join(missing)}', file=sys.stderr)
                for note in watcher.ready.notes[-3:]:
                    print(f'  {note}', file=sys.stderr)
                return 2
            watcher.step()
    finally:
        watcher.close()
    r = watcher.ready
    took = time.monotonic() - t0
    done = {'check_lift_server': '/check_lift answers',
            'spcm_controller': '/dam_grasp action server ready',
            'hand_driver': f'/joint_states published, driver {r.driver_message}'}
    for s in started:
        print(f'    ready: {s.name} (PID {s.pid}): {done[s.name]}')
    print(f'    every node ready after {took:.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
