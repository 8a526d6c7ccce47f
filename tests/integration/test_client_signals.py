"""Every command-line client stops cleanly on SIGINT or SIGTERM at any moment.

``check_lift`` and ``plan_lift`` (exit status 3 when stopped before an answer) and
``dam_grasp`` (3: stopped, or any outcome but SUCCESS) are started with no server to answer
them, so that they wait; a signal drawn at random (SIGINT or SIGTERM) is sent at a random
moment from the time the process has its handlers in place (``SigCgt`` in /proc; before
that Python itself owns the signals) until well into the wait: while it imports rclpy, parses
its arguments, creates its node and waits for the server. Required: the documented status, no
traceback, the exit within 2 s of the signal.
"""

from __future__ import annotations

import os
import random
import signal
import subprocess
import tempfile
import time
from dataclasses import dataclass

import pytest

from ros_testing import installed_executable, wait_for_signal_handlers

pytestmark = [pytest.mark.integration]

#: Trials per client: one in each of TRIALS equal slices of [0, LATEST_S], at a random moment
#: of its slice (the start-up and the wait are both hit by construction; ten uniform draws
#: took 18 s per client and covered no more).
TRIALS = 6
EXIT_WITHIN_S = 2.0
#: Latest moment of a signal after the handlers are in place [s]: past the start-up (about a
#: second on a quiet machine), inside the wait for the server (10 s by default).
LATEST_S = 3.0
SIGNALS = (signal.SIGINT, signal.SIGTERM)
#: The clients with no server, and their documented status when a signal stops them.
CLIENTS = {
    'check_lift': (['dam_analysis', 'check_lift'], ['--k-theta', '7'], 3),
    'plan_lift': (['dam_analysis', 'plan_lift'], ['--mass', '0.03:0.05'], 3),
    'dam_grasp': (['dam_spcm_controller', 'dam_grasp'], ['--k-theta', '7'], 3),
}


@dataclass
class Trial:
    """One start-signal-exit cycle."""

    signal_name: str
    delay_s: float
    returncode: int | None
    exit_s: float
    output: str

    def problem(self, expected: int) -> str:
        """Empty when the trial was clean, else what went wrong."""
        if self.returncode is None:
            return f'still running {self.exit_s:.1f} s after {self.signal_name}'
        if self.returncode != expected:
            return f'exit status {self.returncode}, expected {expected}'
        if 'Traceback' in self.output:
            return 'traceback'
        if self.exit_s > EXIT_WITHIN_S:
            return f'exit took {self.exit_s:.2f} s'
        return ''


def run_trial(command: list[str], delay_s: float, signum: signal.Signals) -> Trial:
    """Start ``command``, signal it ``delay_s`` after its SIGTERM handler is in place."""
    env = dict(os.environ, PYTHONUNBUFFERED='1')
    with tempfile.TemporaryFile(mode='w+') as log:
        proc = subprocess.Popen(command, stdout=log, stderr=subprocess.STDOUT, env=env,
                                stdin=subprocess.DEVNULL)
        try:
            wait_for_signal_handlers(proc)
            time.sleep(delay_s)
            t_signal = time.monotonic()
            proc.send_signal(signum)
            try:
                proc.wait(timeout=10.0)
            except subprocess.TimeoutExpired:
                pass
            exit_s = time.monotonic() - t_signal
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        log.seek(0)
        return Trial(signum.name, delay_s, proc.returncode, exit_s, log.read())


@pytest.mark.parametrize('name', sorted(CLIENTS))
def test_a_client_waiting_for_its_server_stops_cleanly_at_any_moment(name: str) -> None:
    (package, exe), args, expected = CLIENTS[name]
    command = [str(installed_executable(package, exe)), *args]
    rng = random.Random(name)
    slice_s = LATEST_S / TRIALS
    trials = [run_trial(command, (i + rng.random()) * slice_s, rng.choice(SIGNALS))
              for i in range(TRIALS)]
    bad = [(t, t.problem(expected)) for t in trials if t.problem(expected)]
    detail = '\n'.join(f'- {t.signal_name} after {t.delay_s:.3f} s: {why}\n{t.output[-1500:]}'
                       for t, why in bad[:3])
    assert not bad, f'{len(bad)} of {len(trials)} trials not clean:\n{detail}'
    # The signals fell in the start-up and in the wait for the server alike.
    assert min(t.delay_s for t in trials) < 0.5 < 2.0 < max(t.delay_s for t in trials)
