"""Load and validate the DAM configuration (``config/dam.yaml``).

The YAML file is the single source of truth for the hand geometry, the object, friction, the
controller gains and the device link. :func:`load_config` reads it, checks every value and
returns frozen dataclasses in SI units (angles in radians). A bad file raises
:class:`~dam_common.errors.ConfigError` whose message names the key and the value; a key
written twice in one mapping is refused with its path and both lines
(:mod:`dam_common.strict_yaml`).

This module is pure Python (numpy and PyYAML); it does not import rclpy.
"""

from __future__ import annotations

import dataclasses
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from dam_common.config_node import ConfigNode as _Node
from dam_common.cross_section import Circle, CrossSection, Ellipse
from dam_common.dynamixel_config import DynamixelConfig, parse_dynamixel
from dam_common.echo import brief_repr
from dam_common.errors import ConfigError
from dam_common.polygon_section import (
    MAX_VERTICES,
    ConvexPolygon,
    check_convex_polygon,
    regular_polygon,
)
from dam_common.strict_yaml import check_yaml_size, safe_load_unique

#: The joint roles of every finger, from the base (paper Fig. 6: compliant, locked, position).
JOINT_ROLES: tuple[str, str, str] = ('compliant', 'locked', 'position')

#: Environment variable that overrides the default configuration file.
CONFIG_ENV_VAR = 'DAM_CONFIG'

#: 2: the object is a library of column objects (``object.library``, ``object.default``);
#: version 1 described one cylinder (``object.shape``, ``object.radius_m``).
_FORMAT_VERSION = 2
#: The values of ``sim.contact_model``.
CONTACT_MODELS: tuple[str, str] = ('compliant', 'rigid')
#: Smallest ``sim.contact_damping_n_s_per_m`` [N*s/m]: Bullet adds the contact damping of the
#: two bodies of a contact, and the object, which keeps Bullet's default parameters (its table
#: contact stays rigid), contributes 0.1 N*s/m of its own.
SIM_MIN_CONTACT_DAMPING_N_S_PER_M = 0.1
#: Longest the device's slew-limited safe stop may take from the actuator limit to zero [s]
#: (``device.torque_limit_nm / device.torque_rate_limit_nm_per_s``).
_SAFE_STOP_RAMP_MAX_S = 0.2


@dataclass(frozen=True)
class FingerConfig:
    """One finger: where its compliant joint sits and how stiff it is relative to finger 1."""

    name: str
    base_position_m: np.ndarray  # (3,) world position of the compliant joint axis [m]
    base_yaw_rad: float  # rotation of the finger frame about world z [rad]
    stiffness_ratio: float  # k_theta_i / k_theta [-]

    @property
    def joint_names(self) -> tuple[str, str, str]:
        """Joint names ``<finger>_<role>_joint`` in base-to-tip order."""
        return tuple(f'{self.name}_{role}_joint' for role in JOINT_ROLES)  # type: ignore[return-value]

    @property
    def inward_direction(self) -> np.ndarray:
        """Unit vector (3,) of the finger frame's x axis in the world: towards the object."""
        return np.array([math.cos(self.base_yaw_rad), math.sin(self.base_yaw_rad), 0.0])

    @property
    def joint_axis(self) -> np.ndarray:
        """Unit vector (3,) of every joint axis of this finger in the world.

        A positive joint angle is a right-handed rotation about this axis and flexes the finger
        inward: it turns the downward link direction -z towards :attr:`inward_direction`. The
        axis is therefore minus the finger frame's y axis: ``(sin yaw, -cos yaw, 0)``.
        """
        return np.array([math.sin(self.base_yaw_rad), -math.cos(self.base_yaw_rad), 0.0])


@dataclass(frozen=True)
class HandConfig:
    """Hand geometry: three identical planar fingers of capsule links."""

    link_lengths_m: np.ndarray  # (3,) base to tip [m]
    link_radius_m: float  # capsule radius of every link, the fingertip radius [m]
    link_masses_kg: np.ndarray  # (3,) base to tip [kg] (simulator)
    joint_limits_rad: Mapping[str, tuple[float, float]]  # role -> (min, max) [rad]
    fingers: tuple[FingerConfig, ...]
    initial_locked_angle_rad: float
    initial_position_angle_rad: float
    joint_roles: tuple[str, str, str] = JOINT_ROLES

    @property
    def n_fingers(self) -> int:
        return len(self.fingers)

    @property
    def joint_names(self) -> tuple[str, ...]:
        """All joint names, finger by finger, base to tip."""
        return tuple(name for finger in self.fingers for name in finger.joint_names)

    @property
    def stiffness_ratios(self) -> np.ndarray:
        """(n_fingers,) k_theta_i / k_theta."""
        return np.array([f.stiffness_ratio for f in self.fingers])


