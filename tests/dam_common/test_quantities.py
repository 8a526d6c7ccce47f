"""Angles, lengths and masses on command lines: one rule in every command (module quantities).

The issue: a bare number was radians in ``check_lift``, ``dam_grasp`` and ``run.sh`` and degrees
in ``plan_lift``, ``scale_map``, ``lift_map`` and ``sweep``; ``plan_lift --mass 30:50`` planned
for 50 kg and ``scale_map --radius-range 0.005:0.02:4`` drew a radius of 5 micrometres.
"""

from __future__ import annotations

import argparse
import math
import re

import numpy as np
import pytest

from dam_common.quantities import (
    ANGLE,
    LENGTH,
    MASS,
    argument,
    both_units,
    in_degrees,
    number_argument,
    parse_linspace,
    parse_quantity,
    parse_range,
)


@pytest.mark.parametrize(('text', 'quantity', 'si'), [
    ('40deg', ANGLE, math.radians(40.0)), ('0.7rad', ANGLE, 0.7), ('0.7', ANGLE, 0.7),
    (' 5DEG ', ANGLE, math.radians(5.0)), ('-1deg', ANGLE, -math.radians(1.0)),
    ('12mm', LENGTH, 0.012), ('1.2cm', LENGTH, 0.012), ('0.012m', LENGTH, 0.012),
    ('0.012', LENGTH, 0.012), ('250um', LENGTH, 250e-6), ('40g', MASS, 0.04),
    ('0.04kg', MASS, 0.04), ('0.04', MASS, 0.04), ('1e-3', LENGTH, 1e-3),
    ('0', ANGLE, 0.0),
])
def test_a_value_is_read_in_si_units(text: str, quantity, si: float) -> None:
    assert parse_quantity(text, quantity) == pytest.approx(si, rel=1e-12, abs=0.0)


@pytest.mark.parametrize(('text', 'quantity', 'reading', 'meant'), [
    ('10', ANGLE, '10 rad (573 deg)', '10deg'),
    ('2', ANGLE, '2 rad (114.6 deg)', '2deg'),
    ('50', MASS, '50 kg', '50g'),
    ('5', LENGTH, '5 m (5000 mm)', '5mm'),
])
def test_an_implausible_bare_number_says_how_it_was_read_and_what_was_meant(
        text: str, quantity, reading: str, meant: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError) as caught:
        parse_quantity(text, quantity)
    message = str(caught.value)
    assert f'reads as {reading}' in message, message
    assert f'did you mean {meant}?' in message, message


@pytest.mark.parametrize(('text', 'quantity', 'says'), [
    ('-10', ANGLE, 'reads as -10 rad (-573 deg): beyond -90 deg'),
    ('1e-7', LENGTH, 'reads as 1e-07 m (0.0001 mm): less than 0.001 mm in size'),
])
def test_an_implausible_bare_number_without_a_likelier_reading_says_so(text, quantity,
                                                                       says) -> None:
    with pytest.raises(argparse.ArgumentTypeError) as caught:
        parse_quantity(text, quantity)
    assert says in str(caught.value), str(caught.value)
    if text == '1e-7':
        assert 'did you mean' not in str(caught.value)  # no unit makes it plausible


def test_a_range_gives_both_ends_their_unit_or_none() -> None:
    for text in ('1:80deg', '0.1deg:1', '5:60deg'):  # 1:80deg read its 1 as 57 deg
        with pytest.raises(argparse.ArgumentTypeError, match='has no unit while the other end'):
            parse_range(text, ANGLE)
    with pytest.raises(argparse.ArgumentTypeError, match='has no unit while the other end'):
        parse_linspace('0.1:60deg:3', ANGLE, 10)
    assert parse_range('0:80deg', ANGLE) == pytest.approx((0.0, math.radians(80.0)))
    for text in ('3deg:', ':6deg'):
        with pytest.raises(argparse.ArgumentTypeError, match='is not MIN:MAX'):
            parse_range(text, ANGLE)
    with pytest.raises(argparse.ArgumentTypeError, match='is not START:STOP:COUNT'):
        parse_linspace('2mm::3', LENGTH, 10)


