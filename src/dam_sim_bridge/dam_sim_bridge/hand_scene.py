"""The bodies of the stand-in's world in a PyBullet server: the hand, the palm, the table and
the column object (:func:`build_scene`), as :class:`~dam_sim_bridge.world.HandWorld` loads
them.

Model
-----
* The palm is fixed in the world (fixed base, no collision shape). Each finger is a chain of
  three revolute joints (compliant, locked, position) about the finger's
  :attr:`~dam_common.config.FingerConfig.joint_axis`; a positive angle flexes the finger
  inward, all angles zero hang it straight down from its base.
* Link ``i`` is a capsule of radius ``hand.link_radius_m`` whose segment runs from joint ``i``
  to joint ``i + 1`` (``hand.link_lengths_m``); the last segment ends at the fingertip centre.
  Its mass is :attr:`WorldOptions.link_masses_kg`, its centre of mass the segment midpoint and
  its inertia that of a solid cylinder of the segment's length and the link radius. The
  compliant link also carries :attr:`WorldOptions.compliant_rotor_inertia_kg_m2` about its
  joint axis: the reflected inertia of the joint's drive (motor and reduction). The first link
  hangs from the fixed palm by the compliant joint alone, so this is exactly a rotor inertia
  on that joint; it changes no mass, no gravity load and no static torque.
* The palm is a static box (:attr:`WorldOptions.palm_thickness_m`) whose underside is the
  plane of the finger bases, between the fingers (2 mm clear of the capsules at the base
  joints; it never collides with the fingers). It is what the object is pressed against in
  the enveloping grasp (paper section 2: "lifting it up toward the palm, and firmly
  grasping"); without it a cylinder squeezed below its equator by constant finger torques
  squirts upward out of the hand. Its friction with the object is the fingers' ``tan(alpha)``.
* The table is a static box whose top is the plane ``z = 0``; the column object (``object``,
  one of the configuration's object library) lies on it with its axis along ``object.axis``.
  Its collision shape is the convex mesh of a prism of its cross-section (zero collision
  margin): a polygon's own vertices, a circle or an ellipse as
  :attr:`WorldOptions.object_faces` faces tangent to it, with the homogeneous column's mass and
  inertia (:mod:`dam_sim_bridge.column_body`). Bullet's primitive cylinder creeps and rolls
  away on a flat table by itself (about 0.17 m in 5 s), the prism rests.
* Friction. Bullet combines the lateral friction of two bodies by multiplying them. The finger
  links get ``tan(alpha)``, the object ``1.0`` and the table
  ``contact.table_friction_coefficient``, so finger-object = ``tan(alpha)`` and table-object =
  the table coefficient, exactly, also for ``alpha = 0``. Finger-table is their product
  ``tan(alpha) * table coefficient`` (the fingers are not meant to touch the table). Rolling and
  spinning friction are zero, restitution is zero.
* Contact model (:attr:`WorldOptions.contact_model`). ``'rigid'``: Bullet's rigid contacts
  (penetration corrected by the solver's error reduction, a slop of 1e-5 m). ``'compliant'``:
  every contact of a finger link is Bullet's implicit normal spring-damper (``changeDynamics``
  ``contactStiffness`` / ``contactDamping`` on the nine links, contact slop 0): the force of a
  contact point is ``k_n * penetration + d * approach speed``, the CSM's contact spring of
  ``contact.contact_stiffness_n_per_m[0]``. Bullet combines the two bodies of a contact in
  series, ``1/k = 1/k_0 + 1/k_1``, and adds their dampings; a body whose parameters were never
  set has a stiffness of 1e30 N/m (rigid in series) and a damping of 0.1 N*s/m. The object
  and the static table and palm keep those defaults, so the links get ``k_n`` and ``d - 0.1``
  and a finger-object contact has exactly ``k_n`` and ``d``
  (:meth:`~dam_sim_bridge.world.HandWorld.pair_contact`), while the table's and the palm's
  contacts with the object stay rigid: Bullet's contact manifold of a flat face (at most four
  points, found one per step) makes springs there rock and roll the resting prism away.
  Friction stays Bullet's impulse friction (no tangential spring).
"""

from __future__ import annotations

