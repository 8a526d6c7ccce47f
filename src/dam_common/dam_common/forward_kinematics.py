"""Forward kinematics of a URDF: each joint's parent -> child transform (no rclpy).

The pure core of ``dam_state_publisher`` (what ``robot_state_publisher`` does, which is not
among the PyPI wheels): the URDF's joints, read once; for joint positions, the transform of
every movable joint (``/tf``), and once the transform of every fixed joint (``/tf_static``).

A joint's transform takes coordinates in its child link's frame to its parent link's frame:
the joint's ``<origin>`` (``xyz`` [m], then ``rpy`` [rad]: roll about x, pitch about y, yaw
about z, all about the parent's fixed axes, i.e. ``R = Rz(yaw) Ry(pitch) Rx(roll)``), followed
by the motion of the joint along or about its ``<axis>`` (default ``1 0 0``): a rotation by
the position [rad] for ``revolute`` and ``continuous``, a translation by the position [m] for
``prismatic``, nothing for ``fixed``. Rotations are unit quaternions ``(x, y, z, w)``, the
order of ``geometry_msgs/Quaternion``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from xml.etree import ElementTree as ET

import numpy as np

#: Joint types that move, and the one that does not (floating and planar are refused).
MOVING_TYPES = ('revolute', 'continuous', 'prismatic')
FIXED_TYPE = 'fixed'

Quaternion = tuple[float, float, float, float]
Vector = tuple[float, float, float]


class UrdfError(ValueError):
    """A URDF this core cannot use (unreadable XML, a bad number, an unsupported joint)."""


@dataclass(frozen=True)
class Transform:
    """A rigid transform from ``child``'s frame to ``parent``'s frame.

    Attributes
    ----------
    parent, child
        Frame (link) names.
    translation
        The child frame's origin in the parent frame [m].
    rotation
        The child frame's orientation in the parent frame, unit quaternion ``(x, y, z, w)``.
    """

    parent: str
    child: str
    translation: Vector
    rotation: Quaternion


@dataclass(frozen=True)
class Joint:
    """One URDF joint, as this core uses it.

    Attributes
    ----------
    name, kind
        The joint's name and type (``revolute``, ``continuous``, ``prismatic`` or ``fixed``).
    parent, child
        The links it joins.
    origin_xyz
        ``<origin xyz>`` [m].
    origin_rotation
        ``<origin rpy>`` as a unit quaternion ``(x, y, z, w)``.
    axis
        The unit ``<axis>`` in the joint (child) frame.
    """

    name: str
    kind: str
    parent: str
    child: str
    origin_xyz: Vector
    origin_rotation: Quaternion
    axis: Vector


def quaternion_from_rpy(roll: float, pitch: float, yaw: float) -> Quaternion:
    """The unit quaternion ``(x, y, z, w)`` of URDF's ``rpy`` [rad] (``Rz(yaw) Ry(pitch)
    Rx(roll)``)."""
    cr, sr = math.cos(roll / 2.0), math.sin(roll / 2.0)
    cp, sp = math.cos(pitch / 2.0), math.sin(pitch / 2.0)
    cy, sy = math.cos(yaw / 2.0), math.sin(yaw / 2.0)
    return (sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def quaternion_multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """The Hamilton product ``a * b`` (rotation ``b`` first, then ``a``), ``(x, y, z, w)``."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def quaternion_about(axis: Vector, angle_rad: float) -> Quaternion:
    """The rotation by ``angle_rad`` [rad] about the unit vector ``axis``, ``(x, y, z, w)``."""
    s = math.sin(angle_rad / 2.0)
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle_rad / 2.0))


def rotation_matrix(q: Quaternion) -> np.ndarray:
    """The 3x3 rotation matrix of the unit quaternion ``q = (x, y, z, w)``."""
    x, y, z, w = q
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def _numbers(text: str | None, default: Vector, what: str) -> Vector:
    if text is None:
        return default
    parts = text.split()
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        raise UrdfError(f'{what} {text!r} is not three numbers') from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise UrdfError(f'{what} {text!r} is not three finite numbers')
    return values  # type: ignore[return-value]


