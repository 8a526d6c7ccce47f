"""The configuration loader: the shipped file, and each kind of bad file."""

from __future__ import annotations

import copy
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from dam_common.config import (
    JOINT_ROLES,
    config_from_dict,
    default_config_path,
    load_config,
)
from dam_common.errors import ConfigError

REPO_ROOT = Path(__file__).resolve().parents[2]
CONFIG_FILE = REPO_ROOT / 'config' / 'dam.yaml'


@pytest.fixture(scope='module')
def raw() -> dict[str, Any]:
    return yaml.safe_load(CONFIG_FILE.read_text())


def _with(raw: dict[str, Any], path: str, value: Any) -> dict[str, Any]:
    """A deep copy of ``raw`` with the dotted/indexed ``path`` set to ``value``."""
    data = copy.deepcopy(raw)
    node: Any = data
    keys = path.replace('[', '.').replace(']', '').split('.')
    for key in keys[:-1]:
        node = node[int(key)] if key.isdigit() else node[key]
    last = keys[-1]
    if value is _DELETE:
        del node[last]
    elif last.isdigit():
        node[int(last)] = value
    else:
        node[last] = value
    return data


_DELETE = object()


def test_shipped_file_has_the_papers_values() -> None:
    cfg = load_config(CONFIG_FILE)
    hand = cfg.hand
    assert hand.n_fingers == 3
    assert hand.joint_roles == JOINT_ROLES == ('compliant', 'locked', 'position')
    np.testing.assert_allclose(hand.link_lengths_m, [0.040, 0.025, 0.025])
    assert hand.link_radius_m == pytest.approx(0.005)
    assert cfg.object.radius_m == pytest.approx(0.010)
    assert cfg.object.mass_kg == pytest.approx(0.04)
    assert cfg.object_weight_n == pytest.approx(0.04 * 9.81)
    # k_theta2 = k_theta3 = k_theta1 / 2 (paper section 3.3)
    np.testing.assert_allclose(hand.stiffness_ratios, [1.0, 0.5, 0.5])
    assert hand.initial_position_angle_rad == pytest.approx(math.radians(15.0))
    assert cfg.contact.cone_faces == 8
    np.testing.assert_allclose(cfg.contact.contact_stiffness_n_per_m, [1e5, 1e5, 1e5])
    alpha = cfg.contact.friction_angle_rad
    assert cfg.contact.friction_coefficient == pytest.approx(math.tan(alpha))
    assert len(hand.joint_names) == 9
    assert hand.joint_names[:3] == (
        'finger1_compliant_joint', 'finger1_locked_joint', 'finger1_position_joint')


def test_finger_geometry_matches_the_paper_layout() -> None:
    cfg = load_config(CONFIG_FILE)
    f1, f2, f3 = cfg.hand.fingers
    obj_x = cfg.object.position_m[0]
    # Finger 1 opposes fingers 2 and 3: on the other side of the object, facing it.
    assert np.sign(f1.base_position_m[0] - obj_x) == -np.sign(f2.base_position_m[0] - obj_x)
    for finger in (f1, f2, f3):
        towards_object = np.sign(obj_x - finger.base_position_m[0])
        assert np.sign(finger.inward_direction[0]) == towards_object
        # Joint axes are parallel to the cylinder axis.
        assert abs(abs(float(finger.joint_axis @ cfg.object.axis)) - 1.0) < 1e-12
        # A positive rotation about the joint axis turns "down" towards "inward".
        down = np.array([0.0, 0.0, -1.0])
        assert np.cross(finger.joint_axis, down) @ finger.inward_direction == pytest.approx(1.0)
    # Fingers 2 and 3 stand side by side along the cylinder axis (y).
    assert f2.base_position_m[0] == pytest.approx(f3.base_position_m[0])
    assert f2.base_position_m[1] != pytest.approx(f3.base_position_m[1])


def test_default_path_honours_environment(monkeypatch: pytest.MonkeyPatch,
                                          tmp_path: Path) -> None:
    target = tmp_path / 'other.yaml'
    target.write_text(CONFIG_FILE.read_text())
    monkeypatch.setenv('DAM_CONFIG', str(target))
    assert default_config_path() == target
    assert load_config().source == str(target)


