"""Helpers for integration tests that run real ROS 2 processes over DDS.

Processes are started from the installed workspace (``ros2_ws/install/<pkg>/lib/<pkg>/<exe>``,
what ``ros2 run`` runs) or from a test fixture script, inherit the test's environment (and so its
``ROS_DOMAIN_ID``), and are stopped by their own PID: SIGINT first, SIGKILL if they hang.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
import uuid
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path
from typing import Any

REPO_ROOT = Path(__file__).resolve().parents[1]
INSTALL_DIR = REPO_ROOT / 'ros2_ws' / 'install'
FIXTURES_DIR = Path(__file__).resolve().parent / 'fixtures'


def installed_executable(package: str, executable: str) -> Path:
    """Path of an executable as ``ros2 run <package> <executable>`` would find it."""
    return INSTALL_DIR / package / 'lib' / package / executable


class NodeProcess:
    """A ROS 2 process under test: started with a command, its output captured to a file."""

    def __init__(self, command: Sequence[str | os.PathLike[str]],
                 env: dict[str, str] | None = None) -> None:
        self.command = [str(c) for c in command]
        self._log = tempfile.NamedTemporaryFile(prefix='dam-node-', suffix='.log', delete=False)
        full_env = dict(os.environ)
        full_env.setdefault('PYTHONUNBUFFERED', '1')
        if env:
            full_env.update(env)
        self.process = subprocess.Popen(
            self.command, stdout=self._log, stderr=subprocess.STDOUT, env=full_env,
            stdin=subprocess.DEVNULL)

    @property
    def pid(self) -> int:
        return self.process.pid

    def output(self) -> str:
        """Everything the process printed so far."""
        if not self._log.closed:
            self._log.flush()
        return Path(self._log.name).read_text(encoding='utf-8', errors='replace')

    def alive(self) -> bool:
        return self.process.poll() is None

    def stop(self, timeout: float = 10.0) -> int:
        """Stop the process by its PID (SIGINT, then SIGKILL after ``timeout``); return code."""
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout=timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout=timeout)
        self._log.close()
        return self.process.returncode

    def cleanup(self) -> None:
        self.stop()
        try:
            os.unlink(self._log.name)
        except OSError:
            pass


@contextmanager
def node_process(command: Sequence[str | os.PathLike[str]],
                 env: dict[str, str] | None = None) -> Iterator[NodeProcess]:
    """Run a process for the duration of a ``with`` block; on failure its output is shown."""
    proc = NodeProcess(command, env)
    try:
        yield proc
    except BaseException:
        proc.stop()
        sys.stderr.write(f'--- output of {proc.command} ---\n{proc.output()}\n')
        raise
    finally:
        proc.cleanup()


@contextmanager
def cpu_burners(n: int = 2) -> Iterator[list[subprocess.Popen[bytes]]]:
    """``n`` processes that each keep a core busy (what a browser or another CI job does to
    the suite), for the duration of a ``with`` block; stopped by their PID."""
    procs = [subprocess.Popen([sys.executable, '-c', 'while True: pass'],
                              stdin=subprocess.DEVNULL) for _ in range(n)]
    try:
        yield procs
    finally:
        for proc in procs:
            proc.kill()
            proc.wait(timeout=10.0)


def free_udp_ports(n: int) -> list[int]:
    """``n`` distinct UDP ports on 127.0.0.1 that were free a moment ago (for device links)."""
    socks = [socket.socket(socket.AF_INET, socket.SOCK_DGRAM) for _ in range(n)]
    try:
        for sock in socks:
            sock.bind(('127.0.0.1', 0))
        return [sock.getsockname()[1] for sock in socks]
    finally:
        for sock in socks:
            sock.close()


def config_with_free_ports(directory: str | os.PathLike[str]) -> Path:
    """The repository's config/dam.yaml with a device link on free UDP ports, written into
    ``directory``: a driver or stand-in started with it meets no other run's device."""
    import yaml

    data = yaml.safe_load((REPO_ROOT / 'config' / 'dam.yaml').read_text(encoding='utf-8'))
    data['device']['state_port'], data['device']['command_port'] = free_udp_ports(2)
    path = Path(directory) / 'dam.yaml'
    path.write_text(yaml.safe_dump(data), encoding='utf-8')
    return path


def caught_signals(pid: int) -> set[int]:
    """Signal numbers process ``pid`` has handlers for (``SigCgt`` of /proc/PID/status)."""
    for line in Path(f'/proc/{pid}/status').read_text(encoding='ascii').splitlines():
        if line.startswith('SigCgt:'):
            mask = int(line.split()[1], 16)
            return {n for n in range(1, 65) if mask & (1 << (n - 1))}
    return set()


