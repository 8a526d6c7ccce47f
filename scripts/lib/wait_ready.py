"""Wait while the nodes a bring-up started progress, until they serve; report one that died.

Run with the workspace sourced (``source scripts/env.sh``)::

    python scripts/lib/wait_ready.py [--timeout S] [--stall S] [--report S] [--who NAME]
                                     NODE=PID:LOG ...

``NODE`` is one of the suite's nodes; what it must do before it counts as ready:

``check_lift_server``
    ``/check_lift`` answers a default request (the configured pair) with ``ok: true``;
``spcm_controller``
    the ``/dam_grasp`` action server is ready;
``hand_driver``
    ``/joint_states`` is published and ``/diagnostics`` reports the status
    ``dam_hand_driver: device link`` with ``state`` = ``ACTIVE``. A driver that reports
    ``ERROR`` (its device stream stalled while the machine was busy starting the suite) is
    asked once every few seconds to leave it through ``/hand_driver/reset``;
``recorder``
    its log says it records ``/dam/episode`` and ``/joint_states`` (``run.sh``'s recorder);
``dam_state_publisher``
    its log says it took the hand's model from ``/robot_description`` and published the fixed
    frames on ``/tf_static`` (or, with ``robot_state:=false``, that it publishes no hand).

No fixed limit decides on a loaded machine: while every process runs and something still
progresses, it waits. Progress is any of: a new line in the log of a node not ready yet; CPU
time used by a node not ready that has printed nothing yet (it still imports and builds),
or by a child of one (the driver's stand-in); a node met one more of its conditions; a node,
topic or service more in the ROS graph. Every ``--report`` seconds (10) one line per node not
ready says how long it has run, its CPU time and what it still waits for.

Exit status:

0
    every node is ready (one line per node on stdout says so, with the time from its start
    to its first log line and to ready);
1
    a node exited: every ``[FATAL]`` line of its ``LOG`` (else its last lines) on stderr,
    at once;
2
    gave up: ``--timeout`` [s] passed (none by default), or nothing progressed for
    ``--stall`` [s] (120); what is still missing, on stderr;
3
    the arguments are malformed.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

#: The driver's diagnostic status that carries its state.
DRIVER_STATUS_NAME = 'dam_hand_driver: device link'
NODES = ('check_lift_server', 'hand_driver', 'spcm_controller', 'recorder',
         'dam_state_publisher')
#: Lines of the recorder's log that make it ready.
RECORDER_READY = ('recording /dam/episode ', 'recording /joint_states ')
#: Lines of dam_state_publisher's log of which one makes it ready.
STATE_PUBLISHER_READY = ('fixed frames on /tf_static', 'no hand transforms')
#: Lines of a log shown when it has no ``[FATAL]`` line.
_TAIL_LINES = 8
#: Least time between two ``~/reset`` requests to a driver in ERROR [s].
_RESET_INTERVAL_S = 3.0
_POLL_S = 0.05
#: Time between two looks at the processes, their logs and the graph [s].
_LOOK_S = 0.5
DEFAULT_STALL_S = 120.0
DEFAULT_REPORT_S = 10.0
_TICKS = os.sysconf('SC_CLK_TCK')


def boot_time_s() -> float:
    """Now on the clock of ``/proc/PID/stat``'s start times [s since boot]."""
    return time.clock_gettime(time.CLOCK_BOOTTIME)


def process_times(pid: int) -> tuple[float, float] | None:
    """(start [s since boot], CPU time used [s]) of process ``pid``; ``None`` when gone."""
    try:
        stat = Path(f'/proc/{pid}/stat').read_text(encoding='ascii', errors='replace')
    except (FileNotFoundError, ProcessLookupError):
        return None
    fields = stat.rsplit(')', 1)[-1].split()  # fields[0] is stat field 3 (state)
    return int(fields[19]) / _TICKS, (int(fields[11]) + int(fields[12])) / _TICKS


