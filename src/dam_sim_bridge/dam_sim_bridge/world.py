"""The PyBullet world of the DAM hand: three capsule fingers, a table and the cylinder.

:class:`HandWorld` is a plain Python class: no rclpy, no sockets. It is built from the same
``config/dam.yaml`` as the analysis and is stepped in lockstep (:meth:`HandWorld.step` runs as
fast as the CPU allows); the ROS node that serves it over the device link paces it in real time.

Its parts:

* :mod:`dam_sim_bridge.hand_scene` loads the bodies (:func:`build_scene`); its docstring
  describes the model: the fingers' capsules and masses, the palm, the table, the column
  object, the friction and the contact model;
* :mod:`dam_sim_bridge.world_options`: the simulation settings, :class:`WorldOptions`;
* :mod:`dam_sim_bridge.joint_commands`: what a joint command means (the modes, the torque
  slew limit, the mode changes) and the joints' command state, :class:`JointCommands`.
  :meth:`HandWorld.set_joint_commands` hands a command to it and sends the motor commands;
  :meth:`HandWorld.step` applies the torques of the TORQUE and IMPEDANCE joints (their
  impedance law and slew limit) before every physics step.

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

import math
import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from dam_common.config import SIM_MIN_CONTACT_DAMPING_N_S_PER_M, series_stiffness
from dam_common.device_protocol import JointFault
from dam_common.scalars import clip
from dam_sim_bridge.errors import CommandError, SimulationError, WorldConfigError
from dam_sim_bridge.hand_scene import build_scene
from dam_sim_bridge.joint_commands import IMPEDANCE, TORQUE, JointCommands, toward
from dam_sim_bridge.lift_off import TOUCH_DISTANCE_M, LiftOffTracker
from dam_sim_bridge.pybullet_import import bullet_client, pybullet
from dam_sim_bridge.world_options import WorldOptions

if TYPE_CHECKING:
    from dam_common.config import DamConfig

#: Bullet's contact stiffness [N/m] and damping [N*s/m] of a body whose contact parameters
#: were never set (``btCollisionObject``: ``BT_LARGE_FLOAT`` in double precision, 0.1); the
#: damping is ``SIM_MIN_CONTACT_DAMPING_N_S_PER_M`` of the configuration.
_BULLET_DEFAULT_CONTACT = (1.0e30, SIM_MIN_CONTACT_DAMPING_N_S_PER_M)


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
        scene = build_scene(self._pb, config, self.options)
        self.hand_id, self.table_id = scene.hand_id, scene.table_id
        self.palm_id, self.object_id = scene.palm_id, scene.object_id
        self._joints = scene.joints
        self._resting_quaternion = scene.resting_quaternion
        self._friction_angle_rad = float(config.contact.friction_angle_rad)
        self._table_mu = float(config.contact.table_friction_coefficient)
        #: The lift-off rule (:mod:`dam_sim_bridge.lift_off`) on the object's table contacts,
        #: sampled at :meth:`reset` and after every :meth:`step` call.
        self.lift_off = LiftOffTracker()
        self.reset()

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
        self._commands = JointCommands(self.joint_names, self._joints.indices,
                                       self._joints.lower_list, self._joints.upper_list, q0,
                                       self.options)
        self._steps = 0
        self._stepped = False
        self._commands.send_servo_targets(self._send_servo, force=True)
        # Refresh the contact cache: otherwise contact queries return the pre-reset contacts
        # until the next step.
        pb.performCollisionDetection()
        self.lift_off.reset()
        self.lift_off.update(0.0, self.object_table_contacts())

    def joint_modes(self) -> np.ndarray:
        """(n,) current :class:`JointMode` of every joint."""
        return np.array(self._commands.modes, dtype=np.int64)

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
        commands = self._commands
        newly_torque = commands.command(modes, setpoints, stiffness, damping,
                                        self._read_joint_states, self._stepped)
        if newly_torque:
            self._pb.setJointMotorControlArray(self.hand_id, newly_torque,
                                               pybullet.VELOCITY_CONTROL,
                                               forces=[0.0] * len(newly_torque))
        commands.send_servo_targets(self._send_servo)

    def _read_joint_states(self) -> list[tuple]:
        """``getJointStates`` of the joints now, ``joint_names`` order."""
        return self._get_joint_states(self.hand_id, self._joints.indices)

    def _send_servo(self, joints: list[int], targets: list[float]) -> None:
        """Servo the Bullet joints ``joints`` to ``targets`` [rad] (POSITION and HOLD)."""
        n = len(joints)
        self._pb.setJointMotorControlArray(
            self.hand_id, joints, pybullet.POSITION_CONTROL,
            targetPositions=targets, targetVelocities=[0.0] * n,
            forces=[self.options.servo_force_limit_nm] * n,
            positionGains=[self.options.position_gain] * n,
            velocityGains=[self.options.velocity_gain] * n)

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
        commands = self._commands
        plan = commands.plan if commands.plan is not None else commands.step_plan()
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
        forces = [commands.applied_torque[i] for i in plan.rows]
        theta_0_eff = [commands.theta_0_eff[i] for i in plan.rows[n_t:]]
        raw_imp = [0.0] * n_i
        joints, imp_joints = plan.joints, plan.joints[n_t:]
        get_states = self._get_joint_states
        set_torques = self._set_joint_motor_control_array
        torque_control = pybullet.TORQUE_CONTROL
        for _ in range(steps):
            states = get_states(hand, imp_joints) if n_i else ()
            for j in range(n_i):
                theta, theta_dot = states[j][0], states[j][1]
                eff = toward(theta_0_eff[j], theta_0[j], max_shift[j])
                raw = k[j] * (eff - theta) - d[j] * theta_dot
                raw_imp[j] = raw
                target[n_t + j] = clip(raw, -limit, limit)
                theta_0_eff[j] = eff
            for j in range(n_t + n_i):
                forces[j] = toward(forces[j], target[j], max_change)
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
            commands.applied_torque[i] = forces[j]
        for j, i in enumerate(plan.rows[n_t:]):
            commands.theta_0_eff[i] = theta_0_eff[j]
            commands.saturated[i] = abs(raw_imp[j]) > limit
        self.lift_off.update(self.sim_time, self.object_table_contacts())

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
            applied = self._commands.applied_torque
            torques = np.array([applied[i] if mode == TORQUE or mode == IMPEDANCE else s[3]
                                for i, (mode, s) in enumerate(zip(self._commands.modes, states,
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
        saturated = self._commands.saturated
        return (np.where(at_limit, int(JointFault.LIMIT), 0)
                | np.where(saturated, int(JointFault.SATURATED), 0)).astype(np.int64)

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