@dataclass(frozen=True)
class ObjectConfig:
    """A column object lying on the table (one entry of the ``object.library``).

    ``section`` is its cross-section in the plane normal to ``axis``
    (:mod:`dam_common.cross_section`: ``x`` along ``axis x z``, ``z`` up, origin at the
    centroid), in the pose it rests in; ``position_m`` is the centroid resting on the table.
    ``csm_tangential_stiffness_n_per_m`` is the contact stiffness model's effective tangential
    stiffness for this object (a value ``calibrate_csm`` fitted to its grasps), in place of
    the ``contact`` section's ``k_t`` in series with the finger; None: the ``contact``
    section's. Only the lift analysis reads it.
    """

    name: str
    section: CrossSection
    length_m: float
    mass_kg: float
    position_m: np.ndarray  # (3,) centre of gravity [m], resting on the table
    axis: np.ndarray  # (3,) unit axis, horizontal
    csm_tangential_stiffness_n_per_m: float | None = None

    @property
    def radius_m(self) -> float:
        """Radius of a circular cylinder [m].

        Raises
        ------
        ConfigError
            The object is not a circular cylinder.
        """
        if not isinstance(self.section, Circle):
            raise ConfigError(f'object {self.name!r} is a {self.section.describe()}, not a '
                              'circular cylinder: it has no radius')
        return self.section.radius

    @property
    def section_x(self) -> np.ndarray:
        """(3,) world direction of the section's ``x`` axis: ``axis x z``."""
        x = np.cross(self.axis, [0.0, 0.0, 1.0])
        return x / float(np.linalg.norm(x))


@dataclass(frozen=True)
class ContactConfig:
    """Friction and contact stiffness between the object and the finger links."""

    friction_angle_rad: float  # alpha; mu = tan(alpha)
    cone_faces: int  # L of eq. (7)
    contact_stiffness_n_per_m: np.ndarray  # (3,) diagonal of K_pi
    table_friction_coefficient: float
    csm_max_penetration_m: float  # the CSM's domain of validity: f_n / k_n at most this [m]
    #: Tangential stiffness of the finger in series with the contact's tangential spring
    #: [N/m]; ``inf`` (the default): the finger is rigid, the CSM is the paper's.
    series_stiffness_n_per_m: float = math.inf

    @property
    def friction_coefficient(self) -> float:
        """mu = tan(alpha)."""
        return math.tan(self.friction_angle_rad)

    @property
    def tangential_stiffness_n_per_m(self) -> float:
        """Effective tangential stiffness of the CSM's spring-slider [N/m].

        The contact's in-plane tangential stiffness ``k_t`` (``contact_stiffness_n_per_m[1]``)
        in series with ``series_stiffness_n_per_m``: ``1 / (1/k_t + 1/k_s)``; exactly ``k_t``
        when ``k_s`` is infinite.
        """
        return series_stiffness(float(self.contact_stiffness_n_per_m[1]),
                                self.series_stiffness_n_per_m)


def series_stiffness(k_a: float, k_b: float) -> float:
    """Two springs in series, ``1 / (1/k_a + 1/k_b)`` [N/m]; an infinite one drops out."""
    if math.isinf(k_b):
        return k_a
    if math.isinf(k_a):
        return k_b
    return k_a * k_b / (k_a + k_b)


@dataclass(frozen=True)
class TaskConfig:
    gravity_m_per_s2: float
    k_theta_nm_per_rad: float
    delta_theta_p_rad: float
    delta_theta_p_max_rad: float


@dataclass(frozen=True)
class ControllerConfig:
    damping_nms_per_rad: float
    torque_limit_nm: float
    trajectory_duration_s: float
    envelope_torque_nm: float
    contact_torque_threshold_nm: float
    contact_confirm_time_s: float
    approach_speed_rad_per_s: float
    phase_timeout_s: float
    state_timeout_s: float
    torque_ramp_time_s: float
    lost_contact_time_s: float
    lost_contact_torque_ratio: float
    envelope_settle_speed_rad_per_s: float
    envelope_settle_time_s: float
    limit_margin_rad: float
    impedance_on_device: bool


@dataclass(frozen=True)
class ClassificationConfig:
    """Thresholds of the outcome classification from joint signals (paper Fig. 7)."""

    contact_tolerance_m: float
    lift_height_m: float
    cage_depth_ratio: float
    limit_margin_rad: float


@dataclass(frozen=True)
class SimConfig:
    """The PyBullet stand-in hand."""

    time_step_s: float
    solver_iterations: int
    initial_compliant_angle_rad: float
    servo_force_limit_nm: float
    object_faces: int
    compliant_rotor_inertia_kg_m2: float
    palm_thickness_m: float
    #: Simulated time: the longest wall-clock time [s] the simulated clock may stand still
    #: (no state frame, no joint state) before a node calls the stand-in or its peer dead.
    stall_timeout_s: float = 5.0
    #: Simulated time: the longest wall-clock time [s] the driver waits, before answering a
    #: state frame, for the command that answers the previous joint state while a commander
    #: streams (see ``docs/simulation_grasp.md``, "Simulated time").
    command_wait_s: float = 0.5
    #: Contact model of the finger links: ``'compliant'`` (a normal spring of the CSM's
    #: ``contact.contact_stiffness_n_per_m[0]`` and a damper per finger-object contact) or
    #: ``'rigid'`` (Bullet's rigid contacts); see ``docs/simulation_grasp.md``, "Contact model".
    contact_model: str = 'rigid'
    #: Normal damping of a compliant finger-object contact [N*s/m] (unused when rigid).
    contact_damping_n_s_per_m: float = 126.5


