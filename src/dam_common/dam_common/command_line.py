"""The argument parser of every command of the suite (no rclpy).

``argparse`` takes a word that starts with ``-`` for an option unless it is a plain negative
number (``-1``, ``-0.5``): ``--delta-theta-p -1deg``, ``--position-tolerance -1mm`` or
``--radius-range -5:12:3`` were refused with ``expected at least one argument``, before the
value could be read and judged on its merits. :class:`CommandLineParser` reads every word
that starts with ``-`` and a digit (or ``-.`` and a digit) as a value, with or without a unit,
so that a negative value is accepted or refused by its own option, with its name.
"""

from __future__ import annotations

import argparse
import re

#: A word that is a value, not an option: a minus sign, then a digit or a decimal point and a
#: digit (``-1``, ``-.5``, ``-1deg``, ``-5:12:3``, ``-1e-3``).
NEGATIVE_VALUE = re.compile(r'^-\.?\d')


class CommandLineParser(argparse.ArgumentParser):
    """An :class:`argparse.ArgumentParser` that reads negative values with units as values.

    None of the suite's options looks like a negative number, so argparse's own rule for
    negative numbers (a word that looks like one is a value when no option looks like one)
    is widened to every word matching :data:`NEGATIVE_VALUE`. Subcommand parsers made with
    :meth:`add_subparsers` are of this class too.
    """

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        # argparse's matcher (private; in CPython since 3.2, unchanged in use through 3.13).
        self._negative_number_matcher = NEGATIVE_VALUE

    def add_argument(self, *args, **kwargs) -> argparse.Action:
        for name in args:
            if isinstance(name, str) and NEGATIVE_VALUE.match(name):
                raise ValueError(f'option {name!r} looks like a negative value')
        return super().add_argument(*args, **kwargs)
