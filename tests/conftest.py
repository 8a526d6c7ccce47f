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
