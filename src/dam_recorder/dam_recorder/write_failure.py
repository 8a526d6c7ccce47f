"""A bag that can no longer be written: what failed, where, and with which errno (no rclpy).

The first error writing a bag (a full file system, one made read-only, the bag directory
removed, an I/O error) ends its recording: :class:`~dam_recorder.bag_writer.BagWriter` stops
writing, closes what it can with what is on disk, counts every message it could not write and
raises :class:`~dam_recorder.errors.BagWriteError` once with a :class:`WriteFailure`. The
recorder logs that one error and ends with :data:`WRITE_ERROR_STATUS`.

``sqlite3`` errors carry no errno (``database or disk is full``); :func:`failure_from` then
asks the file system what is wrong (the directory gone, mounted read-only, no free block) and
falls back on the SQLite error code.
"""

from __future__ import annotations

import errno
import os
import sqlite3
from dataclasses import dataclass
from pathlib import Path

#: Exit status of a recorder whose bag could not be written (``sysexits.h``'s ``EX_IOERR``).
WRITE_ERROR_STATUS = 74

#: errno of a SQLite primary result code, where the file system does not tell.
_SQLITE_ERRNO = {'SQLITE_FULL': errno.ENOSPC, 'SQLITE_READONLY': errno.EROFS,
                 'SQLITE_CANTOPEN': errno.ENOENT, 'SQLITE_PERM': errno.EACCES,
                 'SQLITE_IOERR': errno.EIO}


@dataclass(frozen=True)
class WriteFailure:
    """The first write error of a bag.

    Attributes
    ----------
    bag_dir : Path
        The bag directory.
    path : Path
        The file that could not be written (a storage file or ``metadata.yaml``).
    errno : int
        The error number (``errno.ENOSPC``, ...).
    detail : str
        The error as the system or SQLite said it.
    """

    bag_dir: Path
    path: Path
    errno: int
    detail: str

    @property
    def errno_name(self) -> str:
        """``ENOSPC``, ``EROFS``, ... (``errno <n>`` for a number without a name)."""
        return errno.errorcode.get(self.errno, f'errno {self.errno}')

    def describe(self) -> str:
        """One sentence naming the bag, the file and the errno."""
        reason = os.strerror(self.errno)
        said = '' if self.detail in ('', reason) else f'; {self.detail}'
        return (f'cannot write the bag {self.bag_dir}: {self.path.name}: {self.errno_name} '
                f'({reason}{said})')


def _probe_errno(directory: Path) -> int | None:
    """What the file system says is wrong with ``directory`` (None: nothing found)."""
    try:
        stat = os.statvfs(directory)
    except FileNotFoundError:
        return errno.ENOENT
    except OSError as exc:
        return exc.errno
    if stat.f_flag & os.ST_RDONLY:
        return errno.EROFS
    if stat.f_bavail == 0:
        return errno.ENOSPC
    if not os.access(directory, os.W_OK):
        return errno.EACCES
    return None


def failure_from(exc: BaseException, bag_dir: Path, path: Path) -> WriteFailure:
    """The :class:`WriteFailure` of ``exc`` (an ``OSError`` or a ``sqlite3.Error``) raised
    while writing ``path`` of the bag ``bag_dir``."""
    if isinstance(exc, OSError) and exc.errno:
        return WriteFailure(bag_dir, Path(exc.filename or path) if isinstance(
            exc.filename, str) else path, exc.errno, exc.strerror or str(exc))
    code = getattr(exc, 'sqlite_errorname', '') if isinstance(exc, sqlite3.Error) else ''
    number = _probe_errno(bag_dir)
    if number is None:
        number = next((n for name, n in _SQLITE_ERRNO.items() if code.startswith(name)),
                      errno.EIO)
    return WriteFailure(bag_dir, path, number, f'{code}: {exc}' if code else str(exc))


def vanished(bag_dir: Path, path: Path) -> WriteFailure | None:
    """A failure when the file ``path`` (or the bag directory) is gone: data written to an
    open file of a removed directory lands nowhere anyone can read."""
    try:
        os.stat(path)
    except FileNotFoundError:
        gone = path if bag_dir.is_dir() else bag_dir
        return WriteFailure(bag_dir, path, errno.ENOENT, f'{gone} was removed while recording')
    except OSError as exc:
        return failure_from(exc, bag_dir, path)
    return None
