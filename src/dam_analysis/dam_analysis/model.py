"""Hand and object geometry: planar finger kinematics, capsule links and the first contact.

Every finger is planar: its three joint axes are parallel to the cylinder axis (world y), so
each finger moves in its own vertical plane spanned by the world z axis and the finger's
``inward_direction``. Inside that plane a point is written ``(u, z)``: ``u`` along
``inward_direction`` and ``z`` vertical, both measured from the compliant joint (the finger
base). A link at cumulative angle ``phi`` points along ``(sin phi, -cos phi)``: ``phi = 0``
hangs straight down and a positive angle flexes the finger inward (the sign convention of
:class:`dam_common.config.FingerConfig`).

Every link is a capsule (segment plus ``link_radius_m``); the object is a column lying on the
table, so in the finger plane it is its convex cross-section (:mod:`dam_common.cross_section`:
a disc, an ellipse or a convex polygon) placed at the column's centroid. The distal (third)
link touches the object when the distance from the cross-section to its segment equals ``r``
(eqs. 2-4 of Kaneko et al.: the two surfaces meet at one point and their normals are opposite
there). For the paper's circular cylinder that distance is the distance from the disc centre
minus ``R``, which the functions here evaluate in closed form; every other section goes
through :meth:`~dam_common.cross_section.CrossSection.segment_distance`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dam_analysis.errors import NoSolutionError
from dam_common.config import DamConfig
from dam_common.cross_section import Circle, CrossSection, SegmentDistance
from dam_common.turned_section import TurnedSection

#: Step of the scan that closes the compliant joint to the first contact [rad].
_SCAN_STEP_RAD = math.radians(0.05)


@dataclass(frozen=True)
class FingerGeometry:
    """One finger reduced to its plane, with the object's cross-section in that plane.

    Attributes
    ----------
    base_position : (3,) world position of the compliant joint axis [m].
    inward_direction : (3,) unit vector, the plane's ``u`` axis in the world.
    joint_axis : (3,) unit vector of every joint axis (positive angle flexes inward).
    link_lengths : (3,) [m].
    link_radius : capsule radius r [m].
    object_center : (2,) the column's centroid in plane coordinates ``(u, z)`` relative to the
        base [m].
    object_radius : R of a circular section [m]; for any other section its circumradius
        (only the circle's closed forms read it).
    base_height : world z of the base [m] (the table is z = 0).
    section : the cross-section in plane coordinates about ``object_center`` (mirrored for a
        finger whose ``u`` axis points against the section's ``x`` axis).
    """

    base_position: np.ndarray
    inward_direction: np.ndarray
    joint_axis: np.ndarray
    link_lengths: np.ndarray
    link_radius: float
    object_center: np.ndarray
    object_radius: float
    base_height: float
    section: CrossSection

    @property
    def is_circle(self) -> bool:
        """The section is a disc: the closed forms of the circle apply."""
        return isinstance(self.section, Circle)

    def to_world(self, point_uz: np.ndarray) -> np.ndarray:
        """Plane point(s) ``(..., 2)`` relative to the base -> world point(s) ``(..., 3)`` [m]."""
        p = np.asarray(point_uz, dtype=np.float64)
        return (self.base_position + p[..., 0:1] * self.inward_direction
                + p[..., 1:2] * np.array([0.0, 0.0, 1.0]))

    def direction_to_world(self, vec_uz: np.ndarray) -> np.ndarray:
        """Plane direction(s) ``(..., 2)`` -> world direction(s) ``(..., 3)``."""
        v = np.asarray(vec_uz, dtype=np.float64)
        return v[..., 0:1] * self.inward_direction + v[..., 1:2] * np.array([0.0, 0.0, 1.0])


def joint_positions(geometry: FingerGeometry, theta_s: float, theta_l: float,
                    theta_p: float) -> np.ndarray:
    """Planar forward kinematics.

    Parameters
    ----------
    geometry : the finger.
    theta_s, theta_l, theta_p : compliant, locked and position joint angles [rad].

    Returns
    -------
    (4, 2) array: compliant joint (the origin), locked joint, position joint and fingertip
    centre, in plane coordinates ``(u, z)`` relative to the base [m].
    """
    phi = np.cumsum([theta_s, theta_l, theta_p])
    # the same operations as stacking [sin, -cos] and prepending the origin, without the
    # array building (called for every node of every cached SPCM branch: start-up time)
    steps = np.empty((3, 2))
    steps[:, 0] = np.sin(phi)
    steps[:, 1] = -np.cos(phi)
    steps *= geometry.link_lengths[:, None]
    out = np.zeros((4, 2))
    np.cumsum(steps, axis=0, out=out[1:])
    return out


def closest_point_on_segment(a: np.ndarray, b: np.ndarray, c: np.ndarray
                             ) -> tuple[np.ndarray, float]:
    """Closest point to ``c`` on segment ``[a, b]`` (2D) and its parameter in [0, 1]."""
    ab = b - a
    denom = float(ab @ ab)
    t = 0.0 if denom == 0.0 else min(1.0, max(0.0, float((c - a) @ ab) / denom))
    return a + t * ab, t


def segment_contact(geometry: FingerGeometry, au: float, az: float, bu: float, bz: float
                    ) -> SegmentDistance:
    """Closest pair between the segment ``[a, b]`` (plane coordinates [m]) and the object.

    Returns the :class:`~dam_common.cross_section.SegmentDistance` of the section, with its
    points moved back to plane coordinates relative to the base.
    """
    cu, cz = float(geometry.object_center[0]), float(geometry.object_center[1])
    sd = geometry.section.segment_distance(au - cu, az - cz, bu - cu, bz - cz)
    (su, sz), (qu, qz) = sd.segment_point, sd.section_point
    return SegmentDistance(sd.distance, (su + cu, sz + cz), (qu + cu, qz + cz), sd.normal, sd.t)


def link_clearances(geometry: FingerGeometry, joints: np.ndarray) -> np.ndarray:
    """Signed gap between each capsule link and the object, ``(3,)`` [m] (< 0: overlap)."""
    gaps = np.empty(3)
    for k in range(3):
        if geometry.is_circle:
            q, _ = closest_point_on_segment(joints[k], joints[k + 1], geometry.object_center)
            gaps[k] = float(np.linalg.norm(q - geometry.object_center)) - (
                geometry.object_radius + geometry.link_radius)
        else:
            a, b = joints[k], joints[k + 1]
            gaps[k] = segment_contact(geometry, float(a[0]), float(a[1]), float(b[0]),
                                      float(b[1])).distance - geometry.link_radius
    return gaps


def _section_gap(geometry: FingerGeometry, qu: float, qz: float, tu: float, tz: float
                 ) -> tuple[float, float, float, float, float]:
    """Gap of the distal segment ``[q, t]`` to a non-circular section: (gap, p_u, p_z, n_u,
    n_z) with ``p`` the closest segment point and ``n`` the section's outward normal."""
    sd = segment_contact(geometry, qu, qz, tu, tz)
    pu, pz = sd.segment_point
    return sd.distance - geometry.link_radius, pu, pz, sd.normal[0], sd.normal[1]


def table_clearance(geometry: FingerGeometry, joints: np.ndarray) -> float:
    """Height of the lowest capsule point above the table z = 0 [m] (< 0: penetration)."""
    return geometry.base_height + float(joints[:, 1].min()) - geometry.link_radius


def distal_gap(geometry: FingerGeometry, theta_s: float, theta_l: float, theta_p: float
               ) -> tuple[float, float]:
    """Gap between the distal capsule and the object and its derivative w.r.t. ``theta_s``.

    Returns
    -------
    gap : distance(section, distal segment) - r [m] (for a disc: distance(centre, segment) -
        (R + r)); zero is the contact of eqs. 2-4.
    dgap_dtheta_s : [m/rad]. Rotating the whole finger about the compliant joint moves a plane
        point ``p`` with velocity ``(-p_z, p_u)``; by the envelope theorem the gap changes at
        ``n . (-q_z, q_u)`` with ``q`` the closest segment point and ``n`` the section's
        outward normal at the closest section point (for a disc: the unit vector from the
        centre to ``q``).
    """
    phi12 = theta_s + theta_l
    phi3 = phi12 + theta_p
    l1, l2, l3 = geometry.link_lengths
    qu = l1 * math.sin(theta_s) + l2 * math.sin(phi12)
    qz = -l1 * math.cos(theta_s) - l2 * math.cos(phi12)
    tu = qu + l3 * math.sin(phi3)
    tz = qz - l3 * math.cos(phi3)
    if not geometry.is_circle:
        gap, pu, pz, nu, nz = _section_gap(geometry, qu, qz, tu, tz)
        return gap, nu * (-pz) + nz * pu
    cu, cz = float(geometry.object_center[0]), float(geometry.object_center[1])
    abu, abz = tu - qu, tz - qz
    t = ((cu - qu) * abu + (cz - qz) * abz) / (abu * abu + abz * abz)
    t = min(1.0, max(0.0, t))
    pu, pz = qu + t * abu, qz + t * abz
    du, dz = pu - cu, pz - cz
    dist = math.hypot(du, dz)
    gap = dist - (geometry.object_radius + geometry.link_radius)
    deriv = (du * (-pz) + dz * pu) / dist
    return gap, deriv


def distal_gap_partials(geometry: FingerGeometry, theta_s: float, theta_l: float,
                        theta_p: float) -> tuple[float, float, float]:
    """Gap of :func:`distal_gap` with both partial derivatives (the SPCM closure, eqs. 2-4).

    Parameters
    ----------
    geometry : the finger.
    theta_s, theta_l, theta_p : compliant, locked and position joint angles [rad].

    Returns
    -------
    gap : distance(section, distal segment) - r [m].
    g_s : d gap / d theta_s [m/rad], rotation of the whole finger about the compliant joint.
    g_p : d gap / d theta_p [m/rad], rotation of the distal link about the position joint
        ``q``: a point ``p`` moves with ``(-(p_z - q_z), p_u - q_u)`` per radian, and by the
        envelope theorem the gap changes at the normal component of the closest point's
        velocity. The Jacobian of the closure in ``(theta_s, theta_p)`` is ``(g_s, g_p)``;
        a fold of the SPCM branch is a point of ``gap = 0`` where ``g_s = 0``.
    """
    phi12 = theta_s + theta_l
    phi3 = phi12 + theta_p
    l1, l2, l3 = (float(v) for v in geometry.link_lengths)
    qu = l1 * math.sin(theta_s) + l2 * math.sin(phi12)
    qz = -l1 * math.cos(theta_s) - l2 * math.cos(phi12)
    tu = qu + l3 * math.sin(phi3)
    tz = qz - l3 * math.cos(phi3)
    if not geometry.is_circle:
        gap, pu, pz, nu, nz = _section_gap(geometry, qu, qz, tu, tz)
        return gap, nu * (-pz) + nz * pu, nu * (-(pz - qz)) + nz * (pu - qu)
    cu, cz = float(geometry.object_center[0]), float(geometry.object_center[1])
    abu, abz = tu - qu, tz - qz
    t = min(1.0, max(0.0, ((cu - qu) * abu + (cz - qz) * abz) / (abu * abu + abz * abz)))
    pu, pz = qu + t * abu, qz + t * abz
    du, dz = pu - cu, pz - cz
    dist = math.hypot(du, dz)
    gap = dist - (geometry.object_radius + geometry.link_radius)
    g_s = (du * (-pz) + dz * pu) / dist
    g_p = (du * (-(pz - qz)) + dz * (pu - qu)) / dist
    return gap, g_s, g_p


@dataclass(frozen=True)
class HandModel:
    """The hand at first contact and everything the analysis needs from the configuration.

    Attributes
    ----------
    fingers : per-finger geometry, configuration order.
    theta_s0 : (n,) compliant angles at first contact [rad] (the spring rest angle: the paper
        assumes tau_s = 0 in the initial state).
    theta_l0, theta_p0 : locked and initial position joint angles [rad] (same for every finger).
    limits_s, limits_p : (min, max) of the compliant and position joints [rad].
    stiffness_ratios : (n,) k_theta_i / k_theta.
    object_weight : m_B g [N].
    object_center : (3,) world position of the column's centroid (centre of gravity) [m].
    friction_angle : configured alpha [rad].
    cone_faces : L of eq. (7).
    contact_stiffness : (3,) diagonal of K_pi [N/m] (normal, in-plane tangent, axial).
    delta_theta_p_max : largest accepted delta_theta_p [rad].
    tangential_stiffness : the CSM's tangential spring [N/m]: ``contact_stiffness[1]`` in
        series with ``contact.series_stiffness_n_per_m`` (equal to it when that is infinite),
        or the object's calibrated ``csm_tangential_stiffness_n_per_m`` where it has one.
    """

    fingers: tuple[FingerGeometry, ...]
    theta_s0: np.ndarray
    theta_l0: float
    theta_p0: float
    limits_s: tuple[float, float]
    limits_p: tuple[float, float]
    stiffness_ratios: np.ndarray
    object_weight: float
    object_center: np.ndarray
    friction_angle: float
    cone_faces: int
    contact_stiffness: np.ndarray
    delta_theta_p_max: float
    tangential_stiffness: float

    @property
    def n_fingers(self) -> int:
        return len(self.fingers)


def finger_geometries(config: DamConfig, turn: float = 0.0,
                      shift: tuple[float, float] = (0.0, 0.0)) -> tuple[FingerGeometry, ...]:
    """Reduce every configured finger to its plane (see the module docstring).

    Parameters
    ----------
    config : validated configuration.
    turn : the object's turn from its resting pose [rad], counter-clockwise in the section's
        ``(x, z)`` plane (:class:`~dam_common.turned_section.TurnedSection`); 0: at rest.
    shift : ``(x, z)`` displacement of the centroid from its resting position [m], ``x``
        along the section's ``x`` axis (``object.section_x``), ``z`` up.
    """
    hand, obj = config.hand, config.object
    out = []
    base_section = obj.section if turn == 0.0 else TurnedSection(obj.section, turn)
    position = (obj.position_m + shift[0] * obj.section_x
                + np.array([0.0, 0.0, shift[1]]))
    for finger in hand.fingers:
        base = np.asarray(finger.base_position_m, dtype=np.float64)
        axis = finger.joint_axis
        if abs(abs(float(axis @ obj.axis)) - 1.0) > 1e-9:
            raise NoSolutionError(f'finger {finger.name}: joint axis {axis.tolist()} is not '
                                  f'parallel to the object axis {obj.axis.tolist()}; the '
                                  'planar contact model needs parallel axes')
        rel = position - base
        # the finger's u axis is the section's x axis or its opposite (both are normal to the
        # object axis): mirror the section for the latter
        section = base_section
        if float(finger.inward_direction @ obj.section_x) < 0.0:
            section = section.mirrored()
        radius = section.radius if isinstance(section, Circle) else section.circumradius
        out.append(FingerGeometry(
            base_position=base, inward_direction=finger.inward_direction, joint_axis=axis,
            link_lengths=np.asarray(hand.link_lengths_m, dtype=np.float64),
            link_radius=hand.link_radius_m,
            object_center=np.array([float(rel @ finger.inward_direction), float(rel[2])]),
            object_radius=radius, base_height=float(base[2]), section=section))
    return tuple(out)


def first_contact_angle(geometry: FingerGeometry, theta_l: float, theta_p: float,
                        limits_s: tuple[float, float], name: str = 'finger') -> float:
    """Close the compliant joint from 0 until the distal capsule touches the object.

    Returns the compliant angle theta_s0 [rad] of first contact, found by a scan in steps of
    0.05 deg and Newton refinement of :func:`distal_gap`.

    Raises
    ------
    NoSolutionError
        The finger overlaps the object already at theta_s = 0, a proximal link touches first,
        the capsule is below the table at first contact, or the joint limit is reached first.
    """
    gap0, _ = distal_gap(geometry, 0.0, theta_l, theta_p)
    joints = joint_positions(geometry, 0.0, theta_l, theta_p)
    if np.any(link_clearances(geometry, joints) < 0.0):
        raise NoSolutionError(f'{name}: the hanging finger (compliant angle 0) already overlaps '
                              'the object; move the finger base')
    lo = 0.0
    hi = None
    theta = 0.0
    while theta < limits_s[1]:
        theta = min(theta + _SCAN_STEP_RAD, limits_s[1])
        joints = joint_positions(geometry, theta, theta_l, theta_p)
        gaps = link_clearances(geometry, joints)
        if gaps[2] <= 0.0:
            hi = theta
            break
        if np.any(gaps[:2] <= 0.0):
            raise NoSolutionError(f'{name}: a proximal link touches the object before the '
                                  f'distal link (compliant angle {math.degrees(theta):.3f} deg)')
        lo = theta
    if hi is None:
        raise NoSolutionError(f'{name}: the distal link does not reach the object before the '
                              f'compliant joint limit {math.degrees(limits_s[1]):.3f} deg '
                              f'(gap at 0 deg: {gap0 * 1e3:.3f} mm)')
    # bisection to machine precision (the gap is continuous and changes sign in [lo, hi])
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if distal_gap(geometry, mid, theta_l, theta_p)[0] > 0.0:
            lo = mid
        else:
            hi = mid
    theta_s0 = 0.5 * (lo + hi)
    joints = joint_positions(geometry, theta_s0, theta_l, theta_p)
    if table_clearance(geometry, joints) < 0.0:
        raise NoSolutionError(f'{name}: at first contact the finger is '
                              f'{-table_clearance(geometry, joints) * 1e3:.3f} mm below the '
                              'table')
    return theta_s0


def build_hand_model(config: DamConfig) -> HandModel:
    """Hand model at first contact from a validated configuration (paper section 3.3 set-up).

    Raises
    ------
    NoSolutionError
        A finger has no valid first contact (see :func:`first_contact_angle`).
    """
    hand = config.hand
    geometries = finger_geometries(config)
    limits_s = tuple(hand.joint_limits_rad['compliant'])
    theta_s0 = np.array([
        first_contact_angle(g, hand.initial_locked_angle_rad, hand.initial_position_angle_rad,
                            limits_s, name=f.name)  # type: ignore[arg-type]
        for g, f in zip(geometries, hand.fingers, strict=True)])
    return HandModel(
        fingers=geometries, theta_s0=theta_s0, theta_l0=hand.initial_locked_angle_rad,
        theta_p0=hand.initial_position_angle_rad, limits_s=limits_s,  # type: ignore[arg-type]
        limits_p=tuple(hand.joint_limits_rad['position']),  # type: ignore[arg-type]
        stiffness_ratios=hand.stiffness_ratios.astype(np.float64),
        object_weight=config.object_weight_n,
        object_center=np.asarray(config.object.position_m, dtype=np.float64),
        friction_angle=config.contact.friction_angle_rad, cone_faces=config.contact.cone_faces,
        contact_stiffness=np.asarray(config.contact.contact_stiffness_n_per_m,
                                     dtype=np.float64),
        delta_theta_p_max=config.task.delta_theta_p_max_rad,
        tangential_stiffness=(config.contact.tangential_stiffness_n_per_m
                              if config.object.csm_tangential_stiffness_n_per_m is None
                              else config.object.csm_tangential_stiffness_n_per_m))
