"""Where and why the SPCM branch ends, located exactly (Kaneko et al., section 3.1, eqs. 1-4).

The SPCM{k_theta, delta_theta_p} of one finger is the curve ``gap(theta_s, theta_p) = 0``
(:func:`dam_analysis.model.distal_gap`, equivalent to eqs. 2-4 for a capsule and a cylinder)
followed from the first contact. :class:`dam_analysis.spcm.SpcmPath` follows it on a grid and
finds the first cell ``[dp_a, dp_b]`` in which it stops; this module locates the end inside
that cell to machine precision. Two things can end the branch:

* **a fold** (turning point): ``gap = 0`` and ``g_s = d gap / d theta_s = 0``, the Jacobian of
  the closure with respect to the compliant angle is singular. ``theta_p`` is at a maximum
  along the curve there, so for larger ``delta_theta_p`` no compliant angle near the branch
  keeps the distal link on the object. It is found by following the curve with ``theta_s`` as
  the parameter (``theta_p(theta_s)`` by Newton's method in ``theta_p``, regular because
  ``g_p = d gap / d theta_p != 0``) until ``g_s`` changes sign, then by Brent's method on
  ``g_s(theta_s, theta_p(theta_s))`` to ``1e-15 rad``; ``theta_p`` is stationary at the fold,
  so its error is of second order.
* **an invalid posture** on the branch (:func:`dam_analysis.spcm.posture_problem`: contact
  lost, a joint limit, the table, a proximal link in the object): bisection on the validity of
  the branch state to ``1e-13 rad``.

Beyond the end no SPCM state exists: the analysis answers "no lift" there.
"""

from __future__ import annotations

import math
import sys
from collections.abc import Callable
from dataclasses import dataclass

from dam_analysis.model import FingerGeometry, distal_gap_partials, segment_contact

#: End kinds (:attr:`BranchEnd.kind`).
END_FOLD = 'fold'
END_POSTURE = 'posture'
END_NO_SOLUTION = 'no contact solution'
END_RANGE = 'range'

_GAP_TOL_M = 1e-16
_BISECTION_TOL_RAD = 1e-13
_TRACE_MAX_STEPS = 4000
_NEWTON_MAX_ITER = 60


@dataclass(frozen=True)
class BranchEnd:
    """End of one finger's SPCM branch.

    Attributes
    ----------
    delta_theta_p : largest ``delta_theta_p`` with an SPCM state [rad].
    theta_s : compliant angle there [rad].
    kind : ``'fold'`` (singular closure Jacobian, ``g_s = 0``), ``'posture'`` (the next state
        is invalid, see ``reason``), ``'no contact solution'`` (Newton's method found none and
        no fold was located) or ``'range'`` (the branch reaches ``delta_theta_p_max``).
    reason : why the branch ends, for messages; empty for ``'range'``.
    """

    delta_theta_p: float
    theta_s: float
    kind: str
    reason: str


def theta_p_on_curve(geometry: FingerGeometry, theta_l: float, theta_s: float,
                     theta_p_start: float) -> float | None:
    """``theta_p`` [rad] with ``gap(theta_s, theta_p) = 0`` (eqs. 2-4), Newton's method in
    ``theta_p`` from ``theta_p_start``.

    Converged when ``|gap| <= 1e-16 m`` or a step is below 1e-16 rad; None when ``g_p = 0`` or
    it has not converged after 60 steps.
    """
    theta_p = theta_p_start
    for _ in range(_NEWTON_MAX_ITER):
        gap, _, g_p = distal_gap_partials(geometry, theta_s, theta_l, theta_p)
        if abs(gap) <= _GAP_TOL_M:
            return theta_p
        if g_p == 0.0:
            return None
        step = gap / g_p
        if abs(step) > 0.05:
            step = math.copysign(0.05, step)
        theta_p -= step
        if abs(step) < 1e-16:
            return theta_p
    return None


