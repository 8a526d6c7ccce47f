"""Axes of a sweep on the command line: values and ranges ``start:stop:count[:log]``.

``--k-theta 0.05:20:24:log`` is 24 values from 0.05 to 20 with a constant ratio
(``numpy.geomspace``), ``--delta-theta-p 5deg:60deg:12`` is 5, 10, ..., 60 deg
(``numpy.linspace``, both ends included); plain numbers and ranges mix freely. An angle takes
its unit, and a bare one is radians, as in every command of the suite
(:mod:`dam_common.quantities`). A bad token is refused with the option and
the token named (:class:`~dam_experiments.errors.SweepError`).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence

import numpy as np

from dam_common.quantities import Quantity, has_unit, parse_quantity
from dam_experiments.errors import SweepError

#: Significant digits kept of a value computed from a range (``0.05:20:24:log``).
_RANGE_DIGITS = 12


def _number(field_name: str, text: str, token: str, quantity: Quantity | None = None,
            unit_si: float = 1.0) -> float:
    if quantity is not None:
        try:
            return parse_quantity(text, quantity) / unit_si
        except argparse.ArgumentTypeError as exc:
            where = '' if text.strip() == token.strip() else f' in {token!r}'
            raise SweepError(f'{field_name}: {exc}{where}') from None
    try:
        value = float(text)
    except ValueError:
        raise SweepError(f'{field_name}: {text!r} in {token!r} is not a number') from None
    if not math.isfinite(value):
        raise SweepError(f'{field_name}: {text!r} in {token!r} is not a finite number')
    return value


def _plain(text: str) -> float | None:
    """``text`` as a bare number, or None."""
    try:
        return float(text)
    except ValueError:
        return None


def parse_range(field_name: str, token: str, quantity: Quantity | None = None,
                unit_si: float = 1.0) -> tuple[float, ...]:
    """Values of one axis token: a number, ``start:stop:count[:lin]`` or
    ``start:stop:count:log``.

    Parameters
    ----------
    field_name
        Name of the option, for the error message (``--k-theta``).
    token
        ``'7'``; ``'5:60:12'`` (``numpy.linspace``: 5, 10, ..., 60); ``'0.05:20:24:log'``
        (``numpy.geomspace``: 24 values with equal ratios, both ends included). ``:lin`` says
        linear explicitly; the suffix is case-blind. ``start > stop`` gives the values in
        descending order. A count of 1 needs ``start == stop``.
    quantity
        The physical quantity of the values (:data:`dam_common.quantities.ANGLE`): each of
        ``start`` and ``stop`` then takes its unit, a bare one is in SI units. None: plain
        numbers.
    unit_si
        The returned values' unit in SI units (``math.pi / 180`` for degrees).

    Returns
    -------
    tuple of float
        The values in the token's order, rounded to 12 significant digits.

    Raises
    ------
    SweepError
        A malformed token, naming the option and the token.
    """
    parts = token.strip().split(':')
    if len(parts) == 1:
        return (float(f'{_number(field_name, parts[0], token, quantity, unit_si):.12g}'),)
    if len(parts) not in (3, 4) or (len(parts) == 4 and parts[3].strip().lower() not in
                                    ('log', 'lin')):
        raise SweepError(f'{field_name}: {token!r} is neither a number nor a range '
                         f'start:stop:count[:lin] or start:stop:count:log')
    if quantity is not None and has_unit(parts[0]) != has_unit(parts[1]) and \
            0.0 not in (_plain(parts[0]), _plain(parts[1])):
        raise SweepError(f'{field_name}: {token!r}: one end has a unit and the other not; give '
                         'both ends their unit (a bare number is SI)')
    start = _number(field_name, parts[0], token, quantity, unit_si)
    stop = _number(field_name, parts[1], token, quantity, unit_si)
    try:
        count = int(parts[2])
    except ValueError:
        raise SweepError(f'{field_name}: count {parts[2]!r} in {token!r} is not a whole '
                         f'number') from None
    if count < 1:
        raise SweepError(f'{field_name}: count {count} in {token!r} must be at least 1')
    if count == 1 and start != stop:
        raise SweepError(f'{field_name}: count 1 in {token!r} needs start == stop')
    log = len(parts) == 4 and parts[3].strip().lower() == 'log'
    if log and (start <= 0.0 or stop <= 0.0):
        raise SweepError(f'{field_name}: a log range needs positive ends, got {token!r}')
    values = np.geomspace(start, stop, count) if log else np.linspace(start, stop, count)
    return tuple(float(f'{v:.{_RANGE_DIGITS}g}') for v in values)


def parse_axis(field_name: str, tokens: Sequence[str], *, lower: float,
               upper: float = math.inf, lower_open: bool = False,
               upper_open: bool = False, unit: str = '', quantity: Quantity | None = None,
               unit_si: float = 1.0) -> tuple[float, ...]:
    """All values of an axis given as tokens (:func:`parse_range`), checked against bounds.

    Parameters
    ----------
    field_name
        Option name for the error messages.
    tokens
        Numbers and ranges, concatenated in order.
    lower, upper
        Bounds of every value (in the option's unit).
    lower_open, upper_open
        Exclude the bound itself.
    unit
        Unit for the messages (``'deg'``).
    quantity, unit_si
        As for :func:`parse_range`.

    Raises
    ------
    SweepError
        No value, a malformed token, a value out of bounds or given twice.
    """
    values: list[float] = []
    seen: set[float] = set()  # a list's ``in`` made 100 000 values take minutes (user test)
    for token in tokens:
        for v in parse_range(field_name, token, quantity, unit_si):
            low_bad = v <= lower if lower_open else v < lower
            high_bad = v >= upper if upper_open else v > upper
            if low_bad or high_bad:
                lo = '(' if lower_open else '['
                hi = ')' if upper_open else ']'
                raise SweepError(f'{field_name}: {v:.4g}{" " + unit if unit else ""} (from '
                                 f'{token!r}) is outside {lo}{lower:.4g}, {upper:.4g}{hi}')
            if v in seen:
                raise SweepError(f'{field_name}: {v:g} is given twice (from {token!r})')
            seen.add(v)
            values.append(v)
    if not values:
        raise SweepError(f'{field_name}: no value given')
    return tuple(values)
