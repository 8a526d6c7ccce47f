"""The README's (or, moved, docs/'s) rate of /joint_states is each backend's configured one
(issue 34: it said "/joint_states (500 Hz)", the UDP link's rate, where the Dynamixel backend
publishes at 250)."""

from __future__ import annotations

import re
from pathlib import Path

from dam_common.config import load_config

REPO_ROOT = Path(__file__).resolve().parents[2]


def test_the_readme_gives_joint_states_the_rate_of_each_backend() -> None:
    config = load_config(REPO_ROOT / 'config' / 'dam.yaml')
    assert config.dynamixel is not None
    pages = [REPO_ROOT / 'README.md', *sorted((REPO_ROOT / 'docs').glob('*.md'))]
    text = ' '.join(' '.join(p.read_text(encoding='utf-8').split()) for p in pages)
    said = re.search(r"`/joint_states` \((at the device's rate[^)]*)\)", text)
    assert said is not None, 'README (or docs/) names no rate of /joint_states'
    rates = said.group(1)
    assert f'{config.device.rate_hz:g} Hz over the UDP link' in rates, rates
    assert f'{config.dynamixel.rate_hz:g} Hz on the Dynamixel bus' in rates, rates
