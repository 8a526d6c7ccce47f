"""The output stream of an MCAP storage file: every byte written or an error, and a way back to
the last point known to be in the file (no rclpy).

``rosbags``' MCAP writer writes through a Python buffered file and ignores what ``write``
returns. On a file system that fills up a write can be short, and a buffered file keeps what it
failed to write and tries it again at the next write or flush, at an offset nobody knows.
:class:`StorageStream` stands in for that file: it collects what the writer writes in memory,
hands it to the operating system on :meth:`~StorageStream.flush` (every chunk the recorder
writes out) in full, retrying short writes, and raises the ``OSError`` otherwise. Whatever
happened, :attr:`~StorageStream.durable` is the length of the file up to which every byte is
in it, and :meth:`~StorageStream.rewind` cuts the file back to such a point (a truncation needs
no free space).
"""

from __future__ import annotations

import errno
import os
from pathlib import Path

#: Bytes collected before they are handed to the operating system without a flush.
BUFFER_BYTES = 1 << 20


class StorageStream:
    """A binary output file for ``rosbags``' ``McapWriter`` (``write``, ``tell``, ``flush``,
    ``close``).

    Parameters
    ----------
    path : path
        The file (for error messages).
    fd : int
        A file descriptor open for writing, positioned at ``position``; the stream owns it.
    position : int
        Bytes in the file before the stream's first write.
    """

    def __init__(self, path: str | os.PathLike[str], fd: int, position: int) -> None:
        self.path = Path(path)
        self._fd: int | None = fd
        self._buffer = bytearray()
        #: Bytes in the file: every one of them was written.
        self.durable = position

    @classmethod
    def replacing(cls, file: object, path: str | os.PathLike[str]) -> StorageStream:
        """A stream that continues the open Python file ``file`` (flushed, then closed)."""
        file.flush()  # type: ignore[attr-defined]
        position = file.tell()  # type: ignore[attr-defined]
        fd = os.dup(file.fileno())  # type: ignore[attr-defined]
        file.close()  # type: ignore[attr-defined]
        os.lseek(fd, position, os.SEEK_SET)
        return cls(path, fd, position)

    @property
    def closed(self) -> bool:
        """Whether the file descriptor was released."""
        return self._fd is None

    def write(self, data: bytes | bytearray | memoryview) -> int:
        """Collect ``data``; hand it over once :data:`BUFFER_BYTES` are collected."""
        self._buffer += data
        if len(self._buffer) >= BUFFER_BYTES:
            self.flush()
        return len(data)

    def tell(self) -> int:
        """The file's length once everything written is in it [bytes]."""
        return self.durable + len(self._buffer)

    def fileno(self) -> int:
        """The file descriptor.

        Raises
        ------
        OSError
            ``EBADF`` once it was released: a write after the file was closed is a write
            error like the others (the recorder stops, counts what it could not write).
        """
        if self._fd is None:
            raise OSError(errno.EBADF, f'{self.path.name} was already closed', str(self.path))
        return self._fd

    def flush(self) -> None:
        """Hand everything collected to the operating system.

        Raises
        ------
        OSError
            What the system said (``ENOSPC``, ``EROFS``, ``EIO``, ...), naming the file; what
            could not be written stays collected, :attr:`durable` counts what was.
        """
        view = memoryview(self._buffer)
        done = 0
        try:
            while done < len(view):
                try:
                    written = os.write(self.fileno(), view[done:])
                except OSError as exc:
                    raise OSError(exc.errno, exc.strerror, str(self.path)) from None
                if written == 0:
                    raise OSError(28, os.strerror(28), str(self.path))
                done += written
                self.durable += written
        finally:
            view.release()
            del self._buffer[:done]

    def rewind(self, position: int) -> None:
        """Drop what is collected and cut the file back to ``position`` bytes (a point at
        which everything before was in the file); write on from there."""
        self._buffer.clear()
        fd = self.fileno()
        os.ftruncate(fd, position)
        os.lseek(fd, position, os.SEEK_SET)
        self.durable = position

    def close(self) -> None:
        """Flush, then release the file descriptor (also when the flush raises)."""
        if self._fd is None:
            return
        try:
            self.flush()
        finally:
            self.release()

    def release(self) -> None:
        """Release the file descriptor without writing what is collected."""
        fd, self._fd = self._fd, None
        self._buffer.clear()
        if fd is not None:
            os.close(fd)