def solve_bracketed(geometry: FingerGeometry, theta_l: float, theta_p: float, lo: float,
                    hi: float) -> float | None:
    """The root of ``gap(., theta_p)`` between ``lo`` and ``hi`` [rad] (safeguarded Newton).

    Newton steps on ``gap`` with ``g_s``; a step that leaves the bracket is replaced by a
    bisection step. Returns the end point itself when ``|gap| <= 1e-13 m`` there (at the
    fold the root is double), None when the bracket holds no sign change.
    """
    g_lo = distal_gap_partials(geometry, lo, theta_l, theta_p)[0]
    g_hi = distal_gap_partials(geometry, hi, theta_l, theta_p)[0]
    if g_lo == 0.0:
        return lo
    if g_hi == 0.0:
        return hi
    if g_lo * g_hi > 0.0:
        closest = lo if abs(g_lo) <= abs(g_hi) else hi
        return closest if min(abs(g_lo), abs(g_hi)) <= 1e-13 else None
    a, b = (lo, hi) if g_lo < 0.0 else (hi, lo)  # gap(a) < 0 < gap(b)
    x = 0.5 * (a + b)
    for _ in range(200):
        gap, g_s, _ = distal_gap_partials(geometry, x, theta_l, theta_p)
        if gap == 0.0:
            return x
        if gap < 0.0:
            a = x
        else:
            b = x
        if abs(gap) <= _GAP_TOL_M or abs(b - a) <= 4e-16 * max(1.0, abs(x)):
            return x
        newton = x - gap / g_s if g_s != 0.0 else math.nan
        x = newton if min(a, b) < newton < max(a, b) else 0.5 * (a + b)
    return x


def brent_root(f: Callable[[float], float], a: float, b: float, xtol: float, rtol: float,
               maxiter: int) -> float:
    """A zero of ``f`` in ``[a, b]`` by Brent's method (bisection, secant and inverse
    quadratic interpolation), to ``xtol + rtol * |x|``; what ``scipy.optimize.brentq`` does,
    without importing scipy (a quarter of a node's start-up).

    Raises
    ------
    ValueError
        ``f(a)`` and ``f(b)`` have the same sign (no bracket), or ``rtol`` is below 4 eps.
    RuntimeError
        No convergence within ``maxiter`` steps.
    """
    if rtol < 4.0 * sys.float_info.epsilon:
        raise ValueError(f'rtol {rtol!r} is below 4 eps')
    fa, fb = f(a), f(b)
    if fa == 0.0:
        return a
    if fb == 0.0:
        return b
    if (fa > 0.0) == (fb > 0.0):
        raise ValueError(f'f({a!r}) = {fa!r} and f({b!r}) = {fb!r} have the same sign')
    # b: the best estimate; c: the other end of the bracket; a: the previous b
    c, fc = a, fa
    step = last = b - a
    for _ in range(maxiter):
        if (fb > 0.0) == (fc > 0.0):
            c, fc = a, fa
            step = last = b - a
        if abs(fc) < abs(fb):
            a, fa = b, fb
            b, fb = c, fc
            c, fc = a, fa
        tol = 0.5 * (xtol + rtol * abs(b))
        half = 0.5 * (c - b)
        if fb == 0.0 or abs(half) <= tol:
            return b
        if abs(last) >= tol and abs(fa) > abs(fb):
            s = fb / fa
            if a == c:  # secant
                num, den = 2.0 * half * s, 1.0 - s
            else:  # inverse quadratic interpolation
                q, r = fa / fc, fb / fc
                num = s * (2.0 * half * q * (q - r) - (b - a) * (r - 1.0))
                den = (q - 1.0) * (r - 1.0) * (s - 1.0)
            if num > 0.0:
                den = -den
            else:
                num = -num
            if 2.0 * num < min(3.0 * half * den - abs(tol * den), abs(last * den)):
                last, step = step, num / den
            else:
                step = last = half  # interpolation would leave the bracket or creep: bisect
        else:
            step = last = half
        a, fa = b, fb
        b += step if abs(step) > tol else math.copysign(tol, half)
        fb = f(b)
    raise RuntimeError(f'no zero to {xtol:g} + {rtol:g} |x| within {maxiter} steps')


