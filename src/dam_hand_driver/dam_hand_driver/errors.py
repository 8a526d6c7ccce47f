"""Errors raised by dam_hand_driver.

Every error names the offending value in its message. The frame decoder never raises: it
rejects a bad frame, counts the reason and returns ``None`` (see
:class:`dam_hand_driver.protocol.FrameDecoder`). The errors below are for programming and
configuration mistakes: encoding a frame from bad values, a bad calibration, a bad watchdog
timeout.
"""

from __future__ import annotations


class HandDriverError(Exception):
    """Base class of every error raised by this package."""


class EncodeError(HandDriverError, ValueError):
    """A frame cannot be encoded: a value is non-finite, out of its field's range or the
    arrays have the wrong length."""


class ParameterError(HandDriverError, ValueError):
    """A parameter (watchdog timeout, joint count, calibration) is out of its allowed range."""
