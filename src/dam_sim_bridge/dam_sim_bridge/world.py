"""The PyBullet world of the DAM hand: three capsule fingers, a table and the cylinder.

:class:`HandWorld` is a plain Python class: no rclpy, no sockets. It is built from the same
``config/dam.yaml`` as the analysis and is stepped in lockstep (:meth:`HandWorld.step` runs as
fast as the CPU allows); the ROS node that serves it over the device link paces it in real time.

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
  (:meth:`HandWorld.pair_contact`), while the table's and the palm's contacts with the object
  stay rigid: Bullet's contact manifold of a flat face (at most four points, found one per
  step) makes springs there rock and roll the resting prism away. Friction stays Bullet's
  impulse friction (no tangential spring).

Joint control
-------------
Each joint is in one :class:`~dam_common.device_protocol.JointMode`:

* ``TORQUE``: the default velocity motor is disabled (``VELOCITY_CONTROL`` with force 0) and the
  torque, clipped to :attr:`WorldOptions.torque_limit_nm`, is applied with ``TORQUE_CONTROL``
  before every physics step.
* ``POSITION``: Bullet's position servo (``POSITION_CONTROL``) tracks the setpoint (clipped to
  the joint limits) with at most :attr:`WorldOptions.servo_force_limit_nm`.
* ``HOLD``: the same servo holds the angle the joint had when it entered ``HOLD``.
* ``IMPEDANCE``: a torque-controlled joint (velocity motor disabled, like ``TORQUE``) whose
  torque the device computes before **every physics step** from the simulated joint state:
  ``tau = clip(k (theta_0 - theta) - d theta_dot, +-torque_limit_nm)`` with the commanded
  equilibrium ``theta_0`` [rad], stiffness ``k`` [N*m/rad] and damping ``d`` [N*m*s/rad].
  This is the device-side joint impedance of torque-controlled arms: the loop runs at the
  physics rate (1 kHz), whatever the latency of the commands.

Both torque modes are slew-limited (next section).

Torque slew limit
-----------------
The torque a TORQUE or IMPEDANCE joint receives changes by at most
``WorldOptions.torque_rate_limit_nm_per_s * time_step_s`` from one physics step to the next
(``device.torque_rate_limit_nm_per_s``; 20 N*m/s is 0.02 N*m per 1 ms step): before every step
the applied torque moves towards the clipped target (the TORQUE setpoint, or the IMPEDANCE law
of that step) by at most this much.

A rate limit inside the impedance loop alone would make a stiff joint oscillate between its
limits after a large step or knock (the restoring torque cannot turn round in time), so an
IMPEDANCE joint also handles its equilibrium like a torque-controlled arm handles a set point:

* the law runs around an effective equilibrium that moves towards the commanded ``theta_0`` by
  at most ``rate * time_step_s / k`` per step, so that the command's share of the torque change
  stays within the limit (a far ``theta_0`` is approached at ``rate / k``, 2 rad/s at
  ``k`` = 10 N*m/rad);
* in a step where the slew limit cuts the law's torque, the effective equilibrium is set to
  where the law gives the torque actually applied: the spring yields instead of winding up,
  and then returns to ``theta_0`` by the first rule.

Mode changes:

* entering TORQUE or IMPEDANCE from POSITION or HOLD, the slew starts from the torque the
  servo applied in the last step (clipped to ``torque_limit_nm``): the hand-over is bumpless;
* between TORQUE and IMPEDANCE it continues from the torque applied last; entering IMPEDANCE,
  or new gains, seat the effective equilibrium where the law gives that torque;
* entering POSITION or HOLD, the position servo takes over at once: a servo's torque is its
  reaction to the load and is not slew-limited (see ``docs/device_protocol.md``).

The watchdog's safe state is a TORQUE command of zero, so it ramps to zero at the same rate:
from the actuator limit in ``torque_limit_nm / torque_rate_limit_nm_per_s`` (50 ms with the
shipped configuration).

Lift-off
--------
:attr:`HandWorld.lift_off` samples the object's table contacts at every :meth:`HandWorld.reset`
and after every :meth:`HandWorld.step` call and applies the lift-off rule of
:mod:`dam_sim_bridge.lift_off` (the object left the table: off it for 50 ms is a lift-off,
and the object is lifted once one happened; off it for the last 0.1 s is off the table at the
end).

Torque sensor
-------------
:meth:`HandWorld.joint_states` reports, like a joint torque sensor between the actuator and the
link of a frictionless joint, the actuator torque transmitted to the link [N*m] (positive in
the positive joint direction): for servoed joints (POSITION, HOLD) Bullet's
``appliedJointMotorTorque`` of the last step (the servo's constraint torque, which carries the
load); for TORQUE and IMPEDANCE joints the torque Bullet applied during the last step after
clipping and the slew limit (for IMPEDANCE computed from the simulated angle and velocity of
that step). Bullet does not report the latter itself: ``appliedJointMotorTorque`` keeps the
last servo value, and the joint reaction excludes generalised forces. Before the first step
every reading is zero.
"""

from __future__ import annotations

import array
import math
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field, fields
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from dam_common.config import (
    CONTACT_MODELS,
    SIM_MIN_CONTACT_DAMPING_N_S_PER_M,
    series_stiffness,
)
from dam_common.cross_section import Circle
from dam_common.device_protocol import JointFault, JointMode
from dam_common.hand_urdf import hand_urdf
from dam_common.scalars import clip
from dam_sim_bridge.column_body import (
    prism_inertia,
    prism_triangles,
    prism_vertices,
    resting_quaternion,
)
from dam_sim_bridge.errors import CommandError, SimulationError, WorldConfigError
from dam_sim_bridge.lift_off import TOUCH_DISTANCE_M, LiftOffTracker
from dam_sim_bridge.pybullet_import import bullet_client, pybullet

if TYPE_CHECKING:
    from dam_common.config import DamConfig

_TABLE_HALF_EXTENTS_M = (0.25, 0.25, 0.02)
_TORQUE, _POSITION, _HOLD = int(JointMode.TORQUE), int(JointMode.POSITION), int(JointMode.HOLD)
_IMPEDANCE = int(JointMode.IMPEDANCE)
_MODES = frozenset((_TORQUE, _POSITION, _HOLD, _IMPEDANCE))
#: Bullet's contact stiffness [N/m] and damping [N*s/m] of a body whose contact parameters
#: were never set (``btCollisionObject``: ``BT_LARGE_FLOAT`` in double precision, 0.1); the
#: damping is ``SIM_MIN_CONTACT_DAMPING_N_S_PER_M`` of the configuration.
_BULLET_DEFAULT_CONTACT = (1.0e30, SIM_MIN_CONTACT_DAMPING_N_S_PER_M)