@pytest.mark.parametrize(
    ('path', 'value', 'expected'),
    [
        ('hand.link_lengths_m[1]', -0.025, r'hand\.link_lengths_m\[1\].*-0\.025'),
        ('hand.link_lengths_m', [0.04, 0.025], r'hand\.link_lengths_m.*expected 3 values'),
        ('hand.link_radius_m', float('nan'), r'hand\.link_radius_m.*finite.*nan'),
        ('hand.link_radius_m', 'five', r"hand\.link_radius_m.*expected a number.*'five'"),
        ('hand.joint_roles', ['locked', 'compliant', 'position'], r'hand\.joint_roles'),
        ('hand.joint_limits_deg.position', [90.0, 10.0], r'joint_limits_deg\.position.*below'),
        ('hand.fingers[1].name', 'finger1', r"hand\.fingers\[1\]\.name.*duplicate.*'finger1'"),
        ('hand.fingers[0].stiffness_ratio', 0.0, r'fingers\[0\]\.stiffness_ratio.*positive.*0\.0'),
        ('hand.fingers[2].base_position_m', [0.0, 0.0], r'fingers\[2\]\.base_position_m'),
        ('hand.initial_position_angle_deg', 120.0, r'initial_position_angle_deg.*120'),
        ('object.library.cylinder.radius_m', 0.0,
         r'object\.library\.cylinder\.radius_m.*positive.*0\.0'),
        ('object.library.cylinder.mass_kg', float('inf'),
         r'object\.library\.cylinder\.mass_kg.*finite.*inf'),
        ('object.axis', [0.0, 0.6, 0.8], r'object\.axis.*horizontal'),
        ('object.position_m', [0.0, 0.0, 0.001], r'object\.position_m.*expected 2 values'),
        ('object.library.cylinder.shape', 'sphere',
         r"object\.library\.cylinder\.shape.*unknown shape 'sphere'"),
        ('object.library.cylinder.sides', 6,
         r"object\.library\.cylinder.*unknown key.*'sides'"),
        ('object.default', 'pencil', r"object\.default.*'pencil' is not in object\.library"),
        ('object.library', {}, r'object\.library.*empty'),
        ('object.library.hex_pencil.sides', 2,
         r'object\.library\.hex_pencil\.sides.*>= 3.*2'),
        ('object.library.hex_pencil.across_flats_m', float('nan'),
         r'object\.library\.hex_pencil\.across_flats_m.*finite.*nan'),
        ('object.library.elliptic_column.semi_axes_m', [0.008, 0.012],
         r'object\.library\.elliptic_column\.semi_axes_m.*flat side.*0\.008, 0\.012'),
        ('object.library.square_bar', {'shape': 'convex_polygon', 'length_m': 0.06,
                                       'mass_kg': 0.04,
                                       'vertices_m': [[0, 0], [0.01, 0], [0.002, 0.002],
                                                      [0, 0.01]]},
         r'object\.library\.square_bar\.vertices_m.*\[0\.002, 0\.002\].*non-convex'),
        ('object.library.square_bar', {'shape': 'convex_polygon', 'length_m': 0.06,
                                       'mass_kg': 0.04,
                                       'vertices_m': [[0, 0], [0.01, 0], [0.01, 0]]},
         r'object\.library\.square_bar\.vertices_m.*repeats'),
        ('object.library.square_bar', {'shape': 'convex_polygon', 'length_m': 0.06,
                                       'mass_kg': 0.04,
                                       'vertices_m': [[0, 0], [0.01, 0], [0.0, float('nan')]]},
         r'object\.library\.square_bar\.vertices_m\[2\]\[1\].*finite.*nan'),
        ('object.library.square_bar', {'shape': 'convex_polygon', 'length_m': 0.06,
                                       'mass_kg': 0.04,
                                       'vertices_m': [[0, 0], [0.01, 0.005], [0.0, 0.01],
                                                      [-0.01, 0.005]]},
         r'object\.library\.square_bar\.vertices_m.*rest on a face'),
        ('object.library.square_bar', {'shape': 'convex_polygon', 'length_m': 0.06,
                                       'mass_kg': 0.04,
                                       'vertices_m': [[0, 0], [0.002, 0], [0.03, 0.01]]},
         r'object\.library\.square_bar\.vertices_m.*tip over'),
        ('contact.friction_angle_deg', 90.0, r'contact\.friction_angle_deg.*90'),
        ('contact.friction_angle_deg', -1.0, r'contact\.friction_angle_deg.*-1'),
        ('contact.cone_faces', 2, r'contact\.cone_faces.*>= 3.*2'),
        ('contact.cone_faces', 8.5, r'contact\.cone_faces.*integer.*8\.5'),
        ('task.delta_theta_p_max_deg', 90.0, r'task\.delta_theta_p_max_deg.*position joint range'),
        ('task.k_theta_nm_per_rad', True, r'task\.k_theta_nm_per_rad.*number.*True'),
        ('controller.envelope_torque_nm', 5.0, r'controller\.envelope_torque_nm.*torque_limit'),
        ('controller.lost_contact_torque_ratio', 1.5, r'lost_contact_torque_ratio.*below 1'),
        ('classification.lift_height_m', -0.01, r'classification\.lift_height_m.*-0\.01'),
        ('sim.time_step_s', 0.05, r'sim\.time_step_s.*too coarse'),
        ('sim.initial_compliant_angle_deg', -80.0, r'sim\.initial_compliant_angle_deg.*-80'),
        ('hand.link_masses_kg', [0.02, 0.0, 0.01], r'hand\.link_masses_kg\[1\].*positive'),
        ('device.watchdog_s', 0.5, r'device\.watchdog_s.*0\.5.*at most 0\.2'),
        ('device.watchdog_s', 0.0, r'device\.watchdog_s.*positive'),
        ('device.torque_rate_limit_nm_per_s', 4.0,
         r'device\.torque_rate_limit_nm_per_s: 4\.0 N\*m/s would take 0\.25 s .* at most '
         r'0\.2 s .* at least 5 N\*m/s'),
        ('device.torque_rate_limit_nm_per_s', 0.0,
         r'device\.torque_rate_limit_nm_per_s.*positive'),
        ('device.state_port', 70000, r'device\.state_port.*65535.*70000'),
        ('device.command_port', 45110, r'device\.command_port.*45110.*state_port'),
        ('device.calibration.locked.torque_scale_nm_per_raw', 0.0, r'torque_scale.*zero'),
        ('sim.compliant_rotor_inertia_kg_m2', -2e-3,
         r'sim\.compliant_rotor_inertia_kg_m2.*non-negative.*-0\.002'),
        ('sim.compliant_rotor_inertia_kg_m2', _DELETE,
         r'sim\.compliant_rotor_inertia_kg_m2: missing key'),
        ('sim.palm_thickness_m', 'thick', r"sim\.palm_thickness_m.*number.*'thick'"),
        ('sim.palm_thickness_m', _DELETE, r'sim\.palm_thickness_m: missing key'),
        ('sim.contact_model', 'soft',
         r"sim\.contact_model: expected one of \['compliant', 'rigid'\], got 'soft'"),
        ('sim.contact_model', 'Rigid', r"sim\.contact_model.*got 'Rigid'"),
        ('sim.contact_model', True, r'sim\.contact_model.*got True'),
        ('sim.contact_model', _DELETE, r'sim\.contact_model: missing key'),
        ('sim.contact_damping_n_s_per_m', 0.05,
         r'sim\.contact_damping_n_s_per_m: 0\.05 N\*s/m is below 0\.1 N\*s/m'),
        ('sim.contact_damping_n_s_per_m', -1.0, r'sim\.contact_damping_n_s_per_m: -1\.0 N'),
        ('sim.contact_damping_n_s_per_m', 'critical',
         r"sim\.contact_damping_n_s_per_m.*number.*'critical'"),
        ('sim.contact_damping_n_s_per_m', float('nan'),
         r'sim\.contact_damping_n_s_per_m.*finite.*nan'),
        ('sim.contact_damping_n_s_per_m', _DELETE,
         r'sim\.contact_damping_n_s_per_m: missing key'),
        ('controller.contact_confirm_time_s', -0.03,
         r'controller\.contact_confirm_time_s.*non-negative.*-0\.03'),
        ('controller.contact_confirm_time_s', _DELETE,
         r'controller\.contact_confirm_time_s: missing key'),
        ('controller.impedance_on_device', 'yes',
         r"controller\.impedance_on_device.*true or false.*'yes'"),
        ('controller.impedance_on_device', _DELETE,
         r'controller\.impedance_on_device: missing key'),
        ('device.max_stiffness_nm_per_rad', 0.0,
         r'device\.max_stiffness_nm_per_rad.*positive.*0\.0'),
        ('device.max_damping_nms_per_rad', -1.0,
         r'device\.max_damping_nms_per_rad.*non-negative.*-1\.0'),
        ('device.calibration.compliant.stiffness_scale_nm_per_rad_per_raw', -1e-4,
         r'calibration\.compliant\.stiffness_scale_nm_per_rad_per_raw.*positive.*-0\.0001'),
        ('device.calibration.position.damping_scale_nms_per_rad_per_raw', 0.0,
         r'calibration\.position\.damping_scale_nms_per_rad_per_raw.*positive.*0\.0'),
        ('device.calibration.locked.damping_scale_nms_per_rad_per_raw', _DELETE,
         r'calibration\.locked\.damping_scale_nms_per_rad_per_raw: missing key'),
        ('object.library.cylinder.radius_m', _DELETE,
         r'object\.library\.cylinder\.radius_m: missing key'),
        ('object.default', _DELETE, r'object\.default: missing key'),
        ('hand.fingers[0].colour', 'red', r"hand\.fingers\[0\].*unknown key.*'colour'"),
        ('format_version', 3, r'format_version.*unsupported.*3'),
        ('format_version', 1, r'format_version.*version 1.*no longer read.*object\.library'),
    ],
)
def test_bad_values_are_named(raw: dict[str, Any], path: str, value: Any, expected: str) -> None:
    with pytest.raises(ConfigError, match=expected):
        config_from_dict(_with(raw, path, value))


