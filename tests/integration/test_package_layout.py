"""Each installed package has the layout `ros2 run` and the ament index rely on."""

from __future__ import annotations

import ast
import os
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

REPO_ROOT = Path(__file__).resolve().parents[2]
SRC = REPO_ROOT / 'src'
INSTALL = REPO_ROOT / 'ros2_ws' / 'install'
PYTHON_PACKAGES = ['dam_common', 'dam_analysis', 'dam_sim_bridge', 'dam_hand_driver',
                   'dam_spcm_controller', 'dam_recorder', 'dam_experiments']
#: The suite's packages each package may import (besides itself and the message definitions,
#: dam_interfaces): the stand-in hand sits beside the driver, below the controller; the
#: experiments on top (they read the recorder's episode bags: calibrate_csm).
LAYERS = {
    'dam_common': set(),
    'dam_analysis': {'dam_common'},
    'dam_sim_bridge': {'dam_common'},
    'dam_hand_driver': {'dam_common'},
    'dam_recorder': {'dam_common'},
    'dam_spcm_controller': {'dam_common', 'dam_analysis', 'dam_hand_driver'},
    'dam_experiments': {'dam_common', 'dam_analysis', 'dam_hand_driver', 'dam_spcm_controller',
                        'dam_sim_bridge', 'dam_recorder'},
}


def declared_executables(setup_py: Path) -> list[str]:
    """Console scripts declared in setup.py, read from its source (not from the install)."""
    tree = ast.parse(setup_py.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.keyword) and node.arg == 'entry_points':
            entry_points = ast.literal_eval(node.value)
            return [spec.split('=')[0].strip() for spec in entry_points.get('console_scripts', [])]
    return []


def test_all_packages_are_in_src_and_installed() -> None:
    found = sorted(p.name for p in SRC.iterdir() if (p / 'package.xml').is_file())
    assert found == sorted(PYTHON_PACKAGES + ['dam_interfaces'])
    for name in found:
        marker = INSTALL / name / 'share' / 'ament_index' / 'resource_index' / 'packages' / name
        assert marker.is_file(), f'{name} is not registered in the ament index'


@pytest.mark.parametrize('package', PYTHON_PACKAGES + ['dam_interfaces'])
def test_package_xml_is_format_3_with_real_dependencies(package: str) -> None:
    root = ET.parse(SRC / package / 'package.xml').getroot()
    assert root.tag == 'package' and root.get('format') == '3'
    assert root.findtext('name') == package
    build_type = root.find('export/build_type')
    assert build_type is not None
    expected_type = 'ament_cmake' if package == 'dam_interfaces' else 'ament_python'
    assert build_type.text == expected_type
    depends = {e.text for e in root if e.tag.endswith('depend')}
    if package == 'dam_interfaces':
        assert {'rosidl_default_generators', 'rosidl_default_runtime'} <= depends
    elif package == 'dam_experiments':  # command-line tools on the pure cores: no node
        assert 'rclpy' not in depends and 'dam_sim_bridge' in depends
    else:
        assert 'rclpy' in depends
        if package != 'dam_common':
            # Node packages: messages, and the shared plumbing from dam_common only.
            assert {'dam_interfaces', 'dam_common'} <= depends
        # Every package.xml dependency that names one of ours must exist.
        for dep in depends:
            if dep.startswith('dam_'):
                assert (SRC / dep / 'package.xml').is_file(), f'{package} depends on {dep}'


@pytest.mark.parametrize('package', PYTHON_PACKAGES)
def test_executables_are_installed_where_ros2_run_looks(package: str) -> None:
    pkg_dir = SRC / package
    assert (pkg_dir / 'resource' / package).is_file()
    assert f'install_scripts=$base/lib/{package}' in (pkg_dir / 'setup.cfg').read_text()
    declared = declared_executables(pkg_dir / 'setup.py')
    lib_dir = INSTALL / package / 'lib' / package
    installed = sorted(p.name for p in lib_dir.iterdir()) if lib_dir.is_dir() else []
    assert sorted(declared) == installed
    for exe in declared:
        path = lib_dir / exe
        assert os.access(path, os.X_OK), f'{path} is not executable'
        assert path.read_text().startswith('#!'), f'{path} has no interpreter line'


