"""scripts/lib/episode_complete.py, which run.sh asks whether the recorder marked an episode
bag complete: the metadata's custom data key ``dam_episode.complete``, nothing without it."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
import yaml

SCRIPT = Path(__file__).resolve().parents[2] / 'scripts' / 'lib' / 'episode_complete.py'


def _bag(tmp_path: Path, custom_data: dict[str, str] | None) -> Path:
    info: dict[str, object] = {'version': 9, 'storage_identifier': 'mcap'}
    if custom_data is not None:
        info['custom_data'] = custom_data
    bag = tmp_path / 'episode'
    bag.mkdir()
    (bag / 'metadata.yaml').write_text(
        yaml.safe_dump({'rosbag2_bagfile_information': info}), encoding='utf-8')
    return bag


def _ask(bag: Path) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, str(SCRIPT), str(bag)], capture_output=True,
                          text=True, timeout=30)


@pytest.mark.parametrize(('custom_data', 'said'), [
    ({'dam_episode.complete': 'false', 'dam_episode.outcome': 'SUCCESS'}, 'false\n'),
    ({'dam_episode.complete': 'true'}, 'true\n'),
    ({'dam_episode.outcome': 'SUCCESS'}, ''),  # an older recorder: say nothing
    (None, ''),
])
def test_the_key_is_read_and_its_absence_says_nothing(
        tmp_path: Path, custom_data: dict[str, str] | None, said: str) -> None:
    asked = _ask(_bag(tmp_path, custom_data))
    assert asked.returncode == 0, asked.stderr
    assert asked.stdout == said


def test_a_directory_without_metadata_says_nothing(tmp_path: Path) -> None:
    asked = _ask(tmp_path)
    assert asked.returncode == 0 and asked.stdout == '', asked.stderr