def test_sim_contact_model(raw: dict[str, Any]) -> None:
    """The shipped stand-in uses compliant contacts damped critically for the cylinder
    (2 sqrt(k_n m)); rigid is the other choice."""
    cfg = load_config(CONFIG_FILE)
    assert cfg.sim.contact_model == 'compliant'
    k_n, m = cfg.contact.contact_stiffness_n_per_m[0], cfg.object.mass_kg
    assert cfg.sim.contact_damping_n_s_per_m == pytest.approx(2.0 * math.sqrt(k_n * m),
                                                              rel=1e-3)
    rigid = config_from_dict(_with(raw, 'sim.contact_model', 'rigid'))
    assert rigid.sim.contact_model == 'rigid'
    low = config_from_dict(_with(raw, 'sim.contact_damping_n_s_per_m', 0.1))
    assert low.sim.contact_damping_n_s_per_m == 0.1


def test_object_library(raw: dict[str, Any]) -> None:
    """The shipped library, the resting heights, the selection and its refusal."""
    cfg = load_config(CONFIG_FILE)
    assert cfg.object.name == 'cylinder'
    assert set(cfg.objects) >= {'cylinder', 'hex_pencil', 'elliptic_column', 'square_bar'}
    pencil = cfg.with_object('hex_pencil').object
    assert pencil.section.inradius == pytest.approx(0.0035)  # 7 mm across flats
    # each object rests on the table: centroid above z = 0 by its lowest point
    for obj in cfg.objects.values():
        assert obj.position_m[2] == pytest.approx(-obj.section.bottom)
    assert cfg.with_object('elliptic_column').object.position_m[2] == pytest.approx(0.008)
    assert cfg.with_object('') is cfg
    with pytest.raises(ConfigError, match=r"'pen' is not in the object library.*hex_pencil"):
        cfg.with_object('pen')
    with pytest.raises(ConfigError, match=r"'square_bar' is a square.*no radius"):
        _ = cfg.with_object('square_bar').object.radius_m
    data = _with(raw, 'object.library.wedge', {
        'shape': 'convex_polygon', 'length_m': 0.05, 'mass_kg': 0.02,
        'vertices_m': [[0.0, 0.0], [0.02, 0.0], [0.0, 0.01]]})
    wedge = config_from_dict(data).with_object('wedge').object
    # the centroid of a triangle is the mean of its vertices: 1/3 of its height above the table
    assert wedge.position_m[2] == pytest.approx(0.01 / 3.0)
    np.testing.assert_allclose(wedge.section.vertices.mean(axis=0), [0.0, 0.0], atol=1e-15)