def locate_fold(geometry: FingerGeometry, theta_l: float, theta_p0: float,
                node: tuple[float, float], dp_limit: float, step_s: float
                ) -> tuple[float, float] | None:
    """The first fold of the branch after ``node``, if it comes before ``dp_limit``.

    Parameters
    ----------
    geometry : the finger; theta_l, theta_p0 : locked and initial position angles [rad].
    node : ``(delta_theta_p, theta_s)`` of a valid branch state [rad].
    dp_limit : stop looking at this ``delta_theta_p`` [rad].
    step_s : ``theta_s`` step of the trace [rad].

    Returns
    -------
    ``(delta_theta_p, theta_s)`` of the fold [rad], or None (no fold before ``dp_limit``, or
    ``g_p = 0`` on the way so that ``theta_s`` cannot serve as the parameter).
    """
    dp_node, s_prev = node
    p_prev = theta_p0 + dp_node
    _, gs_node, gp_node = distal_gap_partials(geometry, s_prev, theta_l, p_prev)
    if gs_node == 0.0 or gp_node == 0.0:
        return None
    sigma = math.copysign(1.0, -gp_node / gs_node)  # sign of d theta_s / d theta_p
    for _ in range(_TRACE_MAX_STEPS):
        s = s_prev + sigma * step_s
        p = theta_p_on_curve(geometry, theta_l, s, p_prev)
        if p is None:
            return None
        _, g_s, g_p = distal_gap_partials(geometry, s, theta_l, p)
        if g_p * gp_node <= 0.0:
            return None
        if g_s * gs_node <= 0.0:  # theta_p(theta_s) passed its maximum: a fold in between
            def slope(x: float, start: float = p_prev) -> float:
                px = theta_p_on_curve(geometry, theta_l, x, start)
                if px is None:
                    raise ArithmeticError('the SPCM closure has no solution on the trace')
                return distal_gap_partials(geometry, x, theta_l, px)[1]

            try:
                s_fold = brent_root(slope, s_prev, s, xtol=1e-15, rtol=1e-15, maxiter=200)
            except (ArithmeticError, ValueError):
                return None
            p_fold = theta_p_on_curve(geometry, theta_l, s_fold, p_prev)
            if p_fold is None or p_fold - theta_p0 > dp_limit:
                return None
            return p_fold - theta_p0, s_fold
        if p - theta_p0 >= dp_limit:
            return None
        s_prev, p_prev = s, p
    return None


def _newton_theta_s(geometry: FingerGeometry, theta_l: float, theta_p: float,
                    start: float) -> float | None:
    """``theta_s`` [rad] with ``gap(theta_s, theta_p) = 0`` near ``start`` (Newton's method,
    ``|gap| < 1e-13 m``); None when it does not converge or steps more than 0.05 rad away."""
    theta = start
    for _ in range(_NEWTON_MAX_ITER):
        gap, g_s, _ = distal_gap_partials(geometry, theta, theta_l, theta_p)
        if abs(gap) < 1e-13:
            return theta
        if abs(g_s) < 1e-9:
            return None
        step = gap / g_s
        if abs(step) > 0.05:
            return None
        theta -= step
    return None


