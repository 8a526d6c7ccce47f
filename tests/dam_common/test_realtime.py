"""Real-time scheduling of a thread: the policy is really set (or the refusal explained), and
what the thread starts does or does not inherit it (no ROS)."""

from __future__ import annotations

import os
import threading

import pytest

from dam_common.realtime import reduce_timer_slack, set_thread_priority

_RESET_ON_FORK = getattr(os, 'SCHED_RESET_ON_FORK', 0)
pytestmark = pytest.mark.skipif(not hasattr(os, 'sched_getscheduler'),
                                reason='POSIX scheduling interface missing')


def _policy() -> tuple[int, int]:
    """(policy without the reset-on-fork flag, priority) of the calling thread."""
    return os.sched_getscheduler(0) & ~_RESET_ON_FORK, os.sched_getparam(0).sched_priority


def _in_thread(body) -> dict:
    """Run ``body(out)`` in a fresh thread (the test process keeps its policy)."""
    out: dict = {}
    thread = threading.Thread(target=body, args=(out,))
    thread.start()
    thread.join(timeout=10.0)
    return out


@pytest.mark.parametrize('bad', [-1, 100, 1.5, True, '50', None])
def test_bad_priorities_are_refused_by_name(bad) -> None:
    with pytest.raises(ValueError, match=repr(bad).replace('.', r'\.')):
        set_thread_priority(bad)


def test_zero_leaves_the_thread_alone() -> None:
    def body(out: dict) -> None:
        before = _policy()
        out['result'] = set_thread_priority(0)
        out['same'] = _policy() == before

    out = _in_thread(body)
    assert out == {'result': None, 'same': True}


@pytest.mark.parametrize('inherit', [False, True])
def test_fifo_is_set_or_the_refusal_explained(inherit: bool) -> None:
    def body(out: dict) -> None:
        out['result'] = set_thread_priority(7, inherit=inherit)
        out['self'] = _policy()
        child: dict = {}

        def grandchild() -> None:
            child['policy'] = _policy()

        t = threading.Thread(target=grandchild)
        t.start()
        t.join()
        out['child'] = child['policy']

    out = _in_thread(body)
    if out['result'] is not None:  # no permission here: say why, change nothing
        assert 'refused' in out['result'] or 'not available' in out['result']
        assert out['self'][0] == os.SCHED_OTHER
        pytest.skip(out['result'])
    assert out['self'] == (os.SCHED_FIFO, 7)
    if inherit:
        assert out['child'] == (os.SCHED_FIFO, 7)
    else:
        assert out['child'][0] == os.SCHED_OTHER  # threads it starts get the normal policy


def test_timer_slack_is_set_on_linux() -> None:
    result = reduce_timer_slack()
    assert result is (os.uname().sysname == 'Linux')


_PROCESS_PROBE = """
import os, threading, time
from dam_common.realtime import set_process_priority
stop = threading.Event()
workers = [threading.Thread(target=stop.wait) for _ in range(2)]
for w in workers:
    w.start()
result = set_process_priority(6)
policies = sorted({(os.sched_getscheduler(int(t)), os.sched_getparam(int(t)).sched_priority)
                   for t in os.listdir('/proc/self/task')})
stop.set()
print(repr(result))
print(policies)
"""


@pytest.mark.skipif(not os.path.isdir('/proc/self/task'), reason='reads /proc')
def test_process_priority_reaches_every_thread() -> None:
    import subprocess
    import sys

    proc = subprocess.run([sys.executable, '-c', _PROCESS_PROBE], capture_output=True,
                          text=True, timeout=30, check=True)
    result, policies = proc.stdout.strip().splitlines()
    if result != 'None':  # no permission here
        assert 'refused' in result
        pytest.skip(result)
    assert policies == repr([(os.SCHED_FIFO, 6)])  # main thread and both workers
