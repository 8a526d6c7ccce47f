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

