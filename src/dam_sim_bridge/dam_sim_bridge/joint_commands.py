"""The joint commands of the stand-in's world: what a command means, the command state of
the joints (:class:`JointCommands`: a command's checks and its mode changes) and the
:class:`StepPlan` by which :meth:`~dam_sim_bridge.world.HandWorld.step` applies the torques
of the TORQUE and IMPEDANCE joints before every physics step.

This module is pure (no PyBullet): the world reads the joint states and sends the motor
commands. The state is plain Python floats and lists in ``joint_names`` order (the per-step
loop works on Python floats: on nine joints numpy's per-call overhead dominates).

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
"""

from __future__ import annotations

import array
import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from dam_common.device_protocol import JointMode
from dam_common.scalars import clip
from dam_sim_bridge.errors import CommandError

if TYPE_CHECKING:
    from dam_sim_bridge.world_options import WorldOptions

TORQUE, POSITION, HOLD = int(JointMode.TORQUE), int(JointMode.POSITION), int(JointMode.HOLD)
IMPEDANCE = int(JointMode.IMPEDANCE)
_MODES = frozenset((TORQUE, POSITION, HOLD, IMPEDANCE))


class StepPlan(NamedTuple):
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


def toward(current: float, target: float, max_change: float) -> float:
    """``current`` moved towards ``target`` by at most ``max_change`` (``target`` itself,
    exactly, when it is that close)."""
    gap = target - current
    return target if abs(gap) <= max_change else current + math.copysign(max_change, gap)


#: A joint state as ``getJointStates`` gives it: angle [rad], velocity [rad/s], reaction
#: forces, applied motor torque [N*m].
JointStateRows = Sequence[Sequence]


