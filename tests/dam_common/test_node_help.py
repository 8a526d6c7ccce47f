"""``--help`` and ``-h`` on every executable print its usage and exit (module node_help).

The issue: ``check_lift_server --help`` brought up a second server and ``spcm_controller
--help`` a second controller with the same name; a node executable had no answer to ``--help``.
"""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

from dam_common.node_help import help_text, plain_text, wants_help

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from ros_testing import installed_executable  # noqa: E402

#: Every executable of the suite, and words its help must contain (its topics, services and
#: parameters for a node).
EXECUTABLES = {
    ('dam_analysis', 'check_lift_server'): ['/check_lift', '/plan_lift',
                                           'default_friction_angle', 'config_file',
                                           'config_overlay'],
    ('dam_hand_driver', 'hand_driver'): ['/joint_states', '/hand/command', 'backend',
                                         '~/reset', 'config_overlay', 'port'],
    ('dam_hand_driver', 'dynamixel_setup'): ['scan', 'fix', 'set-id', 'zero'],
    ('dam_spcm_controller', 'spcm_controller'): ['/dam_grasp', '/dam/status', '/joint_states',
                                                 'require_lift_guarantee'],
    ('dam_sim_bridge', 'sim_bridge'): ['/sim/object_pose', '/clock', '~/reset', 'bus'],
    ('dam_recorder', 'recorder'): ['--episodes', '--storage'],
    ('dam_analysis', 'check_lift'): ['--k-theta', '--delta-theta-p'],
    ('dam_analysis', 'plan_lift'): ['--mass', '--position-tolerance'],
    ('dam_analysis', 'lift_map'): ['--friction-angles'],
    ('dam_analysis', 'scale_map'): ['--radius-range'],
    ('dam_analysis', 'csm_dependence'): ['--k-t', '--friction-angles'],
    ('dam_spcm_controller', 'dam_grasp'): ['--k-theta', '--cancel-after'],
    ('dam_hand_driver', 'hand_urdf'): ['usage'],
    ('dam_hand_driver', 'dam_state_publisher'): ['/tf_static', '/robot_description',
                                                 'robot_state', 'publish_frequency',
                                                 'object_frame'],
    ('dam_recorder', 'bag'): ['info', 'plot', 'export'],
    ('dam_recorder', 'recover'): ['usage'],
    ('dam_sim_bridge', 'dynamixel_bus'): ['usage'],
    ('dam_experiments', 'dam_experiment'): ['--alpha'],
    ('dam_experiments', 'sweep'): ['--friction-angles', '--scheduler'],
    ('dam_experiments', 'sweep_plot'): ['usage'],
    ('dam_experiments', 'sweep_report'): ['--calibrate'],
    ('dam_experiments', 'calibrate_csm'): ['--verdict', '--folds', '--fixed-friction-angle'],
}


@pytest.mark.parametrize('flag', ['--help', '-h'])
@pytest.mark.parametrize(('package', 'executable'), sorted(EXECUTABLES),
                         ids=[e for _, e in sorted(EXECUTABLES)])
def test_every_executable_answers_help_and_exits(package: str, executable: str,
                                                 flag: str) -> None:
    """Exit 0 within seconds with the usage on standard output: a node that came up instead
    would still be running at the timeout."""
    exe = installed_executable(package, executable)
    start = time.monotonic()
    try:
        done = subprocess.run([str(exe), flag], capture_output=True, text=True, timeout=30,
                              stdin=subprocess.DEVNULL)
    except subprocess.TimeoutExpired:
        pytest.fail(f'{executable} {flag} did not exit within 30 s: it started instead')
    assert done.returncode == 0, (done.stdout, done.stderr)
    assert 'usage' in done.stdout.lower(), done.stdout
    for word in EXECUTABLES[package, executable]:
        assert word in done.stdout, (word, done.stdout)
    assert 'Traceback' not in done.stderr, done.stderr
    assert time.monotonic() - start < 30.0


def test_a_node_s_help_is_its_documentation_in_plain_text() -> None:
    text = help_text('dam_analysis.check_lift_server', 'check_lift_server')
    assert text.startswith('usage: ros2 run dam_analysis check_lift_server [-h] [--ros-args')
    assert '``' not in text and ':mod:' not in text
    assert 'ros2 param list /check_lift_server' in text
    assert plain_text('see :class:`~a.b.Thing` and :mod:`a.b`, ``x``') == 'see Thing and a.b, x'


def test_help_inside_the_ros_arguments_is_not_the_node_s() -> None:
    assert wants_help(['--help']) and wants_help(['-h', '--ros-args', '-p', 'a:=1'])
    assert not wants_help(['--ros-args', '--help', '--'])
    assert wants_help(['--ros-args', '-p', 'a:=1', '--', '--help'])
    assert not wants_help(['--gui'])