@dataclass(frozen=True)
class Calibration:
    """Raw device units to SI: ``si = (raw - offset) * scale``."""

    position_scale_rad_per_count: float
    position_offset_counts: float
    torque_scale_nm_per_raw: float
    torque_offset_raw: float
    stiffness_scale_nm_per_rad_per_raw: float  # k [N*m/rad] = raw * scale, raw > 0
    damping_scale_nms_per_rad_per_raw: float  # d [N*m*s/rad] = raw * scale, raw >= 0


@dataclass(frozen=True)
class DeviceConfig:
    host: str
    state_port: int
    command_port: int
    rate_hz: float
    watchdog_s: float
    probe_timeout_s: float
    state_timeout_s: float
    torque_rate_limit_nm_per_s: float
    torque_limit_nm: float
    max_stiffness_nm_per_rad: float  # largest IMPEDANCE stiffness the driver accepts
    max_damping_nms_per_rad: float  # largest IMPEDANCE damping the driver accepts
    calibration: Mapping[str, Calibration]  # joint role -> calibration


@dataclass(frozen=True)
class DamConfig:
    """The whole validated configuration."""

    hand: HandConfig
    object: ObjectConfig
    contact: ContactConfig
    task: TaskConfig
    controller: ControllerConfig
    classification: ClassificationConfig
    sim: SimConfig
    device: DeviceConfig
    source: str = field(default='<dict>')
    #: Every object of ``object.library`` by name; :attr:`object` is the configured default.
    objects: Mapping[str, ObjectConfig] = field(default_factory=dict)
    #: The ``dynamixel:`` section (a hand of Dynamixel servos), ``None`` where it is absent.
    dynamixel: DynamixelConfig | None = None

    def with_object(self, name: str) -> DamConfig:
        """The same configuration with the library object ``name`` in place of the default
        (an empty name keeps the default).

        Raises
        ------
        ConfigError
            No object of that name in the library (the message lists the names).
        """
        if name == '' or name == self.object.name:
            return self
        if name not in self.objects:
            raise ConfigError(f'object {brief_repr(name)} is not in the object library '
                              f'(known: {", ".join(sorted(self.objects))})')
        return dataclasses.replace(self, object=self.objects[name])

    @property
    def object_weight_n(self) -> float:
        """m_B g [N]."""
        return self.object.mass_kg * self.task.gravity_m_per_s2


# --------------------------------------------------------------------------------------------
# Locating the file


def default_config_path() -> Path:
    """Return the configuration file used when none is given.

    Order: the ``DAM_CONFIG`` environment variable; the copy installed in the ``dam_common``
    share directory (``share/dam_common/config/dam.yaml``); ``config/dam.yaml`` of the source
    tree this module lives in.
    """
    env = os.environ.get(CONFIG_ENV_VAR)
    if env:
        return Path(env)
    try:
        from ament_index_python.packages import get_package_share_directory

        installed = Path(get_package_share_directory('dam_common')) / 'config' / 'dam.yaml'
        if installed.is_file():
            return installed
    except Exception:  # noqa: BLE001 - ament index absent or package not installed
        pass
    for parent in Path(__file__).resolve().parents:
        candidate = parent / 'config' / 'dam.yaml'
        if candidate.is_file():
            return candidate
    raise ConfigError(
        f'no configuration file found: set {CONFIG_ENV_VAR} or install dam_common'
    )


def load_config(path: str | os.PathLike[str] | None = None,
                overlays: Sequence[str | os.PathLike[str]] = ()) -> DamConfig:
    """Read and validate a configuration file, with optional overlays.

    Parameters
    ----------
    path
        YAML file; ``None`` uses :func:`default_config_path`.
    overlays
        YAML files holding part of a configuration (e.g. the ``contact`` values a calibration
        fitted, ``docs/analysis.md``), applied in order: a mapping merges key by key into the
        mapping below it, any other value (a number, a list) replaces it. The merged result is
        validated as a whole, by the same rules.

    Raises
    ------
    ConfigError
        A file is missing, is not YAML, holds a key twice in one mapping, an overlay is not a
        mapping, or any key of the result is missing, unknown or has a bad value.
    """
    cfg_path = Path(path) if path is not None else default_config_path()
    data = _read_yaml(cfg_path)
    source = str(cfg_path)
    for overlay in overlays:
        overlay_path = Path(overlay)
        patch = _read_yaml(overlay_path)
        if not isinstance(patch, Mapping):
            raise ConfigError(f'configuration overlay {str(overlay_path)!r} must be a mapping '
                              f'of configuration keys, got {patch!r}')
        data = merge_overlay(data, patch)
        source += f' + {overlay_path}'
    return config_from_dict(data, source=source)