def descendants(pid: int) -> list[int]:
    """PIDs of every living descendant of process ``pid`` (from /proc)."""
    out: list[int] = []
    todo = [pid]
    while todo:
        parent = todo.pop()
        try:
            tasks = list(Path(f'/proc/{parent}/task').iterdir())
        except (FileNotFoundError, ProcessLookupError):
            continue
        for task in tasks:
            try:
                children = [int(c) for c in (task / 'children').read_text().split()]
            except (FileNotFoundError, ProcessLookupError):
                continue
            out += children
            todo += children
    return out


@dataclass
class Started:
    """A node a bring-up started: its name, its PID, its log file, and what was seen of it."""

    name: str
    pid: int
    log: Path
    start_s: float | None = None  #: process start [s since boot]
    cpu_s: float = 0.0  #: CPU time of the process itself [s]
    child_cpu_s: float = 0.0  #: CPU time of its living descendants [s]
    log_size: int = 0
    lines: int = 0  #: non-empty log lines seen
    first_line_s: float | None = None  #: when its log got its first line [s since boot]
    ready_s: float | None = None  #: when it was first seen ready [s since boot]

    def age(self, now_s: float) -> float:
        """Time since the process started [s] (0 when unknown)."""
        return 0.0 if self.start_s is None else max(now_s - self.start_s, 0.0)


@dataclass
class Readiness:
    """What has been seen of the nodes so far."""

    check_lift: bool = False
    grasp_server: bool = False
    joint_states: int = 0  #: /joint_states messages received
    driver_state: str = ''  #: the last ``state`` of the driver's diagnostics ('' never seen)
    driver_message: str = ''  #: its status message
    recorder: bool = False  #: the recorder's log says it records what an episode needs
    #: dam_state_publisher's log says it has the hand's model (or publishes no hand)
    state_publisher: bool = False
    driver_states: set[str] = field(default_factory=set)  #: every driver state seen
    notes: list[str] = field(default_factory=list)

    def score(self) -> int:
        """How many conditions are met (and driver states seen): it grows as nodes come up."""
        return (self.check_lift + self.grasp_server + bool(self.joint_states)
                + self.recorder + self.state_publisher + len(self.driver_states))

    def missing_of(self, name: str) -> list[str]:
        """What node ``name`` still owes, one phrase each (empty: ready)."""
        out = []
        if name == 'check_lift_server' and not self.check_lift:
            out.append('/check_lift has not answered')
        if name == 'spcm_controller' and not self.grasp_server:
            out.append('the /dam_grasp action server is not ready')
        if name == 'hand_driver':
            if not self.joint_states:
                out.append('no /joint_states received')
            if self.driver_state != 'ACTIVE':
                seen = (f'{self.driver_state} ({self.driver_message})' if self.driver_state
                        else 'no diagnostics seen')
                out.append(f'the driver is not ACTIVE: {seen}')
        if name == 'recorder' and not self.recorder:
            out.append('it does not record /dam/episode and /joint_states yet')
        if name == 'dam_state_publisher' and not self.state_publisher:
            out.append('it has not taken the hand\'s model from /robot_description yet')
        return out

    def missing(self, names: list[str]) -> list[str]:
        """What the nodes ``names`` still owe, one phrase each (empty: all ready)."""
        return [phrase for name in names for phrase in self.missing_of(name)]


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


def seconds_or_none(text: str) -> float | None:
    """``--timeout``'s value: a positive number of seconds, or ``none`` (also ``0``, empty):
    no limit.

    Raises
    ------
    argparse.ArgumentTypeError
        Neither.
    """
    if text.strip().lower() in ('', 'none', '0'):
        return None
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value) or value <= 0.0:
        raise argparse.ArgumentTypeError(
            f'must be a positive number of seconds or none, got {text!r}')
    return value


def positive_seconds(text: str) -> float:
    """A positive, finite number of seconds.

    Raises
    ------
    argparse.ArgumentTypeError
        Anything else.
    """
    value = seconds_or_none(text)
    if value is None:
        raise argparse.ArgumentTypeError(f'must be a positive number of seconds, got {text!r}')
    return value


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