def test_unknown_top_level_section(raw: dict[str, Any]) -> None:
    data = copy.deepcopy(raw)
    data['hands'] = {}
    with pytest.raises(ConfigError, match=r"unknown key.*'hands'"):
        config_from_dict(data)


def test_file_errors(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r'cannot read configuration file.*nope\.yaml'):
        load_config(tmp_path / 'nope.yaml')
    broken = tmp_path / 'broken.yaml'
    broken.write_text('hand: [unclosed\n')
    with pytest.raises(ConfigError, match=r'broken\.yaml.*not valid YAML'):
        load_config(broken)
    scalar = tmp_path / 'scalar.yaml'
    scalar.write_text('42\n')
    with pytest.raises(ConfigError, match=r'<root>: expected a mapping, got 42'):
        load_config(scalar)
    empty = tmp_path / 'empty.yaml'
    empty.write_text('')
    with pytest.raises(ConfigError, match=r'expected a mapping, got None'):
        load_config(empty)


def test_angles_are_converted_to_radians(raw: dict[str, Any]) -> None:
    cfg = config_from_dict(_with(raw, 'contact.friction_angle_deg', 30.0))
    assert cfg.contact.friction_angle_rad == pytest.approx(math.pi / 6)
    assert cfg.contact.friction_coefficient == pytest.approx(1 / math.sqrt(3))
    lo, hi = cfg.hand.joint_limits_rad['position']
    assert (lo, hi) == pytest.approx((0.0, math.radians(95.0)))


