"""PyBullet, imported without its start-up banner.

Importing ``pybullet`` writes ``pybullet build time: <date>`` to the process's standard error
from C code. Every process that builds a world would print it: each worker of a sweep in the
middle of its progress line, every stand-in and experiment. Here the import runs once with file
descriptor 2 pointed at ``/dev/null``; a second import is a dictionary look-up and prints
nothing anyway. The window is the import alone (a few milliseconds), taken before anything of
ours runs in the process that imports it.

Use ``from dam_sim_bridge.pybullet_import import bullet_client, pybullet``.
"""

from __future__ import annotations

import os
import sys
from types import ModuleType


def _import_quietly() -> tuple[ModuleType, ModuleType]:
    """``pybullet`` and ``pybullet_utils.bullet_client``, with standard error silenced while
    the extension module initialises (only on the first import in this process)."""
    if 'pybullet' in sys.modules:
        import pybullet
        from pybullet_utils import bullet_client
        return pybullet, bullet_client
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError, AttributeError):  # no usable fd 2: nothing to hide it from
        saved = None
    devnull = os.open(os.devnull, os.O_WRONLY) if saved is not None else None
    try:
        if devnull is not None:
            os.dup2(devnull, 2)
        import pybullet
        from pybullet_utils import bullet_client
    finally:
        if saved is not None and devnull is not None:
            os.dup2(saved, 2)
            os.close(saved)
            os.close(devnull)
    return pybullet, bullet_client


pybullet, bullet_client = _import_quietly()

__all__ = ['bullet_client', 'pybullet']
