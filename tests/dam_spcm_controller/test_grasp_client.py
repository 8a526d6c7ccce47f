"""``dam_grasp`` argument parsing (the exit codes against a real server are in
tests/integration/test_dam_grasp.py)."""

from __future__ import annotations

import argparse
import math

import pytest

from dam_spcm_controller.grasp_client import _parse, parse_angle


@pytest.mark.parametrize('text, expected', [
    ('40deg', math.radians(40.0)), ('40 deg', math.radians(40.0)), ('0.7rad', 0.7),
    ('0.7', 0.7), ('1e-1', 0.1), ('.5deg', math.radians(0.5))])
def test_parse_angle(text: str, expected: float) -> None:
    assert parse_angle(text) == pytest.approx(expected)


@pytest.mark.parametrize('text', ['', 'forty', '40 degrees', 'nan', 'infdeg', '40deg40'])
def test_parse_angle_refuses(text: str) -> None:
    with pytest.raises(argparse.ArgumentTypeError):
        parse_angle(text)


def test_arguments() -> None:
    args = _parse(['--k-theta', '7', '--delta-theta-p', '40deg', '--cancel-after', '2'])
    assert args.k_theta == 7.0
    assert args.delta_theta_p == pytest.approx(math.radians(40.0))
    assert args.cancel_after == 2.0


def test_the_pair_defaults_to_the_configured_one() -> None:
    args = _parse(['--k-theta', '7'])
    assert args.k_theta == 7.0 and args.delta_theta_p is None
    args = _parse([])
    assert args.k_theta is None and args.delta_theta_p is None


@pytest.mark.parametrize('argv', [
    ['--k-theta', '0', '--delta-theta-p', '40deg'],
    ['--k-theta', '-1', '--delta-theta-p', '40deg'],
    ['--k-theta', '7', '--delta-theta-p', 'x'],
    ['--k-theta', '7', '--delta-theta-p', '40deg', '--cancel-after', '-1'],
    ['--k-theta', '7', '--delta-theta-p', '10']])  # 10 rad: 10deg meant, refused
def test_bad_arguments_exit_2(argv: list[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        _parse(argv)
    assert exc.value.code == 2