# --------------------------------------------------------------------------------------------
# Keys written twice: refused with the key path, the file and both lines


def _shipped_lines() -> list[str]:
    return CONFIG_FILE.read_text(encoding='utf-8').splitlines()


def _line_of(lines: list[str], prefix: str, after: int = 0) -> int:
    """1-based number of the first line at or after ``after`` that starts with ``prefix``."""
    return next(i + 1 for i, line in enumerate(lines) if i >= after and line.startswith(prefix))


def _write(tmp_path: Path, lines: list[str]) -> Path:
    path = tmp_path / 'dam.yaml'
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8')
    return path


def test_a_key_written_twice_in_a_section_is_refused(tmp_path: Path) -> None:
    """friction_angle_deg under contact: 5 deg, then 30 deg on the next line (yaml.safe_load
    would take 30 without a word)."""
    lines = _shipped_lines()
    first = _line_of(lines, '  friction_angle_deg:', _line_of(lines, 'contact:'))
    lines.insert(first, '  friction_angle_deg: 30.0')
    path = _write(tmp_path, lines)
    with pytest.raises(ConfigError) as info:
        load_config(path)
    message = str(info.value)
    assert message.startswith('contact.friction_angle_deg: duplicate key')
    assert f'first on line {first}, again on line {first + 1}' in message
    assert str(path) in message


def test_a_section_appended_twice_is_refused(tmp_path: Path) -> None:
    lines = _shipped_lines()
    first = _line_of(lines, 'contact:')
    lines += ['contact:', '  friction_angle_deg: 30.0', '  cone_faces: 8',
              '  contact_stiffness_n_per_m: [1.0e+5, 1.0e+5, 1.0e+5]',
              '  table_friction_coefficient: 0.5']
    again = len(lines) - 4
    path = _write(tmp_path, lines)
    with pytest.raises(ConfigError,
                       match=rf'^contact: duplicate key, first on line {first}, again on line '
                             rf'{again} \(in .*dam\.yaml\)$'):
        load_config(path)


