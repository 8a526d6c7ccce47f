"""Angles, lengths and masses on the command lines people type: one rule for every command.

**A bare number is in SI units** (radians, metres, kilograms), as in every ROS message,
service field and parameter of the suite (REP 103). A unit suffix says otherwise, the same
in every command:

=========  ===============================  ========================
quantity   units                            bare number
=========  ===============================  ========================
angle      ``deg``, ``rad``                 radians
length     ``m``, ``cm``, ``mm``, ``um``    metres
mass       ``kg``, ``g``                    kilograms
=========  ===============================  ========================

A bare number that is implausible for a hand of this size in SI units (an angle beyond
90 deg, a length beyond half a metre or below a micrometre, a mass beyond what the hand can
hold) is refused with how it was read and what was probably meant (``10`` as an angle:
"10 rad (573 deg) ... did you mean 10deg?"). A value written with its unit is taken as
written; the command then judges it on its merits.

Pure Python (no rclpy): the command lines and ``scripts/run.sh`` check a value before they
start anything.
"""

from __future__ import annotations

import argparse
import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Quantity:
    """A kind of physical quantity on a command line.

    Attributes
    ----------
    name : 'angle', 'length' or 'mass'.
    si_unit : the unit of a bare number ('rad', 'm', 'kg').
    units : every accepted suffix and its factor to the SI unit.
    bare_max : the largest plausible bare value [SI unit] for a hand of this size.
    bare_min : the smallest plausible non-zero bare magnitude [SI unit] (0: none).
    meant : the suffix a person most likely meant by an implausible bare number.
    examples : examples for the message of a word that is not a value.
    """

    name: str
    si_unit: str
    units: dict[str, float]
    bare_max: float
    bare_min: float
    meant: str
    examples: str

    def show(self, value: float) -> str:
        """``value`` [SI unit] as a person reads it (angles in degrees, lengths in mm, ...)."""
        if self.name == 'angle':
            return f'{math.degrees(value):.4g} deg'
        if self.name == 'length':
            return f'{value * 1e3:.4g} mm'
        if self.name == 'mass':
            return f'{value * 1e3:.4g} g' if abs(value) < 1.0 else f'{value:.4g} kg'
        return f'{value:.4g} {self.si_unit}'


#: Angles: a bare number is radians; beyond 90 deg no angle of this hand's commands lies.
ANGLE = Quantity('angle', 'rad', {'deg': math.pi / 180.0, 'rad': 1.0},
                 bare_max=math.pi / 2.0, bare_min=0.0, meant='deg',
                 examples='40deg, 0.7rad, 0.7')
#: Lengths: a bare number is metres; the hand's fingers are a few centimetres long.
LENGTH = Quantity('length', 'm', {'um': 1e-6, 'mm': 1e-3, 'cm': 1e-2, 'm': 1.0},
                  bare_max=0.5, bare_min=1e-6, meant='mm',
                  examples='12mm, 1.2cm, 0.012m, 0.012')
#: Masses: a bare number is kilograms; joints of about 1 N*m hold well under 2 kg.
MASS = Quantity('mass', 'kg', {'g': 1e-3, 'kg': 1.0},
                bare_max=2.0, bare_min=0.0, meant='g',
                examples='40g, 0.04kg, 0.04')

#: The friction angle's bound [rad]: a friction cone of 90 deg or more is no cone.
RIGHT_ANGLE = math.pi / 2.0
#: Why a negative value is refused where a request reads one as "the configured value".
LEAVE_OUT = 'leave the option out for the configured value'

_VALUE = re.compile(r'^\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s*([a-zA-Z]*)\s*$')


def both_units(value: float | Sequence[float], quantity: Quantity, *,
               most: int = 6) -> str:
    """``value`` [SI unit] in the SI unit and in the unit a person reads, 4 significant digits
    each: ``'1.396 rad (80 deg)'``, ``'0.006 m (6 mm)'``, ``'[1.396, 0.7] rad ([80, 40.11]
    deg)'`` (a service's refusal, read by command-line users and ``ros2 service call`` users).

    Parameters
    ----------
    value : one value or a sequence of values [SI unit].
    quantity : :data:`ANGLE`, :data:`LENGTH` or :data:`MASS`.
    most : the most values of a sequence written out; more are counted (``... (N values)``).
    """
    if isinstance(value, (int, float, np.floating, np.integer)):
        v = float(value)
        return f'{v:.4g} {quantity.si_unit} ({quantity.show(v)})'
    values = [float(v) for v in np.asarray(value, dtype=np.float64).reshape(-1)]
    tail = f', ... ({len(values)} values)' if len(values) > most else ''
    shown = values[:most]
    usual = [quantity.show(v) for v in shown]
    usual_unit = usual[0].split(' ', 1)[1] if usual else quantity.si_unit
    if any(u.split(' ', 1)[1] != usual_unit for u in usual):  # masses: g and kg mixed
        usual = [f'{v:.4g}' for v in shown]
        usual_unit = quantity.si_unit
    else:
        usual = [u.split(' ', 1)[0] for u in usual]
    si = ', '.join(f'{v:.4g}' for v in shown)
    if usual_unit == quantity.si_unit:
        return f'[{si}{tail}] {quantity.si_unit}'
    return f'[{si}{tail}] {quantity.si_unit} ([{", ".join(usual)}{tail}] {usual_unit})'