def test_the_same_value_with_its_unit_is_taken_as_written() -> None:
    assert parse_quantity('10deg', ANGLE) == pytest.approx(math.radians(10.0))
    assert parse_quantity('50kg', MASS) == 50.0  # implausible, but the unit says it is meant
    assert parse_quantity('90deg', ANGLE) == pytest.approx(math.pi / 2)
    assert parse_quantity(f'{math.pi / 2}', ANGLE) == pytest.approx(math.pi / 2)  # the edge


@pytest.mark.parametrize(('text', 'quantity', 'says'), [
    ('ten', ANGLE, 'is not an angle (examples: 40deg'), ('5kg', ANGLE, "'kg' is not a unit of "
                                                        'angle'),
    ('5deg', LENGTH, "'deg' is not a unit of length"), ('nan', MASS, 'not a finite mass'),
    ('inf', ANGLE, 'not a finite angle'), ('', LENGTH, 'is not a length'),
    ('1 2mm', LENGTH, 'is not a length'),
])
def test_a_word_that_is_no_value_of_its_quantity_is_refused(text, quantity, says) -> None:
    with pytest.raises(argparse.ArgumentTypeError, match=re.escape(says)):
        parse_quantity(text, quantity)


def test_ranges_and_linspaces_read_each_end_with_its_unit() -> None:
    assert parse_range('3deg:6deg', ANGLE) == pytest.approx(
        (math.radians(3.0), math.radians(6.0)))
    assert parse_range('30g:50g', MASS) == pytest.approx((0.03, 0.05))
    assert parse_range('5deg', ANGLE) == pytest.approx((math.radians(5.0),) * 2)
    np.testing.assert_allclose(parse_linspace('3mm:20mm:18', LENGTH, 400),
                               np.arange(3, 21) * 1e-3)
    with pytest.raises(argparse.ArgumentTypeError, match='empty range, max 3 deg is below'):
        parse_range('6deg:3deg', ANGLE)
    with pytest.raises(argparse.ArgumentTypeError, match='did you mean 30g'):
        parse_range('30:50', MASS)
    for bad, says in (('3mm:2mm:3', 'STOP 2 mm is below START 3 mm'),
                      ('3mm:4mm:0', r'COUNT 0 must be in \[1, 400\]'),
                      ('3mm:4mm:x', "COUNT 'x' is not a whole number"),
                      ('3mm:4mm:1', 'one value needs START == STOP'),
                      ('3mm:4mm', 'is not START:STOP:COUNT')):
        with pytest.raises(argparse.ArgumentTypeError, match=says):
            parse_linspace(bad, LENGTH, 400)


def test_an_argument_keeps_its_bounds_and_names_them_in_the_quantity_s_units() -> None:
    positive = argument(ANGLE, low=0.0, low_inclusive=False, high=math.radians(65.0))
    assert positive('40deg') == pytest.approx(math.radians(40.0))
    with pytest.raises(argparse.ArgumentTypeError, match='0 deg must be above 0 deg'):
        positive('0')
    with pytest.raises(argparse.ArgumentTypeError, match='70 deg must be at most 65 deg'):
        positive('70deg')
    with pytest.raises(argparse.ArgumentTypeError, match=r'-1 mm must be at least 0 mm \(why'):
        argument(LENGTH, low=0.0, why_low='why')('-1mm')
    assert in_degrees(argument(ANGLE))('5deg') == 5.0  # no float noise from the round trip
    assert in_degrees(argument(ANGLE))('0.5') == pytest.approx(math.degrees(0.5))
    with pytest.raises(argparse.ArgumentTypeError, match='must be at least 0'):
        number_argument(low=0.0)('-2')
    with pytest.raises(argparse.ArgumentTypeError, match='not a finite number'):
        number_argument()('nan')


# The rule across the commands: the same bare number means the same thing in each, and each
# takes units. (Before: 0.5 was 0.5 rad in check_lift and 0.5 deg in plan_lift.)

COMMANDS = ('check_lift', 'plan_lift', 'scale_map', 'lift_map', 'dam_grasp', 'dam_experiment',
            'sweep')


