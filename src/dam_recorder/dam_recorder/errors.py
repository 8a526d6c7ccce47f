"""Errors raised by dam_recorder.

Every error names the offending value (a path, a topic, a type, a parameter) in its message.
"""

from __future__ import annotations


class DamRecorderError(Exception):
    """Base class of every error raised by this package."""


class ConfigurationError(DamRecorderError, ValueError):
    """A recorder option is malformed: a topic name, a regular expression, a limit."""


class TypeDescriptionError(DamRecorderError):
    """A message type cannot be described (no type description file, unsupported field)."""


class CdrError(DamRecorderError, ValueError):
    """A serialized message is shorter than its own content says (truncated or malformed)."""


class BagError(DamRecorderError):
    """A bag cannot be written: the output exists, the storage cannot be opened, ..."""


class BagWriteError(BagError):
    """Writing a bag failed (a full or read-only file system, its directory removed, an I/O
    error): raised once, by the call that met the error; ``failure`` says what failed
    (:class:`~dam_recorder.write_failure.WriteFailure`). The bag is closed with what is on
    disk by then."""

    def __init__(self, message: str, failure: object) -> None:
        super().__init__(message)
        self.failure = failure


class RecoveryError(DamRecorderError):
    """A bag cannot be recovered: no bag directory, no storage file, no readable record."""


class BagReadError(DamRecorderError):
    """A bag cannot be read: no bag at the path, a malformed ``metadata.yaml``, a storage file
    or a message that cannot be decoded, an unknown topic. The message names the path."""


class EpisodeError(DamRecorderError, ValueError):
    """The episode metadata of a bag (``custom_data['dam_episode.*']``) is malformed; the
    message names the key and the value."""


class ExportError(DamRecorderError):
    """A bag's signals cannot be written out (the output directory, a file)."""
