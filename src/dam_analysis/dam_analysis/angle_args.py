"""Angles on the command lines of the analysis tools: ``40deg``, ``0.7rad`` or a bare number.

A bare number is radians for ``check_lift`` (whose options mirror the service's radian fields)
and degrees for ``plan_lift`` and ``scale_map`` (whose ranges are written in degrees); a unit
suffix means the same everywhere. A bare number below 1 read as degrees is named in a note on
standard error, since it is more often radians meant (0.0873 for 5 deg) than a friction angle
or displacement under a degree.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from typing import Any


def parse_angle(text: str, bare: str = 'rad') -> float:
    """``'40deg'``, ``'0.7rad'`` or a bare number (in ``bare``: 'rad' or 'deg') -> radians.

    Raises
    ------
    argparse.ArgumentTypeError
        Not a number with an optional ``deg`` or ``rad`` suffix, or not finite.
    """
    value = text.strip().lower()
    try:
        if value.endswith('deg'):
            number, unit = float(value[:-3]), 'deg'
        elif value.endswith('rad'):
            number, unit = float(value[:-3]), 'rad'
        else:
            number, unit = float(value), bare
    except ValueError:
        raise argparse.ArgumentTypeError(
            f'{text!r} is not an angle (examples: 40deg, 0.7rad, 0.7)') from None
    if not math.isfinite(number):
        raise argparse.ArgumentTypeError(f'{text!r} is not a finite angle')
    if unit == 'deg' and not value.endswith('deg') and 0.0 < abs(number) < 1.0:  # bare
        print(f'note: {text!r} is read in degrees ({number:g} deg); write {text}rad for '
              'radians', file=sys.stderr)
    return math.radians(number) if unit == 'deg' else number


def parse_degrees(text: str) -> float:
    """A bare number in degrees (or with a unit suffix) -> radians (:func:`parse_angle`)."""
    return parse_angle(text, bare='deg')


def parse_range(text: str, parse_one: Callable[[str], float] = float,
                show: Callable[[float], str] = lambda v: f'{v:g}') -> tuple[float, float]:
    """``'MIN:MAX'`` or one value -> (min, max), each end read by ``parse_one`` and named in
    messages by ``show``.

    Raises
    ------
    argparse.ArgumentTypeError
        Not one or two values, a value ``parse_one`` refuses or that is not finite, or max
        below min.
    """
    parts = text.split(':')
    if len(parts) not in (1, 2):
        raise argparse.ArgumentTypeError(f'{text!r} is not MIN:MAX or one value')
    try:
        low, high = parse_one(parts[0]), parse_one(parts[-1])
    except ValueError:
        raise argparse.ArgumentTypeError(f'{text!r}: not a number') from None
    if not (math.isfinite(low) and math.isfinite(high)):
        raise argparse.ArgumentTypeError(f'{text!r}: not a finite number')
    if high < low:
        raise argparse.ArgumentTypeError(
            f'{text!r}: empty range, max {show(high)} is below min {show(low)}')
    return low, high


def parse_angle_range(text: str) -> tuple[float, float]:
    """``'3:6'``, ``'3deg:6deg'``, ``'0.05rad:0.1rad'`` or one angle -> (min, max) [rad]; bare
    numbers are degrees (:func:`parse_range` of :func:`parse_degrees`)."""
    return parse_range(text, parse_degrees, lambda v: f'{math.degrees(v):g} deg')


def not_negative(parse: Callable[[str], Any]) -> Callable[[str], Any]:
    """``parse``, refusing a negative value (or range end): in a ``CheckLift`` or ``PlanLift``
    request a negative field means "the configuration's", which a person who typed ``-1mm``
    did not ask for; leaving the option out does that.

    Raises
    ------
    argparse.ArgumentTypeError
        What ``parse`` raises, or a value below zero.
    """

    def checked(text: str) -> Any:
        value = parse(text)
        if min(value if isinstance(value, tuple) else (value,)) < 0.0:
            raise argparse.ArgumentTypeError(
                f'{text!r} is negative (leave the option out for the configured value)')
        return value

    checked.__name__ = getattr(parse, '__name__', 'value')  # argparse names it in errors
    return checked