def _read_yaml(cfg_path: Path) -> Any:
    try:
        check_yaml_size(cfg_path.stat().st_size, str(cfg_path))  # before reading it all
        text = cfg_path.read_text(encoding='utf-8')
    except OSError as exc:
        raise ConfigError(f'cannot read configuration file {str(cfg_path)!r}: {exc}') from exc
    try:
        return safe_load_unique(text, str(cfg_path))
    except yaml.YAMLError as exc:
        raise ConfigError(f'{str(cfg_path)!r} is not valid YAML: {exc}') from exc


def merge_overlay(base: Any, patch: Any) -> Any:
    """``patch`` over ``base``: mappings merge key by key, other values replace (new object)."""
    if isinstance(base, Mapping) and isinstance(patch, Mapping):
        merged = dict(base)
        for key, value in patch.items():
            merged[key] = merge_overlay(base[key], value) if key in base else value
        return merged
    return patch


def config_from_dict(data: Any, source: str = '<dict>') -> DamConfig:
    """Validate an already parsed configuration mapping (same rules as :func:`load_config`)."""
    root = _Node(data, '', source)
    root.require_mapping()
    version = root.child('format_version').integer(minimum=1)
    if version == 1:
        raise root.child('format_version').error(
            'format version 1 (one cylinder under object:) is no longer read: the object is '
            'now a library (object.default, object.position_m [x, y], object.axis, '
            'object.library.NAME {shape: circle, radius_m, length_m, mass_kg}, as in the '
            f'shipped config/dam.yaml); this code reads {_FORMAT_VERSION}')
    if version != _FORMAT_VERSION:
        raise root.child('format_version').error(
            f'unsupported format version {version} (this code reads {_FORMAT_VERSION})'
        )
    root.only_keys({'format_version', 'hand', 'object', 'contact', 'task', 'controller',
                    'classification', 'sim', 'device', 'dynamixel'})
    hand = _hand(root.child('hand'))
    objects, default = _objects(root.child('object'), hand)
    obj = objects[default]
    contact = _contact(root.child('contact'))
    task = _task(root.child('task'), hand)
    controller = _controller(root.child('controller'))
    classification = _classification(root.child('classification'))
    sim = _sim(root.child('sim'), hand)
    device = _device(root.child('device'))
    dynamixel = None
    if 'dynamixel' in root.require_mapping():  # optional: only backend:=dynamixel needs it
        roles = tuple(r for _ in hand.fingers for r in hand.joint_roles)
        dynamixel = parse_dynamixel(root.child('dynamixel'), hand.joint_names, roles,
                                    tuple(hand.joint_limits_rad[r] for r in roles))
    return DamConfig(hand=hand, object=obj, contact=contact, task=task, controller=controller,
                     classification=classification, sim=sim, device=device, source=source,
                     objects=objects, dynamixel=dynamixel)


# --------------------------------------------------------------------------------------------
# Sections


def _hand(node: _Node) -> HandConfig:
    node.only_keys({'joint_roles', 'link_lengths_m', 'link_radius_m', 'link_masses_kg',
                    'joint_limits_deg',
                    'fingers', 'initial_locked_angle_deg', 'initial_position_angle_deg'})
    roles = node.child('joint_roles')
    role_list = roles.sequence(length=3)
    if tuple(role_list) != JOINT_ROLES:
        raise roles.error(f'must be {list(JOINT_ROLES)} (base to tip), got {role_list!r}')
    lengths = node.child('link_lengths_m').vector(3, positive=True)
    radius = node.child('link_radius_m').number(positive=True)
    if radius >= float(lengths.min()) / 2.0:
        raise node.child('link_radius_m').error(
            f'{radius!r} is too large for the shortest link ({lengths.min()!r} m)'
        )
    limits_node = node.child('joint_limits_deg')
    limits_node.only_keys(set(JOINT_ROLES))
    limits: dict[str, tuple[float, float]] = {}
    for role in JOINT_ROLES:
        lim = limits_node.child(role).vector(2)
        if not lim[0] < lim[1]:
            raise limits_node.child(role).error(f'min must be below max, got {lim.tolist()!r}')
        if np.any(np.abs(lim) > 180.0):
            raise limits_node.child(role).error(f'limits beyond +-180 deg: {lim.tolist()!r}')
        limits[role] = (math.radians(lim[0]), math.radians(lim[1]))
    fingers_node = node.child('fingers')
    finger_items = fingers_node.sequence()
    if len(finger_items) < 2:
        raise fingers_node.error(f'at least two fingers are needed, got {len(finger_items)}')
    fingers = []
    names: set[str] = set()
    for i in range(len(finger_items)):
        fnode = fingers_node.item(i)
        fnode.only_keys({'name', 'base_position_m', 'base_yaw_deg', 'stiffness_ratio'})
        name = fnode.child('name').identifier()
        if name in names:
            raise fnode.child('name').error(f'duplicate finger name {name!r}')
        names.add(name)
        fingers.append(FingerConfig(
            name=name,
            base_position_m=fnode.child('base_position_m').vector(3),
            base_yaw_rad=math.radians(fnode.child('base_yaw_deg').number()),
            stiffness_ratio=fnode.child('stiffness_ratio').number(positive=True),
        ))
    locked = node.child('initial_locked_angle_deg')
    locked_rad = math.radians(locked.number())
    _check_within(locked, locked_rad, limits['locked'])
    pos = node.child('initial_position_angle_deg')
    pos_rad = math.radians(pos.number())
    _check_within(pos, pos_rad, limits['position'])
    return HandConfig(link_lengths_m=lengths, link_radius_m=radius,
                      link_masses_kg=node.child('link_masses_kg').vector(3, positive=True),
                      joint_limits_rad=limits,
                      fingers=tuple(fingers), initial_locked_angle_rad=locked_rad,
                      initial_position_angle_rad=pos_rad)


