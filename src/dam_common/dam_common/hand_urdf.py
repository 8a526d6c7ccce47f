"""The hand as a URDF, generated from the configuration: the one model of the hand (no rclpy).

The driver publishes it on ``/robot_description`` (``robot_state_publisher``, RViz and
Foxglove show the hand from ``/joint_states``, live or from a bag) and the PyBullet stand-in
loads it, so the picture and the simulated hand cannot drift apart. The model is the one the
analysis uses (``config/dam.yaml``):

- a root link ``hand_base`` in the world frame (z up, the table top at z = 0);
- per finger, the chain ``<finger>_compliant_joint`` -> ``<finger>_locked_joint`` ->
  ``<finger>_position_joint`` (revolute, joint limits of their roles, effort limit
  ``device.torque_limit_nm``), then a fixed ``<finger>_fingertip`` frame at the fingertip
  centre. The compliant joint sits at ``base_position_m`` with the finger frame turned by
  ``base_yaw_deg`` about z; every joint turns about the finger frame's -y axis, so a positive
  angle flexes the finger inward (+x) and all angles zero let it hang straight down;
- each link the capsule of the analysis (radius ``link_radius_m`` around the segment from its
  joint to the next), its mass at its middle with the inertia of a solid cylinder. URDF has no
  capsule, so the standard document draws it as a cylinder with a sphere at its far end.

``for_pybullet=True`` writes the same links, joints, masses and inertias for PyBullet, which
differs in three points of form only: the capsule as PyBullet's own ``<capsule>`` element;
no fingertip frames (PyBullet gives a link without ``<inertial>`` a mass of 1 kg, and a
massless link is singular in its multibody); and the fixed root link with a nominal inertial
(PyBullet warns without one; it never moves).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import TYPE_CHECKING
from xml.etree import ElementTree as ET

if TYPE_CHECKING:  # pragma: no cover
    from dam_common.config import DamConfig

#: Name of the root link.
BASE_LINK = 'hand_base'
#: Joint velocity limit written into the URDF [rad/s] (informative: the driver limits torque,
#: and the stand-in enforces no joint velocity limit).
VELOCITY_LIMIT_RAD_PER_S = 100.0


def _fmt(*values: float) -> str:
    return ' '.join(repr(float(v)) for v in values)


def _origin(parent: ET.Element, xyz: tuple[float, float, float],
            rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
    ET.SubElement(parent, 'origin', xyz=_fmt(*xyz), rpy=_fmt(*rpy))


def solid_cylinder_inertia(mass_kg: float, length_m: float, radius_m: float
                           ) -> tuple[float, float, float]:
    """Principal inertia ``(ixx, iyy, izz)`` [kg*m^2] of a solid cylinder along z about its
    centre (transverse ``m (3 r^2 + L^2) / 12``, axial ``m r^2 / 2``)."""
    transverse = mass_kg * (3.0 * radius_m ** 2 + length_m ** 2) / 12.0
    return transverse, transverse, 0.5 * mass_kg * radius_m ** 2


def _capsule_link(robot: ET.Element, name: str, length_m: float, radius_m: float,
                  mass_kg: float, rotor_kg_m2: float, capsule: bool) -> None:
    link = ET.SubElement(robot, 'link', name=name)
    inertial = ET.SubElement(link, 'inertial')
    _origin(inertial, (0.0, 0.0, -length_m / 2.0))
    ET.SubElement(inertial, 'mass', value=_fmt(mass_kg))
    ixx, iyy, izz = solid_cylinder_inertia(mass_kg, length_m, radius_m)
    # a disc rotor about the joint axis (y); J/2 about the other axes keeps the tensor valid,
    # and the joint does not let the link turn about them
    ixx, iyy, izz = ixx + rotor_kg_m2 / 2.0, iyy + rotor_kg_m2, izz + rotor_kg_m2 / 2.0
    ET.SubElement(inertial, 'inertia', ixx=_fmt(ixx), ixy='0', ixz='0', iyy=_fmt(iyy),
                  iyz='0', izz=_fmt(izz))
    for kind in ('visual', 'collision'):
        if capsule:
            body = ET.SubElement(link, kind, name=f'{name}_capsule')
            _origin(body, (0.0, 0.0, -length_m / 2.0))
            ET.SubElement(ET.SubElement(body, 'geometry'), 'capsule', radius=_fmt(radius_m),
                          length=_fmt(length_m))
            continue
        shaft = ET.SubElement(link, kind, name=f'{name}_shaft')
        _origin(shaft, (0.0, 0.0, -length_m / 2.0))
        ET.SubElement(ET.SubElement(shaft, 'geometry'), 'cylinder', radius=_fmt(radius_m),
                      length=_fmt(length_m))
        tip = ET.SubElement(link, kind, name=f'{name}_end')
        _origin(tip, (0.0, 0.0, -length_m))
        ET.SubElement(ET.SubElement(tip, 'geometry'), 'sphere', radius=_fmt(radius_m))


def hand_urdf(config: DamConfig, robot_name: str = 'dam_hand', *,
              link_masses_kg: Sequence[float] | None = None,
              compliant_rotor_inertia_kg_m2: float = 0.0, for_pybullet: bool = False) -> str:
    """The URDF of the configured hand (see the module docstring).

    Parameters
    ----------
    config
        A validated configuration.
    robot_name
        The ``<robot name=...>``.
    link_masses_kg
        Mass of each link, base to tip [kg]; ``None``: ``hand.link_masses_kg``.
    compliant_rotor_inertia_kg_m2
        Rotor inertia added to each compliant link about its joint axis [kg*m^2] (the
        stand-in's model of the compliant actuator; 0: none).
    for_pybullet
        The document for PyBullet's loader (see the module docstring), not standard URDF.

    Returns
    -------
    str
        The URDF document (UTF-8 XML text).

    Raises
    ------
    ValueError
        A mass list of the wrong length, a mass that is not positive, or a negative rotor
        inertia.
    """
    hand = config.hand
    lengths = [float(v) for v in hand.link_lengths_m]
    masses = [float(v) for v in (hand.link_masses_kg if link_masses_kg is None
                                 else link_masses_kg)]
    if len(masses) != len(lengths) or not all(m > 0.0 for m in masses):
        raise ValueError(f'link_masses_kg {masses!r} must be {len(lengths)} positive masses')
    rotor = float(compliant_rotor_inertia_kg_m2)
    if not rotor >= 0.0:
        raise ValueError(f'compliant_rotor_inertia_kg_m2 {rotor!r} must be >= 0')
    robot = ET.Element('robot', name=robot_name)
    base_link = ET.SubElement(robot, 'link', name=BASE_LINK)
    if for_pybullet:
        inertial = ET.SubElement(base_link, 'inertial')
        ET.SubElement(inertial, 'mass', value='0.1')
        ET.SubElement(inertial, 'inertia', ixx='1e-4', ixy='0', ixz='0', iyy='1e-4', iyz='0',
                      izz='1e-4')
    effort = float(config.device.torque_limit_nm)
    radius = float(hand.link_radius_m)
    for finger in hand.fingers:
        parent = BASE_LINK
        for k, (role, joint_name) in enumerate(zip(hand.joint_roles, finger.joint_names,
                                                   strict=True)):
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
            ET.SubElement(joint, 'dynamics', damping='0', friction='0')
            _capsule_link(robot, child, lengths[k], radius, masses[k],
                          rotor if k == 0 else 0.0, for_pybullet)
            parent = child
        if for_pybullet:
            continue
        tip = ET.SubElement(robot, 'joint', name=f'{finger.name}_fingertip_joint',
                            type='fixed')
        _origin(tip, (0.0, 0.0, -lengths[-1]))
        ET.SubElement(tip, 'parent', link=parent)
        ET.SubElement(tip, 'child', link=f'{finger.name}_fingertip')
        ET.SubElement(robot, 'link', name=f'{finger.name}_fingertip')
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding='unicode') + '\n'