import os
import tempfile
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from dam_common.config import SIM_MIN_CONTACT_DAMPING_N_S_PER_M
from dam_common.cross_section import Circle
from dam_common.hand_urdf import hand_urdf
from dam_sim_bridge.column_body import (
    prism_inertia,
    prism_triangles,
    prism_vertices,
    resting_quaternion,
)
from dam_sim_bridge.errors import SimulationError, WorldConfigError
from dam_sim_bridge.pybullet_import import bullet_client, pybullet

if TYPE_CHECKING:
    from dam_common.config import DamConfig
    from dam_sim_bridge.world_options import WorldOptions

_TABLE_HALF_EXTENTS_M = (0.25, 0.25, 0.02)


@dataclass
class JointTable:
    """The hand's actuated joints in the loaded model, in ``HandConfig.joint_names`` order."""

    indices: list[int] = field(default_factory=list)  #: Bullet joint (= link) indices
    roles: list[str] = field(default_factory=list)  #: 'compliant', 'locked' or 'position'
    lower: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: lower limits [rad]
    upper: np.ndarray = field(default_factory=lambda: np.zeros(0))  #: upper limits [rad]
    lower_list: list[float] = field(default_factory=list)  #: the same limits as lists [rad]
    upper_list: list[float] = field(default_factory=list)


@dataclass(frozen=True)
class Scene:
    """The Bullet bodies of the world, as :func:`build_scene` made them."""

    hand_id: int  #: the hand (fixed base; its links are the finger links)
    table_id: int  #: the static table, top face at z = 0
    palm_id: int | None  #: the static palm box; ``None`` without a palm
    object_id: int  #: the column object
    joints: JointTable  #: the actuated joints of the hand
    resting_quaternion: tuple[float, float, float, float]  #: the object's resting pose


def build_scene(pb: bullet_client.BulletClient, config: DamConfig,
                options: WorldOptions) -> Scene:
    """Load the hand, the table, the palm and the object of ``config`` into ``pb``.

    Every actuated joint is left with its default velocity motor disabled and the contact
    model of ``options`` set (see the module docstring); the friction coefficients are the
    world's to set.

    Raises
    ------
    SimulationError
        The hand model could not be loaded or lacks a joint of ``config``.
    WorldConfigError
        A palm is asked for but the finger bases leave no room for it.
    """
    urdf = hand_urdf(config, link_masses_kg=np.asarray(options.link_masses_kg, dtype=float),
                     compliant_rotor_inertia_kg_m2=options.compliant_rotor_inertia_kg_m2,
                     for_pybullet=True)
    fd, path = tempfile.mkstemp(suffix='.urdf', prefix='dam_hand_')
    try:
        with os.fdopen(fd, 'w', encoding='utf-8') as handle:
            handle.write(urdf)
        hand_id = pb.loadURDF(path, useFixedBase=True,
                              flags=pybullet.URDF_USE_INERTIA_FROM_FILE)
    except Exception as exc:  # noqa: BLE001
        raise SimulationError(f'cannot load the hand model: {exc}') from exc
    finally:
        os.unlink(path)
    by_name = {pb.getJointInfo(hand_id, j)[1].decode(): j
               for j in range(pb.getNumJoints(hand_id))}
    joints = JointTable()
    for name in config.hand.joint_names:
        if name not in by_name:
            raise SimulationError(f'joint {name!r} missing from the loaded model')
        joints.indices.append(by_name[name])
        joints.roles.append(name.rsplit('_', 2)[-2])
    limits = [config.hand.joint_limits_rad[r] for r in joints.roles]
    joints.lower = np.array([lim[0] for lim in limits])
    joints.upper = np.array([lim[1] for lim in limits])
    joints.lower_list = joints.lower.tolist()
    joints.upper_list = joints.upper.tolist()
    for j in joints.indices:
        pb.changeDynamics(hand_id, j, linearDamping=0.0, angularDamping=0.0,
                          jointDamping=0.0, restitution=0.0, rollingFriction=0.0,
                          spinningFriction=0.0)
    # Table: static box, top face at z = 0.
    hx, hy, hz = _TABLE_HALF_EXTENTS_M
    box = pb.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[hx, hy, hz])
    box_vis = pb.createVisualShape(pybullet.GEOM_BOX, halfExtents=[hx, hy, hz],
                                   rgbaColor=[0.6, 0.5, 0.4, 1.0])
    table_id = pb.createMultiBody(0.0, box, box_vis, basePosition=[0.0, 0.0, -hz])
    palm_id = _build_palm(pb, config, options, hand_id, joints)
    # Object: the column, local z along object.axis, a convex mesh of its cross-section.
    obj = config.object
    inertia, beta = prism_inertia(obj.section, obj.mass_kg, obj.length_m)
    vertices = prism_vertices(obj.section, obj.length_m, options.object_faces, beta)
    hull = pb.createCollisionShape(pybullet.GEOM_MESH, vertices=vertices.tolist())
    if isinstance(obj.section, Circle):
        visual = pb.createVisualShape(pybullet.GEOM_CYLINDER, radius=obj.section.radius,
                                      length=obj.length_m, rgbaColor=[0.2, 0.4, 0.8, 1.0])
    else:
        visual = pb.createVisualShape(pybullet.GEOM_MESH, vertices=vertices.tolist(),
                                      indices=prism_triangles(len(vertices) // 2),
                                      rgbaColor=[0.2, 0.4, 0.8, 1.0])
    resting = resting_quaternion(obj)
    object_id = pb.createMultiBody(obj.mass_kg, hull, visual,
                                   basePosition=obj.position_m.tolist(),
                                   baseOrientation=resting)
    for body in (table_id, object_id):
        pb.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0, restitution=0.0,
                          rollingFriction=0.0, spinningFriction=0.0)
    # Zero margin: the hull is the object's true surface; the homogeneous prism's inertia
    # (Bullet would use the hull's bounding box).
    pb.changeDynamics(object_id, -1, collisionMargin=0.0, localInertiaDiagonal=list(inertia))
    pb.setJointMotorControlArray(hand_id, joints.indices, pybullet.VELOCITY_CONTROL,
                                 forces=[0.0] * len(joints.indices))
    _set_contact_model(pb, options, hand_id, joints)
    return Scene(hand_id=hand_id, table_id=table_id, palm_id=palm_id, object_id=object_id,
                 joints=joints, resting_quaternion=resting)