#: Most vertices a convex polygon in the object library may have.
_MAX_POLYGON_VERTICES = MAX_VERTICES
_SHAPE_KEYS = {
    'circle': {'radius_m'},
    'ellipse': {'semi_axes_m'},
    'regular_polygon': {'sides', 'across_flats_m'},
    'convex_polygon': {'vertices_m'},
}


def _objects(node: _Node, hand: HandConfig) -> tuple[dict[str, ObjectConfig], str]:
    """The object library and the name of the default object."""
    node.only_keys({'default', 'position_m', 'axis', 'library'})
    axis_node = node.child('axis')
    axis = axis_node.vector(3)
    norm = float(np.linalg.norm(axis))
    if norm == 0.0:
        raise axis_node.error('axis must not be the zero vector')
    axis = axis / norm
    if abs(axis[2]) > 1e-9:
        raise axis_node.error(f'the object must lie on the table (horizontal axis), got '
                              f'{axis_node.raw!r}')
    place = node.child('position_m').vector(2)
    library_node = node.child('library')
    library = library_node.require_mapping()
    if not library:
        raise library_node.error('the object library is empty')
    objects = {}
    for key in library:
        entry = library_node.child(str(key))
        name = _Node(key, entry.path, entry.source).identifier()
        objects[name] = _library_object(entry, name, axis, place)
        _check_fits_hand(entry, objects[name], hand)
    default_node = node.child('default')
    default = default_node.string()
    if default not in objects:
        raise default_node.error(f'{default!r} is not in object.library '
                                 f'(known: {", ".join(sorted(objects))})')
    return objects, default


#: The thinnest section the stand-in simulates [m]: PyBullet's contact margins are of the
#: order of a millimetre, so a thinner object would pass through the fingers or the table.
MIN_OBJECT_WIDTH_M = 1e-3


def _check_fits_hand(node: _Node, obj: ObjectConfig, hand: HandConfig) -> None:
    """Refuse an object that neither the stand-in nor the hand can take: thinner than
    :data:`MIN_OBJECT_WIDTH_M` in any direction, or too large to lie between the opposing
    finger bases (the fingers would stand inside it).

    Raises
    ------
    ConfigError
        Naming the library entry, its size and the bound.
    """
    section = obj.section
    width = section.min_width
    if width < MIN_OBJECT_WIDTH_M:
        raise node.error(
            f'{section.describe()} is {width * 1e3:.3g} mm thin at its thinnest: the '
            f'stand-in simulates objects of at least {MIN_OBJECT_WIDTH_M * 1e3:g} mm, and the '
            f'joints cannot tell a thinner one from none (a unit missing? lengths are in m)')
    bases = np.array([f.base_position_m for f in hand.fingers])
    across = bases @ obj.section_x
    gap = float(across.max() - across.min())
    if 2.0 * section.circumradius >= gap:
        raise node.error(
            f'{section.describe()} is {2.0 * section.circumradius * 1e3:.6g} mm across its '
            f'widest: it does not fit between the opposing finger bases ({gap * 1e3:.4g} mm '
            f'apart), the fingers would stand inside it (a unit missing? lengths are in m)')