def parse_joints(urdf: str) -> list[Joint]:
    """The joints of the URDF document ``urdf``, in document order.

    Raises
    ------
    UrdfError
        The text is not XML with a ``<robot>`` root, a joint lacks its name, parent or child,
        a number is bad, an axis is zero, or a joint is ``floating`` or ``planar``.
    """
    try:
        robot = ET.fromstring(urdf)
    except ET.ParseError as exc:
        raise UrdfError(f'the robot description is not XML: {exc}') from None
    if robot.tag != 'robot':
        raise UrdfError(f'the robot description\'s root is <{robot.tag}>, not <robot>')
    joints = []
    for element in robot.findall('joint'):
        name = element.get('name')
        kind = element.get('type')
        parent = element.find('parent')
        child = element.find('child')
        if not name or parent is None or child is None or not parent.get('link') \
                or not child.get('link'):
            raise UrdfError(f'joint {name!r} lacks a name, a parent link or a child link')
        if kind not in MOVING_TYPES and kind != FIXED_TYPE:
            raise UrdfError(f'joint {name!r} has type {kind!r}; this publisher takes '
                            f'{", ".join(MOVING_TYPES)} and {FIXED_TYPE}')
        origin = element.find('origin')
        xyz = _numbers(None if origin is None else origin.get('xyz'), (0.0, 0.0, 0.0),
                       f'joint {name!r} origin xyz')
        rpy = _numbers(None if origin is None else origin.get('rpy'), (0.0, 0.0, 0.0),
                       f'joint {name!r} origin rpy')
        axis_element = element.find('axis')
        axis = _numbers(None if axis_element is None else axis_element.get('xyz'),
                        (1.0, 0.0, 0.0), f'joint {name!r} axis')
        norm = math.sqrt(sum(a * a for a in axis))
        if kind != FIXED_TYPE and norm == 0.0:
            raise UrdfError(f'joint {name!r} has the zero axis {axis!r}')
        unit = (axis[0] / norm, axis[1] / norm, axis[2] / norm) if norm > 0.0 else axis
        joints.append(Joint(name, str(kind), str(parent.get('link')),
                            str(child.get('link')), xyz, quaternion_from_rpy(*rpy), unit))
    return joints


def joint_transform(joint: Joint, position: float = 0.0) -> Transform:
    """The transform ``joint.child`` -> ``joint.parent`` at ``position`` [rad or m]."""
    rotation = joint.origin_rotation
    translation = joint.origin_xyz
    if joint.kind in ('revolute', 'continuous'):
        rotation = quaternion_multiply(rotation, quaternion_about(joint.axis, position))
    elif joint.kind == 'prismatic':
        shift = rotation_matrix(rotation) @ (np.asarray(joint.axis) * position)
        translation = (translation[0] + float(shift[0]), translation[1] + float(shift[1]),
                       translation[2] + float(shift[2]))
    return Transform(joint.parent, joint.child, translation, rotation)


class RobotKinematics:
    """The joints of one URDF: transforms for joint positions.

    Parameters
    ----------
    urdf
        The URDF document.

    Raises
    ------
    UrdfError
        See :func:`parse_joints`; also a link that is the child of two joints.
    """

    def __init__(self, urdf: str) -> None:
        self.joints = parse_joints(urdf)
        children: dict[str, str] = {}
        for joint in self.joints:
            if joint.child in children:
                raise UrdfError(f'link {joint.child!r} is the child of both joint '
                                f'{children[joint.child]!r} and joint {joint.name!r}')
            children[joint.child] = joint.name
        self.moving = [j for j in self.joints if j.kind != FIXED_TYPE]
        self.fixed = [j for j in self.joints if j.kind == FIXED_TYPE]
        self._by_name = {j.name: j for j in self.joints}
        roots = {j.parent for j in self.joints} - set(children)
        #: Links that are no joint's child (one for a URDF that is a tree).
        self.roots = sorted(roots)

    def fixed_transforms(self) -> list[Transform]:
        """The transform of every fixed joint (what ``/tf_static`` carries)."""
        return [joint_transform(j) for j in self.fixed]

    def moving_transforms(self, positions: Mapping[str, float]) -> list[Transform]:
        """The transform of every movable joint named in ``positions`` [rad or m].

        Joints not named are left out (their frames are not updated), as are names that are
        no movable joint of this URDF; a position that is not finite is refused.

        Raises
        ------
        ValueError
            A position that is NaN or infinite (names the joint and the value).
        """
        out = []
        for joint in self.moving:
            if joint.name not in positions:
                continue
            value = float(positions[joint.name])
            if not math.isfinite(value):
                raise ValueError(f'joint {joint.name!r} position {value!r} is not finite')
            out.append(joint_transform(joint, value))
        return out

    def unknown_joints(self, names: list[str]) -> list[str]:
        """The names in ``names`` that are no movable joint of this URDF."""
        return [n for n in names if n not in self._by_name
                or self._by_name[n].kind == FIXED_TYPE]

    def link_poses(self, positions: Mapping[str, float]) -> dict[str, np.ndarray]:
        """Every link's pose in its root link's frame, as a 4x4 homogeneous matrix.

        Movable joints missing from ``positions`` are at 0.
        """
        local = {t.child: t for t in self.fixed_transforms()}
        full = {j.name: positions.get(j.name, 0.0) for j in self.moving}
        local.update({t.child: t for t in self.moving_transforms(full)})
        poses: dict[str, np.ndarray] = {root: np.eye(4) for root in self.roots}

        def pose_of(link: str, depth: int = 0) -> np.ndarray:
            if link not in poses:
                if depth > len(local):
                    raise UrdfError(f'link {link!r} lies on a cycle of joints')
                t = local[link]
                m = np.eye(4)
                m[:3, :3] = rotation_matrix(t.rotation)
                m[:3, 3] = t.translation
                poses[link] = pose_of(t.parent, depth + 1) @ m
            return poses[link]

        for link in local:
            pose_of(link)
        return poses
