"""The argument parser of every command of the suite (no rclpy).

``argparse`` takes a word that starts with ``-`` for an option unless it is a plain negative
number (``-1``, ``-0.5``): ``--delta-theta-p -1deg``, ``--position-tolerance -1mm`` or
``--radius-range -5:12:3`` were refused with ``expected at least one argument``, before the
value could be read and judged on its merits. :class:`CommandLineParser` reads every word
that starts with ``-`` and a digit (or ``-.`` and a digit) as a value, with or without a unit,
so that a negative value is accepted or refused by its own option, with its name.

argparse also lets a later option silently replace an earlier one (``--k-theta 3 --k-theta
10`` runs 10 alone; ``--object a --objects b`` runs ``b``): :class:`CommandLineParser` refuses
an option given twice, aliases counted as one, unless it is made to repeat (``append``,
``count``).
"""

from __future__ import annotations

import argparse
import re
import sys
from collections.abc import Sequence

#: A word that is a value, not an option: a minus sign, then a digit or a decimal point and a
#: digit (``-1``, ``-.5``, ``-1deg``, ``-5:12:3``, ``-1e-3``).
NEGATIVE_VALUE = re.compile(r'^-\.?\d')

#: Actions whose option is made to be given more than once (or that end the parse).
_REPEATABLE = tuple(getattr(argparse, name) for name in (
    '_AppendAction', '_AppendConstAction', '_CountAction', '_ExtendAction', '_HelpAction',
    '_VersionAction') if hasattr(argparse, name))


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

    def parse_known_args(self, args: Sequence[str] | None = None,
                         namespace: argparse.Namespace | None = None
                         ) -> tuple[argparse.Namespace, list[str]]:
        words = sys.argv[1:] if args is None else list(args)
        self._refuse_repeated(words)
        return super().parse_known_args(words, namespace)

    def _refuse_repeated(self, words: Sequence[str]) -> None:
        """Exit 2 (usage and a line naming it) when an option is given twice.

        Words after ``--`` or ``--ros-args`` are not this parser's options.
        """
        seen: dict[str, str] = {}
        for word in words:
            if word in ('--', '--ros-args'):
                return
            if not word.startswith('-') or word == '-' or NEGATIVE_VALUE.match(word):
                continue
            name = word.split('=', 1)[0]
            action = self._option_string_actions.get(name)
            if action is None and self.allow_abbrev and name.startswith('--'):
                # a unique abbreviation, as argparse reads it (--object for --objects)
                matches = {a for o, a in self._option_string_actions.items()
                           if o.startswith(name)}
                action = matches.pop() if len(matches) == 1 else None
            if action is None or isinstance(action, _REPEATABLE):
                continue
            if action.dest in seen:
                first = seen[action.dest]
                also = '' if first == name else f' (as {first})'
                self.error(f'{name} given twice{also}: give it once')
            seen[action.dest] = name
