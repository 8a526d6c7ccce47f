"""Whether the recorder marked an episode bag complete.

    python scripts/lib/episode_complete.py BAG_DIR

Reads ``BAG_DIR/metadata.yaml`` (rosbag2 layout) and prints the value of the custom data key
``dam_episode.complete`` of ``rosbag2_bagfile_information``: ``true`` or ``false``. Prints
nothing when the bag has no such key (an older recorder) or no readable metadata. Exit status
0, except 2 for a call without exactly one argument. Needs PyYAML only.
"""

from __future__ import annotations

import sys
from pathlib import Path

KEY = 'dam_episode.complete'


def episode_complete(bag: Path) -> str:
    """``'true'``, ``'false'`` or ``''`` (no key, no metadata): see the module docstring."""
    import yaml

    try:
        data = yaml.safe_load((bag / 'metadata.yaml').read_text(encoding='utf-8'))
    except (OSError, yaml.YAMLError):
        return ''
    info = data.get('rosbag2_bagfile_information') if isinstance(data, dict) else None
    custom = info.get('custom_data') if isinstance(info, dict) else None
    value = custom.get(KEY) if isinstance(custom, dict) else None
    if value is None:
        return ''
    return str(value).strip().lower()


def main(argv: list[str]) -> int:
    if len(argv) != 1:
        print('usage: episode_complete.py BAG_DIR', file=sys.stderr)
        return 2
    value = episode_complete(Path(argv[0]))
    if value:
        print(value)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