class Progress:
    """Follows the started processes and their logs; says whether anything progressed."""

    def __init__(self, started: list[Started]) -> None:
        self.started = started
        now = boot_time_s()
        for s in started:
            times = process_times(s.pid)
            if times is not None:
                s.start_s, s.cpu_s = times
        self._graph: set[str] = set()
        self._met = -1
        self.last_s = now  #: when something last progressed [s since boot]

    def look(self, ready: Readiness, graph: set[str]) -> bool:
        """Look at the processes, their logs and the graph ``graph``; ``True`` when
        something progressed since the last look."""
        now = boot_time_s()
        moved = False
        for s in self.started:
            if s.ready_s is not None:
                continue
            moved |= self._look_at_log(s, ready, now)
            times = process_times(s.pid)
            if times is not None:
                cpu = times[1]
                # its own CPU counts while it starts (nothing printed yet): a node that
                # waits afterwards still spins its timers
                moved |= cpu > s.cpu_s and s.first_line_s is None
                s.cpu_s = cpu
            child_cpu = sum(t[1] for t in map(process_times, descendants(s.pid))
                            if t is not None)
            moved |= child_cpu > s.child_cpu_s
            s.child_cpu_s = max(child_cpu, s.child_cpu_s)
        met = ready.score()
        moved |= met > self._met
        self._met = max(met, self._met)
        moved |= not graph <= self._graph
        self._graph |= graph
        for s in self.started:
            if s.ready_s is None and not ready.missing_of(s.name):
                s.ready_s = now
        if moved:
            self.last_s = now
        return moved

    @staticmethod
    def _look_at_log(s: Started, ready: Readiness, now: float) -> bool:
        try:
            size = s.log.stat().st_size
        except OSError:
            return False
        if size <= s.log_size:
            return False
        try:
            with s.log.open('rb') as f:
                f.seek(s.log_size)
                new = f.read(size - s.log_size)
        except OSError:
            return False
        s.log_size = size
        lines = [ln for ln in new.decode('utf-8', 'replace').splitlines() if ln.strip()]
        if lines and s.first_line_s is None:
            s.first_line_s = now
        s.lines += len(lines)
        if s.name == 'recorder' and not ready.recorder:
            text = s.log.read_text(encoding='utf-8', errors='replace')
            ready.recorder = all(pattern in text for pattern in RECORDER_READY)
        if s.name == 'dam_state_publisher' and not ready.state_publisher:
            text = s.log.read_text(encoding='utf-8', errors='replace')
            ready.state_publisher = any(pattern in text for pattern in STATE_PUBLISHER_READY)
        return bool(lines)

    def report(self, ready: Readiness) -> list[str]:
        """One line per node not ready: how long it has run, its CPU time, what it lacks."""
        now = boot_time_s()
        out = []
        for s in self.started:
            if s.ready_s is not None:
                continue
            cpu = f'CPU {s.cpu_s:.1f} s'
            if s.child_cpu_s:
                cpu += f' (+ {s.child_cpu_s:.1f} s its children)'
            what = 'no log line yet' if s.first_line_s is None else \
                '; '.join(ready.missing_of(s.name))
            out.append(f'    {s.name}: up {s.age(now):.0f} s, {cpu}: {what}')
        return out


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
                self.ready.driver_states.add(self.ready.driver_state)
                self.ready.driver_message = status.message

    def graph(self) -> set[str]:
        """The names of the nodes, topics and services this node has discovered."""
        node = self.node
        return ({f'node {ns.rstrip("/")}/{n}' for n, ns in node.get_node_names_and_namespaces()}
                | {f'topic {t}' for t, _ in node.get_topic_names_and_types()}
                | {f'service {s}' for s, _ in node.get_service_names_and_types()})

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


