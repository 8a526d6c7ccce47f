"""The hand as a URDF, generated from the configuration (no rclpy).

The driver publishes it on ``/robot_description`` so that ``robot_state_publisher``, RViz and
Foxglove show the hand from ``/joint_states``, live or from a bag. The model is the one the
analysis and the stand-in use (``config/dam.yaml``):

- a root link ``hand_base`` in the world frame (z up, the table top at z = 0);
- per finger, the chain ``<finger>_compliant_joint`` -> ``<finger>_locked_joint`` ->
  ``<finger>_position_joint`` (revolute, joint limits of their roles, effort limit
  ``device.torque_limit_nm``), then a fixed ``<finger>_fingertip`` frame at the fingertip
  centre. The compliant joint sits at ``base_position_m`` with the finger frame turned by
  ``base_yaw_deg`` about z; every joint turns about the finger frame's -y axis, so a positive
  angle flexes the finger inward (+x) and all angles zero let it hang straight down;
- each link a cylinder of the link radius along -z with a sphere at its far end (the capsule
  of the analysis, which URDF cannot express), and its mass at its middle.
"""

from __future__ import annotations

from typing import TYPE_CHECKING
from xml.etree import ElementTree as ET

if TYPE_CHECKING:  # pragma: no cover
    from dam_common.config import DamConfig

#: Name of the root link.
BASE_LINK = 'hand_base'
#: Joint velocity limit written into the URDF [rad/s] (informative: the driver limits torque).
VELOCITY_LIMIT_RAD_PER_S = 10.0


def _fmt(*values: float) -> str:
    return ' '.join(repr(float(v)) for v in values)


def _origin(parent: ET.Element, xyz: tuple[float, float, float],
            rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
    ET.SubElement(parent, 'origin', xyz=_fmt(*xyz), rpy=_fmt(*rpy))


def _capsule_link(robot: ET.Element, name: str, length_m: float, radius_m: float,
                  mass_kg: float) -> None:
    link = ET.SubElement(robot, 'link', name=name)
    inertial = ET.SubElement(link, 'inertial')
    _origin(inertial, (0.0, 0.0, -length_m / 2.0))
    ET.SubElement(inertial, 'mass', value=_fmt(mass_kg))
    # solid cylinder about its centre (a thin rod would do; this keeps it positive definite)
    i_axial = 0.5 * mass_kg * radius_m ** 2
    i_radial = mass_kg * (3.0 * radius_m ** 2 + length_m ** 2) / 12.0
    ET.SubElement(inertial, 'inertia', ixx=_fmt(i_radial), ixy='0', ixz='0',
                  iyy=_fmt(i_radial), iyz='0', izz=_fmt(i_axial))
    for kind in ('visual', 'collision'):
        shaft = ET.SubElement(link, kind, name=f'{name}_shaft')
        _origin(shaft, (0.0, 0.0, -length_m / 2.0))
        ET.SubElement(ET.SubElement(shaft, 'geometry'), 'cylinder', radius=_fmt(radius_m),
                      length=_fmt(length_m))
        tip = ET.SubElement(link, kind, name=f'{name}_end')
        _origin(tip, (0.0, 0.0, -length_m))
        ET.SubElement(ET.SubElement(tip, 'geometry'), 'sphere', radius=_fmt(radius_m))


def hand_urdf(config: DamConfig, robot_name: str = 'dam_hand') -> str:
    """The URDF of the configured hand (see the module docstring).

    Parameters
    ----------
    config
        A validated configuration.
    robot_name
        The ``<robot name=...>``.

    Returns
    -------
    str
        The URDF document (UTF-8 XML text).
    """
    hand = config.hand
    robot = ET.Element('robot', name=robot_name)
    ET.SubElement(robot, 'link', name=BASE_LINK)
    effort = float(config.device.torque_limit_nm)
    lengths = [float(v) for v in hand.link_lengths_m]
    masses = [float(v) for v in hand.link_masses_kg]
    radius = float(hand.link_radius_m)
    for finger in hand.fingers:
        parent = BASE_LINK
        names = finger.joint_names
        for k, (role, joint_name) in enumerate(zip(hand.joint_roles, names, strict=True)):
            child = f'{finger.name}_{role}_link'
            joint = ET.SubElement(robot, 'joint', name=joint_name, type='revolute')
            if k == 0:
                base = [float(v) for v in finger.base_position_m]
                _origin(joint, (base[0], base[1], base[2]), (0.0, 0.0, finger.base_yaw_rad))
            else:
                _origin(joint, (0.0, 0.0, -lengths[k - 1]))
            ET.SubElement(joint, 'parent', link=parent)
            ET.SubElement(joint, 'child', link=child)
            ET.SubElement(joint, 'axis', xyz='0 -1 0')
            lower, upper = hand.joint_limits_rad[role]
            ET.SubElement(joint, 'limit', lower=_fmt(lower), upper=_fmt(upper),
                          effort=_fmt(effort), velocity=_fmt(VELOCITY_LIMIT_RAD_PER_S))
            _capsule_link(robot, child, lengths[k], radius, masses[k])
            parent = child
        tip = ET.SubElement(robot, 'joint', name=f'{finger.name}_fingertip_joint',
                            type='fixed')
        _origin(tip, (0.0, 0.0, -lengths[-1]))
        ET.SubElement(tip, 'parent', link=parent)
        ET.SubElement(tip, 'child', link=f'{finger.name}_fingertip')
        ET.SubElement(robot, 'link', name=f'{finger.name}_fingertip')
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding='unicode') + '\n'


def main() -> None:
    """``hand_urdf [CONFIG]``: print the URDF of the configured hand (for
    ``robot_state_publisher``'s ``robot_description`` parameter)."""
    import sys

    from dam_common.config import load_config
    from dam_common.errors import ConfigError

    if any(a in ('-h', '--help') for a in sys.argv[1:]):
        print('usage: hand_urdf [CONFIG.yaml]\nPrint the URDF of the hand described by the '
              'configuration (default: DAM_CONFIG or the installed config/dam.yaml).')
        return
    try:
        config = load_config(sys.argv[1] if len(sys.argv) > 1 else None)
    except ConfigError as exc:
        print(f'hand_urdf: {exc}', file=sys.stderr)
        raise SystemExit(2) from None
    sys.stdout.write(hand_urdf(config))

