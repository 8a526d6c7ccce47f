"""The DAM grasp sequence as an explicit, deterministic state machine (paper sections 3.1, 4).

Phases::

    IDLE --start()--> APPROACH --all fingers in contact--> ROLLING_UP --trajectory done-->
    ENVELOPE --fingers settled--> DONE

    APPROACH / ROLLING_UP / ENVELOPE --cancel()--> ABORTED
    APPROACH / ROLLING_UP / ENVELOPE --timeout, lost contact, joint limit, fail()--> FAILED

Compliant joints are driven in one of two ways (:attr:`SequenceParams.impedance_on_device`):

* on the device (default): the compliant joints are commanded in ``JointMode.IMPEDANCE`` with
  the equilibrium as setpoint and ``k_theta_i`` and ``d`` as gains; the device runs the law
  ``k_theta_i (theta_0 - theta) - d theta_dot`` at its physics rate, so that only the
  equilibrium and the gains cross ROS (as the joint impedance of KUKA FRI / libfranka);
* in this controller: the law is computed here every step and sent as a ``TORQUE``
  command (the loop then runs over ROS and suffers its latency).

IDLE
    Every joint holds the angle measured at the first step in IDLE (clean start).
APPROACH
    Pre-shape: locked joints go to ``initial_locked_angle``, position joints to
    ``initial_position_angle`` (15 deg), both at ``approach_speed``; compliant joints stay
    under impedance around their measured angle (on the device: no torque ramp-in is needed,
    the equilibrium starts at the measured angle). Closing: the equilibrium of each compliant
    joint moves inward at ``approach_speed`` until the compliant-joint torque sensor of that
    finger has read at least ``contact_torque_threshold`` for ``contact_confirm_time`` (a
    single reading is not enough: the impedance loop's transients after the torque ramp-in
    reach the threshold on a stiff joint); then ``theta_0`` of that finger is latched at its
    measured angle, so that ``tau_s = 0`` in the initial state (section 3.2).
ROLLING_UP
    SPCM{K_theta, delta_theta_p}: position joints follow a minimum-jerk trajectory from the
    pre-shape angle by ``delta_theta_p`` over ``trajectory_duration``; compliant joints run the
    impedance law ``tau_s = k_theta_i (theta_0 - theta) - d theta_dot``.
ENVELOPE
    The fingers hold the SPCM grasp that lifted the object; the position joints stay at the
    end of their trajectory. The compliant joints: with the law in this controller they keep
    the impedance around ``theta_0``, its torque capped at the finger's envelope torque
    ``envelope_torque * stiffness_ratio_i / max(stiffness_ratio)`` (balanced: finger 1
    opposes fingers 2 and 3). On the device (where a cap cannot be expressed) they keep the
    device impedance around ``theta_0``; with
    :attr:`SequenceParams.envelope_constant_torque` they get the paper's constant torque
    (Fig. 6(d)), the envelope torque ramped in over ``torque_ramp_time``
    (docs/simulation_grasp.md compares the two). A constant torque on a position joint (a
    distal link of a few 1e-6 kg*m^2, which no torque loop at the device rate can damp)
    throws the object, so the position joints stay servoed. Ends when the fingers have
    settled.
DONE
    The ENVELOPE commands are kept (the object stays grasped).
ABORTED, FAILED
    The fingers relax: every torque command ramps linearly to zero over ``torque_ramp_time``
    (an IMPEDANCE joint becomes a TORQUE joint starting from its static impedance torque
    ``k_theta_i (theta_0 - theta)`` at the last step); moving position setpoints become HOLD
    at their last value.

All timing comes from the ``t`` argument of :meth:`DamSequence.step`; nothing reads a clock.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

import numpy as np

from dam_common.quantities import ANGLE, both_units
from dam_spcm_controller._validate import finite_scalar, finite_vector
from dam_spcm_controller.commands import HandLayout, JointCommand, JointMode
from dam_spcm_controller.errors import InputError, StateError
from dam_spcm_controller.impedance import _impedance_unchecked, finger_stiffness
from dam_spcm_controller.joint_history import JointHistory
from dam_spcm_controller.trajectory import MinimumJerkTrajectory

if TYPE_CHECKING:  # pragma: no cover
    from dam_common.config import DamConfig


def _since(condition: bool, since: float, t: float) -> float:
    """Time [s] since which ``condition`` has held: ``since``, or ``t`` when it starts now;
    NaN when it does not hold."""
    if not condition:
        return math.nan
    return t if since != since else since


class Phase(enum.Enum):
    """Phase of the DAM sequence."""

    IDLE = 'idle'
    APPROACH = 'approach'
    ROLLING_UP = 'rolling_up'
    ENVELOPE = 'envelope'
    DONE = 'done'
    ABORTED = 'aborted'
    FAILED = 'failed'

    @property
    def active(self) -> bool:
        """True for the phases in which the grasp is in progress."""
        return self in (Phase.APPROACH, Phase.ROLLING_UP, Phase.ENVELOPE)

    @property
    def terminal(self) -> bool:
        """True for DONE, ABORTED and FAILED."""
        return self in (Phase.DONE, Phase.ABORTED, Phase.FAILED)


# Share of the overall progress reached at the end of each phase.
_PROGRESS_APPROACH = 0.2
_PROGRESS_ROLLING = 0.9
# Times closer than this count as equal (float rounding of sums of time steps) [s].
_TIME_EPS = 1e-9
# The modes as plain ints: numpy compares an array with an int faster than with an IntEnum.
_HOLD = int(JointMode.HOLD)
_POSITION = int(JointMode.POSITION)
_TORQUE = int(JointMode.TORQUE)
_IMPEDANCE = int(JointMode.IMPEDANCE)


@dataclass(frozen=True)
class SequenceParams:
    """Everything the sequence needs besides ``k_theta`` and ``delta_theta_p``.

    Attributes
    ----------
    layout
        Joint order, stiffness ratios, joint limits and pre-shape angles.
    damping
        Compliant-joint damping ``d`` [N*m*s/rad].
    torque_limit
        ``|tau|`` limit of every torque command [N*m].
    trajectory_duration
        Time of the position-joint motion by ``delta_theta_p`` [s].
    envelope_torque
        Constant torque of the enveloping grasp [N*m].
    contact_torque_threshold
        Compliant-joint torque that signals contact during APPROACH [N*m]; also the load
        level above which a finger counts as loaded in ROLLING_UP.
    approach_speed
        Speed of the pre-shape and of the closing equilibrium [rad/s].
    phase_timeout
        Longest time any active phase may last [s].
    delta_theta_p_max
        Largest ``delta_theta_p`` accepted by :meth:`DamSequence.start` [rad].
    torque_ramp_time
        Torque ramp-in at APPROACH and ENVELOPE entry, ramp-out on abort/failure [s].
    lost_contact_time
        During ROLLING_UP a finger counts as loaded once its static compliant torque
        ``tau_s = -k_theta_i delta_theta_s`` has stayed at or above
        ``contact_torque_threshold`` this long (a bounce at first contact does not arm the
        check); a loaded
        finger whose ``tau_s`` then stays below ``lost_contact_ratio *
        contact_torque_threshold`` this long has lost contact [s].
    lost_contact_ratio
        Release level of the lost-contact hysteresis, in (0, 1] [-].
    settle_speed
        ENVELOPE ends when every compliant joint turns slower than this [rad/s]
    settle_time
        ... for this long [s].
    limit_margin
        A torque-controlled joint fails this close to a joint limit; a position-controlled
        joint fails this far beyond one [rad].
    contact_confirm_time
        The contact torque must persist this long during APPROACH [s].
    impedance_on_device
        Command the compliant joints in ``JointMode.IMPEDANCE`` (the device runs the law)
        instead of computing their torque here.
    envelope_constant_torque
        ENVELOPE applies the paper's constant torque to the compliant joints instead of
        keeping the impedance (on the device, or capped in this controller).
    """

    layout: HandLayout
    damping: float
    torque_limit: float
    trajectory_duration: float
    envelope_torque: float
    contact_torque_threshold: float
    approach_speed: float
    phase_timeout: float
    delta_theta_p_max: float
    torque_ramp_time: float = 0.2
    lost_contact_time: float = 0.1
    lost_contact_ratio: float = 0.5
    settle_speed: float = 0.05
    settle_time: float = 0.3
    limit_margin: float = math.radians(0.5)
    contact_confirm_time: float = 0.03
    impedance_on_device: bool = True
    envelope_constant_torque: bool = False

    def __post_init__(self) -> None:
        for name in ('impedance_on_device', 'envelope_constant_torque'):
            if not isinstance(getattr(self, name), (bool, np.bool_)):
                raise InputError(f'{name} must be a bool, got {getattr(self, name)!r}')
            object.__setattr__(self, name, bool(getattr(self, name)))
        for name in ('damping', 'torque_ramp_time', 'contact_confirm_time'):
            object.__setattr__(self, name, finite_scalar(name, getattr(self, name),
                                                         nonnegative=True))
        for name in ('torque_limit', 'trajectory_duration', 'envelope_torque',
                     'contact_torque_threshold', 'approach_speed', 'phase_timeout',
                     'delta_theta_p_max', 'lost_contact_time', 'lost_contact_ratio',
                     'settle_speed', 'settle_time', 'limit_margin'):
            object.__setattr__(self, name, finite_scalar(name, getattr(self, name),
                                                         positive=True))
        if self.envelope_torque > self.torque_limit:
            raise InputError(f'envelope_torque {self.envelope_torque!r} N*m exceeds '
                             f'torque_limit {self.torque_limit!r} N*m')
        if self.contact_torque_threshold >= self.torque_limit:
            raise InputError(f'contact_torque_threshold {self.contact_torque_threshold!r} N*m '
                             f'must be below torque_limit {self.torque_limit!r} N*m')
        if self.lost_contact_ratio > 1.0:
            raise InputError(f'lost_contact_ratio must be in (0, 1], got '
                             f'{self.lost_contact_ratio!r}')
        if self.phase_timeout <= self.trajectory_duration:
            raise InputError(f'phase_timeout {self.phase_timeout!r} s must exceed '
                             f'trajectory_duration {self.trajectory_duration!r} s')

    @classmethod
    def from_config(cls, config: DamConfig, **overrides: float) -> SequenceParams:
        """Parameters from a validated ``dam_common.config.DamConfig``.

        ``overrides`` replace individual attributes (e.g. ``settle_time=0.5``).
        """
        c = config.controller
        params = cls(layout=HandLayout.from_hand_config(config.hand),
                     damping=c.damping_nms_per_rad, torque_limit=c.torque_limit_nm,
                     trajectory_duration=c.trajectory_duration_s,
                     envelope_torque=c.envelope_torque_nm,
                     contact_torque_threshold=c.contact_torque_threshold_nm,
                     contact_confirm_time=c.contact_confirm_time_s,
                     approach_speed=c.approach_speed_rad_per_s,
                     phase_timeout=c.phase_timeout_s,
                     delta_theta_p_max=config.task.delta_theta_p_max_rad,
                     torque_ramp_time=c.torque_ramp_time_s,
                     lost_contact_time=c.lost_contact_time_s,
                     lost_contact_ratio=c.lost_contact_torque_ratio,
                     settle_speed=c.envelope_settle_speed_rad_per_s,
                     settle_time=c.envelope_settle_time_s,
                     limit_margin=c.limit_margin_rad,
                     impedance_on_device=c.impedance_on_device)
        return replace(params, **overrides) if overrides else params


class DamSequence:
    """The SPCM controller core: one call of :meth:`step` per control cycle.

    Parameters
    ----------
    params
        Gains, limits and timing (see :class:`SequenceParams`).

    Notes
    -----
    Arrays passed to and returned by :meth:`step` have one entry per joint, ordered as
    ``params.layout.joint_names`` (finger by finger, base to tip). Angles are in rad, positive
    flexes the finger inward; torques in N*m; times in s.
    """

    def __init__(self, params: SequenceParams) -> None:
        self._p = params
        lay = params.layout
        self._n = lay.n_fingers
        self._nj = lay.n_joints
        self._c = lay.compliant
        self._l = lay.locked
        self._q = lay.position
        # Torque-mode joints fail inside these bounds, position-mode joints outside the outer.
        self._inner_lo = lay.lower + params.limit_margin
        self._inner_hi = lay.upper - params.limit_margin
        self._outer_lo = lay.lower - params.limit_margin
        self._outer_hi = lay.upper + params.limit_margin
        self._inner_hi_c = self._inner_hi[self._c].copy()
        self._lower_c = lay.lower[self._c].copy()  # compliant joint limits [rad]
        self._upper_c = lay.upper[self._c].copy()
        # The bounds of _check_limits for the modes they were computed for.
        self._limits_for: bytes | None = None
        self._limits_lo = self._outer_lo
        self._limits_hi = self._outer_hi
        self._modes = np.full(self._nj, _HOLD, dtype=np.int8)
        self._set = np.zeros(self._nj)
        self._stiff = np.zeros(self._nj)  # IMPEDANCE gains of the command [N*m/rad]
        self._damp = np.zeros(self._nj)  # [N*m*s/rad]
        self._phase = Phase.IDLE
        self._t_last: float | None = None
        #: Joint samples of the current run, for the object's pose (pose_tracking).
        self._history = JointHistory(self._nj)
        self._reset_run()

    def _reset_run(self) -> None:
        n = self._n
        self._history.clear()
        self._hold: np.ndarray | None = None  # IDLE hold posture, latched at the first step
        self._pending_start = False
        self._relax_latch_measured = False
        self._t_phase = 0.0
        self._t_envelope = 0.0
        self._progress = 0.0
        self._failure_reason: str | None = None
        self._k_theta: float | None = None
        self._k_theta_i = np.zeros(n)
        self._delta_theta_p: float | None = None
        self._theta_0 = np.full(n, np.nan)
        self._contact = np.zeros(n, dtype=bool)
        self._loaded = np.zeros(n, dtype=bool)
        self._below_since = np.full(n, np.nan)
        self._above_since = np.full(n, np.nan)  # APPROACH: torque above threshold since
        self._loaded_since = np.full(n, np.nan)  # ROLLING_UP: tau_s above threshold since
        self._eq_start = np.zeros(n)
        self._preshape_from = np.zeros(self._nj)
        self._preshape_to = np.zeros(self._nj)
        self._preshape_time = 0.0
        self._trajectory: MinimumJerkTrajectory | None = None
        self._tau_from = np.zeros(self._nj)
        self._settled_since: float | None = None
        self._relax_from_modes = np.zeros(self._nj, dtype=np.int8)
        self._relax_from = np.zeros(self._nj)
        self._relax_scale = 1.0
        self._last_theta_c = np.zeros(n)
        self._envelope_goal = np.zeros(n)

    # ------------------------------------------------------------------------------------
    # Public state

    @property
    def params(self) -> SequenceParams:
        return self._p

    @property
    def phase(self) -> Phase:
        """Current phase. After :meth:`start`, APPROACH at once (the approach itself begins
        at the next :meth:`step`, which knows the measured posture)."""
        if self._pending_start:
            return Phase.APPROACH
        return self._phase

    @property
    def progress(self) -> float:
        """Overall progress in [0, 1]: 0.2 at the end of APPROACH, 0.9 at the end of
        ROLLING_UP, 1 at DONE; frozen on abort or failure. Never decreases within a run."""
        return self._progress

    @property
    def history(self) -> JointHistory:
        """The joint samples of the current run, from its first step to the step that ended
        it (DONE, FAILED, ABORTED): what the classifier follows the object's pose through
        (:func:`~dam_spcm_controller.classification.classify_from_joints`). Cleared by
        :meth:`start` and :meth:`reset`; read it, do not change it."""
        return self._history

    @property
    def failure_reason(self) -> str | None:
        """Why the sequence FAILED (names the finger/joint and the values), else ``None``."""
        return self._failure_reason

    @property
    def k_theta(self) -> float | None:
        """``k_theta`` of the current run [N*m/rad] (finger 1), ``None`` before start."""
        return self._k_theta

    @property
    def k_theta_i(self) -> np.ndarray:
        """(n,) per-finger stiffness of the current run [N*m/rad] (zeros before start)."""
        return self._k_theta_i.copy()

    @property
    def delta_theta_p(self) -> float | None:
        """Position-joint displacement of the current run [rad], ``None`` before start."""
        return self._delta_theta_p

    @property
    def contact(self) -> np.ndarray:
        """(n,) True for fingers whose contact posture has been latched."""
        return self._contact.copy()

    @property
    def theta_0(self) -> np.ndarray:
        """(n,) latched contact posture of the compliant joints [rad]; NaN before contact."""
        return self._theta_0.copy()

    @property
    def delta_theta_s(self) -> np.ndarray:
        """(n,) ``theta - theta_0`` of the compliant joints at the last step [rad] (NaN
        before contact)."""
        return self._last_theta_c - self._theta_0

    @property
    def tau_s(self) -> np.ndarray:
        """(n,) static compliant torque ``-K_theta delta_theta_s`` at the last step [N*m]."""
        return -self._k_theta_i * self.delta_theta_s

    # ------------------------------------------------------------------------------------
    # Commands from the user

    def start(self, k_theta: float, delta_theta_p: float) -> None:
        """Begin a grasp ``SPCM{k_theta, delta_theta_p}``; APPROACH begins at the next step.

        Parameters
        ----------
        k_theta
            Compliant-joint stiffness of finger 1 [N*m/rad], positive; finger ``i`` gets
            ``stiffness_ratio_i * k_theta``.
        delta_theta_p
            Position-joint displacement [rad], in (0, ``delta_theta_p_max``].

        Raises
        ------
        InputError
            A value is NaN/inf, not positive, or ``delta_theta_p`` is too large.
        StateError
            A grasp is already in progress.
        """
        if self._phase.active or self._pending_start:
            raise StateError(f'cannot start: a grasp is in progress (phase '
                             f'{self._phase.value})')
        k = finite_scalar('k_theta', k_theta, positive=True)
        dp = finite_scalar('delta_theta_p', delta_theta_p, positive=True)
        if dp > self._p.delta_theta_p_max + 1e-12:
            raise InputError(f'delta_theta_p {both_units(dp, ANGLE)} exceeds delta_theta_p_max '
                             f'{both_units(self._p.delta_theta_p_max, ANGLE)}')
        goal = self._p.layout.initial_position_angle + dp
        upper = float(self._p.layout.upper[2])
        if goal > upper + 1e-12:
            raise InputError(f'delta_theta_p {both_units(dp, ANGLE)} takes the position joints '
                             f'to {math.degrees(goal):.4g} deg, beyond their limit '
                             f'{math.degrees(upper):.4g} deg')
        t_last = self._t_last
        phase_before = self._phase
        self._reset_run()
        self._t_last = t_last
        if phase_before.terminal:
            self._phase = Phase.IDLE
        self._k_theta = k
        self._k_theta_i = finger_stiffness(k, self._p.layout.stiffness_ratios)
        self._delta_theta_p = dp
        self._pending_start = True

    def cancel(self) -> bool:
        """Abort an active grasp: the phase becomes ABORTED and the torques ramp to zero.

        Returns
        -------
        bool
            True if a grasp was cancelled (pending or active), False if there was none.
        """
        if self._pending_start:
            self._pending_start = False
            self._phase = Phase.ABORTED
            self._relax_from_modes[:] = _HOLD
            self._relax_latch_measured = True  # hold whatever is measured at the next step
            self._t_phase = self._t_last if self._t_last is not None else 0.0
            return True
        if not self._phase.active:
            return False
        self._enter_relax(Phase.ABORTED, self._t_last if self._t_last is not None else 0.0)
        return True

    def fail(self, reason: str) -> bool:
        """Fail an active grasp from outside (e.g. joint states went silent, driver error).

        Returns
        -------
        bool
            True if a grasp was active and is now FAILED with ``reason``.
        """
        if not (self._phase.active or self._pending_start):
            return False
        self._pending_start = False
        self._failure_reason = str(reason)
        self._enter_relax(Phase.FAILED, self._t_last if self._t_last is not None else 0.0)
        return True

    def reset(self) -> None:
        """Return from DONE, ABORTED or FAILED to IDLE (hold the measured posture).

        Raises
        ------
        StateError
            A grasp is in progress.
        """
        if self._phase.active:
            raise StateError(f'cannot reset during phase {self._phase.value}; cancel first')
        t_last = self._t_last
        self._reset_run()
        self._t_last = t_last
        self._phase = Phase.IDLE

    # ------------------------------------------------------------------------------------
    # The control cycle

    def step(self, t: float, positions: np.ndarray, velocities: np.ndarray,
             efforts: np.ndarray) -> JointCommand:
        """Advance the sequence to time ``t`` and return the command for every joint.

        Parameters
        ----------
        t
            Time [s], any origin, never decreasing between calls.
        positions
            (3n,) measured joint angles [rad].
        velocities
            (3n,) measured joint velocities [rad/s].
        efforts
            (3n,) measured joint torques [N*m] (positive = flexion).

        Returns
        -------
        JointCommand
            Fresh arrays of modes and setpoints (angles [rad] or torques [N*m]).

        Raises
        ------
        InputError
            ``t`` is NaN/inf or earlier than the previous step, or an array has the wrong
            length or holds NaN/inf. The sequence state is unchanged.
        """
        t = finite_scalar('t', t)
        if self._t_last is not None and t < self._t_last:
            raise InputError(f't must not decrease: got {t!r} s after {self._t_last!r} s')
        pos = finite_vector('positions', positions, self._nj)
        vel = finite_vector('velocities', velocities, self._nj)
        eff = finite_vector('efforts', efforts, self._nj)
        self._t_last = t
        self._last_theta_c = pos[self._c].copy()
        if self._pending_start or self._phase.active:
            self._history.append(t, pos, eff)

        if self._pending_start:
            self._pending_start = False
            self._enter_approach(t, pos)
        if self._relax_latch_measured:
            self._relax_latch_measured = False
            self._relax_from[:] = pos
            self._modes[:] = _HOLD
        phase = self._phase
        if phase.active:
            if t - self._t_phase > self._p.phase_timeout:
                self._fail(t, f'phase {phase.value} exceeded phase_timeout '
                              f'{self._p.phase_timeout:g} s (at t = {t:.6g} s)')
            else:
                self._check_limits(t, pos)
        phase = self._phase
        if phase is Phase.IDLE:
            self._step_idle(pos)
        elif phase is Phase.APPROACH:
            self._step_approach(t, pos, vel, eff)
        elif phase is Phase.ROLLING_UP:
            self._step_rolling(t, pos, vel, eff)
        if self._phase is Phase.ENVELOPE or self._phase is Phase.DONE:
            self._step_envelope(t, pos, vel)
        if self._phase is Phase.ABORTED or self._phase is Phase.FAILED:
            self._step_relax(t)
        return JointCommand(modes=self._modes.copy(), setpoints=self._set.copy(),
                            stiffness=self._stiff.copy(), damping=self._damp.copy())

    # ------------------------------------------------------------------------------------
    # Phases

    def _step_idle(self, pos: np.ndarray) -> None:
        if self._hold is None:
            self._hold = pos.copy()
        self._modes[:] = _HOLD
        self._set[:] = self._hold
        self._stiff[:] = 0.0
        self._damp[:] = 0.0

    def _device_impedance(self, theta_eq: np.ndarray) -> None:
        """Command the compliant joints in IMPEDANCE around ``theta_eq`` [rad] (clipped to
        the joint limits) with ``k_theta_i`` and ``d``."""
        c = self._c
        self._modes[c] = _IMPEDANCE
        self._set[c] = np.clip(theta_eq, self._lower_c, self._upper_c)
        self._stiff[c] = self._k_theta_i
        self._damp[c] = self._p.damping

    def _torque_mode(self) -> None:
        """Compliant joints in TORQUE (gains cleared)."""
        self._modes[self._c] = _TORQUE
        self._stiff[:] = 0.0
        self._damp[:] = 0.0

    def _enter_approach(self, t: float, pos: np.ndarray) -> None:
        lay = self._p.layout
        self._phase = Phase.APPROACH
        self._t_phase = t
        self._preshape_from[:] = pos
        self._preshape_to[:] = pos
        self._preshape_to[self._l] = lay.initial_locked_angle
        self._preshape_to[self._q] = lay.initial_position_angle
        dist = np.abs(self._preshape_to - self._preshape_from)
        self._preshape_time = float(dist.max()) / self._p.approach_speed
        self._eq_start[:] = pos[self._c]
        self._modes[:] = _POSITION
        if self._p.impedance_on_device:
            self._device_impedance(self._eq_start)
        else:
            self._torque_mode()
        self._progress = 0.0

    def _compliant_torque(self, theta_eq: np.ndarray, pos: np.ndarray,
                          vel: np.ndarray) -> np.ndarray:
        p = self._p
        return _impedance_unchecked(self._k_theta_i, p.damping, p.torque_limit, theta_eq,
                                    pos[self._c], vel[self._c])

    def _step_approach(self, t: float, pos: np.ndarray, vel: np.ndarray,
                       eff: np.ndarray) -> None:
        p = self._p
        elapsed = t - self._t_phase
        # Pre-shape of locked and position joints, rate-limited towards the targets.
        step = p.approach_speed * elapsed
        delta = self._preshape_to - self._preshape_from
        moved = self._preshape_from + np.clip(delta, -step, step)
        self._set[self._l] = moved[self._l]
        self._set[self._q] = moved[self._q]
        preshaped = elapsed >= self._preshape_time
        # Closing: the equilibrium of fingers without contact moves inward.
        closing_time = max(elapsed - self._preshape_time, 0.0)
        theta_eq = self._eq_start + p.approach_speed * closing_time
        if preshaped:  # per finger (three numbers: plain floats are faster than numpy)
            contact = self._contact.tolist()
            tau_c = eff[self._c].tolist()
            theta = pos[self._c].tolist()
            above_since = self._above_since.tolist()
            confirm = p.contact_confirm_time - _TIME_EPS
            for i in range(self._n):
                above = not contact[i] and tau_c[i] >= p.contact_torque_threshold
                above_since[i] = _since(above, above_since[i], t)
                if above and t - above_since[i] >= confirm:  # new contact
                    self._theta_0[i] = theta[i]
                    self._contact[i] = True
            self._above_since = np.array(above_since)
        theta_eq = np.where(self._contact, self._theta_0, theta_eq)
        if p.impedance_on_device:
            self._device_impedance(theta_eq)
        else:
            tau = self._compliant_torque(theta_eq, pos, vel)
            if p.torque_ramp_time > 0.0 and elapsed < p.torque_ramp_time:
                tau = tau * (elapsed / p.torque_ramp_time)
            self._set[self._c] = tau
        frac_pre = 1.0 if self._preshape_time <= 0.0 else min(elapsed / self._preshape_time,
                                                               1.0)
        frac = 0.5 * frac_pre + 0.5 * (int(np.count_nonzero(self._contact)) / self._n)
        self._progress = max(self._progress, _PROGRESS_APPROACH * frac)
        if self._contact.all():
            self._enter_rolling(t, pos, vel)
            return
        # A finger whose equilibrium has passed its joint limit will never find the object.
        upper_c = self._inner_hi_c
        open_limit = (~self._contact) & (theta_eq >= upper_c)
        if open_limit.any():
            i = int(np.flatnonzero(open_limit)[0])
            self._fail(t, f'{p.layout.finger_name(i)} closed to its compliant joint limit '
                          f'({math.degrees(upper_c[i]):.6g} deg) without contact: compliant '
                          f'torque {eff[self._c][i]:.4g} N*m stayed below '
                          f'contact_torque_threshold {p.contact_torque_threshold:g} N*m')

    def _enter_rolling(self, t: float, pos: np.ndarray, vel: np.ndarray) -> None:
        p = self._p
        self._phase = Phase.ROLLING_UP
        self._t_phase = t
        self._progress = _PROGRESS_APPROACH
        start = self._set[self._q].copy()
        self._trajectory = MinimumJerkTrajectory(
            start, np.full(self._n, self._delta_theta_p), p.trajectory_duration)
        self._loaded[:] = False
        self._below_since[:] = np.nan
        self._loaded_since[:] = np.nan
        self._modes[self._q] = _POSITION
        self._modes[self._l] = _HOLD
        self._set[self._l] = self._p.layout.initial_locked_angle
        if p.impedance_on_device:
            self._device_impedance(self._theta_0)
        else:
            self._torque_mode()
            self._set[self._c] = self._compliant_torque(self._theta_0, pos, vel)

    def _step_rolling(self, t: float, pos: np.ndarray, vel: np.ndarray,
                      eff: np.ndarray) -> None:
        p = self._p
        traj = self._trajectory
        assert traj is not None
        elapsed = t - self._t_phase
        self._set[self._q] = traj.position(elapsed)
        self._set[self._l] = p.layout.initial_locked_angle
        if not p.impedance_on_device:
            self._set[self._c] = self._compliant_torque(self._theta_0, pos, vel)
        self._progress = max(self._progress, _PROGRESS_APPROACH + (
            _PROGRESS_ROLLING - _PROGRESS_APPROACH) * traj.phase(elapsed))
        # Lost contact: a finger that carried load drops below the release level. The load is
        # the paper's tau_s = -K_theta delta_theta_s from the encoders (the torque sensor would
        # still show the approach torque for a cycle after the contact posture is latched).
        # Per finger (three numbers: plain floats are faster than numpy).
        k = self._k_theta_i.tolist()
        theta_0 = self._theta_0.tolist()
        theta = pos[self._c].tolist()
        loaded = self._loaded.tolist()
        loaded_since = self._loaded_since.tolist()
        below_since = self._below_since.tolist()
        release = p.lost_contact_ratio * p.contact_torque_threshold
        loaded_after = p.lost_contact_time - _TIME_EPS
        lost: int | None = None
        for i in range(self._n):
            tau_c = k[i] * (theta_0[i] - theta[i])
            over = tau_c >= p.contact_torque_threshold
            loaded_since[i] = _since(over, loaded_since[i], t)
            loaded[i] = loaded[i] or (over and t - loaded_since[i] >= loaded_after)
            below = loaded[i] and tau_c < release
            below_since[i] = _since(below, below_since[i], t)
            if lost is None and below and t - below_since[i] >= p.lost_contact_time:
                lost = i
                lost_tau = tau_c
        self._loaded[:] = loaded
        self._loaded_since = np.array(loaded_since)
        self._below_since = np.array(below_since)
        if lost is not None:
            self._fail(t, f'lost contact on {p.layout.finger_name(lost)}: compliant torque '
                          f'{lost_tau:.4g} N*m below {release:.4g} N*m for '
                          f'{t - below_since[lost]:.4g} s during rolling_up')
            return
        if elapsed >= traj.duration:
            self._enter_envelope(t, pos)

    def _enter_envelope(self, t: float, pos: np.ndarray) -> None:
        p = self._p
        self._phase = Phase.ENVELOPE
        self._t_phase = t
        self._t_envelope = t
        self._progress = _PROGRESS_ROLLING
        self._tau_from[:] = 0.0
        if p.impedance_on_device:
            # the static impedance torque the device applies now
            self._tau_from[self._c] = np.clip(
                self._k_theta_i * (self._theta_0 - pos[self._c]), -p.torque_limit,
                p.torque_limit)
        else:
            self._tau_from[self._c] = self._set[self._c]  # last compliant torque command
        ratios = p.layout.stiffness_ratios
        self._envelope_goal = p.envelope_torque * ratios / float(ratios.max())
        if p.impedance_on_device and not p.envelope_constant_torque:
            self._device_impedance(self._theta_0)
        else:
            self._torque_mode()
        self._modes[self._q] = _POSITION  # stays at the trajectory's goal
        self._modes[self._l] = _HOLD
        self._set[self._l] = self._p.layout.initial_locked_angle
        self._settled_since = None

    def _step_envelope(self, t: float, pos: np.ndarray, vel: np.ndarray) -> None:
        p = self._p
        elapsed = t - self._t_envelope
        frac = 1.0 if p.torque_ramp_time <= 0.0 else min(elapsed / p.torque_ramp_time, 1.0)
        c = self._c
        ramp = self._tau_from[c] + (self._envelope_goal - self._tau_from[c]) * frac
        if p.envelope_constant_torque:
            self._set[c] = np.maximum(ramp, 0.0)
        elif not p.impedance_on_device:
            hold = self._compliant_torque(self._theta_0, pos, vel)
            self._set[c] = np.minimum(hold, np.maximum(ramp, 0.0))
        if self._phase is Phase.DONE:
            return
        settled_frac = 0.0
        if frac >= 1.0:
            # The position joints are servoed at a fixed angle: their readings show only the
            # servo's buzz against the contacts, not whether the grasp has settled.
            moving = float(np.abs(vel[self._c]).max())
            if moving < p.settle_speed:
                if self._settled_since is None:
                    self._settled_since = t
                settled_frac = min((t - self._settled_since) / p.settle_time, 1.0)
            else:
                self._settled_since = None
        self._progress = max(self._progress, _PROGRESS_ROLLING + (1.0 - _PROGRESS_ROLLING) * (
            0.5 * frac + 0.5 * settled_frac))
        if settled_frac >= 1.0:
            self._phase = Phase.DONE
            self._t_phase = t
            self._progress = 1.0

    # ------------------------------------------------------------------------------------
    # Failure, abort, relaxation

    def _check_limits(self, t: float, pos: np.ndarray) -> None:
        modes = self._modes.tobytes()
        if modes != self._limits_for:  # the bounds change with the modes only
            torque = (self._modes == _TORQUE) | (self._modes == _IMPEDANCE)
            self._limits_lo = np.where(torque, self._inner_lo, self._outer_lo)
            self._limits_hi = np.where(torque, self._inner_hi, self._outer_hi)
            self._limits_for = modes
        bad = (pos < self._limits_lo) | (pos > self._limits_hi)
        if bad.any():
            j = int(np.flatnonzero(bad)[0])
            lay = self._p.layout
            self._fail(t, f'{lay.joint_names[j]} at {math.degrees(pos[j]):.6g} deg reached its '
                          f'joint limit [{math.degrees(lay.lower[j]):.6g}, '
                          f'{math.degrees(lay.upper[j]):.6g}] deg during phase '
                          f'{self._phase.value}')

    def _fail(self, t: float, reason: str) -> None:
        self._failure_reason = reason
        self._enter_relax(Phase.FAILED, t)

    def _enter_relax(self, phase: Phase, t: float) -> None:
        impedance = self._modes == _IMPEDANCE
        if impedance.any():
            # the device's static impedance torque at the last step, then ramped to zero
            theta = np.zeros(self._nj)
            theta[self._c] = self._last_theta_c
            tau = np.clip(self._stiff * (self._set - theta), -self._p.torque_limit,
                          self._p.torque_limit)
            self._set[impedance] = tau[impedance]
            self._modes[impedance] = _TORQUE
            self._stiff[:] = 0.0
            self._damp[:] = 0.0
        self._phase = phase
        self._t_phase = t
        self._relax_from_modes[:] = self._modes
        self._relax_from[:] = self._set
        self._relax_scale = 1.0
        moving = self._modes == _POSITION
        self._modes[moving] = _HOLD

    def _step_relax(self, t: float) -> None:
        p = self._p
        elapsed = t - self._t_phase
        if elapsed >= p.torque_ramp_time - _TIME_EPS:
            scale = 0.0
        else:
            scale = 1.0 - elapsed / p.torque_ramp_time
        self._relax_scale = scale
        torque = self._relax_from_modes == _TORQUE
        self._set[:] = np.where(torque, self._relax_from * scale, self._relax_from)

    @property
    def relaxed(self) -> bool:
        """True in ABORTED/FAILED once every torque command has reached zero."""
        if not (self._phase is Phase.ABORTED or self._phase is Phase.FAILED):
            return False
        torque = self._relax_from_modes == _TORQUE
        return bool(not torque.any() or self._relax_scale == 0.0)
