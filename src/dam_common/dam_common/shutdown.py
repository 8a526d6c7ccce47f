"""SIGINT and SIGTERM as a request to stop, honoured at any moment of a node's life (no rclpy).

A node's executable catches both signals from its first line (:func:`run_node_entry`, the
package's entry point, before the heavy imports). What a signal does then depends on the
moment:

- while the node starts (imports, building the node: seconds on a loaded machine), the first
  signal raises :class:`StartupInterrupted` wherever the interpreter is, like
  ``KeyboardInterrupt``; :func:`~dam_common.node.run_node` and the node's own constructor clean
  up what was started and the process exits with status 0;
- once it runs, a signal only records the request; :func:`~dam_common.node.run_node` looks at
  it between two callbacks, so no callback is interrupted half-way and no thread publishes on a
  context that is gone.

A command-line client (``check_lift``, ``plan_lift``) follows the same rules through
:func:`run_client_entry`: interrupted at once while it imports and parses its arguments, then
(once it calls :meth:`ShutdownRequest.started`, before it creates its ROS context) it looks at
the request in each of its waits, cleans up, and exits with its documented status for a stop.
A command that a signal stops at any moment of its work (``dynamixel_setup``: short bus
transactions, the port closed in ``finally``) runs within :meth:`ShutdownRequest.interruptible`,
which gives the signals their previous handling back at its end.
"""

from __future__ import annotations

import importlib
import signal
import sys
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from types import FrameType

from dam_common.closed_output import quiet_when_output_closed

#: The signals that ask a node to stop.
STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM)


class StartupInterrupted(BaseException):  # noqa: N818 - like KeyboardInterrupt
    """A stop was requested while the node was still starting (raised by
    :meth:`ShutdownRequest.raise_if_requested`; :func:`~dam_common.node.run_node` ends the
    process with status 0 on it)."""


class ShutdownRequest:
    """Whether, and by which signal, this process was asked to stop."""

    def __init__(self) -> None:
        self._event = threading.Event()
        self._signal: signal.Signals | None = None
        self._installed = False
        self._interrupt = False  # a signal raises StartupInterrupted (once)

    @property
    def requested(self) -> bool:
        """``True`` once SIGINT or SIGTERM arrived (or :meth:`request` was called)."""
        return self._event.is_set()

    @property
    def signal_name(self) -> str:
        """Name of the first signal received (``''`` if none)."""
        return self._signal.name if self._signal is not None else ''

    def request(self, signum: int | None = None) -> None:
        """Record a stop request (what the signal handler does)."""
        if self._signal is None and signum is not None:
            self._signal = signal.Signals(signum)
        self._event.set()

    def wait(self, timeout_s: float) -> bool:
        """Sleep up to ``timeout_s`` [s], waking at once on a stop request; ``True`` if one
        came."""
        return self._event.wait(timeout_s)

    def raise_if_requested(self) -> None:
        """For long start-up steps: raise :class:`StartupInterrupted` after a stop request."""
        if self._event.is_set():
            raise StartupInterrupted(self.signal_name)

    @property
    def interrupting(self) -> bool:
        """True while a signal raises :class:`StartupInterrupted` (the node is starting)."""
        return self._interrupt

    @contextmanager
    def uninterrupted(self) -> Iterator[None]:
        """A start-up step that must not be cut in two (e.g. creating an object whose
        destructor cannot cope with a half-built one): a signal meanwhile only records the
        request, and :class:`StartupInterrupted` is raised once the step is done."""
        interrupting = self._interrupt
        self._interrupt = False
        try:
            yield
        finally:
            self._interrupt = interrupting and not self._event.is_set()
        if interrupting and self._event.is_set():
            raise StartupInterrupted(self.signal_name)

    def started(self) -> None:
        """From now on a signal only records the request (the node runs)."""
        self._interrupt = False

    @contextmanager
    def interruptible(self) -> Iterator[ShutdownRequest]:
        """A command that a signal may stop at any moment of its work, not only while it
        starts (its steps are short and what it opened is closed in ``finally``).

        Within ``with``, SIGINT and SIGTERM are handled as after
        ``install(interrupt_startup=True)``: the first signal raises
        :class:`StartupInterrupted` where the interpreter is (or, where that exception
        would be lost, only records the request: :meth:`raise_if_requested` between two
        steps raises it), later ones are only recorded. On exit the handlers and the
        interrupting from before come back, so that a process can run the command more than
        once (its tests) and keep its own handling of the signals. From a thread other than
        the main one nothing is installed.
        """
        if threading.current_thread() is not threading.main_thread():
            yield self
            return
        previous = {sig: signal.getsignal(sig) for sig in STOP_SIGNALS}
        installed, interrupting = self._installed, self._interrupt
        try:
            self.install(interrupt_startup=True)
            yield self
        finally:
            self._interrupt = interrupting and not self._event.is_set()
            if not installed:
                for sig, handler in previous.items():
                    signal.signal(sig, handler)
                self._installed = False

    def install(self, interrupt_startup: bool = False) -> bool:
        """Handle SIGINT and SIGTERM by recording the request (idempotent); with
        ``interrupt_startup`` the first signal also raises :class:`StartupInterrupted` until
        :meth:`started`.

        Returns
        -------
        bool
            ``False`` where handlers cannot be installed (not the main thread of the main
            interpreter): the signals keep their previous handling.
        """
        if threading.current_thread() is not threading.main_thread():
            return False
        if interrupt_startup and not self._event.is_set():
            self._interrupt = True
        if self._installed:
            return True
        for sig in STOP_SIGNALS:
            signal.signal(sig, self._on_signal)
        self._installed = True
        return True

    def _on_signal(self, signum: int, frame: FrameType | None) -> None:
        first = not self._event.is_set()
        self.request(signum)
        if first and self._interrupt and not _swallows_exceptions(frame):
            self._interrupt = False
            raise StartupInterrupted(self.signal_name)


