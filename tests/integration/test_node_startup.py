"""Every node refuses a bad start-up configuration with one clear line and a non-zero exit
status, never a traceback: a configuration file that does not exist, one that does not
validate, a parameter override of the wrong type or out of its range. The controller starts
without the analysis' heavy parts (issue #32: on a loaded machine the nodes' start-up took
over a minute)."""

from __future__ import annotations

import signal
import subprocess
from pathlib import Path

import pytest
import yaml

from ros_testing import INSTALL_DIR, installed_executable

pytestmark = pytest.mark.integration

#: (package, executable, exit status on a start-up error)
NODES = [('dam_analysis', 'check_lift_server', 1), ('dam_hand_driver', 'hand_driver', 1),
         ('dam_sim_bridge', 'sim_bridge', 1), ('dam_spcm_controller', 'spcm_controller', 2)]


def _start(package: str, executable: str, *ros_args: str) -> subprocess.CompletedProcess:
    cmd = [str(installed_executable(package, executable)), '--ros-args', *ros_args]
    return subprocess.run(cmd, capture_output=True, text=True, timeout=60,
                          stdin=subprocess.DEVNULL)


def _assert_refused(proc: subprocess.CompletedProcess, status: int, *words: str) -> None:
    output = proc.stdout + proc.stderr
    assert proc.returncode == status, output
    assert 'cannot start' in output, output
    assert 'Traceback' not in output, output
    for word in words:
        assert word in output, output


@pytest.mark.parametrize(('package', 'executable', 'status'), NODES)
def test_a_missing_config_file_is_refused_by_name(tmp_path: Path, package: str,
                                                   executable: str, status: int) -> None:
    missing = tmp_path / 'no_such_dam.yaml'
    proc = _start(package, executable, '-p', f'config_file:={missing}')
    _assert_refused(proc, status, str(missing))


@pytest.mark.parametrize(('package', 'executable', 'status'), NODES)
def test_an_invalid_config_file_is_refused_by_key(tmp_path: Path, package: str,
                                                   executable: str, status: int) -> None:
    repo = Path(__file__).resolve().parents[2]
    text = (repo / 'config' / 'dam.yaml').read_text(encoding='utf-8')
    bad = tmp_path / 'dam.yaml'
    data = yaml.safe_load(text)
    data['object']['library']['cylinder']['radius_m'] = -0.01
    bad.write_text(yaml.safe_dump(data), encoding='utf-8')
    proc = _start(package, executable, '-p', f'config_file:={bad}')
    _assert_refused(proc, status, 'object.library.cylinder.radius_m', '-0.01')


@pytest.mark.parametrize(('package', 'executable', 'status'), [
    node for node in NODES if node[1] in ('hand_driver', 'sim_bridge', 'spcm_controller')])
def test_an_object_outside_the_library_is_refused_by_name(package: str, executable: str,
                                                          status: int) -> None:
    proc = _start(package, executable, '-p', 'object:=pencil')
    _assert_refused(proc, status, "'pencil' is not in the object library", 'hex_pencil')


@pytest.mark.parametrize(('package', 'executable', 'override', 'word'), [
    ('dam_analysis', 'check_lift_server', 'default_friction_angle:=2.0', 'default_friction_angle'),
    ('dam_hand_driver', 'hand_driver', 'thread_priority:=200', 'thread_priority'),
    ('dam_hand_driver', 'hand_driver', 'thread_priority:=high', 'thread_priority'),
    ('dam_sim_bridge', 'sim_bridge', 'thread_priority:=-3', 'thread_priority'),
    ('dam_hand_driver', 'dam_state_publisher', 'publish_frequency:=-1.0', 'publish_frequency'),
    ('dam_hand_driver', 'dam_state_publisher', 'publish_frequency:=0.0', 'publish_frequency'),
    ('dam_hand_driver', 'dam_state_publisher', 'robot_state:=maybe', 'robot_state'),
])
def test_a_bad_parameter_override_is_refused_by_name(package: str, executable: str,
                                                      override: str, word: str) -> None:
    proc = _start(package, executable, '-p', override)
    _assert_refused(proc, 1, word)


@pytest.mark.parametrize(('package', 'executable', 'status'), NODES)
def test_a_malformed_params_file_is_one_line_naming_it(tmp_path: Path, package: str,
                                                       executable: str, status: int) -> None:
    bad = tmp_path / 'params.yaml'
    bad.write_text(f'{executable}:\n  ros__parameters:\n    config_file: [unclosed\n',
                   encoding='utf-8')
    proc = _start(package, executable, '--params-file', str(bad))
    _assert_refused(proc, status, str(bad))
    fatal = [line for line in (proc.stdout + proc.stderr).splitlines() if 'FATAL' in line]
    assert len(fatal) == 1, proc.stdout + proc.stderr