def test_interfaces_are_generated_for_python() -> None:
    from dam_interfaces.srv import CheckLift

    request_fields = CheckLift.Request.get_fields_and_field_types()
    assert request_fields == {
        'k_theta': 'sequence<double>', 'delta_theta_p': 'sequence<double>',
        'friction_angle': 'double', 'object': 'string'}
    response_fields = CheckLift.Response.get_fields_and_field_types()
    assert response_fields == {
        'ok': 'boolean', 'message': 'string', 'lift_guaranteed': 'boolean',
        'worst_case_margin': 'double', 'csm_lift': 'boolean', 'csm_margin': 'double',
        'delta_theta_s': 'sequence<double>', 'compliant_torque': 'sequence<double>',
        'friction_angle': 'double', 'torque_limit': 'double', 'within_torque_limit': 'boolean',
        'csm_penetration': 'sequence<double>', 'csm_in_domain': 'boolean', 'object': 'string',
        'rolling_checked': 'boolean', 'rolling_margin': 'double', 'rolling_turn': 'double',
        'rolling_slide': 'double', 'csm_path_lift': 'boolean', 'csm_path_margin': 'double',
        'csm_path_delta_theta_p': 'double'}
    from dam_interfaces.srv import PlanLift

    assert PlanLift.Request.get_fields_and_field_types() == {
        **{name: 'double' for name in ('friction_angle_min', 'friction_angle_max', 'mass_min',
                                       'mass_max', 'position_tolerance', 'k_theta_max',
                                       'delta_theta_p_min', 'delta_theta_p_max', 'min_margin')},
        'object': 'string'}
    defaults = PlanLift.Request()
    assert defaults.position_tolerance == 0.0 and defaults.friction_angle_min == -1.0
    assert PlanLift.Response.get_fields_and_field_types()['method'] == 'string'
    from dam_interfaces.msg import GraspEpisode, LiftAnswer

    answer_fields = LiftAnswer.get_fields_and_field_types()
    assert answer_fields == response_fields  # the same answer, as a message of its own
    episode_fields = GraspEpisode.get_fields_and_field_types()
    assert episode_fields['check_lift'] == 'dam_interfaces/LiftAnswer'
    assert episode_fields['object'] == 'string'
    assert (GraspEpisode.EVENT_STARTED, GraspEpisode.EVENT_ENDED) == (0, 1)


def test_config_is_installed_with_dam_analysis() -> None:
    installed = INSTALL / 'dam_common' / 'share' / 'dam_common' / 'config' / 'dam.yaml'
    assert installed.read_text() == (REPO_ROOT / 'config' / 'dam.yaml').read_text()


def test_hand_command_and_grasp_action_are_generated() -> None:
    from dam_interfaces.action import DamGrasp
    from dam_interfaces.msg import DamStatus, HandCommand

    assert HandCommand.get_fields_and_field_types() == {
        'header': 'std_msgs/Header', 'name': 'sequence<string>', 'mode': 'sequence<uint8>',
        'setpoint': 'sequence<double>', 'stiffness': 'sequence<double>',
        'damping': 'sequence<double>'}
    modes = {HandCommand.MODE_TORQUE, HandCommand.MODE_POSITION, HandCommand.MODE_HOLD,
             HandCommand.MODE_IMPEDANCE}
    assert len(modes) == 4 and HandCommand.MODE_IMPEDANCE == 3
    assert DamGrasp.Goal.get_fields_and_field_types() == {
        'k_theta': 'sequence<double>', 'delta_theta_p': 'sequence<double>'}
    outcomes = {DamGrasp.Result.OUTCOME_UNKNOWN, DamGrasp.Result.OUTCOME_SUCCESS,
                DamGrasp.Result.OUTCOME_LIFTED_DAM_FAILED, DamGrasp.Result.OUTCOME_FAILURE,
                DamGrasp.Result.OUTCOME_ABORTED}
    assert len(outcomes) == 5
    assert 'phase' in DamGrasp.Feedback.get_fields_and_field_types()
    assert DamStatus.get_fields_and_field_types()['compliant_torque'] == 'sequence<double>'


def test_node_plumbing_comes_from_dam_common_only() -> None:
    """The driver needs nothing of the analysis, the controller nothing of the driver."""
    def depends(package: str) -> set[str]:
        root = ET.parse(SRC / package / 'package.xml').getroot()
        return {e.text for e in root if e.tag.endswith('depend')}

    assert 'dam_analysis' not in depends('dam_hand_driver')
    assert 'dam_hand_driver' not in depends('dam_spcm_controller')
    for package in ('dam_hand_driver', 'dam_spcm_controller'):
        sources = '\n'.join(p.read_text() for p in (SRC / package / package).glob('*.py'))
        forbidden = 'dam_analysis' if package == 'dam_hand_driver' else 'dam_hand_driver'
        assert f'from {forbidden}' not in sources and f'import {forbidden}' not in sources


#: Top-level Python modules of other projects -> their rosdep key. A key of the ROS rosdep
#: database where one exists (rosdistro's rosdep/base.yaml and python.yaml); otherwise the
#: ``-pip`` key convention (pip package name). ROS packages are their own key.
ROSDEP_KEYS = {
    'numpy': 'python3-numpy', 'scipy': 'python3-scipy', 'yaml': 'python3-yaml',
    'matplotlib': 'python3-matplotlib', 'tqdm': 'python3-tqdm',
    'pybullet': 'python3-pybullet-pip', 'pybullet_utils': 'python3-pybullet-pip',
    'rosbags': 'python3-rosbags-pip', 'mcap': 'python3-mcap-pip',
    'dask': 'python3-dask-pip', 'distributed': 'python3-distributed-pip',
    'dynamixel_sdk': 'python3-dynamixel-sdk-pip', 'serial': 'python3-serial',
    'zstandard': 'python3-zstandard-pip', 'lz4': 'python3-lz4-pip',
}
#: ROS packages imported as Python modules (their name is their key).
ROS_MODULES = {'rclpy', 'rcl_interfaces', 'std_msgs', 'sensor_msgs', 'std_srvs',
               'diagnostic_msgs', 'geometry_msgs', 'builtin_interfaces', 'rosgraph_msgs',
               'action_msgs', 'ament_index_python', 'tf2_msgs'}


