"""Errors raised by dam_common.

Every error names the offending key or value in its message, so that a user can fix the input
without reading the code.
"""

from __future__ import annotations


class DamCommonError(Exception):
    """Base class of every error raised by this package."""


class ConfigError(DamCommonError, ValueError):
    """The configuration file is missing, unreadable or holds a bad value.

    The message starts with the dotted key path (``hand.link_lengths_m[1]``) and names the value.
    """


class DeviceProtocolError(DamCommonError, ValueError):
    """Base of the device link's frame-layer errors (:mod:`dam_common.device_protocol`)."""


class EncodeError(DeviceProtocolError):
    """A frame cannot be encoded: a value is non-finite, out of its field's range or the
    arrays have the wrong length."""


class DeviceParameterError(DeviceProtocolError):
    """A device-link parameter (joint count, calibration, impedance gains, modes) is out of
    its allowed range."""
