"""Self-Posture Changing Motion kinematics (Kaneko et al., section 3.1, eqs. 1-4).

With the object held fixed, a displacement ``delta_theta_p`` of the position joint is imparted
and the compliant joint turns by ``delta_theta_s`` so that the distal link keeps touching the
object: the contact point lies on both surfaces (eq. 2), is the same point seen from the object
and from the finger (eq. 3) and the surface normals are opposite (eq. 4). For a capsule link
and a convex column with parallel axes these three conditions reduce to one scalar equation,
``gap(theta_s, theta_p) = 0`` (:func:`dam_analysis.model.distal_gap`), solved by Newton's method:
the contact is the closest pair of the distal segment and the cross-section, on a polygon's
vertex or face, on an ellipse or a disc anywhere. The circle keeps closed-form fast paths.

The physical solution branch is followed by continuation from the first contact
(``delta_theta_p = 0``, ``delta_theta_s = 0``) on a fine grid (:class:`SpcmPath`, built once);
a request at an arbitrary ``delta_theta_p`` starts Newton from the interpolated grid value.
Where the branch ends (a fold of the closure or an invalid posture) is located exactly inside
the last grid cell (:mod:`dam_analysis.branch_end`); requests between the last valid node and
that end are solved by a bracketed root search.

Failure policy: the solver never returns a posture that is not a valid SPCM state. It raises
:class:`~dam_analysis.errors.NoSolutionError` naming the finger, ``delta_theta_p`` and the
reason: contact lost (the compliant joint would have to open past its rest angle, i.e. the
finger would have to pull on the object), a proximal link or the table penetrated, a joint
limit exceeded, or Newton failed (no contact solution on the branch).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dam_analysis.branch_end import END_RANGE, BranchEnd, locate_branch_end, solve_bracketed
from dam_analysis.errors import NoSolutionError
from dam_analysis.model import (
    FingerGeometry,
    HandModel,
    distal_gap,
    joint_positions,
    segment_contact,
)

#: Grid step of the cached continuation path [rad].
PATH_STEP_RAD = math.radians(0.05)
_NEWTON_TOL_M = 1e-13
_NEWTON_MAX_ITER = 30


@dataclass(frozen=True)
class FingerContact:
    """SPCM state of one finger.

    Attributes
    ----------
    delta_theta_s : compliant-joint displacement from first contact [rad] (eq. 2-4 solution).
    theta_s, theta_p : absolute compliant and position joint angles [rad].
    contact_point : (3,) world p_Ci [m].
    normal_object : (3,) n_CBi, unit outward normal of the object at p_Ci.
    normal_finger : (3,) n_CFi = -n_CBi (eq. 4).
    on_fingertip : True when the contact is on the hemispherical tip, False on the inner side.
    dtheta_s_dtheta_p : d(theta_s)/d(theta_p) along the SPCM [-] (implicit differentiation).
    joints : (4, 2) plane positions of the compliant, locked, position joints and tip [m].
    """

    delta_theta_s: float
    theta_s: float
    theta_p: float
    contact_point: np.ndarray
    normal_object: np.ndarray
    normal_finger: np.ndarray
    on_fingertip: bool
    dtheta_s_dtheta_p: float
    joints: np.ndarray


def newton_theta_s(geometry: FingerGeometry, theta_l: float, theta_p: float,
                   theta_start: float) -> float | None:
    """Solve ``gap(theta_s, theta_p) = 0`` by damped Newton from ``theta_start`` (None: failed)."""
    theta = theta_start
    for _ in range(_NEWTON_MAX_ITER):
        gap, deriv = distal_gap(geometry, theta, theta_l, theta_p)
        if abs(gap) < _NEWTON_TOL_M:
            return theta
        if abs(deriv) < 1e-9:
            return None
        step = gap / deriv
        if abs(step) > 0.2:
            step = math.copysign(0.2, step)
        theta -= step
    gap, _ = distal_gap(geometry, theta, theta_l, theta_p)
    return theta if abs(gap) < 1e-11 else None


def contact_state(geometry: FingerGeometry, theta_s: float, theta_l: float, theta_p: float,
                  theta_s0: float) -> FingerContact:
    """Contact point, normals and SPCM rate for a posture that satisfies eqs. 2-4."""
    joints = joint_positions(geometry, theta_s, theta_l, theta_p)
    q, tip = joints[2], joints[3]
    if geometry.is_circle:
        c = geometry.object_center
        ab = tip - q
        t = min(1.0, max(0.0, float((c - q) @ ab) / float(ab @ ab)))
        closest = q + t * ab
        n_uz = (closest - c) / float(np.linalg.norm(closest - c))
        p_uz = c + geometry.object_radius * n_uz
    else:
        sd = segment_contact(geometry, float(q[0]), float(q[1]), float(tip[0]), float(tip[1]))
        t = sd.t
        closest, n_uz = np.array(sd.segment_point), np.array(sd.normal)
        p_uz = np.array(sd.section_point)
    # implicit differentiation of gap(theta_s, theta_p) = 0 (envelope theorem, both derivatives
    # are the normal component of the rigid-rotation velocity of the closest segment point)
    g_s = float(n_uz @ np.array([-closest[1], closest[0]]))
    rel = closest - q
    g_p = float(n_uz @ np.array([-rel[1], rel[0]]))
    return FingerContact(
        delta_theta_s=theta_s - theta_s0, theta_s=theta_s, theta_p=theta_p,
        contact_point=geometry.to_world(p_uz), normal_object=geometry.direction_to_world(n_uz),
        normal_finger=-geometry.direction_to_world(n_uz), on_fingertip=t >= 1.0 - 1e-12,
        dtheta_s_dtheta_p=-g_p / g_s if g_s != 0.0 else math.nan, joints=joints)


def _segment_distance(au: float, az: float, bu: float, bz: float, cu: float, cz: float
                      ) -> tuple[float, float, float]:
    """Distance from (cu, cz) to segment [a, b] and the closest point (pure float math)."""
    abu, abz = bu - au, bz - az
    denom = abu * abu + abz * abz
    t = 0.0 if denom == 0.0 else min(1.0, max(0.0, ((cu - au) * abu + (cz - az) * abz) / denom))
    pu, pz = au + t * abu, az + t * abz
    return math.hypot(pu - cu, pz - cz), pu, pz


def plane_joints(geometry: FingerGeometry, theta_s: float, theta_l: float, theta_p: float
                 ) -> tuple[float, ...]:
    """Scalar forward kinematics: (u1, z1, u2, z2, u3, z3) of locked joint, position joint, tip."""
    l1, l2, l3 = (float(v) for v in geometry.link_lengths)
    phi2 = theta_s + theta_l
    phi3 = phi2 + theta_p
    u1, z1 = l1 * math.sin(theta_s), -l1 * math.cos(theta_s)
    u2, z2 = u1 + l2 * math.sin(phi2), z1 - l2 * math.cos(phi2)
    return u1, z1, u2, z2, u2 + l3 * math.sin(phi3), z2 - l3 * math.cos(phi3)


def posture_problem(geometry: FingerGeometry, theta_s: float, theta_l: float, theta_p: float,
                    theta_s0: float, limits_s: tuple[float, float],
                    limits_p: tuple[float, float]) -> str | None:
    """Reason why an SPCM posture is not valid, or None when it is."""
    if theta_s > theta_s0 + 1e-12:
        return (f'contact lost: the compliant joint would open past its rest angle by '
                f'{math.degrees(theta_s - theta_s0):.4f} deg (the finger would have to pull)')
    if not limits_s[0] <= theta_s <= limits_s[1]:
        return (f'compliant joint limit: theta_s = {math.degrees(theta_s):.3f} deg outside '
                f'[{math.degrees(limits_s[0]):.3g}, {math.degrees(limits_s[1]):.3g}] deg')
    if not limits_p[0] <= theta_p <= limits_p[1] + 1e-12:
        return (f'position joint limit: theta_p = {math.degrees(theta_p):.3f} deg outside '
                f'[{math.degrees(limits_p[0]):.3g}, {math.degrees(limits_p[1]):.3g}] deg')
    u1, z1, u2, z2, u3, z3 = plane_joints(geometry, theta_s, theta_l, theta_p)
    clearance = geometry.base_height + min(0.0, z1, z2, z3) - geometry.link_radius
    if clearance < 0.0:
        return f'the finger passes {-clearance * 1e3:.3f} mm through the table'
    if geometry.is_circle:
        cu, cz = float(geometry.object_center[0]), float(geometry.object_center[1])
        reach = geometry.object_radius + geometry.link_radius
        d1 = _segment_distance(0.0, 0.0, u1, z1, cu, cz)[0]
        d2 = _segment_distance(u1, z1, u2, z2, cu, cz)[0]
    else:  # distances to the section itself: the reach is the capsule radius
        reach = geometry.link_radius
        d1 = segment_contact(geometry, 0.0, 0.0, u1, z1).distance
        d2 = segment_contact(geometry, u1, z1, u2, z2).distance
    if min(d1, d2) - reach < -1e-9:
        return (f'a proximal link penetrates the object by {(reach - min(d1, d2)) * 1e3:.3f} '
                'mm (contact would move off the distal link)')
    return None


def plane_contact(geometry: FingerGeometry, theta_s: float, theta_l: float, theta_p: float
                  ) -> tuple[float, float, float, float, bool]:
    """Contact in plane coordinates (pure float math, for the fast path).

    Returns
    -------
    (p_u, p_z, n_u, n_z, on_fingertip): contact point relative to the base [m] and the
    object's outward unit normal n_CB.
    """
    _, _, u2, z2, u3, z3 = plane_joints(geometry, theta_s, theta_l, theta_p)
    if not geometry.is_circle:
        sd = segment_contact(geometry, u2, z2, u3, z3)
        return (*sd.section_point, *sd.normal, sd.t >= 1.0 - 1e-12)
    cu, cz = float(geometry.object_center[0]), float(geometry.object_center[1])
    abu, abz = u3 - u2, z3 - z2
    t = min(1.0, max(0.0, ((cu - u2) * abu + (cz - z2) * abz) / (abu * abu + abz * abz)))
    qu, qz = u2 + t * abu, z2 + t * abz
    dist = math.hypot(qu - cu, qz - cz)
    n_u, n_z = (qu - cu) / dist, (qz - cz) / dist
    r_obj = geometry.object_radius
    return cu + r_obj * n_u, cz + r_obj * n_z, n_u, n_z, t >= 1.0 - 1e-12


class SpcmPath:
    """Cached SPCM continuation of one finger on a fine ``delta_theta_p`` grid, with the exact
    end of the branch.

    Attributes
    ----------
    delta_theta_p : (m,) grid [rad], from 0 to ``delta_theta_p_max``.
    theta_s : (m,) compliant angle on the branch [rad]; NaN from the first invalid node on.
    last_node : index of the last valid grid node.
    end : :class:`~dam_analysis.branch_end.BranchEnd`, where and why the branch ends, located
        exactly inside the cell after ``last_node`` (``kind == 'range'``: it reaches
        ``delta_theta_p_max``).
    valid_until : largest ``delta_theta_p`` with an SPCM state [rad] (``end.delta_theta_p``).
    failure : why the branch ends before ``delta_theta_p_max`` (``end.reason``), or None.
    """

    def __init__(self, model: HandModel, index: int, step: float = PATH_STEP_RAD) -> None:
        self.model = model
        self.index = index
        self.geometry = model.fingers[index]
        self.theta_s0 = float(model.theta_s0[index])
        n_steps = max(1, int(math.ceil(model.delta_theta_p_max / step)))
        self.delta_theta_p = np.linspace(0.0, model.delta_theta_p_max, n_steps + 1)
        self.theta_s = np.full(n_steps + 1, np.nan)
        self.theta_s[0] = self.theta_s0
        last = 0
        failed: tuple[float, float | None] | None = None
        theta = self.theta_s0
        for j in range(1, n_steps + 1):
            theta_p = model.theta_p0 + float(self.delta_theta_p[j])
            rate = contact_state(self.geometry, theta, model.theta_l0, theta_p,
                                 self.theta_s0).dtheta_s_dtheta_p
            guess = theta + (rate * (self.delta_theta_p[j] - self.delta_theta_p[j - 1])
                             if math.isfinite(rate) else 0.0)
            sol = newton_theta_s(self.geometry, model.theta_l0, theta_p, guess)
            if sol is None or abs(sol - theta) > 0.2:
                failed = (float(self.delta_theta_p[j]), None)
                break
            if self._problem(sol, float(self.delta_theta_p[j])) is not None:
                failed = (float(self.delta_theta_p[j]), sol)
                break
            theta = sol
            self.theta_s[j] = sol
            last = j
        self.last_node = last
        grid_end = (float(self.delta_theta_p[last]), float(self.theta_s[last]))
        if failed is None:
            self.end = BranchEnd(*grid_end, END_RANGE, '')
        else:
            before = ((float(self.delta_theta_p[last - 1]), float(self.theta_s[last - 1]))
                      if last > 0 else None)
            self.end = locate_branch_end(self.geometry, model.theta_l0, model.theta_p0,
                                         (grid_end, before), failed, self._problem)
        self.valid_until = self.end.delta_theta_p
        self.failure: str | None = None if failed is None else self.end.reason
        self._tail = (grid_end[0], grid_end[1], self.end.theta_s)
        self.step = float(self.delta_theta_p[1] - self.delta_theta_p[0])
        # plain-float copies for the scalar solver (plane_state)
        g = self.geometry
        l1, l2, l3 = (float(v) for v in g.link_lengths)
        self._grid: list[float] = self.delta_theta_p.tolist()
        self._nodes: list[float] = self.theta_s.tolist()
        self._consts = (l1, l2, l3, float(g.object_center[0]), float(g.object_center[1]),
                        float(g.object_radius), float(g.object_radius + g.link_radius),
                        float(model.theta_l0), float(model.theta_p0))
        self._limits = (float(model.limits_s[0]), float(model.limits_s[1]),
                        float(model.limits_p[0]), float(model.limits_p[1]),
                        float(g.base_height), float(g.link_radius),
                        float(g.object_radius + g.link_radius))

    def same_branch_key(self) -> tuple:
        """Everything :meth:`plane_state` reads: two paths with equal keys give equal states
        (the fingers of a symmetric hand around a circle share one). A non-circular section
        may be mirrored for one finger: such a path's key is its own."""
        shape = 'circle' if self.geometry.is_circle else id(self)
        return (shape, self._consts, self._limits, self.theta_s0, self.valid_until, self._tail,
                self.delta_theta_p.tobytes(), self.theta_s.tobytes())  # (NaN beyond the end)

    def _problem(self, theta_s: float, delta_theta_p: float) -> str | None:
        """:func:`posture_problem` of this finger at ``delta_theta_p`` [rad]."""
        model = self.model
        return posture_problem(self.geometry, theta_s, model.theta_l0,
                               model.theta_p0 + delta_theta_p, self.theta_s0, model.limits_s,
                               model.limits_p)

    def beyond_message(self, delta_theta_p: float) -> str:
        """Why there is no SPCM state at ``delta_theta_p`` [rad] beyond the branch end."""
        return (f'finger {self.index + 1}: no SPCM solution at delta_theta_p = '
                f'{math.degrees(delta_theta_p):.5f} deg: the SPCM branch ends at '
                f'{math.degrees(self.valid_until):.5f} deg: {self.end.reason}')

    def solve(self, delta_theta_p: float) -> FingerContact:
        """SPCM state at one ``delta_theta_p`` [rad] (see :meth:`solve_theta_s`)."""
        theta_s = self.solve_theta_s(delta_theta_p)
        return contact_state(self.geometry, theta_s, self.model.theta_l0,
                             self.model.theta_p0 + delta_theta_p, self.theta_s0)

    def solve_theta_s(self, delta_theta_p: float) -> float:
        """Compliant angle theta_s [rad] at one ``delta_theta_p`` [rad] (Newton from the branch).

        Raises
        ------
        NoSolutionError
            Beyond the valid part of the branch or at an invalid posture.
        """
        return self.plane_state(delta_theta_p)[0]

    def plane_state(self, delta_theta_p: float
                    ) -> tuple[float, float, float, float, float, bool]:
        """SPCM state at one ``delta_theta_p`` [rad] in plane coordinates (pure float math).

        Newton's method on ``gap(theta_s, theta_p) = 0`` (eqs. 2-4) starts from the linear
        interpolation of the cached branch (second-order accurate, so one or two steps reach
        ``|gap| < 1e-13 m``); the posture is then checked as :func:`posture_problem` does and
        the contact is evaluated as :func:`plane_contact` does, on the same trigonometry.
        Every expression is the scalar twin of :func:`~dam_analysis.model.distal_gap`,
        :func:`newton_theta_s`, :func:`posture_problem` and :func:`plane_contact`, in the same
        floating-point order, so the result equals theirs to the last bit. Between the last
        valid grid node and the exact branch end the root is bracketed instead
        (:meth:`_tail_state`).

        Returns
        -------
        (theta_s, p_u, p_z, n_u, n_z, on_fingertip): compliant angle [rad], contact point
        relative to the base [m] and the object's outward unit normal n_CB in the finger plane.

        Raises
        ------
        NoSolutionError
            Beyond the valid part of the branch, Newton failed, or an invalid posture (the
            message is the one of :func:`posture_problem`).
        """
        if not delta_theta_p <= self.valid_until:
            raise NoSolutionError(self.beyond_message(delta_theta_p))
        if delta_theta_p > self._tail[0]:
            return self._tail_state(delta_theta_p)
        grid, nodes, step = self._grid, self._nodes, self.step
        j = min(int(delta_theta_p / step), len(grid) - 2)
        frac = (delta_theta_p - grid[j]) / step
        guess = nodes[j] + frac * (nodes[j + 1] - nodes[j]) if frac > 0.0 else nodes[j]
        if not math.isfinite(guess):
            guess = nodes[j]
        if not self.geometry.is_circle:
            return self._section_state(delta_theta_p, guess)
        l1, l2, l3, cu, cz, radius, reach_gap, theta_l, theta_p0 = self._consts
        theta_p = theta_p0 + delta_theta_p
        sin, cos = math.sin, math.cos
        # damped Newton, the scalar twin of newton_theta_s / distal_gap
        theta = guess
        sol: float | None = None
        for it in range(_NEWTON_MAX_ITER + 1):
            phi12 = theta + theta_l
            phi3 = phi12 + theta_p
            u1, z1 = l1 * sin(theta), -l1 * cos(theta)
            qu, qz = u1 + l2 * sin(phi12), z1 - l2 * cos(phi12)
            tu, tz = qu + l3 * sin(phi3), qz - l3 * cos(phi3)
            abu, abz = tu - qu, tz - qz
            t = ((cu - qu) * abu + (cz - qz) * abz) / (abu * abu + abz * abz)
            t = t if t > 0.0 else 0.0  # min(1.0, max(0.0, t))
            t = t if t < 1.0 else 1.0
            pu, pz = qu + t * abu, qz + t * abz
            du, dz = pu - cu, pz - cz
            dist = math.hypot(du, dz)
            gap = dist - reach_gap
            if it == _NEWTON_MAX_ITER:
                sol = theta if abs(gap) < 1e-11 else None
                break
            if abs(gap) < _NEWTON_TOL_M:
                sol = theta
                break
            deriv = (du * (-pz) + dz * pu) / dist
            if abs(deriv) < 1e-9:
                break
            newton = gap / deriv
            if abs(newton) > 0.2:
                newton = math.copysign(0.2, newton)
            theta -= newton
        if sol is None or abs(sol - guess) > 10.0 * step:
            raise NoSolutionError(f'finger {self.index + 1}: Newton failed at delta_theta_p = '
                                  f'{math.degrees(delta_theta_p):.4f} deg')
        theta_s0 = self.theta_s0
        sol = theta_s0 if delta_theta_p == 0.0 else min(sol, theta_s0)
        if sol == theta:  # the last Newton evaluation is the posture: reuse its kinematics
            state = None
            if self._posture_ok(sol, theta_p, u1, z1, qu, qz, tz):
                n_u, n_z = du / dist, dz / dist
                state = (cu + radius * n_u, cz + radius * n_z, n_u, n_z, t >= 1.0 - 1e-12)
        else:
            state = self._checked_contact(sol, theta_p)
        if state is None:
            problem = posture_problem(self.geometry, sol, theta_l, theta_p, theta_s0,
                                      self.model.limits_s, self.model.limits_p)
            if problem is None:  # unreachable: the fast check is posture_problem's twin
                problem = 'invalid posture'
            raise NoSolutionError(f'finger {self.index + 1} at delta_theta_p = '
                                  f'{math.degrees(delta_theta_p):.4f} deg: {problem}')
        return (sol, *state)

    def _section_state(self, delta_theta_p: float, guess: float
                       ) -> tuple[float, float, float, float, float, bool]:
        """:meth:`plane_state` of a non-circular section: Newton's method of
        :func:`newton_theta_s` from ``guess``, the checks of :func:`posture_problem` and the
        contact of :func:`plane_contact` (the circle's scalar twins do not apply)."""
        model = self.model
        theta_p = model.theta_p0 + delta_theta_p
        sol = newton_theta_s(self.geometry, model.theta_l0, theta_p, guess)
        if sol is None or abs(sol - guess) > 10.0 * self.step:
            raise NoSolutionError(f'finger {self.index + 1}: Newton failed at delta_theta_p = '
                                  f'{math.degrees(delta_theta_p):.4f} deg')
        sol = self.theta_s0 if delta_theta_p == 0.0 else min(sol, self.theta_s0)
        problem = self._problem(sol, delta_theta_p)
        if problem is not None:
            raise NoSolutionError(f'finger {self.index + 1} at delta_theta_p = '
                                  f'{math.degrees(delta_theta_p):.4f} deg: {problem}')
        return (sol, *plane_contact(self.geometry, sol, model.theta_l0, theta_p))

    def _tail_state(self, delta_theta_p: float
                    ) -> tuple[float, float, float, float, float, bool]:
        """:meth:`plane_state` between the last valid grid node and the branch end.

        Near a fold ``theta_s(theta_p)`` behaves like a square root and Newton's method from
        an interpolated start may jump to the other half of the fold; here the root is
        bracketed by the compliant angles at the last node and at the end
        (:func:`~dam_analysis.branch_end.solve_bracketed`).
        """
        model = self.model
        theta_p = model.theta_p0 + delta_theta_p
        dp_node, s_node, s_end = self._tail
        sol = solve_bracketed(self.geometry, model.theta_l0, theta_p, s_node, s_end)
        if sol is None:
            frac = (delta_theta_p - dp_node) / (self.valid_until - dp_node)
            sol = newton_theta_s(self.geometry, model.theta_l0, theta_p,
                                 s_node + frac * (s_end - s_node))
        if sol is None:
            raise NoSolutionError(f'finger {self.index + 1}: Newton failed at delta_theta_p = '
                                  f'{math.degrees(delta_theta_p):.5f} deg')
        sol = min(sol, self.theta_s0)
        state = self._checked_contact(sol, theta_p)
        if state is None:
            raise NoSolutionError(f'finger {self.index + 1} at delta_theta_p = '
                                  f'{math.degrees(delta_theta_p):.5f} deg: '
                                  f'{self._problem(sol, delta_theta_p)}')
        return (sol, *state)

    def _posture_ok(self, theta_s: float, theta_p: float, u1: float, z1: float, u2: float,
                    z2: float, z3: float) -> bool:
        """:func:`posture_problem` is None, given the plane joint positions (pure float math)."""
        lim_s0, lim_s1, lim_p0, lim_p1, base_height, link_radius, reach = self._limits
        if theta_s > self.theta_s0 + 1e-12 or not lim_s0 <= theta_s <= lim_s1 \
                or not lim_p0 <= theta_p <= lim_p1 + 1e-12:
            return False
        if base_height + min(0.0, z1, z2, z3) - link_radius < 0.0:
            return False
        cu, cz = self._consts[3], self._consts[4]
        # _segment_distance to links 1 (base -> u1, z1) and 2 (u1, z1 -> u2, z2), inlined
        den = u1 * u1 + z1 * z1
        t = 0.0 if den == 0.0 else ((cu - 0.0) * u1 + (cz - 0.0) * z1) / den
        t = t if t > 0.0 else 0.0  # min(1.0, max(0.0, t)), NaN included
        t = t if t < 1.0 else 1.0
        d1 = math.hypot(0.0 + t * u1 - cu, 0.0 + t * z1 - cz)
        abu, abz = u2 - u1, z2 - z1
        den = abu * abu + abz * abz
        t = 0.0 if den == 0.0 else ((cu - u1) * abu + (cz - z1) * abz) / den
        t = t if t > 0.0 else 0.0  # min(1.0, max(0.0, t)), NaN included
        t = t if t < 1.0 else 1.0
        d2 = math.hypot(u1 + t * abu - cu, z1 + t * abz - cz)
        return not min(d1, d2) - reach < -1e-9

    def _checked_contact(self, theta_s: float, theta_p: float
                         ) -> tuple[float, float, float, float, bool] | None:
        """:func:`plane_contact` of a posture, None where :func:`posture_problem` objects."""
        if not self.geometry.is_circle:
            if self._problem(theta_s, theta_p - self.model.theta_p0) is not None:
                return None
            return plane_contact(self.geometry, theta_s, self._consts[7], theta_p)
        u1, z1, u2, z2, u3, z3 = plane_joints(self.geometry, theta_s, self._consts[7], theta_p)
        if not self._posture_ok(theta_s, theta_p, u1, z1, u2, z2, z3):
            return None
        cu, cz, radius = self._consts[3], self._consts[4], self._consts[5]
        abu, abz = u3 - u2, z3 - z2
        t = min(1.0, max(0.0, ((cu - u2) * abu + (cz - z2) * abz) / (abu * abu + abz * abz)))
        qu, qz = u2 + t * abu, z2 + t * abz
        dist = math.hypot(qu - cu, qz - cz)
        n_u, n_z = (qu - cu) / dist, (qz - cz) / dist
        return cu + radius * n_u, cz + radius * n_z, n_u, n_z, t >= 1.0 - 1e-12


def build_paths(model: HandModel, step: float = PATH_STEP_RAD) -> tuple[SpcmPath, ...]:
    """One cached :class:`SpcmPath` per finger."""
    return tuple(SpcmPath(model, i, step) for i in range(model.n_fingers))


def solve_spcm(paths: tuple[SpcmPath, ...], delta_theta_p: np.ndarray
               ) -> tuple[FingerContact, ...]:
    """SPCM{K_theta, delta_theta_p} kinematics of all fingers (eqs. 1-4).

    Parameters
    ----------
    paths : cached continuation paths, one per finger (:func:`build_paths`).
    delta_theta_p : (n,) position-joint displacement per finger [rad].

    Returns
    -------
    One :class:`FingerContact` per finger.

    Raises
    ------
    NoSolutionError
        Any finger has no valid SPCM state (see the module docstring).
    """
    return tuple(p.solve(float(d)) for p, d in zip(paths, delta_theta_p, strict=True))
