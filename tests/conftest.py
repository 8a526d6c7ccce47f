"""Shared pytest configuration.

Unit tests import the pure cores straight from ``src/`` so that they test the working tree;
integration tests start the installed executables from ``ros2_ws/install``.
"""

from __future__ import annotations

import sys
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[1]
CONFIG_FILE = REPO_ROOT / 'config' / 'dam.yaml'

TESTS_DIR = Path(__file__).resolve().parent
if str(TESTS_DIR) not in sys.path:
    sys.path.insert(0, str(TESTS_DIR))  # shared helpers such as ros_testing

for _pkg in sorted((REPO_ROOT / 'src').iterdir()):
    if (_pkg / 'setup.py').is_file() and str(_pkg) not in sys.path:
        sys.path.insert(0, str(_pkg))


def _reserve_worker_domain() -> None:
    """Give this pytest-xdist worker a ROS_DOMAIN_ID of its own.

    ``scripts/test.sh`` reserves one domain for the run; with several workers the first keeps
    it and every other worker takes a free id the same way the script does (a lock on
    ``$TMPDIR/dam-ros-domains/<id>.lock``, held until the worker exits), so the nodes each
    worker starts never meet another worker's.
    """
    import fcntl
    import os
    import tempfile

    worker = os.environ.get('PYTEST_XDIST_WORKER', '')
    if not worker or worker == 'gw0' or 'ROS_DOMAIN_ID' not in os.environ:
        return
    lock_dir = Path(tempfile.gettempdir()) / 'dam-ros-domains'
    lock_dir.mkdir(parents=True, exist_ok=True)
    for offset in range(101):
        candidate = (offset + os.getpid()) % 101 + 1
        handle = open(lock_dir / f'{candidate}.lock', 'w')  # noqa: SIM115 (held to the end)
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            handle.close()
            continue
        _WORKER_DOMAIN_LOCKS.append(handle)
        os.environ['ROS_DOMAIN_ID'] = str(candidate)
        return
    raise RuntimeError('every ROS_DOMAIN_ID 1..101 is reserved by another run on this machine')


_WORKER_DOMAIN_LOCKS: list = []
_reserve_worker_domain()
