"""ShutdownRequest: a signal interrupts a start-up once, and only records a stop request later."""

from __future__ import annotations

import signal
import subprocess
import sys
import textwrap
from collections.abc import Iterator

import pytest

from dam_common.shutdown import STOP_SIGNALS, ShutdownRequest, StartupInterrupted


@pytest.fixture
def restore_handlers() -> Iterator[None]:
    saved = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)


@pytest.mark.parametrize('signum', STOP_SIGNALS)
def test_a_signal_while_running_only_records_the_request(restore_handlers, signum) -> None:
    request = ShutdownRequest()
    assert request.install()
    assert not request.requested and request.signal_name == ''
    signal.raise_signal(signum)  # no exception
    assert request.requested and request.signal_name == signum.name
    assert request.wait(0.0)


def test_the_first_signal_interrupts_a_start_up_and_only_the_first(restore_handlers) -> None:
    request = ShutdownRequest()
    request.install(interrupt_startup=True)
    assert request.interrupting
    with pytest.raises(StartupInterrupted, match='SIGTERM'):
        signal.raise_signal(signal.SIGTERM)
    assert request.requested and not request.interrupting
    signal.raise_signal(signal.SIGINT)  # a second signal: recorded, never raised
    assert request.signal_name == 'SIGTERM'  # the first one is reported
    with pytest.raises(StartupInterrupted):
        request.raise_if_requested()


def test_started_ends_the_interrupting(restore_handlers) -> None:
    request = ShutdownRequest()
    request.install(interrupt_startup=True)
    request.started()
    signal.raise_signal(signal.SIGINT)
    assert request.requested


def test_an_uninterrupted_step_finishes_then_raises(restore_handlers) -> None:
    request = ShutdownRequest()
    request.install(interrupt_startup=True)
    done = []
    with pytest.raises(StartupInterrupted):
        with request.uninterrupted():
            signal.raise_signal(signal.SIGINT)
            done.append('the step ran to its end')
    assert done == ['the step ran to its end']
    # without a signal the step is transparent and the start-up stays interruptible
    quiet = ShutdownRequest()
    quiet.install(interrupt_startup=True)
    with quiet.uninterrupted():
        pass
    assert quiet.interrupting and not quiet.requested


def test_an_interruptible_command_is_interrupted_then_the_handlers_come_back(
        restore_handlers) -> None:
    def before(signum: int, frame: object) -> None:
        raise AssertionError('the handler from before ran inside the command')

    for sig in STOP_SIGNALS:
        signal.signal(sig, before)
    request = ShutdownRequest()
    steps = []
    with pytest.raises(StartupInterrupted, match='SIGINT'):
        with request.interruptible() as inside:
            assert inside is request and request.interrupting
            steps.append('a step')
            signal.raise_signal(signal.SIGINT)
            steps.append('never reached')
    assert steps == ['a step']
    assert request.requested and not request.interrupting
    assert all(signal.getsignal(sig) is before for sig in STOP_SIGNALS)
    with pytest.raises(StartupInterrupted):
        request.raise_if_requested()
    # A second signal inside is only recorded; the first one is the one reported.
    second = ShutdownRequest()
    with pytest.raises(StartupInterrupted):
        with second.interruptible():
            try:
                signal.raise_signal(signal.SIGTERM)
            finally:
                signal.raise_signal(signal.SIGINT)  # the clean-up is not cut in two
    assert second.signal_name == 'SIGTERM'
    # Without a signal the command runs to its end and nothing is left installed.
    quiet = ShutdownRequest()
    with quiet.interruptible():
        pass
    assert not quiet.requested and not quiet.interrupting
    assert all(signal.getsignal(sig) is before for sig in STOP_SIGNALS)


def test_an_interruptible_command_keeps_a_request_s_own_installation(restore_handlers) -> None:
    """Inside a process whose request is installed already (a node's), the command is
    interrupted, and the request's handlers and its running state stay after."""
    request = ShutdownRequest()
    request.install()
    handlers = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    with request.interruptible():
        assert request.interrupting
    assert not request.interrupting
    assert {sig: signal.getsignal(sig) for sig in STOP_SIGNALS} == handlers
    signal.raise_signal(signal.SIGINT)  # recorded, not raised: the node runs
    assert request.requested


def test_an_interruptible_command_off_the_main_thread_installs_nothing() -> None:
    import threading

    handlers = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
    seen = []

    def command() -> None:
        request = ShutdownRequest()
        with request.interruptible() as inside:
            seen.append((inside is request, request.interrupting))

    thread = threading.Thread(target=command)
    thread.start()
    thread.join()
    assert seen == [(True, False)]
    assert {sig: signal.getsignal(sig) for sig in STOP_SIGNALS} == handlers


def test_handlers_are_only_installed_from_the_main_thread() -> None:
    import threading

    results = []
    thread = threading.Thread(target=lambda: results.append(ShutdownRequest().install()))
    thread.start()
    thread.join()
    assert results == [False]


def test_a_signal_during_the_import_of_a_node_module_exits_quietly(tmp_path) -> None:
    """run_node_entry: a module whose import is interrupted (here: it signals itself) ends the
    process with status 0 and prints nothing."""
    module = tmp_path / 'slow_node.py'
    module.write_text(textwrap.dedent('''
        import os
        import signal
        os.kill(os.getpid(), signal.SIGTERM)
        import time
        time.sleep(5)  # never reached: the signal interrupts the import

        def main():
            raise AssertionError('main must not run')
    '''))
    code = ('import sys; sys.path.insert(0, sys.argv[1]); '
            'from dam_common.shutdown import run_node_entry; run_node_entry("slow_node")')
    proc = subprocess.run([sys.executable, '-c', code, str(tmp_path)], capture_output=True,
                          text=True, timeout=30)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout == '' and proc.stderr == ''


def test_a_signal_inside_an_import_lock_callback_is_recorded_not_raised() -> None:
    """An exception raised in the import machinery's weak-reference callback is only reported
    ("Exception ignored", with a traceback) and the interrupt would be lost: there the
    handler records the request and raises nothing; elsewhere it still raises."""
    import signal as signal_module

    from dam_common.shutdown import ShutdownRequest, StartupInterrupted

    namespace: dict = {}
    exec(compile('def cb():\n    import sys\n    return sys._getframe()\n',  # noqa: S102
                 '<frozen importlib._bootstrap>', 'exec'), namespace)
    import_frame = namespace['cb']()
    request = ShutdownRequest()
    request._interrupt = True  # noqa: SLF001 - starting, as install(interrupt_startup=True)
    request._on_signal(signal_module.SIGTERM, import_frame)  # noqa: SLF001
    assert request.requested and request.signal_name == 'SIGTERM'
    with pytest.raises(StartupInterrupted):
        request.raise_if_requested()  # the start-up's next check ends it
    other = ShutdownRequest()
    other._interrupt = True  # noqa: SLF001
    with pytest.raises(StartupInterrupted):
        other._on_signal(signal_module.SIGINT, sys._getframe())  # noqa: SLF001
