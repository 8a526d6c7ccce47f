"""One sweep at a time in a sweep directory: an exclusive lock on ``DIR/.sweep.lock``.

Two sweeps writing one directory would rename each other's ``sweep.json.tmp`` away and run
the same trials twice. The first takes an exclusive ``flock`` on the lock file and writes who
it is (PID, host, start time, command line) into it; a second finds the lock taken and is
refused with that description. The kernel drops the lock when the process ends, however it
ends, so a sweep that was killed leaves no stale lock: its description stays in the file
until the next sweep takes the lock and writes its own.
"""

from __future__ import annotations

import datetime
import fcntl
import os
import shlex
import socket
import sys
from pathlib import Path

from dam_experiments.errors import SweepError

#: The lock file, inside the sweep directory.
LOCK_FILE = '.sweep.lock'


class SweepLocked(SweepError):
    """Another sweep holds the directory; the message names it."""


class SweepLock:
    """The exclusive lock of one sweep directory (:meth:`acquire`, then :meth:`release`)."""

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self.path = Path(directory) / LOCK_FILE
        self._fd: int | None = None

    def acquire(self) -> None:
        """Take the lock and write this sweep's description into it.

        Raises
        ------
        SweepLocked
            Another process holds it: its PID, host, start and command line are named.
        OSError
            The lock file cannot be created.
        """
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = os.pread(fd, 4096, 0).decode('utf-8', 'replace').strip()
            os.close(fd)
            raise SweepLocked(
                f'{self.path.parent} is being written by another sweep '
                f'({holder or "its description not written yet"}); wait for it to finish or '
                f'stop it, or use another --out') from None
        except BaseException:
            os.close(fd)
            raise
        started = datetime.datetime.now().astimezone().isoformat(timespec='seconds')
        who = (f'PID {os.getpid()} on {socket.gethostname()}, started {started}: '
               f'{shlex.join([Path(sys.argv[0]).name, *sys.argv[1:]])}')
        os.ftruncate(fd, 0)
        os.pwrite(fd, (who + '\n').encode('utf-8'), 0)
        self._fd = fd

    def release(self) -> None:
        """Give the lock back (idempotent); the description stays for the record."""
        fd, self._fd = self._fd, None
        if fd is not None:
            fcntl.flock(fd, fcntl.LOCK_UN)
            os.close(fd)
