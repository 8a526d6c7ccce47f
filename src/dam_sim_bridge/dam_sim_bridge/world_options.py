"""The simulation settings of the stand-in's world (:class:`WorldOptions`): what
:class:`~dam_sim_bridge.world.HandWorld` needs beyond the task configuration, checked when
built, and read from the configuration by :meth:`WorldOptions.from_config`.

This module is pure (no PyBullet).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING

from dam_common.config import CONTACT_MODELS, SIM_MIN_CONTACT_DAMPING_N_S_PER_M
from dam_sim_bridge.errors import WorldConfigError

if TYPE_CHECKING:
    from dam_common.config import DamConfig


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
        Compliant joints after :meth:`~dam_sim_bridge.world.HandWorld.reset` [rad]: slightly
        open (negative), so that no finger touches the object; the controller's APPROACH
        phase closes them.
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
        ``contact_damping_n_s_per_m`` (see :mod:`dam_sim_bridge.hand_scene`, "Contact model").
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