def _read(command: str, word: str) -> float:
    """The displacement [rad] ``command`` reads from ``word`` (by its own parser)."""
    from dam_analysis import check_lift_client, lift_map, plan_lift_client, scale_map
    from dam_experiments import experiment
    from dam_experiments.sweep_axes import parse_axis
    from dam_spcm_controller import grasp_client

    if command == 'check_lift':
        return check_lift_client.build_parser().parse_args(
            ['--delta-theta-p', word]).delta_theta_p[0]
    if command == 'plan_lift':
        return plan_lift_client.build_parser().parse_args(
            ['--delta-theta-p', word]).delta_theta_p[0]
    if command == 'scale_map':
        return scale_map.build_parser().parse_args(
            ['--radius-range', '5mm:6mm:2', '--delta-theta-p', word]).delta_theta_p[0]
    if command == 'lift_map':
        return math.radians(lift_map.build_parser().parse_args(
            ['--friction-angles', '5deg', '--delta-theta-p-max', word]).delta_theta_p_max)
    if command == 'dam_grasp':
        return grasp_client._parse(['--delta-theta-p', word]).delta_theta_p
    if command == 'dam_experiment':
        return math.radians(experiment._parse(['--delta-theta-p', word]).delta_theta_p[0])
    return math.radians(parse_axis('--delta-theta-p', [word], lower=0.0, quantity=ANGLE,
                                   unit_si=math.pi / 180)[0])


@pytest.mark.parametrize(('word', 'radians'), [('0.5', 0.5), ('10deg', math.radians(10.0)),
                                                ('0.3rad', 0.3)])
def test_every_command_reads_an_angle_the_same_way(word: str, radians: float) -> None:
    read = {command: _read(command, word) for command in COMMANDS}
    assert read == pytest.approx(dict.fromkeys(read, radians), rel=1e-9), read


@pytest.mark.parametrize('command', COMMANDS)
@pytest.mark.parametrize('word', ['10', '25'])
def test_every_command_refuses_a_bare_angle_in_degrees_and_says_what_was_meant(
        command: str, word: str, capsys: pytest.CaptureFixture[str]) -> None:
    from dam_experiments.errors import SweepError

    with pytest.raises((SystemExit, SweepError)) as caught:
        _read(command, word)
    said = (capsys.readouterr().err if caught.type is SystemExit else str(caught.value))
    assert f'did you mean {word}deg?' in said, said


@pytest.mark.parametrize(('value', 'quantity', 'text'), [
    (math.radians(80.0), ANGLE, '1.396 rad (80 deg)'),
    (0.006, LENGTH, '0.006 m (6 mm)'),
    ([math.radians(80.0)] * 3, ANGLE, '[1.396, 1.396, 1.396] rad ([80, 80, 80] deg)'),
    (np.full(9, 0.1), ANGLE, '[0.1, 0.1, 0.1, 0.1, 0.1, 0.1, ... (9 values)] rad '
                             '([5.73, 5.73, 5.73, 5.73, 5.73, 5.73, ... (9 values)] deg)'),
    ((0.03, 0.05), MASS, '[0.03, 0.05] kg ([30, 50] g)'),
])
def test_a_service_s_refusal_gives_si_and_the_usual_unit_to_4_digits(value, quantity,
                                                                     text) -> None:
    """``check_lift --delta-theta-p 80deg`` was refused as ``[1.3962634015954636, ...] rad``."""
    assert both_units(value, quantity) == text


@pytest.mark.parametrize(('text', 'says'), [
    ('10Nm/rad', "'10Nm/rad' is not a number: a stiffness is a plain number in N*m/rad (10, "
                 'not 10Nm/rad)'),
    ('soft', "'soft' is not a number: a stiffness is a plain number in N*m/rad"),
    ('0', "'0' must be greater than 0 N*m/rad"),
])
def test_a_stiffness_that_is_no_plain_number_is_refused_with_its_unit(text, says) -> None:
    with pytest.raises(argparse.ArgumentTypeError) as info:
        number_argument(above=0.0, unit='N*m/rad', what='stiffness')(text)
    assert str(info.value) == says