def _library_object(node: _Node, name: str, axis: np.ndarray, place: np.ndarray
                    ) -> ObjectConfig:
    """One named column object; its centroid stands at ``place`` (x, y), resting on the table."""
    shape_node = node.child('shape')
    shape = shape_node.string()
    if shape not in _SHAPE_KEYS:
        raise shape_node.error(f'unknown shape {shape!r} (known: {", ".join(_SHAPE_KEYS)})')
    node.only_keys({'shape', 'length_m', 'mass_kg', 'csm_tangential_stiffness_n_per_m'}
                   | _SHAPE_KEYS[shape])
    section: CrossSection
    if shape == 'circle':
        section = Circle(node.child('radius_m').number(positive=True))
    elif shape == 'ellipse':
        axes_node = node.child('semi_axes_m')
        a, b = axes_node.vector(2, positive=True)
        if a < b:
            raise axes_node.error(f'an elliptic column lies on its flat side: the horizontal '
                                  f'semi-axis must be the larger, got {axes_node.raw!r}')
        section = Ellipse(float(a), float(b))
    elif shape == 'regular_polygon':
        sides = node.child('sides').integer(minimum=3, maximum=_MAX_POLYGON_VERTICES)
        section = regular_polygon(sides, node.child('across_flats_m').number(positive=True))
    else:
        section = _convex_polygon(node.child('vertices_m'), name)
    position = np.array([float(place[0]), float(place[1]), section.rest_height])
    k_t = None
    if 'csm_tangential_stiffness_n_per_m' in node.require_mapping():
        k_t = node.child('csm_tangential_stiffness_n_per_m').number(positive=True)
    return ObjectConfig(name=name, section=section,
                        length_m=node.child('length_m').number(positive=True),
                        mass_kg=node.child('mass_kg').number(positive=True),
                        position_m=position, axis=axis, csm_tangential_stiffness_n_per_m=k_t)


def _convex_polygon(node: _Node, name: str) -> ConvexPolygon:
    """A convex polygon from ``vertices_m``, resting stably on one of its faces as given."""
    items = node.sequence()
    if not 3 <= len(items) <= _MAX_POLYGON_VERTICES:
        raise node.error(f'expected 3 to {_MAX_POLYGON_VERTICES} vertices, got {len(items)}')
    vertices = np.array([node.item(k).vector(2) for k in range(len(items))])
    try:
        check_convex_polygon(vertices)
    except ValueError as exc:
        raise node.error(str(exc).removeprefix('vertices: ')) from exc
    polygon = ConvexPolygon(vertices, f'convex polygon {name!r} of {len(items)} vertices')
    v = polygon.vertices
    scale = float(np.abs(v).max())
    low = np.flatnonzero(v[:, 1] <= polygon.bottom + 1e-9 * scale)
    if low.size < 2:
        raise node.error('the polygon must rest on a face: its lowest z must be shared by two '
                         f'vertices, got {node.raw!r}')
    if not float(v[low, 0].min()) < 0.0 < float(v[low, 0].max()):
        raise node.error('the polygon would tip over: its centroid does not stand above the '
                         f'face it rests on, got {node.raw!r}')
    return polygon


def _contact(node: _Node) -> ContactConfig:
    node.only_keys({'friction_angle_deg', 'cone_faces', 'contact_stiffness_n_per_m',
                    'table_friction_coefficient', 'csm_max_penetration_m',
                    'series_stiffness_n_per_m'})
    alpha = node.child('friction_angle_deg')
    alpha_deg = alpha.number()
    if not 0.0 <= alpha_deg < 90.0:
        raise alpha.error(f'friction angle must be in [0, 90) deg, got {alpha_deg!r}')
    return ContactConfig(
        friction_angle_rad=math.radians(alpha_deg),
        cone_faces=node.child('cone_faces').integer(minimum=3, maximum=64),
        contact_stiffness_n_per_m=node.child('contact_stiffness_n_per_m').vector(
            3, positive=True),
        table_friction_coefficient=node.child('table_friction_coefficient').number(
            nonnegative=True),
        csm_max_penetration_m=node.child('csm_max_penetration_m').number(positive=True),
        series_stiffness_n_per_m=_series_stiffness(node),
    )


def _series_stiffness(node: _Node) -> float:
    """``contact.series_stiffness_n_per_m``: optional, positive, ``.inf`` allowed."""
    if 'series_stiffness_n_per_m' not in node.require_mapping():
        return math.inf
    child = node.child('series_stiffness_n_per_m')
    value = child.raw
    if isinstance(value, (int, float)) and not isinstance(value, bool) and value == math.inf:
        return math.inf
    return child.number(positive=True)


def _task(node: _Node, hand: HandConfig) -> TaskConfig:
    node.only_keys({'gravity_m_per_s2', 'k_theta_nm_per_rad', 'delta_theta_p_deg',
                    'delta_theta_p_max_deg'})
    max_node = node.child('delta_theta_p_max_deg')
    max_rad = math.radians(max_node.number(positive=True))
    reachable = hand.joint_limits_rad['position'][1] - hand.initial_position_angle_rad
    if max_rad > reachable + 1e-12:
        raise max_node.error(f'{max_node.raw!r} deg exceeds the position joint range from the '
                             f'initial angle ({math.degrees(reachable):.6g} deg)')
    dp_node = node.child('delta_theta_p_deg')
    dp_rad = math.radians(dp_node.number(nonnegative=True))
    if dp_rad > max_rad + 1e-12:
        raise dp_node.error(f'{dp_node.raw!r} deg exceeds delta_theta_p_max_deg')
    return TaskConfig(
        gravity_m_per_s2=node.child('gravity_m_per_s2').number(positive=True),
        k_theta_nm_per_rad=node.child('k_theta_nm_per_rad').number(positive=True),
        delta_theta_p_rad=dp_rad,
        delta_theta_p_max_rad=max_rad,
    )


