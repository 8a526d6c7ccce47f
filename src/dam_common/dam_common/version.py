"""The suite's version, as recorded with data (episode bags) so that a run can be reproduced."""

from __future__ import annotations

import subprocess
from functools import lru_cache
from importlib import metadata
from pathlib import Path

#: The suite's packages whose versions make up :func:`software_version`.
PACKAGES: tuple[str, ...] = ('dam_common', 'dam_analysis', 'dam_hand_driver',
                             'dam_spcm_controller', 'dam_sim_bridge', 'dam_experiments',
                             'dam_recorder')


def _git_commit(directory: Path) -> str:
    """``<commit>`` or ``<commit>-dirty`` of the git checkout holding ``directory``; empty when
    it is not in one (an install from a tarball, a deb) or git is missing."""
    try:
        head = subprocess.run(['git', '-C', str(directory), 'rev-parse', '--short=12', 'HEAD'],
                              capture_output=True, text=True, timeout=2.0, check=True)
        status = subprocess.run(['git', '-C', str(directory), 'status', '--porcelain',
                                 '--untracked-files=no'],
                                capture_output=True, text=True, timeout=2.0, check=True)
    except (OSError, subprocess.SubprocessError):
        return ''
    commit = head.stdout.strip()
    return f'{commit}-dirty' if commit and status.stdout.strip() else commit


@lru_cache(maxsize=1)
def software_version() -> str:
    """The installed versions of the suite's packages, and the commit of the git checkout the
    install lies in (``scripts/setup.sh`` builds into the checkout's ``ros2_ws/install`` and
    rebuilds whenever the sources change), with ``-dirty`` when tracked files are modified,
    e.g. ``dam_common 0.1.0, dam_analysis 0.1.0, ... (git 1a2b3c4d5e6f)``.

    Computed once per process (a git call of at most a few milliseconds).
    """
    versions = []
    for package in PACKAGES:
        try:
            versions.append(f'{package} {metadata.version(package)}')
        except metadata.PackageNotFoundError:
            continue
    text = ', '.join(versions) or 'unknown'
    commit = _git_commit(Path(__file__).resolve().parent)
    return f'{text} (git {commit})' if commit else text