def imported_modules(package: str) -> set[str]:
    """Top-level names of every module the package's code imports (at any depth of the code),
    without the standard library and ``__future__``."""
    import sys

    found: set[str] = set()
    for path in (SRC / package / package).rglob('*.py'):
        for node in ast.walk(ast.parse(path.read_text(encoding='utf-8'))):
            if isinstance(node, ast.Import):
                found |= {alias.name.split('.')[0] for alias in node.names}
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                found.add(node.module.split('.')[0])
    return {m for m in found if m not in sys.stdlib_module_names and m != '__future__'}


@pytest.mark.parametrize('package', PYTHON_PACKAGES)
def test_every_import_is_declared_in_package_xml(package: str) -> None:
    """`rosdep install --from-paths src` installs what the code imports: every module the
    package imports is an exec dependency of its package.xml, by its rosdep key."""
    root = ET.parse(SRC / package / 'package.xml').getroot()
    declared = {e.text for e in root if e.tag in ('depend', 'exec_depend')}
    missing = []
    for module in sorted(imported_modules(package)):
        if module == package:
            continue
        if module.startswith('dam_') or module in ROS_MODULES:
            key = module
        elif module in ROSDEP_KEYS:
            key = ROSDEP_KEYS[module]
        else:
            missing.append(f'{module} (no rosdep key known: add it to ROSDEP_KEYS)')
            continue
        if key not in declared:
            missing.append(f'{module} -> <exec_depend>{key}</exec_depend>')
    assert not missing, f'{package}/package.xml lacks: {missing}'


@pytest.mark.parametrize('package', PYTHON_PACKAGES)
def test_a_package_imports_and_declares_only_the_packages_below_it(package: str) -> None:
    above = {m for m in imported_modules(package) if m.startswith('dam_')} - LAYERS[package] \
        - {package, 'dam_interfaces'}
    assert not above, f'{package} imports {sorted(above)}, which are not below it'
    root = ET.parse(SRC / package / 'package.xml').getroot()
    declared = {e.text for e in root if e.tag in ('depend', 'exec_depend')}
    suite = {name for name in declared if name and name.startswith('dam_')}
    assert suite - LAYERS[package] <= {'dam_interfaces'}, \
        f'{package}/package.xml depends on {sorted(suite - LAYERS[package])}, not below it'


#: -pip keys the ROS rosdep database has (rosdistro rosdep/python.yaml).
PIP_KEYS_IN_DATABASE = {'python3-pybullet-pip', 'python3-rosbags-pip'}


def test_pip_keys_outside_the_database_are_defined_in_rosdep_yaml() -> None:
    """Every -pip key a package.xml names resolves: the database has it, or the workspace's
    rosdep.yaml (a source `rosdep update` takes) defines it with the pip package to install."""
    import yaml

    defined = yaml.safe_load((REPO_ROOT / 'rosdep.yaml').read_text(encoding='utf-8'))
    used = {e.text for package in PYTHON_PACKAGES
            for e in ET.parse(SRC / package / 'package.xml').getroot()
            if e.tag.endswith('depend') and (e.text or '').endswith('-pip')}
    assert used - PIP_KEYS_IN_DATABASE == set(defined), (used, sorted(defined))
    for key, rules in defined.items():
        pip_name = key[len('python3-'):-len('-pip')]
        for platform in ('debian', 'ubuntu'):
            assert rules[platform]['pip']['packages'] == [pip_name], (key, platform)


def test_tf2_msgs_is_the_standard_type() -> None:
    """/tf and /tf_static carry tf2_msgs/msg/TFMessage with Jazzy's own type hash, whether it
    comes from the system or from interfaces/ (RViz, Foxglove and ros2 bag match on it)."""
    import json

    import tf2_msgs
    from rosbags.typesys import Stores, get_typestore

    module = Path(tf2_msgs.__file__).resolve()
    prefix = next(p for p in module.parents if (p / 'share' / 'tf2_msgs' / 'msg').is_dir())
    description = json.loads((prefix / 'share' / 'tf2_msgs' / 'msg' / 'TFMessage.json')
                             .read_text(encoding='utf-8'))
    [ours] = [h['hash_string'] for h in description['type_hashes']
              if h['type_name'] == 'tf2_msgs/msg/TFMessage']
    jazzy = get_typestore(Stores.ROS2_JAZZY).hash_rihs01('tf2_msgs/msg/TFMessage')
    assert ours == jazzy