def _controller(node: _Node) -> ControllerConfig:
    node.only_keys({'damping_nms_per_rad', 'torque_limit_nm', 'trajectory_duration_s',
                    'envelope_torque_nm', 'contact_torque_threshold_nm', 'contact_confirm_time_s',
                    'approach_speed_deg_per_s', 'phase_timeout_s', 'state_timeout_s',
                    'torque_ramp_time_s', 'lost_contact_time_s', 'lost_contact_torque_ratio',
                    'envelope_settle_speed_deg_per_s', 'envelope_settle_time_s',
                    'limit_margin_deg', 'impedance_on_device'})
    ratio = node.child('lost_contact_torque_ratio')
    ratio_value = ratio.number(positive=True)
    if ratio_value >= 1.0:
        raise ratio.error(f'expected a ratio below 1, got {ratio_value!r}')
    limit = node.child('torque_limit_nm').number(positive=True)
    envelope = node.child('envelope_torque_nm')
    envelope_nm = envelope.number(positive=True)
    if envelope_nm > limit:
        raise envelope.error(f'{envelope_nm!r} N*m exceeds torque_limit_nm ({limit!r})')
    return ControllerConfig(
        damping_nms_per_rad=node.child('damping_nms_per_rad').number(nonnegative=True),
        torque_limit_nm=limit,
        trajectory_duration_s=node.child('trajectory_duration_s').number(positive=True),
        envelope_torque_nm=envelope_nm,
        contact_torque_threshold_nm=node.child('contact_torque_threshold_nm').number(
            positive=True),
        contact_confirm_time_s=node.child('contact_confirm_time_s').number(nonnegative=True),
        approach_speed_rad_per_s=math.radians(
            node.child('approach_speed_deg_per_s').number(positive=True)),
        phase_timeout_s=node.child('phase_timeout_s').number(positive=True),
        state_timeout_s=node.child('state_timeout_s').number(positive=True),
        torque_ramp_time_s=node.child('torque_ramp_time_s').number(positive=True),
        lost_contact_time_s=node.child('lost_contact_time_s').number(positive=True),
        lost_contact_torque_ratio=ratio_value,
        envelope_settle_speed_rad_per_s=math.radians(
            node.child('envelope_settle_speed_deg_per_s').number(positive=True)),
        envelope_settle_time_s=node.child('envelope_settle_time_s').number(positive=True),
        limit_margin_rad=math.radians(node.child('limit_margin_deg').number(nonnegative=True)),
        impedance_on_device=node.child('impedance_on_device').boolean(),
    )


def _classification(node: _Node) -> ClassificationConfig:
    node.only_keys({'contact_tolerance_m', 'lift_height_m', 'cage_depth_ratio',
                    'limit_margin_deg'})
    return ClassificationConfig(
        contact_tolerance_m=node.child('contact_tolerance_m').number(positive=True),
        lift_height_m=node.child('lift_height_m').number(positive=True),
        cage_depth_ratio=node.child('cage_depth_ratio').number(nonnegative=True),
        limit_margin_rad=math.radians(node.child('limit_margin_deg').number(nonnegative=True)),
    )


def _sim(node: _Node, hand: HandConfig) -> SimConfig:
    node.only_keys({'time_step_s', 'solver_iterations', 'initial_compliant_angle_deg',
                    'servo_force_limit_nm', 'object_faces', 'compliant_rotor_inertia_kg_m2',
                    'palm_thickness_m', 'stall_timeout_s', 'command_wait_s', 'contact_model',
                    'contact_damping_n_s_per_m'})
    step = node.child('time_step_s')
    step_s = step.number(positive=True)
    if step_s > 0.01:
        raise step.error(f'{step_s!r} s is too coarse for contact dynamics (at most 0.01 s)')
    angle = node.child('initial_compliant_angle_deg')
    angle_rad = math.radians(angle.number())
    _check_within(angle, angle_rad, hand.joint_limits_rad['compliant'])
    model = node.child('contact_model')
    model_name = model.raw
    if not isinstance(model_name, str) or model_name not in CONTACT_MODELS:
        raise model.error(f'expected one of {list(CONTACT_MODELS)}, got {model_name!r}')
    damping = node.child('contact_damping_n_s_per_m')
    damping_value = damping.number()
    if damping_value < SIM_MIN_CONTACT_DAMPING_N_S_PER_M:
        raise damping.error(
            f'{damping_value!r} N*s/m is below {SIM_MIN_CONTACT_DAMPING_N_S_PER_M} N*s/m, the '
            f'contact damping Bullet gives the object of its own (it adds the two bodies\' '
            f'dampings)')
    return SimConfig(
        time_step_s=step_s,
        solver_iterations=node.child('solver_iterations').integer(minimum=1, maximum=1000),
        initial_compliant_angle_rad=angle_rad,
        servo_force_limit_nm=node.child('servo_force_limit_nm').number(positive=True),
        object_faces=node.child('object_faces').integer(minimum=8, maximum=512),
        compliant_rotor_inertia_kg_m2=node.child('compliant_rotor_inertia_kg_m2').number(
            nonnegative=True),
        palm_thickness_m=node.child('palm_thickness_m').number(nonnegative=True),
        stall_timeout_s=_wall_bound(node.child('stall_timeout_s')),
        command_wait_s=_wall_bound(node.child('command_wait_s')),
        contact_model=model_name,
        contact_damping_n_s_per_m=damping_value,
    )


