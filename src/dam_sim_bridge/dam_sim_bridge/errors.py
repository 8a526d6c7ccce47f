"""Errors raised by dam_sim_bridge.

Every error names the offending value in its message.
"""

from __future__ import annotations


class SimBridgeError(Exception):
    """Base class of every error raised by this package."""


class WorldConfigError(SimBridgeError, ValueError):
    """A world option (time step, link mass, initial angle, gain, limit) is out of range."""


class CommandError(SimBridgeError, ValueError):
    """A joint command is malformed: wrong length, unknown mode, non-finite setpoint."""


class SimulationError(SimBridgeError, RuntimeError):
    """The physics server failed (disconnected, could not load the model)."""


class SweepError(SimBridgeError, ValueError):
    """A sweep is malformed (a bad range or option, naming the field and the value) or does
    not match the sweep already in its output directory."""


class SweepPlotError(SimBridgeError, ValueError):
    """A sweep directory cannot be drawn: a missing directory or file, an empty or malformed
    table (naming the file, the trial and the value), or a picture that cannot be written."""
