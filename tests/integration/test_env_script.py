"""``scripts/env.sh`` sourced from a strict bash script: it must work under ``set -u`` (and
leave the caller's setting as it was), and afterwards the ament index must list the ROS
packages of the ROS 2 installation (the wheels in the venv, or the system's) as well as the
workspace's own."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]

#: Asks the ament index, as `ros2` tools do, and prints what it found as JSON.
_ASK_INDEX = """
import json, os
from ament_index_python.packages import get_package_prefix, get_packages_with_prefixes
packages = get_packages_with_prefixes()
print(json.dumps({'packages': sorted(packages),
                  'distro': [os.environ.get(k) for k in
                             ('ROS_DISTRO', 'ROS_VERSION', 'ROS_PYTHON_VERSION')],
                  'sensor_msgs': get_package_prefix('sensor_msgs'),
                  'dam_common': get_package_prefix('dam_common')}))
"""


def _clean_environment() -> dict[str, str]:
    """This process's environment without what env.sh sets up (a fresh login shell's view):
    no ament, colcon or venv variables, no PYTHONPATH, nothing of the repository on PATH."""
    drop_prefixes = ('AMENT_', 'COLCON_', 'CMAKE_PREFIX_PATH', 'VIRTUAL_ENV', 'PYTHONPATH',
                     'ROS_', 'DAM_REPO_ROOT', '_ROS_WHEELS', 'LD_LIBRARY_PATH')
    env = {k: v for k, v in os.environ.items() if not k.startswith(drop_prefixes)}
    env['PATH'] = os.pathsep.join(p for p in os.environ.get('PATH', '').split(os.pathsep)
                                  if p and not p.startswith(str(REPO_ROOT)))
    return env


def _bash(script: str) -> subprocess.CompletedProcess:
    return subprocess.run(['bash', '-c', script], cwd=REPO_ROOT, env=_clean_environment(),
                          capture_output=True, text=True, timeout=120, stdin=subprocess.DEVNULL)


@pytest.mark.skipif(not (REPO_ROOT / 'ros2_ws' / 'install' / 'setup.bash').is_file(),
                    reason='the workspace is not built (scripts/setup.sh)')
def test_env_sh_works_under_set_u_and_the_ament_index_lists_the_ros_packages() -> None:
    proc = _bash('set -euo pipefail\n'
                 'source scripts/env.sh\n'
                 'case $- in *u*) ;; *) echo "env.sh switched set -u off" >&2; exit 3 ;; esac\n'
                 f'python -c "{_ASK_INDEX}"\n')
    assert proc.returncode == 0, proc.stderr
    found = json.loads(proc.stdout.strip().splitlines()[-1])
    for package in ('sensor_msgs', 'std_msgs', 'diagnostic_msgs', 'rclpy', 'dam_common',
                    'dam_interfaces', 'dam_hand_driver'):
        assert package in found['packages'], package
    ros_prefix = Path(found['sensor_msgs'])
    marker = ros_prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / 'sensor_msgs'
    assert marker.is_file()
    system_ros = (Path('/opt/ros/jazzy/setup.bash').is_file()
                  and os.environ.get('DAM_ROS', 'auto') != 'wheels')
    if not system_ros:  # the wheels in the repository's venv
        assert ros_prefix == REPO_ROOT / '.venv'
    # the workspace overlay comes first
    assert Path(found['dam_common']) == REPO_ROOT / 'ros2_ws' / 'install' / 'dam_common'
    # as a sourced Jazzy install (ros2 doctor's distribution check reads ROS_DISTRO)
    assert found['distro'] == ['jazzy', '2', '3']


def test_env_sh_leaves_set_u_off_when_the_caller_had_it_off() -> None:
    proc = _bash('set +u\nsource scripts/env.sh\necho "flags $-"\n')
    assert proc.returncode == 0, proc.stderr
    assert 'u' not in proc.stdout.split('flags ')[-1]