@dataclass(frozen=True)
class WorldOptions:
    """Simulation settings that are not part of the task configuration.

    Attributes
    ----------
    time_step_s
        Physics step [s] (1 kHz by default).
    gui
        Open the PyBullet GUI instead of the headless DIRECT server.
    link_masses_kg
        Mass of each link, base to tip [kg].
    initial_compliant_angle_rad
        Compliant joints after :meth:`HandWorld.reset` [rad]: slightly open (negative), so that
        no finger touches the object; the controller's APPROACH phase closes them.
    servo_force_limit_nm
        Largest torque of the position servo (POSITION and HOLD joints) [N*m].
    torque_limit_nm
        TORQUE commands are clipped to +-this [N*m] (the device's actuator limit).
    torque_rate_limit_nm_per_s
        Slew limit of every torque applied in TORQUE and IMPEDANCE mode [N*m/s]: the torque
        changes by at most this times ``time_step_s`` per physics step; ``math.inf`` turns the
        limit off (a device that does not slew).
    position_gain, velocity_gain
        Gains of Bullet's position servo (dimensionless, see ``setJointMotorControlArray``).
    solver_iterations
        Constraint solver iterations per step (Bullet's default is 50; 20 keeps the lockstep
        world well above 10x real time with three fingers on the object, and the friction
        and gravity tests hold to 1-3 %).
    object_faces
        Faces of the prism that stands in for the cylinder's collision shape.
    compliant_rotor_inertia_kg_m2
        Reflected drive inertia on every compliant joint [kg*m^2] (2e-3: a small motor,
        1.3e-7 kg*m^2, through a 125:1 reduction). Without it a compliant joint has only the
        finger's own ~1.1e-4 kg*m^2, and the impedance loop closed over the device link and
        ROS (measured: median 0.6 ms, p99 7.5 ms, max 12 ms from /joint_states to
        /hand/command, plus state gaps up to 17 ms) is unstable at stiffnesses of the
        sufficient-lift region (``k_theta`` of 6-35 N*m/rad). With it and
        ``controller.damping`` 0.2 the lockstep loop tolerates 6 device cycles (12 ms) at
        ``k_theta`` = 10 and 4 cycles at 15. Zero disables it.
    palm_thickness_m
        Thickness of the palm box above the base plane [m]; zero: no palm.
    contact_model
        ``'rigid'``: Bullet's rigid contacts; ``'compliant'``: every finger-object contact is a
        normal spring of ``contact_stiffness_n_per_m`` with the damper
        ``contact_damping_n_s_per_m`` (see the module docstring, "Contact model").
    contact_stiffness_n_per_m
        Normal stiffness ``k_n`` of a compliant finger-object contact point [N/m] (the CSM's
        ``contact.contact_stiffness_n_per_m[0]``).
    contact_damping_n_s_per_m
        Normal damping of a compliant finger-object contact [N*s/m], at least 0.1 (the
        object's own share in Bullet). The default, 126.5, critically damps the 0.04 kg
        cylinder on 1e5 N/m: ``2 sqrt(k_n m)``.
    """

    time_step_s: float = 1.0e-3
    gui: bool = False
    link_masses_kg: tuple[float, float, float] = (0.020, 0.012, 0.012)
    initial_compliant_angle_rad: float = math.radians(-10.0)
    servo_force_limit_nm: float = 2.0
    torque_limit_nm: float = 1.0
    torque_rate_limit_nm_per_s: float = 20.0
    position_gain: float = 0.3
    velocity_gain: float = 1.0
    solver_iterations: int = 20
    object_faces: int = 64
    compliant_rotor_inertia_kg_m2: float = 2.0e-3
    palm_thickness_m: float = 0.01
    contact_model: str = 'rigid'
    contact_stiffness_n_per_m: float = 1.0e5
    contact_damping_n_s_per_m: float = 126.5

    def __post_init__(self) -> None:
        if not (math.isfinite(self.time_step_s) and 1e-5 <= self.time_step_s <= 0.01):
            raise WorldConfigError(f'time_step_s {self.time_step_s!r} is outside [1e-5, 0.01] s')
        masses = tuple(self.link_masses_kg)
        if len(masses) != 3 or not all(math.isfinite(m) and m > 0.0 for m in masses):
            raise WorldConfigError(f'link_masses_kg {self.link_masses_kg!r} must be three '
                                   f'positive masses')
        for name in ('servo_force_limit_nm', 'torque_limit_nm', 'position_gain',
                     'velocity_gain'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise WorldConfigError(f'{name} {value!r} must be a positive number')
        rate = self.torque_rate_limit_nm_per_s
        if not (isinstance(rate, (int, float)) and rate > 0.0):  # inf allowed, NaN not
            raise WorldConfigError(f'torque_rate_limit_nm_per_s {rate!r} must be a positive '
                                   f'number or inf')
        if not math.isfinite(self.initial_compliant_angle_rad):
            raise WorldConfigError(f'initial_compliant_angle_rad '
                                   f'{self.initial_compliant_angle_rad!r} is not finite')
        if not 16 <= int(self.object_faces) <= 256:
            raise WorldConfigError(f'object_faces {self.object_faces!r} is outside [16, 256]')
        for name in ('compliant_rotor_inertia_kg_m2', 'palm_thickness_m'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise WorldConfigError(f'{name} {value!r} must be a number >= 0')
        if int(self.solver_iterations) < 1:
            raise WorldConfigError(f'solver_iterations {self.solver_iterations!r} must be >= 1')
        if self.contact_model not in CONTACT_MODELS:
            raise WorldConfigError(f'contact_model {self.contact_model!r} is not one of '
                                   f'{list(CONTACT_MODELS)}')
        k_n = self.contact_stiffness_n_per_m
        if not (isinstance(k_n, (int, float)) and math.isfinite(k_n) and k_n > 0.0):
            raise WorldConfigError(f'contact_stiffness_n_per_m {k_n!r} must be a positive '
                                   f'number')
        d = self.contact_damping_n_s_per_m
        if not (isinstance(d, (int, float)) and math.isfinite(d)
                and d >= SIM_MIN_CONTACT_DAMPING_N_S_PER_M):
            raise WorldConfigError(f'contact_damping_n_s_per_m {d!r} must be a number >= '
                                   f'{SIM_MIN_CONTACT_DAMPING_N_S_PER_M} (the object\'s own '
                                   f'contact damping in Bullet)')

    @classmethod
    def from_config(cls, config: DamConfig, **overrides: object) -> WorldOptions:
        """Options from ``config``: ``sim`` section, ``hand.link_masses_kg``,
        ``device.torque_limit_nm``, ``device.torque_rate_limit_nm_per_s`` and
        ``contact.contact_stiffness_n_per_m[0]`` (the normal stiffness); ``overrides``
        (field name -> value) win.

        Raises
        ------
        WorldConfigError
            An override names no field of :class:`WorldOptions`, or a value is out of range.
        """
        sim = config.sim
        values: dict[str, object] = {
            'time_step_s': float(sim.time_step_s),
            'link_masses_kg': tuple(float(m) for m in config.hand.link_masses_kg),
            'initial_compliant_angle_rad': float(sim.initial_compliant_angle_rad),
            'servo_force_limit_nm': float(sim.servo_force_limit_nm),
            'torque_limit_nm': float(config.device.torque_limit_nm),
            'torque_rate_limit_nm_per_s': float(config.device.torque_rate_limit_nm_per_s),
            'solver_iterations': int(sim.solver_iterations),
            'object_faces': int(sim.object_faces),
            'compliant_rotor_inertia_kg_m2': float(sim.compliant_rotor_inertia_kg_m2),
            'palm_thickness_m': float(sim.palm_thickness_m),
            'contact_model': str(sim.contact_model),
            'contact_stiffness_n_per_m': float(config.contact.contact_stiffness_n_per_m[0]),
            'contact_damping_n_s_per_m': float(sim.contact_damping_n_s_per_m),
        }
        names = {f.name for f in fields(cls)}
        for key, value in overrides.items():
            if key not in names:
                raise WorldConfigError(f'unknown world option {key!r} (known: {sorted(names)})')
            values[key] = value
        return cls(**values)  # type: ignore[arg-type]


class JointStates(NamedTuple):
    """Joint state in ``HandConfig.joint_names`` order (SI)."""

    positions: np.ndarray  #: [rad]
    velocities: np.ndarray  #: [rad/s]
    torques: np.ndarray  #: torque-sensor readings [N*m], see the module docstring


class ObjectPose(NamedTuple):
    """Pose of the cylinder's centre of mass in the world."""

    position: np.ndarray  #: (3,) [m]
    quaternion: np.ndarray  #: (4,) x, y, z, w
    sim_time: float  #: simulated time since the last reset [s]


class _StepPlan(NamedTuple):
    """The torque-controlled joints of a command, as :meth:`HandWorld.step` uses them: rows
    (``joint_names`` order) of the TORQUE joints, then of the IMPEDANCE joints."""

    rows: tuple[int, ...]
    joints: list[int]  #: Bullet joint indices of ``rows``
    n_torque: int  #: the first ``n_torque`` rows are TORQUE joints
    target: tuple[float, ...]  #: clipped TORQUE setpoints [N*m], then zeros
    stiffness: tuple[float, ...]  #: of the IMPEDANCE rows [N*m/rad]
    damping: tuple[float, ...]  #: [N*m*s/rad]
    theta_0: tuple[float, ...]  #: commanded equilibria [rad]
    max_shift: tuple[float, ...]  #: the equilibria's ramp per step [rad]
    max_change: float  #: slew limit per step [N*m]
    limit: float  #: torque limit [N*m]


@dataclass
class _JointTable:
    indices: list[int] = field(default_factory=list)  # Bullet joint indices, joint_names order
    roles: list[str] = field(default_factory=list)
    lower: np.ndarray = field(default_factory=lambda: np.zeros(0))
    upper: np.ndarray = field(default_factory=lambda: np.zeros(0))
    lower_list: list[float] = field(default_factory=list)  # the same limits as lists [rad]
    upper_list: list[float] = field(default_factory=list)


def _toward(current: float, target: float, max_change: float) -> float:
    """``current`` moved towards ``target`` by at most ``max_change`` (``target`` itself,
    exactly, when it is that close)."""
    gap = target - current
    return target if abs(gap) <= max_change else current + math.copysign(max_change, gap)


class HandWorld:
    """The simulated hand, table and cylinder, steppable in lockstep.

    Parameters
    ----------
    config
        A ``DamConfig`` (``dam_common.config.load_config()``).
    options
        Simulation settings; defaults to :meth:`WorldOptions.from_config` of ``config``.

    Raises
    ------
    WorldConfigError
        The initial compliant angle is outside the compliant joint limits.
    SimulationError
        The physics server could not be started or the model not loaded.
    """

    def __init__(self, config: DamConfig, options: WorldOptions | None = None) -> None:
        self.config = config
        self.options = options or WorldOptions.from_config(config)
        hand = config.hand
        lo, hi = hand.joint_limits_rad['compliant']
        if not lo <= self.options.initial_compliant_angle_rad <= hi:
            raise WorldConfigError(
                f'initial_compliant_angle_rad {self.options.initial_compliant_angle_rad!r} is '
                f'outside the compliant joint limits [{lo!r}, {hi!r}] rad')
        self.joint_names: tuple[str, ...] = tuple(hand.joint_names)
        self.n_joints = len(self.joint_names)
        self.link_masses_kg = np.asarray(self.options.link_masses_kg, dtype=float)
        mode = pybullet.GUI if self.options.gui else pybullet.DIRECT
        if (self.options.gui and os.name == 'posix' and not os.environ.get('DISPLAY')
                and not os.environ.get('WAYLAND_DISPLAY')):
            raise SimulationError('gui=True but neither DISPLAY nor WAYLAND_DISPLAY is set; '
                                  'use gui=False (headless DIRECT mode)')
        try:
            self._pb = bullet_client.BulletClient(connection_mode=mode)
        except Exception as exc:  # noqa: BLE001 - pybullet raises plain errors
            raise SimulationError(f'cannot start the PyBullet server (mode {mode}): {exc}') from exc
        self._closed = False
        # The calls of the per-step loop, bound to this world's server once.
        self._get_joint_states = self._pb.getJointStates
        self._set_joint_motor_control_array = self._pb.setJointMotorControlArray
        self._step_simulation = self._pb.stepSimulation
        self._get_base_pose = self._pb.getBasePositionAndOrientation
        self._pb.setTimeStep(self.options.time_step_s)
        self._pb.setPhysicsEngineParameter(numSolverIterations=int(self.options.solver_iterations))
        self.set_gravity((0.0, 0.0, -config.task.gravity_m_per_s2))
        self._build()
        self._friction_angle_rad = float(config.contact.friction_angle_rad)
        self._table_mu = float(config.contact.table_friction_coefficient)
        #: The lift-off rule (:mod:`dam_sim_bridge.lift_off`) on the object's table contacts,
        #: sampled at :meth:`reset` and after every :meth:`step` call.
        self.lift_off = LiftOffTracker()
        self.reset()

    # ---------------------------------------------------------------------------------------
    # Construction

    def _build(self) -> None:
        pb = self._pb
        urdf = hand_urdf(self.config, link_masses_kg=self.link_masses_kg,
                         compliant_rotor_inertia_kg_m2=self.options.compliant_rotor_inertia_kg_m2,
                         for_pybullet=True)
        fd, path = tempfile.mkstemp(suffix='.urdf', prefix='dam_hand_')
        try:
            with os.fdopen(fd, 'w', encoding='utf-8') as handle:
                handle.write(urdf)
            self.hand_id = pb.loadURDF(path, useFixedBase=True,
                                       flags=pybullet.URDF_USE_INERTIA_FROM_FILE)
        except Exception as exc:  # noqa: BLE001
            raise SimulationError(f'cannot load the hand model: {exc}') from exc
        finally:
            os.unlink(path)
        by_name = {pb.getJointInfo(self.hand_id, j)[1].decode(): j
                   for j in range(pb.getNumJoints(self.hand_id))}
        table = _JointTable()
        for name in self.joint_names:
            if name not in by_name:
                raise SimulationError(f'joint {name!r} missing from the loaded model')
            table.indices.append(by_name[name])
            table.roles.append(name.rsplit('_', 2)[-2])
        limits = [self.config.hand.joint_limits_rad[r] for r in table.roles]
        table.lower = np.array([lim[0] for lim in limits])
        table.upper = np.array([lim[1] for lim in limits])
        table.lower_list = table.lower.tolist()
        table.upper_list = table.upper.tolist()
        self._joints = table
        for j in table.indices:
            pb.changeDynamics(self.hand_id, j, linearDamping=0.0, angularDamping=0.0,
                              jointDamping=0.0, restitution=0.0, rollingFriction=0.0,
                              spinningFriction=0.0)
        # Table: static box, top face at z = 0.
        hx, hy, hz = _TABLE_HALF_EXTENTS_M
        box = pb.createCollisionShape(pybullet.GEOM_BOX, halfExtents=[hx, hy, hz])
        box_vis = pb.createVisualShape(pybullet.GEOM_BOX, halfExtents=[hx, hy, hz],
                                       rgbaColor=[0.6, 0.5, 0.4, 1.0])
        self.table_id = pb.createMultiBody(0.0, box, box_vis, basePosition=[0.0, 0.0, -hz])
        self.palm_id = self._build_palm()
        # Object: the column, local z along object.axis, a convex mesh of its cross-section.
        obj = self.config.object
        inertia, beta = prism_inertia(obj.section, obj.mass_kg, obj.length_m)
        vertices = prism_vertices(obj.section, obj.length_m, self.options.object_faces, beta)
        hull = pb.createCollisionShape(pybullet.GEOM_MESH, vertices=vertices.tolist())
        if isinstance(obj.section, Circle):
            visual = pb.createVisualShape(pybullet.GEOM_CYLINDER, radius=obj.section.radius,
                                          length=obj.length_m, rgbaColor=[0.2, 0.4, 0.8, 1.0])
        else:
            visual = pb.createVisualShape(pybullet.GEOM_MESH, vertices=vertices.tolist(),
                                          indices=prism_triangles(len(vertices) // 2),
                                          rgbaColor=[0.2, 0.4, 0.8, 1.0])
        self._resting_quaternion = resting_quaternion(obj)
        self.object_id = pb.createMultiBody(obj.mass_kg, hull, visual,
                                            basePosition=obj.position_m.tolist(),
                                            baseOrientation=self._resting_quaternion)
        for body in (self.table_id, self.object_id):
            pb.changeDynamics(body, -1, linearDamping=0.0, angularDamping=0.0, restitution=0.0,
                              rollingFriction=0.0, spinningFriction=0.0)
        # Zero margin: the hull is the object's true surface; the homogeneous prism's inertia
        # (Bullet would use the hull's bounding box).
        pb.changeDynamics(self.object_id, -1, collisionMargin=0.0,
                          localInertiaDiagonal=list(inertia))
        self._pb.setJointMotorControlArray(
            self.hand_id, self._joints.indices, pybullet.VELOCITY_CONTROL,
            forces=[0.0] * self.n_joints)
        self._set_contact_model()

    def _set_contact_model(self) -> None:
        """Compliant contacts: the finger links get ``k_n`` and ``d - 0.1`` (the object's
        own damping in Bullet), so that every finger-object contact has the normal stiffness
        ``k_n`` and the damping ``d``; the contact slop is zero (the spring's rest length).
        Rigid: nothing changes. ``changeDynamics`` calls without ``contactStiffness`` (the
        friction settings) keep these values."""
        options = self.options
        if options.contact_model != 'compliant':
            return
        self._pb.setPhysicsEngineParameter(contactSlop=0.0)
        link_damping = options.contact_damping_n_s_per_m - SIM_MIN_CONTACT_DAMPING_N_S_PER_M
        for j in self._joints.indices:
            self._pb.changeDynamics(self.hand_id, j,
                                    contactStiffness=options.contact_stiffness_n_per_m,
                                    contactDamping=link_damping)

    def _build_palm(self) -> int | None:
        """The static palm box (see the module docstring); ``None`` if disabled."""
        thickness = float(self.options.palm_thickness_m)
        if thickness <= 0.0:
            return None
        hand = self.config.hand
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
        pb = self._pb
        box = pb.createCollisionShape(pybullet.GEOM_BOX, halfExtents=half)
        vis = pb.createVisualShape(pybullet.GEOM_BOX, halfExtents=half,
                                   rgbaColor=[0.3, 0.3, 0.3, 1.0])
        palm = pb.createMultiBody(0.0, box, vis, basePosition=centre)
        for j in [-1, *self._joints.indices]:
            pb.setCollisionFilterPair(palm, self.hand_id, -1, j, 0)
        pb.changeDynamics(palm, -1, restitution=0.0, rollingFriction=0.0,
                          spinningFriction=0.0)
        return int(palm)

    # ---------------------------------------------------------------------------------------
    # Settings

    @property
    def client(self) -> bullet_client.BulletClient:
        """The PyBullet client of this world (for inspection and tests)."""
        return self._pb

    @property
    def joint_indices(self) -> tuple[int, ...]:
        """Bullet joint (= link) indices in ``joint_names`` order."""
        return tuple(self._joints.indices)

    @property
    def joint_lower_limits(self) -> np.ndarray:
        """(n,) lower joint limits [rad]."""
        return self._joints.lower.copy()

    @property
    def joint_upper_limits(self) -> np.ndarray:
        """(n,) upper joint limits [rad]."""
        return self._joints.upper.copy()

    @property
    def sim_time(self) -> float:
        """Simulated time since the last :meth:`reset` [s]."""
        return self._steps * self.options.time_step_s

    @property
    def time_step_s(self) -> float:
        return self.options.time_step_s

    def set_gravity(self, gravity_m_per_s2: Sequence[float]) -> None:
        """Set the gravity vector [m/s^2] (world frame; default ``(0, 0, -g)`` of the config)."""
        g = np.asarray(gravity_m_per_s2, dtype=float)
        if g.shape != (3,) or not np.all(np.isfinite(g)):
            raise WorldConfigError(f'gravity {gravity_m_per_s2!r} must be three finite numbers')
        self._pb.setGravity(*g.tolist())

    def set_friction_angle(self, alpha_rad: float) -> None:
        """Set the finger-object friction angle: the pair coefficient becomes ``tan(alpha)``.

        Parameters
        ----------
        alpha_rad
            Friction angle [rad], ``0 <= alpha < pi/2``.
        """
        a = float(alpha_rad)
        if not (math.isfinite(a) and 0.0 <= a < math.pi / 2.0):
            raise WorldConfigError(f'friction angle {alpha_rad!r} rad is outside [0, pi/2)')
        self._friction_angle_rad = a
        mu = math.tan(a)
        for j in self._joints.indices:
            self._pb.changeDynamics(self.hand_id, j, lateralFriction=mu)
        if self.palm_id is not None:
            self._pb.changeDynamics(self.palm_id, -1, lateralFriction=mu)
        self._pb.changeDynamics(self.object_id, -1, lateralFriction=1.0)

    def set_table_friction(self, coefficient: float) -> None:
        """Set the table-object friction coefficient (>= 0)."""
        mu = float(coefficient)
        if not (math.isfinite(mu) and mu >= 0.0):
            raise WorldConfigError(f'table friction coefficient {coefficient!r} must be >= 0')
        self._table_mu = mu
        self._pb.changeDynamics(self.table_id, -1, lateralFriction=mu)

    def pair_friction(self) -> dict[str, float]:
        """Effective Coulomb coefficients of the body pairs, as Bullet combines them (product).

        Returns
        -------
        dict
            ``finger_object``, ``table_object``, ``finger_table`` (each link of every finger has
            the same value; the first is read).
        """
        def mu(body: int, link: int) -> float:
            return float(self._pb.getDynamicsInfo(body, link)[1])

        finger = mu(self.hand_id, self._joints.indices[0])
        obj = mu(self.object_id, -1)
        table = mu(self.table_id, -1)
        return {'finger_object': finger * obj, 'table_object': table * obj,
                'finger_table': finger * table}

    def pair_contact(self) -> dict[str, tuple[float, float] | None]:
        """Normal stiffness [N/m] and damping [N*s/m] of the body pairs' compliant contacts,
        as Bullet combines the bodies' values (stiffness in series, damping summed; a body
        without values counts as 1e30 N/m and 0.1 N*s/m); ``None`` for a rigid pair (neither
        body has values).

        Returns
        -------
        dict
            ``finger_object``, ``table_object``, ``palm_object`` (``None`` too without a
            palm), ``finger_table`` (each link of every finger has the same values; the
            first is read).
        """
        def values(body: int, link: int) -> tuple[float, float] | None:
            info = self._pb.getDynamicsInfo(body, link)
            damping, stiffness = float(info[8]), float(info[9])
            return None if stiffness < 0.0 else (stiffness, damping)

        def pair(a: tuple[float, float] | None,
                 b: tuple[float, float] | None) -> tuple[float, float] | None:
            if a is None and b is None:
                return None
            k0, d0 = a if a is not None else _BULLET_DEFAULT_CONTACT
            k1, d1 = b if b is not None else _BULLET_DEFAULT_CONTACT
            return series_stiffness(k0, k1), d0 + d1

        finger = values(self.hand_id, self._joints.indices[0])
        obj = values(self.object_id, -1)
        table = values(self.table_id, -1)
        palm = None if self.palm_id is None else pair(values(self.palm_id, -1), obj)
        return {'finger_object': pair(finger, obj), 'table_object': pair(table, obj),
                'palm_object': palm, 'finger_table': pair(finger, table)}

    # ---------------------------------------------------------------------------------------
    # Reset and commands

    def initial_positions(self) -> np.ndarray:
        """(n,) joint angles after :meth:`reset` [rad]."""
        hand = self.config.hand
        per_role = {'compliant': self.options.initial_compliant_angle_rad,
                    'locked': hand.initial_locked_angle_rad,
                    'position': hand.initial_position_angle_rad}
        return np.array([per_role[r] for r in self._joints.roles])

    def reset(self, object_position: Sequence[float] | None = None,
              object_quaternion: Sequence[float] | None = None,
              friction_angle_rad: float | None = None,
              table_friction_coefficient: float | None = None,
              joint_positions: Sequence[float] | None = None) -> None:
        """Put the hand in a posture (all joints HOLD) and the object at rest; sim time 0.

        Parameters
        ----------
        object_position
            (3,) centre of gravity [m]; default ``object.position_m``.
        object_quaternion
            (4,) x, y, z, w; default: axis along ``object.axis``.
        friction_angle_rad
            New finger-object friction angle [rad]; default: keep the current one.
        table_friction_coefficient
            New table-object coefficient; default: keep the current one.
        joint_positions
            (n,) joint angles [rad] within the joint limits; default
            :meth:`initial_positions`.
        """
        obj = self.config.object
        pos = obj.position_m if object_position is None else np.asarray(object_position, float)
        quat = (self._resting_quaternion if object_quaternion is None
                else np.asarray(object_quaternion, float))
        if np.shape(pos) != (3,) or not np.all(np.isfinite(pos)):
            raise WorldConfigError(f'object_position {object_position!r} must be 3 finite numbers')
        qn = float(np.linalg.norm(quat))
        if np.shape(quat) != (4,) or not math.isfinite(qn) or qn < 1e-9:
            raise WorldConfigError(f'object_quaternion {object_quaternion!r} must be a nonzero '
                                   f'quaternion (x, y, z, w)')
        self.set_friction_angle(self._friction_angle_rad if friction_angle_rad is None
                                else friction_angle_rad)
        self.set_table_friction(self._table_mu if table_friction_coefficient is None
                                else table_friction_coefficient)
        pb = self._pb
        pb.resetBasePositionAndOrientation(self.object_id, list(map(float, pos)),
                                           [float(q) / qn for q in quat])
        pb.resetBaseVelocity(self.object_id, [0.0, 0.0, 0.0], [0.0, 0.0, 0.0])
        q0 = self.initial_positions()
        if joint_positions is not None:
            q0 = np.asarray(joint_positions, dtype=float)
            if q0.shape != (self.n_joints,) or not np.all(np.isfinite(q0)):
                raise WorldConfigError(f'joint_positions {joint_positions!r} must be '
                                       f'{self.n_joints} finite angles')
            outside = (q0 < self._joints.lower - 1e-12) | (q0 > self._joints.upper + 1e-12)
            if np.any(outside):
                bad = [self.joint_names[i] for i in np.flatnonzero(outside)]
                raise WorldConfigError(f'joint_positions {q0.tolist()!r} outside the limits '
                                       f'of {bad}')
        for j, q in zip(self._joints.indices, q0, strict=True):
            pb.resetJointState(self.hand_id, j, float(q), 0.0)
        n = self.n_joints
        # The joint command state, as plain lists in joint_names order (the per-step loop
        # works on Python floats: on nine joints numpy's per-call overhead dominates).
        self._modes: list[int] = [_HOLD] * n
        self._targets: list[float] = [float(q) for q in q0]  # servo targets [rad]
        self._torque_cmd: list[float] = [0.0] * n  # clipped TORQUE setpoints [N*m]
        self._applied_torque: list[float] = [0.0] * n  # torque applied in the last step [N*m]
        self._saturated: list[bool] = [False] * n
        self._theta_0: list[float] = [0.0] * n  # commanded IMPEDANCE equilibria [rad]
        self._theta_0_eff: list[float] = [0.0] * n  # effective equilibria [rad]
        self._stiffness: list[float] = [0.0] * n  # [N*m/rad]
        self._damping: list[float] = [0.0] * n  # [N*m*s/rad]
        self._sent_servo: tuple[tuple[int, ...], bytes] | None = None
        self._plan: _StepPlan | None = None
        self._plan_key: tuple[tuple[int, ...], bytes] | None = None  # the plan's command
        self._steps = 0
        self._stepped = False
        self._send_servo_targets(force=True)
        # Refresh the contact cache: otherwise contact queries return the pre-reset contacts
        # until the next step.
        pb.performCollisionDetection()
        self.lift_off.reset()
        self.lift_off.update(0.0, self.object_table_contacts())

    def joint_modes(self) -> np.ndarray:
        """(n,) current :class:`JointMode` of every joint."""
        return np.array(self._modes, dtype=np.int64)

    def _checked_modes(self, m_in: np.ndarray) -> list[int]:
        """``m_in`` as a list of :class:`JointMode` values.

        Raises
        ------
        CommandError
            A value that is not an integer or not a JointMode.
        """
        if m_in.dtype.kind in 'iu':
            values = m_in.tolist()
            if all(v in _MODES for v in values):
                return values
        try:
            m = m_in.astype(np.int64)
            valid = (m == m_in) & ((m == _TORQUE) | (m == _POSITION) | (m == _HOLD)
                                   | (m == _IMPEDANCE))
        except (ValueError, TypeError) as exc:
            raise CommandError(f'modes {m_in.tolist()!r} are not integers: {exc}') from exc
        if not np.all(valid):
            raise CommandError(f'modes {m_in.tolist()!r}: {m_in[~valid].tolist()!r} is not a '
                               f'JointMode ({_TORQUE}, {_POSITION}, {_HOLD}, {_IMPEDANCE})')
        return m.tolist()

    def _checked_gains(self, impedance: list[bool],
                       stiffness: Sequence[float] | np.ndarray | None,
                       damping: Sequence[float] | np.ndarray | None
                       ) -> tuple[list[float], list[float]]:
        """Stiffness [N*m/rad] and damping [N*m*s/rad] of the IMPEDANCE joints, zero for the
        others.

        Raises
        ------
        CommandError
            Missing gains, a wrong shape, or a gain of an IMPEDANCE joint that is not finite
            or not positive (stiffness), negative (damping).
        """
        n = self.n_joints
        if not any(impedance):
            return [0.0] * n, [0.0] * n
        if stiffness is None or damping is None:
            raise CommandError('IMPEDANCE joints need a stiffness and a damping')
        k_in = np.asarray(stiffness, dtype=float)
        d_in = np.asarray(damping, dtype=float)
        if k_in.shape != (n,) or d_in.shape != (n,):
            raise CommandError(f'stiffness {k_in.shape} and damping {d_in.shape} must '
                               f'both have shape ({n},)')
        k_all, d_all = k_in.tolist(), d_in.tolist()
        k = [0.0] * n
        d = [0.0] * n
        for i in range(n):
            if impedance[i]:
                k[i], d[i] = k_all[i], d_all[i]
                if not (math.isfinite(k[i]) and math.isfinite(d[i]) and k[i] > 0.0
                        and d[i] >= 0.0):
                    raise CommandError(f'IMPEDANCE gains must be finite with stiffness > 0 '
                                       f'and damping >= 0: stiffness {k_all!r}, damping '
                                       f'{d_all!r}')
        return k, d

    def set_joint_commands(self, modes: Sequence[int] | np.ndarray,
                           setpoints: Sequence[float] | np.ndarray,
                           stiffness: Sequence[float] | np.ndarray | None = None,
                           damping: Sequence[float] | np.ndarray | None = None) -> None:
        """Set the mode and setpoint of every joint (held until the next call).

        Parameters
        ----------
        modes
            (n,) :class:`JointMode` per joint, ``joint_names`` order.
        setpoints
            (n,) torque [N*m] (TORQUE, clipped to ``torque_limit_nm``), angle [rad] (POSITION,
            clipped to the joint limits; IMPEDANCE: the equilibrium ``theta_0``), ignored
            (HOLD: the angle at the switch to HOLD is held; NaN allowed).
        stiffness, damping
            (n,) impedance stiffness ``k`` [N*m/rad], positive, and damping ``d``
            [N*m*s/rad], non-negative, of the IMPEDANCE joints (ignored, NaN allowed, for
            the others); ``None`` only when no joint is in IMPEDANCE.

        Raises
        ------
        CommandError
            Wrong length, an unknown mode, a non-finite TORQUE/POSITION/IMPEDANCE setpoint,
            or missing or bad gains of an IMPEDANCE joint.
        """
        n = self.n_joints
        m_in = np.asarray(modes)
        sp_in = np.asarray(setpoints, dtype=float)
        if m_in.shape != (n,) or sp_in.shape != (n,):
            raise CommandError(f'modes {m_in.shape} and setpoints {sp_in.shape} must both have '
                               f'shape ({n},)')
        m = self._checked_modes(m_in)
        sp = sp_in.tolist()
        bad = [self.joint_names[i] for i in range(n)
               if m[i] != _HOLD and not math.isfinite(sp[i])]
        if bad:
            raise CommandError(f'non-finite setpoint for {bad}: {sp!r}')
        impedance = [mode == _IMPEDANCE for mode in m]
        k, d = self._checked_gains(impedance, stiffness, damping)
        old, old_k, old_d = self._modes, self._stiffness, self._damping
        lower, upper = self._joints.lower_list, self._joints.upper_list
        limit = self.options.torque_limit_nm
        targets, applied = self._targets, self._applied_torque
        theta_0_eff = self._theta_0_eff
        theta_0 = [0.0] * n
        newly_torque: list[int] = []  # Bullet indices of the joints that leave the servo
        states = None  # one read of the joints serves every reading below (nothing moves)
        for i in range(n):
            mode, before = m[i], old[i]
            if mode == _HOLD:
                if before != _HOLD:  # hold the angle of the switch
                    if states is None:
                        states = self._get_joint_states(self.hand_id, self._joints.indices)
                    targets[i] = states[i][0]
            elif mode == _POSITION:
                targets[i] = clip(sp[i], lower[i], upper[i])
            tau = sp[i] if mode == _TORQUE else 0.0  # NaN setpoints of other modes dropped
            self._torque_cmd[i] = clip(tau, -limit, limit)
            self._saturated[i] = abs(tau) > limit
            if mode == _TORQUE or mode == _IMPEDANCE:
                if before != _TORQUE and before != _IMPEDANCE:
                    # the slew starts from the servo's last torque: bumpless
                    newly_torque.append(self._joints.indices[i])
                    applied[i] = 0.0
                    if self._stepped:
                        if states is None:
                            states = self._get_joint_states(self.hand_id,
                                                            self._joints.indices)
                        applied[i] = clip(states[i][3], -limit, limit)
            else:
                applied[i] = 0.0
            if mode == _IMPEDANCE:
                theta_0[i] = sp[i]
                if before != _IMPEDANCE or k[i] != old_k[i] or d[i] != old_d[i]:
                    # the law starts where it gives the torque applied now
                    if states is None:
                        states = self._get_joint_states(self.hand_id, self._joints.indices)
                    theta, theta_dot = states[i][0], states[i][1]
                    theta_0_eff[i] = theta + (applied[i] + d[i] * theta_dot) / k[i]
            else:
                theta_0_eff[i] = 0.0
        self._theta_0 = theta_0
        self._stiffness = k
        self._damping = d
        self._modes = m
        plan_key = (tuple(m), array.array('d', theta_0 + k + d + self._torque_cmd).tobytes())
        if plan_key != self._plan_key:  # (the bytes: a zero's sign counts too)
            self._plan = None
            self._plan_key = plan_key
        if newly_torque:
            self._pb.setJointMotorControlArray(self.hand_id, newly_torque,
                                               pybullet.VELOCITY_CONTROL,
                                               forces=[0.0] * len(newly_torque))
        self._send_servo_targets()

    def _send_servo_targets(self, force: bool = False) -> None:
        servo = tuple(i for i, mode in enumerate(self._modes)
                      if mode != _TORQUE and mode != _IMPEDANCE)
        targets = [self._targets[i] for i in servo]
        key = (servo, array.array('d', targets).tobytes())
        if not servo or (key == self._sent_servo and not force):
            return
        n = len(servo)
        self._pb.setJointMotorControlArray(
            self.hand_id, [self._joints.indices[i] for i in servo], pybullet.POSITION_CONTROL,
            targetPositions=targets, targetVelocities=[0.0] * n,
            forces=[self.options.servo_force_limit_nm] * n,
            positionGains=[self.options.position_gain] * n,
            velocityGains=[self.options.velocity_gain] * n)
        self._sent_servo = key

    # ---------------------------------------------------------------------------------------
    # Stepping and reading

    def step(self, n: int = 1) -> None:
        """Advance the physics by ``n`` steps of ``time_step_s`` (lockstep, no pacing).

        Torque-mode joints receive their torque before every step; IMPEDANCE joints the
        torque of their impedance law, computed from the joint state before that step. Both
        move from the torque applied in the previous step by at most
        ``torque_rate_limit_nm_per_s * time_step_s`` (the slew limit).
        """
        steps = int(n)
        if steps < 0:
            raise CommandError(f'step count {n!r} must be >= 0')
        if self._closed:
            raise SimulationError('the world is closed')
        if steps == 0:
            return
        hand = self.hand_id
        step_simulation = self._step_simulation
        plan = self._plan if self._plan is not None else self._step_plan()
        if not plan.rows:
            for _ in range(steps):
                step_simulation()
            self._steps += steps
            self._stepped = True
            self.lift_off.update(self.sim_time, self.object_table_contacts())
            return
        n_t, n_i = plan.n_torque, len(plan.stiffness)
        k, d, theta_0, max_shift = plan.stiffness, plan.damping, plan.theta_0, plan.max_shift
        max_change, limit = plan.max_change, plan.limit
        target = list(plan.target)  # TORQUE setpoints, then the impedance laws of the step
        forces = [self._applied_torque[i] for i in plan.rows]
        theta_0_eff = [self._theta_0_eff[i] for i in plan.rows[n_t:]]
        raw_imp = [0.0] * n_i
        joints, imp_joints = plan.joints, plan.joints[n_t:]
        get_states = self._get_joint_states
        set_torques = self._set_joint_motor_control_array
        torque_control = pybullet.TORQUE_CONTROL
        for _ in range(steps):
            states = get_states(hand, imp_joints) if n_i else ()
            for j in range(n_i):
                theta, theta_dot = states[j][0], states[j][1]
                eff = _toward(theta_0_eff[j], theta_0[j], max_shift[j])
                raw = k[j] * (eff - theta) - d[j] * theta_dot
                raw_imp[j] = raw
                target[n_t + j] = clip(raw, -limit, limit)
                theta_0_eff[j] = eff
            for j in range(n_t + n_i):
                forces[j] = _toward(forces[j], target[j], max_change)
            for j in range(n_i):
                force = forces[n_t + j]
                if force != target[n_t + j]:  # slewed: the spring yields, no wind-up
                    theta, theta_dot = states[j][0], states[j][1]
                    theta_0_eff[j] = theta + (force + d[j] * theta_dot) / k[j]
            set_torques(hand, joints, torque_control, forces=forces)
            step_simulation()
        self._steps += steps
        self._stepped = True
        for j, i in enumerate(plan.rows):
            self._applied_torque[i] = forces[j]
        for j, i in enumerate(plan.rows[n_t:]):
            self._theta_0_eff[i] = theta_0_eff[j]
            self._saturated[i] = abs(raw_imp[j]) > limit
        self.lift_off.update(self.sim_time, self.object_table_contacts())

    def _step_plan(self) -> _StepPlan:
        """What :meth:`step` needs of the current command (kept until the next command)."""
        modes = self._modes
        torque_rows = [i for i, mode in enumerate(modes) if mode == _TORQUE]
        imp_rows = [i for i, mode in enumerate(modes) if mode == _IMPEDANCE]
        max_change = float(self.options.torque_rate_limit_nm_per_s) * self.options.time_step_s
        k = tuple(self._stiffness[i] for i in imp_rows)
        self._plan = _StepPlan(
            rows=tuple(torque_rows + imp_rows),
            joints=[self._joints.indices[i] for i in torque_rows + imp_rows],
            n_torque=len(torque_rows),
            target=tuple([self._torque_cmd[i] for i in torque_rows] + [0.0] * len(imp_rows)),
            stiffness=k, damping=tuple(self._damping[i] for i in imp_rows),
            theta_0=tuple(self._theta_0[i] for i in imp_rows),
            max_shift=tuple(max_change / k_j for k_j in k),
            max_change=max_change, limit=float(self.options.torque_limit_nm))
        return self._plan

    def _read_positions(self) -> np.ndarray:
        states = self._get_joint_states(self.hand_id, self._joints.indices)
        return np.array([s[0] for s in states])

    def joint_states(self) -> JointStates:
        """Positions [rad], velocities [rad/s] and torque-sensor readings [N*m].

        Arrays in ``joint_names`` order; see the module docstring for the torque reading.
        """
        states = self._get_joint_states(self.hand_id, self._joints.indices)
        positions = np.array([s[0] for s in states])
        velocities = np.array([s[1] for s in states])
        if not self._stepped:
            torques = np.zeros(self.n_joints)
        else:
            applied = self._applied_torque
            torques = np.array([applied[i] if mode == _TORQUE or mode == _IMPEDANCE else s[3]
                                for i, (mode, s) in enumerate(zip(self._modes, states,
                                                                  strict=True))])
        return JointStates(positions, velocities, torques)

    def joint_faults(self, limit_tolerance_rad: float = 1e-3) -> np.ndarray:
        """(n,) :class:`~dam_common.device_protocol.JointFault` bits of every joint.

        ``LIMIT`` when the joint is within ``limit_tolerance_rad`` of a joint limit,
        ``SATURATED`` when its TORQUE setpoint, or its IMPEDANCE law in the last physics step,
        was clipped to ``torque_limit_nm``.
        """
        q = self._read_positions()
        at_limit = ((q <= self._joints.lower + limit_tolerance_rad)
                    | (q >= self._joints.upper - limit_tolerance_rad))
        return (np.where(at_limit, int(JointFault.LIMIT), 0)
                | np.where(self._saturated, int(JointFault.SATURATED), 0)).astype(np.int64)

    def object_pose(self) -> ObjectPose:
        """Position [m] and orientation (x, y, z, w) of the cylinder, and the sim time [s]."""
        pos, quat = self._get_base_pose(self.object_id)
        return ObjectPose(np.array(pos), np.array(quat), self.sim_time)

    def object_velocity(self) -> tuple[np.ndarray, np.ndarray]:
        """Linear [m/s] and angular [rad/s] velocity of the cylinder (world frame)."""
        lin, ang = self._pb.getBaseVelocity(self.object_id)
        return np.array(lin), np.array(ang)

    def fingertip_positions(self) -> np.ndarray:
        """(n_fingers, 3) world positions of the fingertip centres (end of the last segment)."""
        hand = self.config.hand
        tips = []
        last = float(hand.link_lengths_m[-1])
        for f in range(hand.n_fingers):
            link = self._joints.indices[3 * f + 2]
            state = self._pb.getLinkState(self.hand_id, link, computeForwardKinematics=True)
            frame_pos, frame_quat = state[4], state[5]
            rot = np.array(self._pb.getMatrixFromQuaternion(frame_quat)).reshape(3, 3)
            tips.append(np.array(frame_pos) + rot @ np.array([0.0, 0.0, -last]))
        return np.array(tips)

    def hand_object_contacts(self) -> list[tuple[str, float]]:
        """Current finger-object contacts: (joint name of the touching link, normal force [N])."""
        names = dict(zip(self._joints.indices, self.joint_names, strict=True))
        return [(names.get(c[3], str(c[3])), float(c[9]))
                for c in self._pb.getContactPoints(self.hand_id, self.object_id)]

    def object_table_contacts(self, max_distance_m: float | None = TOUCH_DISTANCE_M) -> int:
        """Number of contact points between the object and the table of the last step.

        Parameters
        ----------
        max_distance_m
            Count the points closer than this [m] (Bullet's contact distance, negative in
            penetration): by default :data:`~dam_sim_bridge.lift_off.TOUCH_DISTANCE_M`
            (0.1 mm), the points that touch; ``None``: every point Bullet's contact manifold
            holds, up to about 0.7 mm apart.
        """
        points = self._pb.getContactPoints(self.object_id, self.table_id)
        if max_distance_m is None:
            return len(points)
        return sum(1 for c in points if c[8] <= max_distance_m)

    def close(self) -> None:
        """Disconnect from the physics server (idempotent)."""
        if not self._closed:
            self._closed = True
            try:
                self._pb.disconnect()
            except Exception:  # noqa: BLE001 - already gone
                pass

    def __enter__(self) -> HandWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