def parse_quantity(text: str, quantity: Quantity) -> float:
    """One value of ``quantity`` from a command-line word -> SI units (float).

    Parameters
    ----------
    text : a number with an optional unit of ``quantity.units`` (``'40deg'``, ``'-1mm'``).
    quantity : :data:`ANGLE`, :data:`LENGTH` or :data:`MASS`.

    Returns
    -------
    The value in ``quantity.si_unit``.

    Raises
    ------
    argparse.ArgumentTypeError
        Not a number with a unit of this quantity, not finite, or a bare number that is
        implausible in SI units (the message says how it was read and what was probably
        meant).
    """
    match = _VALUE.match(text)
    if match is None and _is_float(text):  # nan, inf: numbers _VALUE does not take
        raise argparse.ArgumentTypeError(f'{text!r} is not a finite {quantity.name}')
    if match is None:
        raise argparse.ArgumentTypeError(
            f'{text!r} is not {_article(quantity.name)} (examples: {quantity.examples})')
    number, unit = float(match.group(1)), match.group(2).lower()
    if not math.isfinite(number):
        raise argparse.ArgumentTypeError(f'{text!r} is not a finite {quantity.name}')
    if unit:
        if unit not in quantity.units:
            raise argparse.ArgumentTypeError(
                f'{text!r}: {unit!r} is not a unit of {quantity.name} (one of '
                f'{", ".join(quantity.units)})')
        return number * quantity.units[unit]
    magnitude = abs(number)
    if magnitude > quantity.bare_max or 0.0 < magnitude < quantity.bare_min:
        read = f'{number:g} {quantity.si_unit}'
        shown = quantity.show(number)
        if shown.replace(' ', '') != read.replace(' ', ''):
            read += f' ({shown})'
        if magnitude > quantity.bare_max:
            why = (f'more than {quantity.show(quantity.bare_max)}' if number > 0 else
                   f'beyond -{quantity.show(quantity.bare_max)}')
            meant = f'did you mean {match.group(1)}{quantity.meant}? '
        else:  # below the smallest plausible size: no unit makes it plausible
            why = f'less than {quantity.show(quantity.bare_min)} in size'
            meant = ''
        raise argparse.ArgumentTypeError(
            f'{text!r} has no unit, so it reads as {read}: {why}, implausible for this hand; '
            f'{meant}(a bare number is in {quantity.si_unit}; write the unit)')
    return number


def parse_range(text: str, quantity: Quantity) -> tuple[float, float]:
    """``'MIN:MAX'`` or one value of ``quantity`` -> (min, max) in SI units.

    Raises
    ------
    argparse.ArgumentTypeError
        Not one or two values, a value :func:`parse_quantity` refuses, or max below min.
    """
    parts = text.split(':')
    if len(parts) not in (1, 2) or not all(part.strip() for part in parts):
        raise argparse.ArgumentTypeError(f'{text!r} is not MIN:MAX or one {quantity.name}')
    _same_way(text, parts)
    low, high = parse_quantity(parts[0], quantity), parse_quantity(parts[-1], quantity)
    if high < low:
        raise argparse.ArgumentTypeError(
            f'{text!r}: empty range, max {quantity.show(high)} is below min '
            f'{quantity.show(low)}')
    return low, high


def parse_linspace(text: str, quantity: Quantity, max_count: int) -> np.ndarray:
    """``'START:STOP:COUNT'`` -> ``COUNT`` values of ``quantity`` evenly from START to STOP.

    Returns
    -------
    (COUNT,) float64 array in SI units.

    Raises
    ------
    argparse.ArgumentTypeError
        Not three fields, START or STOP refused by :func:`parse_quantity`, COUNT not a whole
        number in [1, max_count], STOP below START, or COUNT 1 with START != STOP.
    """
    parts = text.split(':')
    if len(parts) != 3 or not all(part.strip() for part in parts):
        raise argparse.ArgumentTypeError(f'{text!r} is not START:STOP:COUNT')
    _same_way(text, parts[:2])
    start, stop = parse_quantity(parts[0], quantity), parse_quantity(parts[1], quantity)
    try:
        count = int(parts[2])
    except ValueError:
        raise argparse.ArgumentTypeError(
            f'{text!r}: COUNT {parts[2]!r} is not a whole number') from None
    if not 1 <= count <= max_count:
        raise argparse.ArgumentTypeError(f'{text!r}: COUNT {count} must be in [1, {max_count}]')
    if stop < start:
        raise argparse.ArgumentTypeError(
            f'{text!r}: STOP {quantity.show(stop)} is below START {quantity.show(start)}')
    if count == 1 and start != stop:
        raise argparse.ArgumentTypeError(f'{text!r}: one value needs START == STOP')
    return np.linspace(start, stop, count)