class JointCommands:
    """The command state of a world's joints after a reset, and its update by a command.

    Every list is in ``joint_names`` order. :meth:`HandWorld.step
    <dam_sim_bridge.world.HandWorld.step>` reads :attr:`plan` and writes the torques it
    applied (:attr:`applied_torque`), the effective equilibria and :attr:`saturated`.

    Parameters
    ----------
    joint_names
        (n,) joint names (for the errors).
    joint_indices
        (n,) Bullet joint indices.
    lower, upper
        (n,) joint limits [rad].
    positions
        (n,) joint angles of the reset [rad]: every joint HOLDs its angle.
    options
        The world's options (torque limit, slew limit, time step).
    """

    def __init__(self, joint_names: Sequence[str], joint_indices: Sequence[int],
                 lower: list[float], upper: list[float], positions: Sequence[float],
                 options: WorldOptions) -> None:
        n = len(joint_names)
        self._names = tuple(joint_names)
        self._indices = list(joint_indices)
        self._lower, self._upper = lower, upper
        self._options = options
        self.modes: list[int] = [HOLD] * n
        self.targets: list[float] = [float(q) for q in positions]  #: servo targets [rad]
        self.torque_cmd: list[float] = [0.0] * n  #: clipped TORQUE setpoints [N*m]
        self.applied_torque: list[float] = [0.0] * n  #: applied in the last step [N*m]
        self.saturated: list[bool] = [False] * n
        self.theta_0: list[float] = [0.0] * n  #: commanded IMPEDANCE equilibria [rad]
        self.theta_0_eff: list[float] = [0.0] * n  #: effective equilibria [rad]
        self.stiffness: list[float] = [0.0] * n  #: [N*m/rad]
        self.damping: list[float] = [0.0] * n  #: [N*m*s/rad]
        self._sent_servo: tuple[tuple[int, ...], bytes] | None = None  # what was sent last
        self.plan: StepPlan | None = None  #: of the current command; ``None``: not made yet
        self._plan_key: tuple[tuple[int, ...], bytes] | None = None  # the plan's command

    def command(self, modes: Sequence[int] | np.ndarray,
                setpoints: Sequence[float] | np.ndarray,
                stiffness: Sequence[float] | np.ndarray | None,
                damping: Sequence[float] | np.ndarray | None,
                read_states: Callable[[], JointStateRows], stepped: bool) -> list[int]:
        """Take a command (see :meth:`HandWorld.set_joint_commands
        <dam_sim_bridge.world.HandWorld.set_joint_commands>` for the arguments).

        Parameters
        ----------
        read_states
            Reads the joint states now (called at most once, and only when a mode change
            needs the angle, the velocity or the servo's torque).
        stepped
            Whether the world was stepped since the reset (before, the servo's torque is 0).

        Returns
        -------
        list of int
            Bullet indices of the joints that leave the servo (their velocity motor is to be
            disabled).

        Raises
        ------
        CommandError
            Wrong length, an unknown mode, a non-finite TORQUE/POSITION/IMPEDANCE setpoint,
            or missing or bad gains of an IMPEDANCE joint; the state is unchanged.
        """
        n = len(self._names)
        m_in = np.asarray(modes)
        sp_in = np.asarray(setpoints, dtype=float)
        if m_in.shape != (n,) or sp_in.shape != (n,):
            raise CommandError(f'modes {m_in.shape} and setpoints {sp_in.shape} must both have '
                               f'shape ({n},)')
        m = checked_modes(m_in)
        sp = sp_in.tolist()
        bad = [self._names[i] for i in range(n)
               if m[i] != HOLD and not math.isfinite(sp[i])]
        if bad:
            raise CommandError(f'non-finite setpoint for {bad}: {sp!r}')
        impedance = [mode == IMPEDANCE for mode in m]
        k, d = checked_gains(impedance, stiffness, damping)
        old, old_k, old_d = self.modes, self.stiffness, self.damping
        lower, upper = self._lower, self._upper
        limit = self._options.torque_limit_nm
        targets, applied = self.targets, self.applied_torque
        theta_0_eff = self.theta_0_eff
        theta_0 = [0.0] * n
        newly_torque: list[int] = []  # Bullet indices of the joints that leave the servo
        states = None  # one read of the joints serves every reading below (nothing moves)
        for i in range(n):
            mode, before = m[i], old[i]
            if mode == HOLD:
                if before != HOLD:  # hold the angle of the switch
                    if states is None:
                        states = read_states()
                    targets[i] = states[i][0]
            elif mode == POSITION:
                targets[i] = clip(sp[i], lower[i], upper[i])
            tau = sp[i] if mode == TORQUE else 0.0  # NaN setpoints of other modes dropped
            self.torque_cmd[i] = clip(tau, -limit, limit)
            self.saturated[i] = abs(tau) > limit
            if mode == TORQUE or mode == IMPEDANCE:
                if before != TORQUE and before != IMPEDANCE:
                    # the slew starts from the servo's last torque: bumpless
                    newly_torque.append(self._indices[i])
                    applied[i] = 0.0
                    if stepped:
                        if states is None:
                            states = read_states()
                        applied[i] = clip(states[i][3], -limit, limit)
            else:
                applied[i] = 0.0
            if mode == IMPEDANCE:
                theta_0[i] = sp[i]
                if before != IMPEDANCE or k[i] != old_k[i] or d[i] != old_d[i]:
                    # the law starts where it gives the torque applied now
                    if states is None:
                        states = read_states()
                    theta, theta_dot = states[i][0], states[i][1]
                    theta_0_eff[i] = theta + (applied[i] + d[i] * theta_dot) / k[i]
            else:
                theta_0_eff[i] = 0.0
        self.theta_0 = theta_0
        self.stiffness = k
        self.damping = d
        self.modes = m
        plan_key = (tuple(m), array.array('d', theta_0 + k + d + self.torque_cmd).tobytes())
        if plan_key != self._plan_key:  # (the bytes: a zero's sign counts too)
            self.plan = None
            self._plan_key = plan_key
        return newly_torque

    def send_servo_targets(self, send: Callable[[list[int], list[float]], None],
                           force: bool = False) -> None:
        """Send the servoed joints (POSITION, HOLD) and their targets: ``send(joint indices,
        target angles [rad])``, unless there are none or (without ``force``) the same were
        sent last."""
        servo = tuple(i for i, mode in enumerate(self.modes)
                      if mode != TORQUE and mode != IMPEDANCE)
        targets = [self.targets[i] for i in servo]
        key = (servo, array.array('d', targets).tobytes())
        if not servo or (key == self._sent_servo and not force):
            return
        send([self._indices[i] for i in servo], targets)
        self._sent_servo = key

    def step_plan(self) -> StepPlan:
        """:attr:`plan`, made for the current command if it is not yet."""
        if self.plan is not None:
            return self.plan
        modes = self.modes
        torque_rows = [i for i, mode in enumerate(modes) if mode == TORQUE]
        imp_rows = [i for i, mode in enumerate(modes) if mode == IMPEDANCE]
        options = self._options
        max_change = float(options.torque_rate_limit_nm_per_s) * options.time_step_s
        k = tuple(self.stiffness[i] for i in imp_rows)
        self.plan = StepPlan(
            rows=tuple(torque_rows + imp_rows),
            joints=[self._indices[i] for i in torque_rows + imp_rows],
            n_torque=len(torque_rows),
            target=tuple([self.torque_cmd[i] for i in torque_rows] + [0.0] * len(imp_rows)),
            stiffness=k, damping=tuple(self.damping[i] for i in imp_rows),
            theta_0=tuple(self.theta_0[i] for i in imp_rows),
            max_shift=tuple(max_change / k_j for k_j in k),
            max_change=max_change, limit=float(options.torque_limit_nm))
        return self.plan


def checked_modes(m_in: np.ndarray) -> list[int]:
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
        valid = (m == m_in) & ((m == TORQUE) | (m == POSITION) | (m == HOLD)
                               | (m == IMPEDANCE))
    except (ValueError, TypeError) as exc:
        raise CommandError(f'modes {m_in.tolist()!r} are not integers: {exc}') from exc
    if not np.all(valid):
        raise CommandError(f'modes {m_in.tolist()!r}: {m_in[~valid].tolist()!r} is not a '
                           f'JointMode ({TORQUE}, {POSITION}, {HOLD}, {IMPEDANCE})')
    return m.tolist()


def checked_gains(impedance: list[bool], stiffness: Sequence[float] | np.ndarray | None,
                  damping: Sequence[float] | np.ndarray | None
                  ) -> tuple[list[float], list[float]]:
    """Stiffness [N*m/rad] and damping [N*m*s/rad] of the IMPEDANCE joints, zero for the
    others.

    Parameters
    ----------
    impedance
        (n,) whether each joint is in IMPEDANCE.
    stiffness, damping
        (n,) the commanded gains, or ``None`` (allowed only when no joint is in IMPEDANCE).

    Raises
    ------
    CommandError
        Missing gains, a wrong shape, or a gain of an IMPEDANCE joint that is not finite
        or not positive (stiffness), negative (damping).
    """
    n = len(impedance)
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
