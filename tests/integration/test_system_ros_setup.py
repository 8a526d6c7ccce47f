"""setup.sh's path for a system ROS 2 Jazzy, run against a stand-in for /opt/ros/jazzy.

``scripts/lib/make_fake_system_ros.sh`` lays the pinned ROS 2 wheels out as the apt packages
lay out /opt/ros/jazzy (setup.bash, bin/, lib/, lib/pythonX.Y/site-packages, share/, the
ament index). A copy of the repository's tracked files is then set up with
``DAM_SYSTEM_ROS_PREFIX`` pointing there, from an environment that carries nothing of this
test run's own ROS 2 (no venv, PYTHONPATH, LD_LIBRARY_PATH or ament paths), with the system
Python (the base interpreter of the running one). The tests check the branch setup.sh took,
the venv with system site packages, the overlay build, what ``scripts/env.sh`` imports, and
one real node answering over DDS in that environment.

Slow by nature (pip into the prefix and the venv, a full colcon build): a few minutes.
"""

from __future__ import annotations

import json
import math
import os
import re
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from dam_analysis.analysis import LiftAnalyzer
from dam_common.config import load_config

pytestmark = pytest.mark.integration

REPO_ROOT = Path(__file__).resolve().parents[2]
MAKE_PREFIX = REPO_ROOT / 'scripts' / 'lib' / 'make_fake_system_ros.sh'
PY_VERSION = f'{sys.version_info.major}.{sys.version_info.minor}'
SERVER = Path('ros2_ws/install/dam_analysis/lib/dam_analysis/check_lift_server')

# What an environment that sourced ROS 2, a venv or a workspace carries; none of it may leak
# from this test run into the system-ROS setup (DAM_* settings are dropped as well).
ROS_VARIABLES = (
    'VIRTUAL_ENV', 'VIRTUAL_ENV_PROMPT', 'PYTHONPATH', 'PYTHONHOME', 'LD_LIBRARY_PATH',
    'AMENT_PREFIX_PATH', 'CMAKE_PREFIX_PATH', 'COLCON_PREFIX_PATH', 'PKG_CONFIG_PATH',
    'ROS_DISTRO', 'ROS_VERSION', 'ROS_PYTHON_VERSION', '_ROS_WHEELS_BOOTSTRAP_COMPLETE',
)

ENV_PROBE = '''
import json, os, sys
import dam_analysis, dam_interfaces, numpy, rclpy
from dam_interfaces.srv import CheckLift
print(json.dumps({
    'sys_prefix': sys.prefix, 'rclpy': rclpy.__file__, 'numpy': numpy.__file__,
    'dam_analysis': dam_analysis.__file__, 'dam_interfaces': dam_interfaces.__file__,
    'check_lift_srv': sys.modules[CheckLift.__module__].__file__,
    'ros_distro': os.environ.get('ROS_DISTRO'),
}))
'''

CLIENT = '''
import json, math, sys
import rclpy
from dam_interfaces.srv import CheckLift

rclpy.init()
node = rclpy.create_node('system_ros_setup_client')
client = node.create_client(CheckLift, '/check_lift')
if not client.wait_for_service(timeout_sec=30.0):
    sys.exit('/check_lift did not appear within 30 s')
future = client.call_async(CheckLift.Request(
    k_theta=[7.0], delta_theta_p=[math.radians(10.0)], friction_angle=math.radians(5.0)))
rclpy.spin_until_future_complete(node, future, timeout_sec=30.0)
if not future.done():
    sys.exit('/check_lift did not answer within 30 s')
r = future.result()
print(json.dumps({
    'ok': r.ok, 'message': r.message, 'lift_guaranteed': r.lift_guaranteed,
    'csm_lift': r.csm_lift, 'worst_case_margin': r.worst_case_margin,
    'csm_margin': r.csm_margin, 'delta_theta_s': list(r.delta_theta_s),
}))
node.destroy_node()
rclpy.shutdown()
'''


def _system_python() -> str:
    """The interpreter this test's venv was made from: what setup.sh would find as python3."""
    if sys.prefix != sys.base_prefix:
        return getattr(sys, '_base_executable', sys.executable)
    return sys.executable


def _inside(path: str, roots: list[str]) -> bool:
    return any(root and (path == root or path.startswith(root.rstrip('/') + '/'))
               for root in roots)


def _clean_env() -> dict[str, str]:
    """os.environ without this run's ROS 2, venv and workspace (variables and PATH entries)."""
    env = dict(os.environ)
    outer = [sys.prefix, str(REPO_ROOT)]
    for name in ('AMENT_PREFIX_PATH', 'COLCON_PREFIX_PATH', 'VIRTUAL_ENV'):
        outer += env.get(name, '').split(os.pathsep)
    for name in list(env):
        if name in ROS_VARIABLES or name.startswith('DAM_'):
            del env[name]
    env['PATH'] = os.pathsep.join(
        p for p in env.get('PATH', '').split(os.pathsep) if p and not _inside(p, outer))
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    return env


