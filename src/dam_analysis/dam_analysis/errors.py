"""Errors raised by dam_analysis.

Every error names the offending key or value in its message, so that a user can fix the input
without reading the code.
"""

from __future__ import annotations


class DamAnalysisError(Exception):
    """Base class of every error raised by this package."""


class InputError(DamAnalysisError, ValueError):
    """An argument to an analysis function is malformed (NaN, wrong shape, out of range)."""


class NoSolutionError(DamAnalysisError):
    """A kinematic problem has no solution (contact lost, table penetrated, joint limit)."""


class Interrupted(DamAnalysisError):
    """A long computation was asked to stop before it finished (the node is stopping)."""
