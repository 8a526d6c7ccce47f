"""Errors raised by dam_hand_driver.

Every error names the offending value in its message. The frame decoder never raises: it
rejects a bad frame, counts the reason and returns ``None`` (see
:class:`dam_common.device_protocol.FrameDecoder`). The frame layer's own errors (a frame
encoded from bad values, a bad calibration) are in :mod:`dam_common.errors`; the ones below
are for this package's configuration mistakes (a bad port, a bad slew limit, a backend that
cannot start).
"""

from __future__ import annotations

from dam_common.errors import DeviceParameterError


class HandDriverError(Exception):
    """Base class of every error raised by this package."""


class ParameterError(HandDriverError, DeviceParameterError):
    """A parameter of the driver (a port, a slew limit, a watchdog timeout) is out of its
    allowed range."""
