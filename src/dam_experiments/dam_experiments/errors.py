"""Errors raised by dam_experiments.

Every error names the offending value in its message.
"""

from __future__ import annotations


class ExperimentError(Exception):
    """Base class of every error raised by this package."""


class SweepError(ExperimentError, ValueError):
    """A sweep is malformed (a bad range or option, naming the field and the value) or does
    not match the sweep already in its output directory."""


class SweepPlotError(ExperimentError, ValueError):
    """A sweep directory cannot be drawn: a missing directory or file, an empty or malformed
    table (naming the file, the trial and the value), or a picture that cannot be written."""