def test_a_key_written_twice_in_a_list_item_is_refused(tmp_path: Path) -> None:
    lines = _shipped_lines()
    first = _line_of(lines, '      stiffness_ratio:', _line_of(lines, '    - name: finger2'))
    lines.insert(first, '      stiffness_ratio: 0.25')
    path = _write(tmp_path, lines)
    with pytest.raises(ConfigError,
                       match=rf'^hand\.fingers\[1\]\.stiffness_ratio: duplicate key, first on '
                             rf'line {first}, again on line {first + 1} '):
        load_config(path)


@pytest.mark.parametrize('entry, match', [
    ({'shape': 'regular_polygon', 'sides': 3, 'across_flats_m': 1e-9},
     r'object\.library\.odd: .*thin at its thinnest.*at least 1 mm'),
    ({'shape': 'ellipse', 'semi_axes_m': [0.01, 1e-9]}, r'object\.library\.odd: .*thin'),
    ({'shape': 'circle', 'radius_m': 10.0},
     r'object\.library\.odd: .*20000 mm across its widest.*finger bases \(58 mm apart\)'),
])
def test_objects_the_hand_and_the_standin_cannot_take_are_refused(entry, match) -> None:
    from dam_common.config import config_from_dict

    data = yaml.safe_load((REPO_ROOT / 'config' / 'dam.yaml').read_text(encoding='utf-8'))
    data = copy.deepcopy(data)
    data['object']['library']['odd'] = dict(entry, length_m=0.1, mass_kg=0.04)
    with pytest.raises(ConfigError, match=match):
        config_from_dict(data)


# --------------------------------------------------------------------------------------------
# Overlays


def test_an_overlay_merges_key_by_key_and_replaces_values(tmp_path: Path) -> None:
    from dam_common.config import load_config

    overlay = tmp_path / 'overlay.yaml'
    overlay.write_text('contact:\n  friction_angle_deg: 12.5\n'
                       '  contact_stiffness_n_per_m: [2.0e+5, 40.0, 3.0e+5]\n', encoding='utf-8')
    base = load_config(CONFIG_FILE)
    merged = load_config(CONFIG_FILE, [overlay])
    assert merged.contact.friction_angle_rad == pytest.approx(math.radians(12.5))
    np.testing.assert_array_equal(merged.contact.contact_stiffness_n_per_m, [2e5, 40.0, 3e5])
    # keys the overlay does not name keep the file's values
    assert merged.contact.cone_faces == base.contact.cone_faces
    assert merged.task == base.task
    assert merged.contact.series_stiffness_n_per_m == math.inf
    assert merged.contact.tangential_stiffness_n_per_m == 40.0
    assert str(overlay) in merged.source


def test_overlays_apply_in_order(tmp_path: Path) -> None:
    from dam_common.config import load_config

    first, second = tmp_path / 'a.yaml', tmp_path / 'b.yaml'
    first.write_text('contact:\n  friction_angle_deg: 10.0\n', encoding='utf-8')
    second.write_text('contact:\n  friction_angle_deg: 20.0\n', encoding='utf-8')
    assert load_config(CONFIG_FILE, [first, second]).contact.friction_angle_rad == \
        pytest.approx(math.radians(20.0))


@pytest.mark.parametrize('text, match', [
    ('- 1\n- 2\n', 'must be a mapping'),
    ('contact:\n  friction_angle_deg: 95.0\n', 'friction_angle_deg'),
    ('contact:\n  stiffnes: 1\n', 'unknown key'),
    ('contact: [1\n', 'not valid YAML'),
])
def test_a_bad_overlay_is_refused_naming_it(tmp_path: Path, text: str, match: str) -> None:
    from dam_common.config import load_config

    overlay = tmp_path / 'bad.yaml'
    overlay.write_text(text, encoding='utf-8')
    with pytest.raises(ConfigError, match=match) as info:
        load_config(CONFIG_FILE, [overlay])
    assert 'bad.yaml' in str(info.value)


def test_a_missing_overlay_is_refused(tmp_path: Path) -> None:
    from dam_common.config import load_config

    with pytest.raises(ConfigError, match='cannot read'):
        load_config(CONFIG_FILE, [tmp_path / 'nope.yaml'])
