"""SIGINT and SIGTERM as a request to stop, honoured at any moment of a node's life (no rclpy).

An executable catches both signals from its first line (:func:`catch_signals`, called by the
package's entry point before the heavy imports). A signal then only records the request; the
node's code looks at it where it can stop cleanly: :func:`~dam_common.node.run_node` between
callbacks, long start-up waits through :meth:`ShutdownRequest.raise_if_requested`. Nothing is
interrupted half-way, so nothing is left half-done: no traceback, no thread publishing on a
context that is gone.
"""

from __future__ import annotations

import signal
import threading
from types import FrameType

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

    def install(self) -> bool:
        """Handle SIGINT and SIGTERM by recording the request (idempotent).

        Returns
        -------
        bool
            ``False`` where handlers cannot be installed (not the main thread of the main
            interpreter): the signals keep their previous handling.
        """
        if self._installed:
            return True
        if threading.current_thread() is not threading.main_thread():
            return False
        for sig in STOP_SIGNALS:
            signal.signal(sig, self._on_signal)
        self._installed = True
        return True

    def _on_signal(self, signum: int, _frame: FrameType | None) -> None:
        self.request(signum)


#: The one request of this process.
SHUTDOWN = ShutdownRequest()


def catch_signals() -> ShutdownRequest:
    """Install the handlers of :data:`SHUTDOWN` (from the main thread) and return it."""
    SHUTDOWN.install()
    return SHUTDOWN