def test_an_override_that_matches_no_parameter_is_warned_about(tmp_path: Path) -> None:
    """A misspelled name in a params file or a -p override: the node starts and says which."""
    params = tmp_path / 'params.yaml'
    params.write_text('check_lift_server:\n  ros__parameters:\n    default_fiction_angle: 0.1\n',
                      encoding='utf-8')
    cmd = [str(installed_executable('dam_analysis', 'check_lift_server')), '--ros-args',
           '--params-file', str(params), '-p', 'defualt_friction_angle:=0.2',
           '-p', 'default_friction_angle:=0.1']
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            stdin=subprocess.DEVNULL)
    lines: list[str] = []
    try:
        assert proc.stdout is not None
        for line in proc.stdout:  # until both warnings came (or the node ended)
            lines.append(line)
            if sum('matches no parameter' in seen for seen in lines) == 2:
                break
        proc.send_signal(signal.SIGINT)
        rest, _ = proc.communicate(timeout=10.0)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    output = ''.join(lines) + rest
    assert proc.returncode == 0, output
    warnings = [line for line in output.splitlines() if 'matches no parameter' in line]
    assert len(warnings) == 2, output
    assert any("'default_fiction_angle'" in w for w in warnings)
    assert any("'defualt_friction_angle'" in w for w in warnings)
    # how to list them, with ros2cli and without it (the PyPI wheels have none)
    assert all('`ros2 param list /check_lift_server`' in w and
               '/check_lift_server/list_parameters (rcl_interfaces/srv/ListParameters)' in w
               for w in warnings), warnings


@pytest.mark.parametrize(('package', 'executable', 'status'), NODES)
def test_a_config_file_with_a_key_written_twice_is_refused(tmp_path: Path, package: str,
                                                           executable: str,
                                                           status: int) -> None:
    """friction_angle_deg under contact: twice (5 deg, then 30 deg): refused by key path and
    both lines, in one line, not run with the later value."""
    repo = Path(__file__).resolve().parents[2]
    lines = (repo / 'config' / 'dam.yaml').read_text(encoding='utf-8').splitlines()
    first = next(i for i, line in enumerate(lines)
                 if line.startswith('  friction_angle_deg:')) + 1
    lines.insert(first, '  friction_angle_deg: 30.0')
    bad = tmp_path / 'dam.yaml'
    bad.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    proc = _start(package, executable, '-p', f'config_file:={bad}')
    _assert_refused(proc, status, 'contact.friction_angle_deg: duplicate key',
                    f'first on line {first}, again on line {first + 1}', str(bad))
    output = proc.stdout + proc.stderr
    assert len([line for line in output.splitlines() if 'cannot start' in line]) == 1, output


def test_the_nodes_start_without_scipy_and_the_controller_without_the_tables() -> None:
    """What spcm_controller imports and builds before it serves: dam_analysis without scipy
    (a quarter of a second of CPU idle, seconds at load 40) and, for its check that the
    fingers reach the object, the hand model without the cached SPCM branches (a few tenths
    of a second more). check_lift_server builds those branches before it serves, still
    without scipy (its branch ends are found by dam_analysis.branch_end.brent_root)."""
    import os
    import sys

    code = (
        'import sys\n'
        'import dam_spcm_controller.controller_node\n'
        'import dam_analysis.check_lift_server\n'
        'print(sorted({m.split(".")[0] for m in sys.modules} & {"scipy", "matplotlib"}))\n'
        'from dam_analysis.analysis import LiftAnalyzer\n'
        'from dam_common.config import load_config\n'
        'analyzer = LiftAnalyzer(load_config())\n'
        'print(analyzer._table is None, analyzer.build() is analyzer, '
        'analyzer._table is not None)\n'
        # check_lift_server builds the configured object's analysis before it serves
        'print(sorted({m.split(".")[0] for m in sys.modules} & {"scipy", "matplotlib"}))\n')
    site = sorted(INSTALL_DIR.glob('*/lib/python3*/site-packages'))
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [*map(str, site), os.environ.get('PYTHONPATH', '')]))
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=120, env=env, stdin=subprocess.DEVNULL)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert proc.stdout.splitlines() == ['[]', 'True True True', '[]'], proc.stdout
