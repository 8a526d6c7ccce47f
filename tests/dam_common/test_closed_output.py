"""Every command-line entry point ends quietly when its standard output is closed (issue 34:
``dam_experiment ... | head -2`` ended with a ``BrokenPipeError`` traceback).

Each installed executable (every ``console_scripts`` entry of the packages' ``setup.py``)
writes its ``--help`` into a pipe whose reading end is closed already, as ``head`` leaves it:
status 141 (128 + SIGPIPE, as a shell reports ``cat`` ended by ``head``) or 0, and nothing on
standard error but what the command says itself: no traceback, no "Exception ignored".
"""

from __future__ import annotations

import ast
import os
import subprocess
from pathlib import Path

import pytest

from dam_common.closed_output import OUTPUT_CLOSED
from ros_testing import installed_executable

REPO_ROOT = Path(__file__).resolve().parents[2]


def _console_scripts() -> list[tuple[str, str]]:
    """(package, executable) of every console script the packages install."""
    found = []
    for setup in sorted(REPO_ROOT.glob('src/*/setup.py')):
        for node in ast.walk(ast.parse(setup.read_text(encoding='utf-8'))):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                    and ' = ' in node.value and ':' in node.value:
                found.append((setup.parent.name, node.value.split(' = ')[0].strip()))
    return found


SCRIPTS = _console_scripts()


def test_the_packages_install_the_commands_this_test_knows() -> None:
    names = {name for _, name in SCRIPTS}
    assert {'dam_experiment', 'sweep', 'check_lift', 'lift_map', 'bag', 'hand_urdf',
            'recorder', 'dam_grasp'} <= names, names


def _write_into_closed_pipe(command: list[str]) -> subprocess.CompletedProcess[str]:
    read_end, write_end = os.pipe()
    os.close(read_end)  # as `| head` leaves it once it has its lines
    try:
        return subprocess.run(command, stdout=write_end, stderr=subprocess.PIPE, text=True,
                              timeout=120)
    finally:
        os.close(write_end)


@pytest.mark.parametrize(('package', 'executable'), SCRIPTS,
                         ids=[name for _, name in SCRIPTS])
def test_a_closed_standard_output_ends_a_command_quietly(package: str,
                                                         executable: str) -> None:
    path = installed_executable(package, executable)
    ran = _write_into_closed_pipe([str(path), '--help'])
    assert ran.returncode in (0, OUTPUT_CLOSED), (ran.returncode, ran.stderr)
    assert 'Traceback' not in ran.stderr and 'BrokenPipe' not in ran.stderr, ran.stderr
    assert 'Exception ignored' not in ran.stderr, ran.stderr


def test_a_command_at_work_ends_quietly_when_head_has_its_lines() -> None:
    """The issue's command: a grid of grasps whose table goes into ``head -2``."""
    path = installed_executable('dam_experiments', 'dam_experiment')
    ran = _write_into_closed_pipe([str(path), '--k-theta', '0.5', '1', '--delta-theta-p',
                                   '5deg', '--max-time', '0.6'])
    assert ran.returncode == OUTPUT_CLOSED, (ran.returncode, ran.stderr)
    assert 'Traceback' not in ran.stderr and 'BrokenPipe' not in ran.stderr, ran.stderr
