"""Errors raised by dam_spcm_controller.

Every message names the offending argument and its value, so that a caller can fix the input
without reading the code.
"""

from __future__ import annotations


class SpcmControllerError(Exception):
    """Base class of every error raised by this package."""


class InputError(SpcmControllerError, ValueError):
    """An argument is malformed: NaN or infinite, wrong length, out of range, not positive."""


class StateError(SpcmControllerError, RuntimeError):
    """A method was called in a phase that does not allow it (e.g. ``start`` while active)."""