def _wall_bound(node: _Node) -> float:
    """A wall-clock bound of simulated time [s]: positive, at most a minute."""
    value = node.number(positive=True)
    if value > 60.0:
        raise node.error(f'{value!r} s is longer than a minute: a dead peer would go unnoticed')
    return value


def _device(node: _Node) -> DeviceConfig:
    node.only_keys({'host', 'state_port', 'command_port', 'rate_hz', 'watchdog_s',
                    'probe_timeout_s', 'state_timeout_s', 'torque_rate_limit_nm_per_s',
                    'torque_limit_nm', 'max_stiffness_nm_per_rad', 'max_damping_nms_per_rad',
                    'calibration'})
    watchdog = node.child('watchdog_s')
    watchdog_s = watchdog.number(positive=True)
    if watchdog_s > 0.2:
        raise watchdog.error(f'{watchdog_s!r} s: the watchdog may be at most 0.2 s')
    state_port = node.child('state_port').integer(minimum=1, maximum=65535)
    command = node.child('command_port')
    command_port = command.integer(minimum=1, maximum=65535)
    if command_port == state_port:
        raise command.error(f'{command_port} is also the state_port')
    torque_limit = node.child('torque_limit_nm').number(positive=True)
    rate_node = node.child('torque_rate_limit_nm_per_s')
    rate = rate_node.number(positive=True)
    if torque_limit / rate > _SAFE_STOP_RAMP_MAX_S:
        raise rate_node.error(
            f'{rate!r} N*m/s would take {torque_limit / rate:.3g} s to bring torque_limit_nm '
            f'({torque_limit!r} N*m) to zero after a watchdog trip; at most '
            f'{_SAFE_STOP_RAMP_MAX_S} s is allowed (a rate of at least '
            f'{torque_limit / _SAFE_STOP_RAMP_MAX_S:.6g} N*m/s)')
    cal_node = node.child('calibration')
    cal_node.only_keys(set(JOINT_ROLES))
    calibration: dict[str, Calibration] = {}
    for role in JOINT_ROLES:
        rnode = cal_node.child(role)
        rnode.only_keys({'position_scale_rad_per_count', 'position_offset_counts',
                         'torque_scale_nm_per_raw', 'torque_offset_raw',
                         'stiffness_scale_nm_per_rad_per_raw',
                         'damping_scale_nms_per_rad_per_raw'})
        calibration[role] = Calibration(
            position_scale_rad_per_count=_nonzero(rnode.child('position_scale_rad_per_count')),
            position_offset_counts=rnode.child('position_offset_counts').number(),
            torque_scale_nm_per_raw=_nonzero(rnode.child('torque_scale_nm_per_raw')),
            torque_offset_raw=rnode.child('torque_offset_raw').number(),
            stiffness_scale_nm_per_rad_per_raw=rnode.child(
                'stiffness_scale_nm_per_rad_per_raw').number(positive=True),
            damping_scale_nms_per_rad_per_raw=rnode.child(
                'damping_scale_nms_per_rad_per_raw').number(positive=True),
        )
    return DeviceConfig(
        host=node.child('host').string(),
        state_port=state_port,
        command_port=command_port,
        rate_hz=node.child('rate_hz').number(positive=True),
        watchdog_s=watchdog_s,
        probe_timeout_s=node.child('probe_timeout_s').number(positive=True),
        state_timeout_s=node.child('state_timeout_s').number(positive=True),
        torque_rate_limit_nm_per_s=rate,
        torque_limit_nm=torque_limit,
        max_stiffness_nm_per_rad=node.child('max_stiffness_nm_per_rad').number(positive=True),
        max_damping_nms_per_rad=node.child('max_damping_nms_per_rad').number(nonnegative=True),
        calibration=calibration,
    )


def _nonzero(node: _Node) -> float:
    value = node.number()
    if value == 0.0:
        raise node.error('scale must not be zero')
    return value


def _check_within(node: _Node, value_rad: float, limits: tuple[float, float]) -> None:
    if not limits[0] <= value_rad <= limits[1]:
        raise node.error(
            f'{node.raw!r} deg is outside the joint limits '
            f'[{math.degrees(limits[0]):.6g}, {math.degrees(limits[1]):.6g}] deg'
        )


# --------------------------------------------------------------------------------------------
# A cursor into the parsed YAML that knows its key path, for error messages.
