"""Angles on the analysis tools' command lines (module angle_args)."""

from __future__ import annotations

import argparse
import math

import pytest

from dam_analysis.angle_args import parse_angle, parse_angle_range, parse_degrees


def test_a_suffix_means_the_same_everywhere_a_bare_number_its_tool_s_unit() -> None:
    assert parse_angle('40deg') == pytest.approx(math.radians(40.0))
    assert parse_angle('0.7rad') == 0.7 and parse_angle('0.7') == 0.7  # check_lift: radians
    assert parse_degrees('40') == pytest.approx(math.radians(40.0))  # plan_lift, scale_map
    assert parse_degrees('0.7rad') == 0.7 and parse_degrees(' 5DEG ') == pytest.approx(
        math.radians(5.0))
    for bad in ('forty', '5 degrees', 'nan', 'infdeg', ''):
        with pytest.raises(argparse.ArgumentTypeError):
            parse_degrees(bad)


def test_a_bare_number_below_one_degree_is_named(capsys: pytest.CaptureFixture[str]) -> None:
    """0.0873 is 5 deg in radians: read as degrees it plans for almost no friction."""
    assert parse_degrees('0.0873') == pytest.approx(math.radians(0.0873))
    assert "'0.0873' is read in degrees (0.0873 deg); write 0.0873rad" in capsys.readouterr().err
    for quiet in ('3', '0', '0.5deg', '0.05rad'):
        parse_degrees(quiet)
    parse_angle('0.0873')  # radians there: nothing to say
    assert capsys.readouterr().err == ''


def test_ranges() -> None:
    low, high = parse_angle_range('3:6')
    assert (low, high) == pytest.approx((math.radians(3.0), math.radians(6.0)))
    assert parse_angle_range('0.05rad:6deg') == pytest.approx((0.05, math.radians(6.0)))
    assert parse_angle_range('5') == pytest.approx((math.radians(5.0),) * 2)
    for bad, words in (('6:3', 'empty range, max 3 deg is below min 6 deg'),
                       ('1:2:3', 'is not MIN:MAX'), ('a:3', 'is not an angle')):
        with pytest.raises(argparse.ArgumentTypeError, match=words):
            parse_angle_range(bad)