def _dead(started: list[Started], who: str) -> bool:
    """Report every started process that exited (its fatal lines); ``True`` if one did."""
    dead = [s for s in started if process_exited(s.pid)]
    for s in dead:
        print(f'{who}: {s.name} (PID {s.pid}) exited while starting; its log {s.log}:',
              file=sys.stderr)
        for line in fatal_lines(s.log) or ['(empty)']:
            print(f'  {line}', file=sys.stderr)
    return bool(dead)


def _done_line(s: Started, ready: Readiness) -> str:
    done = {'check_lift_server': '/check_lift answers',
            'spcm_controller': '/dam_grasp action server ready',
            'hand_driver': f'/joint_states published, driver {ready.driver_message}',
            'recorder': 'records /dam/episode and /joint_states',
            'dam_state_publisher': 'publishes /tf and /tf_static'}[s.name]
    when = ''
    if s.start_s is not None and s.ready_s is not None:
        first = ('no log line yet' if s.first_line_s is None else
                 f'first log line after {s.first_line_s - s.start_s:.1f} s')
        when = f' after {s.ready_s - s.start_s:.1f} s ({first}, CPU {s.cpu_s:.1f} s)'
    return f'    ready: {s.name} (PID {s.pid}){when}: {done}'


def main(argv: list[str] | None = None) -> int:
    """Wait for the nodes; see the module docstring. Returns the exit status."""
    parser = argparse.ArgumentParser(prog='wait_ready', description=__doc__.splitlines()[0])
    parser.add_argument('nodes', nargs='+', metavar='NODE=PID:LOG')
    parser.add_argument('--timeout', type=seconds_or_none, default=None, metavar='S',
                        help='give up after this long [s] (default none: wait while the '
                             'nodes progress)')
    parser.add_argument('--stall', type=positive_seconds, default=DEFAULT_STALL_S,
                        metavar='S', help='give up when nothing progressed for this long [s] '
                                          f'(default {DEFAULT_STALL_S:g})')
    parser.add_argument('--report', type=positive_seconds, default=DEFAULT_REPORT_S,
                        metavar='S', help='say what each node still waits for every S seconds '
                                          f'(default {DEFAULT_REPORT_S:g})')
    parser.add_argument('--who', default='wait_ready',
                        help='the name the error lines start with')
    try:
        args = parser.parse_args(argv)
        started = [parse_node(text) for text in args.nodes]
    except SystemExit as exc:
        return 0 if exc.code == 0 else 3
    except ValueError as exc:
        print(f'{parser.prog}: {exc}', file=sys.stderr)
        return 3
    names = [s.name for s in started]
    t0 = time.monotonic()
    progress = Progress(started)
    if _dead(started, args.who):  # before the watcher's imports: a node that died at once
        return 1
    watcher = Watcher(names)
    next_look = time.monotonic()
    next_report = t0 + args.report
    try:
        while True:
            now = time.monotonic()
            if now >= next_look:
                next_look = now + _LOOK_S
                if _dead(started, args.who):
                    return 1
                progress.look(watcher.ready, watcher.graph())
                missing = watcher.ready.missing(names)
                if not missing:
                    break
                why = ''
                if args.timeout is not None and now - t0 >= args.timeout:
                    why = f'not ready after {args.timeout:g} s (--timeout)'
                elif boot_time_s() - progress.last_s >= args.stall:
                    why = (f'nothing progressed for {args.stall:g} s (no log line, no CPU '
                           f'time of a starting node, no new node, topic or service)')
                if why:
                    print(f'{args.who}: {why}: {"; ".join(missing)}', file=sys.stderr)
                    for line in progress.report(watcher.ready):
                        print(line, file=sys.stderr)
                    for note in watcher.ready.notes[-3:]:
                        print(f'  {note}', file=sys.stderr)
                    return 2
                if now >= next_report:
                    next_report = now + args.report
                    print(f'    still waiting after {now - t0:.0f} s:', flush=True)
                    for line in progress.report(watcher.ready):
                        print(line, flush=True)
            watcher.step()
    finally:
        watcher.close()
    for s in started:
        print(_done_line(s, watcher.ready))
    print(f'    every node ready after {time.monotonic() - t0:.1f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