def _tail(text: str, lines: int = 60) -> str:
    return '\n'.join(text.splitlines()[-lines:])


def _run(command: list[str], env: dict[str, str], cwd: Path | None = None,
         timeout: float = 120.0) -> subprocess.CompletedProcess[str]:
    return subprocess.run(command, env=env, cwd=cwd, timeout=timeout, text=True,
                          stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                          stderr=subprocess.STDOUT)


def _in_env_sh(copy: Path, command: str) -> str:
    """A bash command line that runs ``command`` after ``source scripts/env.sh`` in the copy,
    sourced from a strict script (``set -euo pipefail``), as a user's bring-up script would."""
    cd = shlex.quote(str(copy))
    return f'set -euo pipefail; cd {cd}; source scripts/env.sh; {command}'


@pytest.fixture(scope='module')
def work_dir() -> Iterator[Path]:
    path = Path(tempfile.mkdtemp(prefix='dam-system-ros-'))
    yield path
    shutil.rmtree(path, ignore_errors=True)


@pytest.fixture(scope='module')
def clean_env() -> dict[str, str]:
    env = _clean_env()
    env['DAM_PYTHON'] = _system_python()
    return env


@pytest.fixture(scope='module')
def fake_prefix(work_dir: Path, clean_env: dict[str, str]) -> Path:
    prefix = work_dir / 'opt-ros-jazzy'
    start = time.monotonic()
    result = _run(['bash', str(MAKE_PREFIX), str(prefix)], clean_env, timeout=900.0)
    if result.returncode != 0:
        pytest.fail(f'make_fake_system_ros.sh failed ({result.returncode}):\n'
                    + _tail(result.stdout))
    sys.stderr.write(f'[fake system prefix made in {time.monotonic() - start:.0f} s]\n')
    return prefix