def argument(quantity: Quantity, *, low: float | None = None, high: float | None = None,
             low_inclusive: bool = True, high_inclusive: bool = True,
             form: str = 'value', max_count: int = 1000,
             why_low: str = '') -> Callable[[str], object]:
    """An argparse ``type=`` that reads ``quantity`` and keeps it within [low, high].

    Parameters
    ----------
    quantity : :data:`ANGLE`, :data:`LENGTH` or :data:`MASS`.
    low, high : bounds [SI unit] of every value (None: none).
    low_inclusive, high_inclusive : whether a value equal to the bound is accepted.
    form : 'value' (one value), 'range' (``MIN:MAX`` -> tuple) or 'linspace'
        (``START:STOP:COUNT`` -> array).
    max_count : the largest COUNT of a 'linspace'.
    why_low : said after a value below ``low`` (e.g. "leave the option out for the
        configured value").

    Returns
    -------
    A callable ``str -> float | tuple[float, float] | numpy.ndarray``; argparse names the
    option in its messages.
    """
    if form not in ('value', 'range', 'linspace'):
        raise ValueError(f'form {form!r} is not value, range or linspace')

    def checked(text: str) -> object:
        if form == 'value':
            value = parse_quantity(text, quantity)
            values: tuple[float, ...] = (value,)
        elif form == 'range':
            value = parse_range(text, quantity)
            values = value
        else:
            value = parse_linspace(text, quantity, max_count)
            values = tuple(float(v) for v in value)
        for v in values:
            if low is not None and (v < low or (v == low and not low_inclusive)):
                bound = 'at least' if low_inclusive else 'above'
                tail = f' ({why_low})' if why_low else ''
                raise argparse.ArgumentTypeError(
                    f'{text!r}: {quantity.show(v)} must be {bound} {quantity.show(low)}{tail}')
            if high is not None and (v > high or (v == high and not high_inclusive)):
                bound = 'at most' if high_inclusive else 'below'
                raise argparse.ArgumentTypeError(
                    f'{text!r}: {quantity.show(v)} must be {bound} {quantity.show(high)}')
        return value

    checked.__name__ = quantity.name  # argparse says "invalid angle value" for other errors
    return checked


def has_unit(text: str) -> bool:
    """Whether the value ``text`` carries a unit (``'5deg'``; not ``'5'``, ``'0'``)."""
    match = _VALUE.match(text)
    return bool(match and match.group(2))


def _same_way(text: str, ends: list[str]) -> None:
    """Refuse a range with one end bare and the other with a unit (``1:80deg`` read its 1 as
    57 deg): a person who wrote one unit meant it for both. A bare 0 goes with anything."""
    bare = [end for end in ends if not has_unit(end) and _is_float(end) and float(end) != 0.0]
    if bare and any(has_unit(end) for end in ends):
        raise argparse.ArgumentTypeError(
            f'{text!r}: {bare[0]!r} has no unit while the other end has one; give both ends '
            'their unit (a bare number is SI)')


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _article(noun: str) -> str:
    return f'an {noun}' if noun[0] in 'aeiou' else f'a {noun}'


def number_argument(*, low: float | None = None, why_low: str = '', unit: str = '',
                    above: float | None = None, what: str = '') -> Callable[[str], float]:
    """An argparse ``type=`` for a plain finite number (a stiffness [N*m/rad], a margin [N],
    a time [s]) at least ``low`` and greater than ``above``.

    ``what`` names the quantity (``'stiffness'``) for the message of a word that is not a
    number: "'10Nm/rad' is not a number: a stiffness is a plain number in N*m/rad (10, not
    10Nm/rad)".

    Raises
    ------
    argparse.ArgumentTypeError
        Not a finite number, below ``low`` (followed by ``why_low``), or not greater than
        ``above``.
    """

    def checked(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            why = ''
            if what or unit:
                why = (f': {_article(what or "value")} is a plain number'
                       f'{" in " + unit if unit else ""}')
                match = _VALUE.match(text.split('/')[0])
                if match and match.group(2):  # a number with a unit written after it
                    why += f' ({match.group(1)}, not {text})'
            raise argparse.ArgumentTypeError(f'{text!r} is not a number{why}') from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f'{text!r} is not a finite number')
        if low is not None and value < low:
            tail = f' ({why_low})' if why_low else ''
            raise argparse.ArgumentTypeError(
                f'{text!r} must be at least {low:g}{" " + unit if unit else ""}{tail}')
        if above is not None and not value > above:
            raise argparse.ArgumentTypeError(
                f'{text!r} must be greater than {above:g}{" " + unit if unit else ""}')
        return value

    checked.__name__ = 'number'
    return checked


def in_degrees(parse: Callable[[str], object]) -> Callable[[str], float]:
    """An argparse ``type=``: the angle ``parse`` reads [rad], in degrees to 12 significant
    digits (``5deg`` stays 5.0), for the commands whose tables and plots are in degrees."""

    def degrees(text: str) -> float:
        return float(f'{math.degrees(float(parse(text))):.12g}')  # type: ignore[arg-type]

    degrees.__name__ = 'angle'
    return degrees
