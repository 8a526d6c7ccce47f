"""The answer of :meth:`dam_analysis.analysis.LiftAnalyzer.check_lift`.

:class:`LiftResult` holds the verdicts, margins and per-finger values of one request; its
per-contact arrays (world contact points, normals, CSM forces) are built on first access from
the plane data the fast path keeps. Pure numpy; no rclpy.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


def _world(frame: tuple[list[float], list[float]], u: float, z: float, point: bool
           ) -> list[float]:
    """Plane ``(u, z)`` -> world (3,): a point (relative to the base) or a direction."""
    base, inward = frame
    out = [b + u * w for b, w in zip(base, inward, strict=True)] if point \
        else [u * w for w in inward]
    out[2] += z  # the plane z axis is the world z axis
    return out



@dataclass(frozen=True)
class LiftResult:
    """Answer of :meth:`LiftAnalyzer.check_lift`.

    Attributes
    ----------
    lift_guaranteed : eq. (18) holds for every admissible contact force.
    worst_case_margin : ``min c_z^T f_o - m_B g`` [N]; -inf when the worst case is unbounded,
        +inf when no admissible force exists (then lift_guaranteed is False); NaN when a
        finger is beyond the end of its SPCM branch.
    sufficient_status : (n,) per-finger ``'bounded' | 'unbounded' | 'infeasible'``, or
        ``'no_spcm'`` for a finger beyond the end of its SPCM branch.
    csm_lift : the contact stiffness model lifts the object (margin > 0, no separation).
    csm_margin : ``c_z^T f_o - m_B g`` with the CSM forces [N] (NaN on separation and beyond
        the end of the SPCM branch).
    csm_separation : (n,) bool, the CSM normal force would be negative.
    csm_forces : (n, 3) CSM force of each finger on the object [N].
    delta_theta_s : (n,) compliant displacement [rad].
    compliant_torque : (n,) tau_s = -K_theta delta_theta_s [N m].
    contact_points : (n, 3) [m]; normals : (n, 3) outward object normals n_CB.
    on_fingertip : (n,) bool.
    k_theta : (n,) [N m/rad]; delta_theta_p : (n,) [rad]; friction_angle [rad].
    beyond_branch : (n,) bool, the finger's ``delta_theta_p`` lies beyond the end of its SPCM
        branch (eqs. 1-4 have no solution there). The per-finger values of such a finger
        (``delta_theta_s``, ``compliant_torque``, forces, contacts, normals) are NaN; the other
        fingers keep theirs.
    branch_message : where and why the branch ends, for the first finger beyond it (its
        ``delta_theta_p`` and the end in degrees, and the reason); empty when no finger is.
    torque_limit : the largest compliant torque the hand gives [N m]
        (:class:`~dam_analysis.hand_limits.HandLimits`).
    within_torque_limit : every ``|compliant_torque|`` is at most ``torque_limit``; a pair
        guaranteed by eq. (18) but not within it is not guaranteed for this hand.
    csm_penetration : (n,) CSM contact penetration ``f_n / k_n`` per finger [m] (negative
        where the contact would open, NaN beyond the end of the branch).
    csm_in_domain : every ``csm_penetration`` is finite and at most the configured bound
        (``contact.csm_max_penetration_m``): the CSM's answer is inside its domain of validity.
    rolling_checked : the object's section can roll on the table (not a circle) and eq. (18)
        held at rest, so the poses it can roll or slide into were checked
        (:mod:`dam_analysis.rolling`, docs/analysis.md section 11); ``lift_guaranteed`` then
        also needs that it can rest in none of them.
    rolling_margin : least vertical force the fingers give in a pose where the object can
        rest on the table, minus its weight [N] (the first such pose found; NaN when not
        checked or not decided, +inf when it can rest in none).
    rolling_turn, rolling_slide : that pose: turn from the resting pose [rad] (counter-
        clockwise in the section's frame) and slide along the table [m]; NaN when none.
    rolling_message : why the rolling check refuses the guarantee (empty otherwise).
    csm_path_lift, csm_path_margin, csm_path_delta_theta_p : the CSM's path verdict
        (:mod:`dam_analysis.csm_path`): the largest CSM margin on the way from 0 to
        ``delta_theta_p`` [N] (``-inf`` when no displacement on the way has an equilibrium),
        positive for a lift, and finger 1's displacement where it is reached [rad].

    In an answer of ``check_lift`` the per-contact arrays (``csm_separation``, ``csm_forces``,
    ``contact_points``, ``normals``, ``on_fingertip``) are built on first access.
    """

    lift_guaranteed: bool
    worst_case_margin: float
    sufficient_status: tuple[str, ...]
    csm_lift: bool
    csm_margin: float
    csm_separation: np.ndarray
    csm_forces: np.ndarray
    delta_theta_s: np.ndarray
    compliant_torque: np.ndarray
    contact_points: np.ndarray
    normals: np.ndarray
    on_fingertip: np.ndarray
    k_theta: np.ndarray
    delta_theta_p: np.ndarray
    friction_angle: float
    beyond_branch: np.ndarray
    branch_message: str
    torque_limit: float
    within_torque_limit: bool
    csm_penetration: np.ndarray
    csm_in_domain: bool
    rolling_checked: bool = False
    rolling_margin: float = math.nan
    rolling_turn: float = math.nan
    rolling_slide: float = math.nan
    rolling_message: str = ''
    csm_path_lift: bool = False
    csm_path_margin: float = math.nan
    csm_path_delta_theta_p: float = math.nan

    def __getattr__(self, name: str) -> np.ndarray:
        """Build the per-contact arrays of a :meth:`LiftAnalyzer.check_lift` answer on first use.

        ``check_lift`` leaves ``csm_separation``, ``csm_forces``, ``contact_points``,
        ``normals`` and ``on_fingertip`` unset and keeps their plane data; Python calls this
        method only for attributes that are missing, so an ordinary instance never gets here.
        """
        state = self.__dict__
        if name in _LAZY_FIELDS:
            lazy = state.get('_lazy_contacts')
            if lazy is not None:
                state.update(_contact_arrays(*lazy))
                state.pop('_lazy_contacts', None)
            if name in state:  # also when another thread has just built them
                return state[name]
        raise AttributeError(f'{type(self).__name__!r} object has no attribute {name!r}')

    @classmethod
    def _with_lazy_contacts(cls, lazy: tuple, **values: object) -> LiftResult:
        """Instance whose per-contact arrays come from ``_contact_arrays(*lazy)`` when read."""
        obj = object.__new__(cls)
        obj.__dict__.update(values)
        obj.__dict__['_lazy_contacts'] = lazy
        return obj


_LAZY_FIELDS = frozenset({'csm_separation', 'csm_forces', 'contact_points', 'normals',
                          'on_fingertip'})


def _contact_arrays(frames: list[tuple[list[float], list[float]]],
                    states: list[tuple[float, float, float, float, float, bool]],
                    f_n: list[float], f_t: list[float]) -> dict[str, np.ndarray]:
    """World-frame per-contact arrays of :class:`LiftResult` from the plane states.

    Parameters
    ----------
    frames : per finger (base position (3,) [m], inward direction (3,)).
    states : per finger ``(theta_s, p_u, p_z, n_u, n_z, on_fingertip)``
        (:meth:`SpcmPath.plane_state`), None for a finger beyond its branch end (NaN rows).
    f_n, f_t : per finger CSM normal (pressing) and tangential force [N].

    Returns
    -------
    ``csm_separation`` (n,) ``f_n < 0``; ``csm_forces`` (n, 3) ``-f_n n_CB + f_t t`` [N];
    ``contact_points`` (n, 3) [m]; ``normals`` (n, 3) n_CB; ``on_fingertip`` (n,).
    """
    points, normals, forces = [], [], []
    nan = math.nan
    for frame, state, fn, ft in zip(frames, states, f_n, f_t, strict=True):
        _, p_u, p_z, n_u, n_z, _ = state if state is not None else (nan,) * 6
        points.append(_world(frame, p_u, p_z, True))
        nrm = _world(frame, n_u, n_z, False)
        tan = _world(frame, -n_z, n_u, False)  # t = b x n_CB
        normals.append(nrm)
        forces.append([-fn * a + ft * b for a, b in zip(nrm, tan, strict=True)])
    return {'csm_separation': np.array([v < 0.0 for v in f_n]),
            'csm_forces': np.array(forces), 'contact_points': np.array(points),
            'normals': np.array(normals),
            'on_fingertip': np.array([st is not None and st[5] for st in states])}