@pytest.fixture(scope='module')
def repo_copy(work_dir: Path) -> Path:
    """The repository's tracked files (no .venv, no ros2_ws outputs) in a new directory."""
    listed = subprocess.run(['git', '-C', str(REPO_ROOT), 'ls-files', '-z'],
                            capture_output=True, check=False)
    if listed.returncode != 0:
        pytest.fail('git ls-files failed: the test copies the tracked files of a git checkout: '
                    + listed.stderr.decode(errors='replace'))
    copy = work_dir / 'repo'
    for raw in listed.stdout.split(b'\0'):
        if not raw:
            continue
        rel = os.fsdecode(raw)
        src = REPO_ROOT / rel
        if not src.exists() and not src.is_symlink():
            continue  # deleted in the working tree
        (copy / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy2(src, copy / rel, follow_symlinks=False)
    assert (copy / 'scripts' / 'setup.sh').is_file()
    assert not (copy / '.venv').exists() and not (copy / 'ros2_ws' / 'install').exists()
    return copy


@pytest.fixture(scope='module')
def setup_output(fake_prefix: Path, repo_copy: Path, clean_env: dict[str, str]) -> str:
    """Everything ``DAM_SYSTEM_ROS_PREFIX=<prefix> bash scripts/setup.sh`` printed."""
    env = dict(clean_env, DAM_SYSTEM_ROS_PREFIX=str(fake_prefix))
    start = time.monotonic()
    result = _run(['bash', 'scripts/setup.sh'], env, cwd=repo_copy, timeout=1200.0)
    if result.returncode != 0:
        pytest.fail(f'setup.sh with DAM_SYSTEM_ROS_PREFIX failed ({result.returncode}):\n'
                    + _tail(result.stdout))
    sys.stderr.write(f'[setup.sh in system mode took {time.monotonic() - start:.0f} s]\n')
    return result.stdout


@pytest.fixture(scope='module')
def ros_env(clean_env: dict[str, str], fake_prefix: Path) -> dict[str, str]:
    """The environment the nodes and the client run in: this run's own ROS_DOMAIN_ID."""
    domain = os.environ.get('ROS_DOMAIN_ID')
    if not domain:
        pytest.fail('ROS_DOMAIN_ID is not set: run through scripts/test.sh, which reserves one')
    return dict(clean_env, DAM_SYSTEM_ROS_PREFIX=str(fake_prefix), ROS_DOMAIN_ID=domain)


def test_prefix_is_laid_out_as_apt_lays_out_opt_ros(fake_prefix: Path) -> None:
    site = fake_prefix / 'lib' / f'python{PY_VERSION}' / 'site-packages'
    for rel in ('setup.bash', 'local_setup.bash', 'bin/colcon', 'lib/librcl.so',
                'lib/librmw_fastrtps_cpp.so', 'include/rcl/rcl/rcl.h',
                'share/rclpy/package.xml', 'share/std_msgs/msg/String.msg',
                'share/ament_index/resource_index/packages/rclpy',
                'share/ament_index/resource_index/packages/rosidl_default_generators'):
        assert (fake_prefix / rel).exists(), f'{rel} is missing from the prefix'
    for module in ('rclpy', 'std_msgs', 'rosidl_generator_py', 'numpy', 'scipy', 'yaml',
                   'matplotlib', 'colcon_core'):
        assert (site / module / '__init__.py').is_file(), f'{module} is not in {site}'
    # The libraries auditwheel vendored in site-packages live in lib/ now, the re-exec hook
    # of the wheels is gone: only setup.bash's LD_LIBRARY_PATH finds the libraries.
    assert sorted(site.glob('ros_*.libs')) == []
    assert sorted(site.glob('ros_wheels_bootstrapper*')) == []
    assert sorted((fake_prefix / 'lib').glob('libtinyxml2-*.so*')), 'vendored libs not in lib/'
    stale = [p for p in (fake_prefix / 'share').glob('*/cmake/*.cmake')
             if '/opt/python/' in p.read_text(errors='replace')]
    assert stale == [], 'CMake files still name the wheel build machine'


def test_setup_bash_sets_what_the_real_one_sets(fake_prefix: Path,
                                                clean_env: dict[str, str]) -> None:
    probe = ('import json, os, rclpy; rclpy.init(); rclpy.shutdown(); '
             'print(json.dumps(dict(os.environ, rclpy_file=rclpy.__file__)))')
    # Sourced twice, under set -u, with the interpreter named by its path.
    setup = shlex.quote(f'{fake_prefix}/setup.bash')
    script = f'set -euo pipefail; source {setup}; source {setup}; exec "$DAM_PYTHON" -c "$0"'
    result = _run(['bash', '-c', script, probe], clean_env)
    assert result.returncode == 0, _tail(result.stdout)
    env = json.loads(result.stdout.strip().splitlines()[-1])
    assert [env.get(name) for name in ('ROS_DISTRO', 'ROS_VERSION', 'ROS_PYTHON_VERSION')] == \
        ['jazzy', '2', '3']
    site = f'{fake_prefix}/lib/python{PY_VERSION}/site-packages'
    for name, entry in (('AMENT_PREFIX_PATH', str(fake_prefix)),
                        ('CMAKE_PREFIX_PATH', str(fake_prefix)), ('PYTHONPATH', site),
                        ('LD_LIBRARY_PATH', f'{fake_prefix}/lib'),
                        ('PATH', f'{fake_prefix}/bin')):
        entries = env.get(name, '').split(os.pathsep)
        assert entries[0] == entry and entries.count(entry) == 1, f'{name}={env.get(name)}'
    assert env['rclpy_file'].startswith(site + '/')
    assert '_ROS_WHEELS_BOOTSTRAP_COMPLETE' not in env, 'the wheels re-exec hook ran'


def test_setup_takes_the_system_branch(setup_output: str, repo_copy: Path,
                                       fake_prefix: Path) -> None:
    assert f'ROS 2: system install at {fake_prefix}' in setup_output
    assert 'wheels from PyPI' not in setup_output
    assert "Repairing the wheels' CMake exports" not in setup_output
    assert 'apt-get' not in setup_output, 'the system Python packages were not found'
    pyvenv = (repo_copy / '.venv' / 'pyvenv.cfg').read_text().splitlines()
    assert 'include-system-site-packages = true' in pyvenv
    # Only the extras go into the venv; ROS 2 and numpy come from the system.
    venv_site = repo_copy / '.venv' / 'lib' / f'python{PY_VERSION}' / 'site-packages'
    assert sorted(venv_site.glob('pybullet*')), 'pybullet is not in the venv'
    for module in ('rclpy', 'numpy', 'colcon_core'):
        assert not (venv_site / module).exists(), f'{module} was installed into the venv'


def test_overlay_is_built_on_the_system_prefix(setup_output: str, repo_copy: Path,
                                               fake_prefix: Path) -> None:
    n_packages = len(list((REPO_ROOT / 'src').glob('*/package.xml')))
    if not (fake_prefix / 'share' / 'tf2_msgs' / 'package.xml').is_file():
        # interfaces/ (tf2_msgs) is built where the ROS 2 underneath lacks it
        n_packages += len(list((REPO_ROOT / 'interfaces').glob('*/package.xml')))
    assert f'Summary: {n_packages} packages finished' in setup_output
    install = repo_copy / 'ros2_ws' / 'install'
    assert (install / '.dam-source-hash').is_file()
    assert (install / 'dam_analysis' / 'lib' / 'dam_analysis' / 'check_lift_server').is_file()
    cache = (repo_copy / 'ros2_ws' / 'build' / 'dam_interfaces' / 'CMakeCache.txt').read_text()
    generators = f'rosidl_default_generators_DIR:PATH={fake_prefix}/share/'
    assert generators in cache, 'dam_interfaces did not find rosidl in the system prefix'
    # colcon chains the system prefix (its local_setup.bash) into the overlay's setup.bash, as
    # it does /opt/ros/jazzy.
    assert f'COLCON_CURRENT_PREFIX="{fake_prefix}"' in (install / 'setup.bash').read_text()
    # Progress while it works: a line per package colcon starts and finishes, with its time.
    for pkg in sorted(d.parent.name for d in (REPO_ROOT / 'src').glob('*/package.xml')):
        assert f'    Starting >>> {pkg}' in setup_output
        assert re.search(rf'^    Finished <<< {pkg} \[[0-9.]+s\]$', setup_output, re.M), pkg


def test_setup_says_what_pip_is_doing(setup_output: str) -> None:
    # One line per package pip collects and a count of what it installed, each with the
    # seconds since the step began, and the expected duration before it starts.
    assert 'about 2 minutes on an idle machine' in setup_output
    collected = re.findall(r'^    \[ *\d+ s\] collecting (\S+)', setup_output, re.M)
    assert any(name.startswith('rosbags==') for name in collected), collected
    installed = re.search(r'^    \[ *\d+ s\] installed (\d+) packages$', setup_output, re.M)
    assert installed and int(installed.group(1)) >= len(collected) > 0


def test_env_sh_imports_rclpy_from_the_system_and_ours_from_the_overlay(
        setup_output: str, repo_copy: Path, fake_prefix: Path,
        ros_env: dict[str, str]) -> None:
    result = _run(['bash', '-c', _in_env_sh(repo_copy, 'python -c "$0"'), ENV_PROBE], ros_env)
    assert result.returncode == 0, _tail(result.stdout)
    found = json.loads(result.stdout.strip().splitlines()[-1])
    site = f'{fake_prefix}/lib/python{PY_VERSION}/site-packages/'
    install = f'{repo_copy}/ros2_ws/install/'
    assert found['sys_prefix'] == f'{repo_copy}/.venv'
    assert found['rclpy'].startswith(site), found['rclpy']
    assert found['numpy'].startswith(site), found['numpy']
    for key in ('dam_analysis', 'dam_interfaces', 'check_lift_srv'):
        assert found[key].startswith(install), f'{key} from {found[key]}'
    assert found['ros_distro'] == 'jazzy'


def _mapped_files(pid: int) -> set[str]:
    lines = Path(f'/proc/{pid}/maps').read_text().splitlines()
    return {line.split(None, 5)[5] for line in lines if len(line.split(None, 5)) == 6}


def test_check_lift_server_answers_on_the_system_ros(setup_output: str, repo_copy: Path,
                                                    fake_prefix: Path,
                                                    ros_env: dict[str, str]) -> None:
    log = tempfile.TemporaryFile(mode='w+')
    server = subprocess.Popen(['bash', '-c', _in_env_sh(repo_copy, f'exec {SERVER}')],
                              env=ros_env, stdin=subprocess.DEVNULL, stdout=log,
                              stderr=subprocess.STDOUT)
    try:
        result = _run(['bash', '-c', _in_env_sh(repo_copy, 'python -c "$0"'), CLIENT],
                      ros_env, timeout=90.0)
        log.seek(0)
        assert result.returncode == 0, f'{_tail(result.stdout)}\n--- server ---\n{log.read()}'
        answer = json.loads(result.stdout.strip().splitlines()[-1])
        # The server runs the system prefix's rcl and the overlay's message libraries.
        mapped = _mapped_files(server.pid)
        assert f'{fake_prefix}/lib/librcl.so' in mapped
        assert any(p.startswith(f'{repo_copy}/ros2_ws/install/dam_interfaces/')
                   for p in mapped)
    finally:
        if server.poll() is None:
            server.send_signal(signal.SIGINT)
        try:
            status = server.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            server.kill()
            status = server.wait(timeout=10.0)
        log.seek(0)
        server_output = log.read()
        log.close()
    assert status == 0, f'check_lift_server exited with {status} on SIGINT:\n{server_output}'

    config = load_config(REPO_ROOT / 'config' / 'dam.yaml')
    expected = LiftAnalyzer(config).check_lift([7.0], [math.radians(10.0)], math.radians(5.0))
    assert answer['ok'], answer['message']
    assert answer['lift_guaranteed'] is True and expected.lift_guaranteed
    assert answer['csm_lift'] == expected.csm_lift
    np.testing.assert_allclose(answer['worst_case_margin'], expected.worst_case_margin)
    np.testing.assert_allclose(answer['csm_margin'], expected.csm_margin)
    np.testing.assert_allclose(answer['delta_theta_s'], expected.delta_theta_s)