def locate_branch_end(geometry: FingerGeometry, theta_l: float, theta_p0: float,
                      nodes: tuple[tuple[float, float], tuple[float, float] | None],
                      failed: tuple[float, float | None],
                      problem: Callable[[float, float], str | None]) -> BranchEnd:
    """Locate the end of the branch inside the grid cell where the continuation stopped.

    Parameters
    ----------
    geometry : the finger; theta_l, theta_p0 : locked and initial position angles [rad].
    nodes : the last valid grid node ``(delta_theta_p, theta_s)`` [rad] and the one before it
        (None when the last valid node is the first contact); the latter sets the trace step.
    failed : ``(delta_theta_p, theta_s)`` of the first invalid node [rad]; ``theta_s`` is the
        Newton solution there (an invalid posture) or None (no solution found).
    problem : ``problem(theta_s, delta_theta_p)``, why a posture is not a valid SPCM state
        (:func:`dam_analysis.spcm.posture_problem`), None when it is valid.

    Returns
    -------
    The exact :class:`BranchEnd` in ``[dp_a, dp_b)``.
    """
    (dp_a, s_a), before = nodes
    dp_b, s_b = failed
    step_s = abs(s_a - before[1]) / 8.0 if before is not None else 1e-5
    step_s = min(max(step_s, 1e-7), 1e-2)
    fold = locate_fold(geometry, theta_l, theta_p0, (dp_a, s_a), dp_b, step_s)
    if fold is not None:
        dp_f, s_f = fold
        fold_problem = problem(s_f, dp_f)
        if fold_problem is None:
            return BranchEnd(dp_f, s_f, END_FOLD, fold_reason(geometry, theta_l, theta_p0,
                                                              s_f, dp_f))

        def on_branch(dp: float, _start: float) -> float | None:
            return solve_bracketed(geometry, theta_l, theta_p0 + dp, s_a, s_f)

        return _bisect_validity(on_branch, problem, (dp_a, s_a), dp_f, fold_problem)

    def continued(dp: float, start: float) -> float | None:
        return _newton_theta_s(geometry, theta_l, theta_p0 + dp, start)

    reason = (problem(s_b, dp_b) if s_b is not None else None) or (
        'no contact solution near the branch (Newton\'s method does not converge)')
    return _bisect_validity(continued, problem, (dp_a, s_a), dp_b, reason)


def _bisect_validity(solve: Callable[[float, float], float | None],
                     problem: Callable[[float, float], str | None],
                     valid: tuple[float, float], dp_hi: float, reason_hi: str) -> BranchEnd:
    """Bisection on 'the branch state at delta_theta_p exists and is valid'."""
    dp_lo, s_lo = valid
    for _ in range(200):
        if dp_hi - dp_lo <= _BISECTION_TOL_RAD:
            break
        mid = 0.5 * (dp_lo + dp_hi)
        s_mid = solve(mid, s_lo)
        mid_problem = 'no contact solution near the branch' if s_mid is None \
            else problem(s_mid, mid)
        if mid_problem is None:
            dp_lo, s_lo = mid, s_mid
        else:
            dp_hi, reason_hi = mid, mid_problem
    kind = END_NO_SOLUTION if reason_hi.startswith('no contact solution') else END_POSTURE
    return BranchEnd(dp_lo, s_lo, kind, reason_hi)


def fold_reason(geometry: FingerGeometry, theta_l: float, theta_p0: float, theta_s: float,
                delta_theta_p: float) -> str:
    """Explain a fold at ``(theta_s, delta_theta_p)`` [rad] in words, for messages."""
    theta_p = theta_p0 + delta_theta_p
    _, _, g_p = distal_gap_partials(geometry, theta_s, theta_l, theta_p)
    l1, l2, l3 = (float(v) for v in geometry.link_lengths)
    phi3 = theta_s + theta_l + theta_p
    qu = l1 * math.sin(theta_s) + l2 * math.sin(theta_s + theta_l)
    qz = -l1 * math.cos(theta_s) - l2 * math.cos(theta_s + theta_l)
    abu, abz = l3 * math.sin(phi3), -l3 * math.cos(phi3)
    if geometry.is_circle:
        cu, cz = float(geometry.object_center[0]), float(geometry.object_center[1])
        t = min(1.0, max(0.0, ((cu - qu) * abu + (cz - qz) * abz) / (l3 * l3)))
        elevation = math.degrees(math.atan2(qz + t * abz - cz, abs(qu + t * abu - cu)))
    else:  # the elevation of the section's normal at the contact
        sd = segment_contact(geometry, qu, qz, qu + abu, qz + abz)
        t = sd.t
        elevation = math.degrees(math.atan2(sd.normal[1], abs(sd.normal[0])))
    where = 'fingertip' if t >= 1.0 - 1e-12 else 'inner side of the distal link'
    beyond = ('the distal link passes over the object and loses contact' if g_p > 0.0 else
              'the distal link would have to pass into the object')
    return (f'fold of the SPCM closure: d gap/d theta_s = 0 at theta_s = '
            f'{math.degrees(theta_s):.4f} deg, so the compliant joint can no longer keep the '
            f'distal link on the object (contact on the {where}, {elevation:.1f} deg above '
            f'the object\'s equator); beyond it {beyond}')