def _set_contact_model(pb: bullet_client.BulletClient, options: WorldOptions, hand_id: int,
                       joints: JointTable) -> None:
    """Compliant contacts: the finger links get ``k_n`` and ``d - 0.1`` (the object's
    own damping in Bullet), so that every finger-object contact has the normal stiffness
    ``k_n`` and the damping ``d``; the contact slop is zero (the spring's rest length).
    Rigid: nothing changes. ``changeDynamics`` calls without ``contactStiffness`` (the
    friction settings) keep these values."""
    if options.contact_model != 'compliant':
        return
    pb.setPhysicsEngineParameter(contactSlop=0.0)
    link_damping = options.contact_damping_n_s_per_m - SIM_MIN_CONTACT_DAMPING_N_S_PER_M
    for j in joints.indices:
        pb.changeDynamics(hand_id, j, contactStiffness=options.contact_stiffness_n_per_m,
                          contactDamping=link_damping)


def _build_palm(pb: bullet_client.BulletClient, config: DamConfig, options: WorldOptions,
                hand_id: int, joints: JointTable) -> int | None:
    """The static palm box (see the module docstring); ``None`` if disabled."""
    thickness = float(options.palm_thickness_m)
    if thickness <= 0.0:
        return None
    hand = config.hand
    bases = np.array([f.base_position_m for f in hand.fingers], dtype=float)
    clear = float(hand.link_radius_m) + 0.002
    half_x = float(np.abs(bases[:, 0]).min()) - clear
    half_y = float(np.abs(bases[:, 1]).max()) + clear
    if half_x <= 0.0:
        raise WorldConfigError('the finger bases leave no room for a palm; set '
                               'palm_thickness_m = 0')
    half = [half_x, half_y, thickness / 2.0]
    centre = [float(bases[:, 0].mean()), float(bases[:, 1].mean()),
              float(bases[:, 2].max()) + thickness / 2.0]
    box = pb.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
    vis = pb.createVisualShape(pybullet.GEOM_BOX, halfExtents=half,
                               rgbaColor=[0.3, 0.3, 0.3, 1.0])
    palm = pb.createMultiBody(0.0, box, vis, basePosition=centre)
    for j in [-1, *joints.indices]:
        pb.setCollisionFilterPair(palm, hand_id, -1, j, 0)
    pb.changeDynamics(palm, -1, restitution=0.0, rollingFriction=0.0, spinningFriction=0.0)
    return int(palm)