def _swallows_exceptions(frame: FrameType | None) -> bool:
    """The signal interrupted code whose exceptions the interpreter only reports ("Exception
    ignored in ...", with a traceback) instead of raising them on: a weak-reference callback of
    the import machinery (a module lock released during a garbage collection) or a
    finalizer. Raising there would lose the interrupt: the request is only recorded, and the
    start-up ends at its next check (``raise_if_requested``, or the spin loop at once)."""
    if frame is None:
        return False
    code = frame.f_code
    return (code.co_name == '__del__'
            or (code.co_name == 'cb' and code.co_filename.startswith('<frozen importlib')))


#: The one request of this process.
SHUTDOWN = ShutdownRequest()


def catch_signals(interrupt_startup: bool = False) -> ShutdownRequest:
    """Install the handlers of :data:`SHUTDOWN` (from the main thread) and return it."""
    SHUTDOWN.install(interrupt_startup)
    return SHUTDOWN


@quiet_when_output_closed
def run_node_entry(module: str, own_help: bool = False) -> None:
    """Entry point of a node executable: catch SIGINT and SIGTERM, then import ``module`` and
    call its ``main()`` (which runs :func:`~dam_common.node.run_node`). A signal during the
    import, or in ``main()`` before the node takes the signals over, ends the process quietly
    with status 0.

    ``-h`` or ``--help`` (outside ``--ros-args``) prints the node's usage, parameters and
    topics (:mod:`dam_common.node_help`) and exits with status 0 before anything of ROS
    starts, unless the node parses its own options (``own_help``: the recorder). A closed
    standard output ends it with status 141, no traceback (:mod:`dam_common.closed_output`)."""
    if not own_help:
        from dam_common.node_help import answer_help  # noqa: PLC0415 - no rclpy

        if answer_help(module):
            return
    catch_signals(interrupt_startup=True)
    try:
        main = importlib.import_module(module).main
    except StartupInterrupted:
        return
    except Exception:
        if SHUTDOWN.requested:
            return  # the interrupt surfaced as another error (a C extension's init wraps it)
        raise
    try:
        main()
    except StartupInterrupted:
        return  # before the node took the signals over (e.g. while parsing arguments)


@quiet_when_output_closed
def run_client_entry(module: str, interrupted_status: int) -> None:
    """Entry point of a command-line client: catch SIGINT and SIGTERM, import ``module``, call
    its ``main()`` and exit with the status it returns.

    ``main()`` calls :meth:`ShutdownRequest.started` on :data:`SHUTDOWN` before it creates
    anything of ROS (from then on a signal only records the request, and the client's waits
    end on it) and returns ``interrupted_status`` when a stop was requested. A signal during
    the import, or in ``main()`` before that (parsing the arguments), ends the process with
    ``interrupted_status`` at once; either way no traceback. A closed standard output (``|
    head``) ends it with status 141, no traceback (:mod:`dam_common.closed_output`).
    """
    catch_signals(interrupt_startup=True)
    try:
        try:
            try:
                main = importlib.import_module(module).main
            except Exception:
                if SHUTDOWN.requested:  # the interrupt surfaced as another error
                    raise StartupInterrupted(SHUTDOWN.signal_name) from None
                raise
            status = main()
        except SystemExit as exc:  # argparse: --help, or bad arguments
            SHUTDOWN.started()
            status = exc.code
    except StartupInterrupted:
        status = interrupted_status
    SHUTDOWN.started()  # a signal now only records the request
    sys.exit(status)