def wait_for_signal_handlers(proc: subprocess.Popen, timeout_s: float = 20.0) -> None:
    """Return once ``proc`` handles SIGTERM (its entry point's first lines have run); a
    signal sent earlier is the interpreter's to handle, not the program's.

    Raises AssertionError when ``proc`` exits first or ``timeout_s`` [s] passes.
    """
    give_up = time.monotonic() + timeout_s
    while signal.SIGTERM not in caught_signals(proc.pid):
        assert proc.poll() is None, 'the program exited before installing its handlers'
        assert time.monotonic() < give_up, 'no SIGTERM handler installed'
        time.sleep(0.002)


def stop_with_signal(proc: subprocess.Popen, signum: int, timeout_s: float = 60.0
                     ) -> tuple[str, str]:
    """Send ``signum`` to ``proc`` (by its PID) and return its output; killed if it does not
    end within ``timeout_s`` (then ``communicate`` raises ``TimeoutExpired``)."""
    try:
        proc.send_signal(signum)
        return proc.communicate(timeout=timeout_s)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def child_pids(pid: int) -> list[int]:
    """PIDs of the direct children of process ``pid`` (from /proc; empty once it is gone)."""
    out: list[int] = []
    try:
        for task in Path(f'/proc/{pid}/task').iterdir():
            out += [int(c) for c in (task / 'children').read_text().split()]
    except (FileNotFoundError, ProcessLookupError):
        pass
    return out


def _proc_stat(path: str | os.PathLike[str]) -> list[str]:
    """The fields of a /proc ``stat`` file after the command name (field 3 onwards)."""
    return Path(path).read_text(encoding='ascii').rsplit(')', 1)[1].split()


def thread_policies(pid: int) -> list[tuple[int, int]]:
    """(scheduling policy, real-time priority) of every thread of process ``pid``, from /proc
    (policy 0: normal, 1: SCHED_FIFO)."""
    out = []
    for task in Path(f'/proc/{pid}/task').iterdir():
        fields = _proc_stat(task / 'stat')
        out.append((int(fields[38]), int(fields[37])))  # stat fields 41 and 40
    return out


def process_gone(pid: int) -> bool:
    """The process has exited (no such process, or a zombie nobody reaped yet)."""
    try:
        return _proc_stat(f'/proc/{pid}/stat')[0] in ('Z', 'X')
    except FileNotFoundError:
        return True


def fixture_command(script: str, *args: str) -> list[str]:
    """Command that runs a test fixture script from tests/fixtures with this interpreter."""
    return [sys.executable, str(FIXTURES_DIR / script), *args]


class RosClient:
    """A client node in its own rclpy context with a single-threaded executor."""

    def __init__(self) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor

        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(f'dam_test_{uuid.uuid4().hex[:8]}', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)

    def call(self, srv_type: Any, name: str, request: Any, timeout: float = 10.0,
             wait: float = 30.0) -> Any:
        """Call a service and return its response; raise AssertionError on time-out."""
        client = self.node.create_client(srv_type, name)
        try:
            if not client.wait_for_service(timeout_sec=wait):
                raise AssertionError(f'service {name} did not appear within {wait} s')
            future = client.call_async(request)
            if not self.wait_future(future, timeout):
                raise AssertionError(f'service {name} did not answer within {timeout} s')
            return future.result()
        finally:
            self.node.destroy_client(client)

    def wait_future(self, future: Any, timeout: float) -> bool:
        """Spin until ``future`` is done or ``timeout`` seconds pass; return whether it is done.

        A plain ``spin_once`` loop: rclpy's ``spin_until_future_complete`` with a time-out adds
        about a millisecond per call, which dominates service round trips.
        """
        deadline = time.monotonic() + timeout
        while not future.done():
            remaining = deadline - time.monotonic()
            if remaining <= 0.0:
                return False
            self.executor.spin_once(timeout_sec=min(remaining, 0.1))
        return True

    def spin_until(self, predicate: Callable[[], bool], timeout: float) -> bool:
        """Spin until ``predicate()`` is true or ``timeout`` seconds pass; return the predicate."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=0.05)
        return predicate()

    def close(self) -> None:
        import rclpy

        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


class FakeStateDevice:
    """A device that sends valid state frames (every joint HOLD at 0, status bits ``status``:
    0 a hand, 2 the SIMULATED bit) to the configured state port every 2 ms for 6 s, or until
    :meth:`close`; it ignores commands."""

    def __init__(self, config: Path, status: int) -> None:
        import yaml

        from dam_common.device_protocol import JointMode, encode_state

        data = yaml.safe_load(config.read_text(encoding='utf-8'))
        n = 3 * len(data['hand']['joint_roles'])
        self._port = int(data['device']['state_port'])
        hold = [int(JointMode.HOLD)] * n
        self._frames = [encode_state(seq, seq * 2_000_000, [0] * n, [0] * n, [0] * n, hold,
                                     status=status) for seq in range(1, 3001)]
        self._stop = threading.Event()
        self._sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _run(self) -> None:
        for frame in self._frames:
            if self._stop.wait(0.002):
                return
            self._sock.sendto(frame, ('127.0.0.1', self._port))

    def close(self) -> None:
        self._stop.set()
        self._thread.join()
        self._sock.close()
