"""A robust ``(k_theta, delta_theta_p)`` planner: which pair lifts when the friction, the mass
and the object's position are only known to lie in ranges?

For a pair, the sufficient condition (eq. 18) must hold for every friction angle in
``[alpha_min, alpha_max]``, every mass in ``[m_min, m_max]`` and every position of the object
along the fingers (world x) within ``+-position_tolerance`` of the configured one. Three
properties reduce those continua to a few evaluations:

* **Friction.** A larger friction angle gives a cone that contains the smaller one, so it
  admits every force the smaller one admits and more: its worst case (a minimum over a larger
  set) is no higher. The worst case over the range is the one at ``alpha_max``.
  (``tests/dam_analysis/test_planner.py`` checks it on samples, and the answers by brute force.)
* **Mass.** The margin is ``c_z^T f_o - m_B g``, the forces do not depend on the mass (the
  object is held fixed during SPCM, section 3.2): the worst case is at ``m_max``.
* **Stiffness.** Under SPCM ``tau_s = -K_theta delta_theta_s`` is linear in ``k_theta`` and so
  is the worst case of the linear program of eq. (18) (scaling the torques scales its feasible
  set): ``margin = k_theta A(delta_theta_p) - m_B g``, with ``A`` the worst case at
  ``k_theta = 1`` (:meth:`LiftAnalyzer.check_lift`) plus the weight; ``A = -inf`` where the
  worst case is unbounded.
* **Position.** The object's position changes the contact geometry, so ``A`` is computed on a
  grid of offsets ``x_j`` (spacing :data:`POSITION_STEP_M` at most, both ends included), each
  with a :class:`LiftAnalyzer` of its own. Between the nodes ``A`` is bounded below by
  ``min_j A(x_j) - max_j |A(x_{j+1}) - A(x_j)|``: the smallest node value less the largest
  change between two neighbouring nodes (an estimate that holds while ``A`` changes between
  two nodes by no more than it does across one grid step; the tests check it on a grid ten
  times finer). The pair's ``position_error_bound`` is ``k_theta`` times that change [N].

The guaranteed pair is the one with the smallest ``k_theta`` whose bounded worst-case margin is
at least ``min_margin`` [N], over ``delta_theta_p`` on a grid of :data:`DP_STEP_RAD` in the
requested range, under a cap: ``k_theta_max``, the device's largest accepted stiffness and the
stiffness at which a finger's ``|tau_s|`` reaches the hand's torque limit
(:mod:`dam_analysis.hand_limits`, bounded over the offsets in the same way). Without one, the
answer names why and the pair with the largest bounded worst-case margin under the cap. The
contact stiffness model's pair is the one whose smallest CSM margin over the ranges (friction
angles sampled at :data:`CSM_FRICTION_SAMPLES` values, both ends included; the mass at
``m_max``; the offset nodes) is largest, at the cap.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dam_analysis.analysis import LiftAnalyzer
from dam_analysis.errors import InputError, Interrupted, NoSolutionError
from dam_analysis.hand_limits import HandLimits
from dam_analysis.lift import STATUS_BOUNDED
from dam_common.config import DamConfig
from dam_common.quantities import ANGLE, LENGTH, MASS, Quantity, both_units

#: Largest spacing of the position grid [m].
POSITION_STEP_M = 0.5e-3
#: Spacing of the delta_theta_p grid [rad].
DP_STEP_RAD = math.radians(0.25)
#: Friction angles at which the CSM margin is evaluated over the range (ends included).
CSM_FRICTION_SAMPLES = 5
#: Default of the smallest worst-case margin a guaranteed pair must keep [N].
DEFAULT_MIN_MARGIN_N = 0.01
#: Largest position tolerance [m]: beyond, the fingers meet the object elsewhere entirely.
MAX_POSITION_TOLERANCE_M = 5.0e-3


@dataclass(frozen=True)
class PlanRanges:
    """What the planner is asked for; validated by :func:`check_ranges`.

    Attributes
    ----------
    friction_angle : (alpha_min, alpha_max) [rad].
    mass : (m_min, m_max) [kg].
    position_tolerance : the object's position along the fingers within +-this [m].
    k_theta_max : largest finger-1 stiffness to propose [N m/rad].
    delta_theta_p : (min, max) [rad].
    min_margin : smallest worst-case margin a guaranteed pair keeps [N].
    """

    friction_angle: tuple[float, float]
    mass: tuple[float, float]
    position_tolerance: float
    k_theta_max: float
    delta_theta_p: tuple[float, float]
    min_margin: float


def _finite(name: str, value: float) -> float:
    value = float(value)
    if not math.isfinite(value):
        raise InputError(f'{name}: non-finite value {value!r}')
    return value


def _interval(name: str, low: float, high: float, quantity: Quantity) -> tuple[float, float]:
    low, high = _finite(f'{name}_min', low), _finite(f'{name}_max', high)
    if high < low:
        raise InputError(f'{name}: empty range, max {both_units(high, quantity)} is below min '
                         f'{both_units(low, quantity)}')
    return low, high


def check_ranges(config: DamConfig, friction_angle: tuple[float, float],
                 mass: tuple[float, float], position_tolerance: float, k_theta_max: float,
                 delta_theta_p: tuple[float, float], min_margin: float) -> PlanRanges:
    """Validate a request at the boundary; every value is in SI units.

    Raises
    ------
    InputError
        NaN or inf, an empty range (max below min), a friction angle outside ``[0, pi/2)``,
        a non-positive mass or stiffness, a negative or too large position tolerance, a
        displacement outside ``[0, task.delta_theta_p_max]``, a negative margin; the message
        names the field and the value.
    """
    alpha = _interval('friction_angle', *friction_angle, ANGLE)
    if not (0.0 <= alpha[0] and alpha[1] < math.pi / 2):
        raise InputError(f'friction_angle: {both_units(alpha, ANGLE)} is outside [0, pi/2) '
                         'rad ([0, 90) deg)')
    masses = _interval('mass', *mass, MASS)
    if masses[0] <= 0.0:
        raise InputError(f'mass_min: {both_units(masses[0], MASS)} must be positive')
    tol = _finite('position_tolerance', position_tolerance)
    if not 0.0 <= tol <= MAX_POSITION_TOLERANCE_M:
        raise InputError(f'position_tolerance: {both_units(tol, LENGTH)} is outside [0, '
                         f'{MAX_POSITION_TOLERANCE_M:.4g}] m ([0, '
                         f'{MAX_POSITION_TOLERANCE_M * 1e3:.4g}] mm)')
    k_max = _finite('k_theta_max', k_theta_max)
    if k_max <= 0.0:
        raise InputError(f'k_theta_max: {k_max:.4g} N*m/rad must be positive')
    dps = _interval('delta_theta_p', *delta_theta_p, ANGLE)
    dp_limit = float(config.task.delta_theta_p_max_rad)
    if dps[0] < 0.0 or dps[1] > dp_limit + 1e-12:
        raise InputError(f'delta_theta_p: {both_units(dps, ANGLE)} is outside [0, '
                         f'{dp_limit:.4g}] rad ([0, {math.degrees(dp_limit):.4g}] deg, '
                         'task.delta_theta_p_max_deg)')
    margin = _finite('min_margin', min_margin)
    if margin < 0.0:
        raise InputError(f'min_margin: {margin:.4g} N must not be negative')
    return PlanRanges(alpha, masses, tol, k_max, dps, margin)


@dataclass(frozen=True)
class PlanResult:
    """Answer of :meth:`LiftPlanner.plan`; NaN where a value does not exist.

    Attributes
    ----------
    found : a pair is guaranteed over the ranges.
    k_theta, delta_theta_p : that pair [N m/rad, rad] (finger 1's stiffness).
    worst_case_margin : its smallest worst-case margin over the position nodes, at
        ``alpha_max`` and ``m_max`` [N].
    position_error_bound : how much lower the margin may be between the nodes [N].
    best_k_theta, best_delta_theta_p, best_worst_case_margin : the pair with the largest
        bounded worst-case margin under the cap (the guaranteed one's neighbour in quality
        when ``found``; the best available otherwise) [N m/rad, rad, N].
    csm_k_theta, csm_delta_theta_p, csm_margin : the pair whose smallest CSM margin over the
        ranges is largest, and that margin [N m/rad, rad, N]; NaN when that margin is not
        positive (the CSM predicts a lift for no pair under the cap).
    csm_in_domain : the CSM stays inside its domain of validity at that pair everywhere it
        was evaluated.
    k_theta_cap : the cap at ``delta_theta_p`` (of the guaranteed or else the best pair).
    reason : why no pair is guaranteed ('' when one is).
    method : how the guarantee over the ranges was established (for the answer's message).
    offsets : (J,) the position nodes [m].
    """

    found: bool
    k_theta: float
    delta_theta_p: float
    worst_case_margin: float
    position_error_bound: float
    best_k_theta: float
    best_delta_theta_p: float
    best_worst_case_margin: float
    csm_k_theta: float
    csm_delta_theta_p: float
    csm_margin: float
    csm_in_domain: bool
    k_theta_cap: float
    reason: str
    method: str
    offsets: np.ndarray


def ranges_from_request(planner: LiftPlanner, friction_angle_min: float,
                        friction_angle_max: float, mass_min: float, mass_max: float,
                        position_tolerance: float, k_theta_max: float,
                        delta_theta_p_min: float, delta_theta_p_max: float,
                        min_margin: float) -> tuple[PlanRanges, list[str]]:
    """The ranges of a ``PlanLift`` request (SI units), its negative fields replaced by the
    configured values (``PlanLift.srv``); also the list of what came from the configuration,
    for the answer's message.

    Raises
    ------
    InputError
        As :func:`check_ranges` (NaN is never taken for "left out").
    """
    defaults = planner.default_ranges()

    def left_out(value: float) -> bool:  # negative, not NaN: NaN is refused below
        return math.isfinite(float(value)) and float(value) < 0.0

    def pick(value: float, default: float) -> float:
        return float(default) if left_out(value) else float(value)

    a_min = pick(friction_angle_min, defaults['friction_angle'][0])
    a_max = pick(friction_angle_max, a_min)
    m_min = pick(mass_min, defaults['mass'][0])
    m_max = pick(mass_max, m_min)
    k_max = pick(k_theta_max, defaults['k_theta_max'])
    d_min = pick(delta_theta_p_min, 0.0)
    d_max = pick(delta_theta_p_max, defaults['delta_theta_p'][1])
    margin = pick(min_margin, DEFAULT_MIN_MARGIN_N)
    taken = []
    if left_out(friction_angle_min):
        taken.append(f'friction_angle = {math.degrees(a_min):.4g} deg')
    if left_out(mass_min):
        taken.append(f'mass = {m_min:g} kg')
    if left_out(k_theta_max):
        taken.append(f'k_theta_max = {k_max:.4g} N*m/rad')
    if left_out(min_margin):
        taken.append(f'min_margin = {margin:g} N')
    ranges = check_ranges(planner.config, (a_min, a_max), (m_min, m_max),
                          float(position_tolerance), k_max, (d_min, d_max), margin)
    return ranges, taken


def position_nodes(tolerance: float) -> np.ndarray:
    """Offsets [m] from ``-tolerance`` to ``+tolerance`` at a spacing of at most
    :data:`POSITION_STEP_M` (0 alone for no tolerance; always odd, so 0 is a node)."""
    if tolerance == 0.0:
        return np.zeros(1)
    half = max(1, math.ceil(tolerance / POSITION_STEP_M - 1e-9))
    return np.linspace(-tolerance, tolerance, 2 * half + 1)


class LiftPlanner:
    """Plans over ranges with one :class:`LiftAnalyzer` per object position (built on first
    use, about 0.5 s each, and kept).

    Parameters
    ----------
    config : the validated configuration.
    analyzer : the analyzer of the configured position, if one exists already.
    """

    def __init__(self, config: DamConfig, analyzer: LiftAnalyzer | None = None) -> None:
        self.config = config
        self._analyzers: dict[int, LiftAnalyzer | NoSolutionError] = {}
        if analyzer is not None:
            self._analyzers[0] = analyzer
        self._torque_limit = HandLimits.from_config(config).torque_limit
        ratios = np.asarray(config.hand.stiffness_ratios, dtype=np.float64)
        #: largest finger-1 stiffness the device accepts on every finger [N m/rad]
        self.device_k_max = float(config.device.max_stiffness_nm_per_rad) / float(
            np.max(ratios / ratios[0]))

    def analyzer_at(self, offset: float) -> LiftAnalyzer | NoSolutionError:
        """The analyzer with the object moved by ``offset`` [m] along world x, or the error
        that says why the fingers make no first contact there."""
        key = int(round(offset * 1e7))  # 0.1 um
        if key not in self._analyzers:
            position = np.array(self.config.object.position_m, dtype=np.float64)
            position[0] += key * 1e-7
            moved = dataclasses.replace(self.config, object=dataclasses.replace(
                self.config.object, position_m=position))
            try:
                self._analyzers[key] = LiftAnalyzer(moved)
            except NoSolutionError as exc:
                self._analyzers[key] = exc
        return self._analyzers[key]

    def default_ranges(self) -> dict[str, object]:
        """The request's values when nothing is given: the configured friction angle and
        mass, no position tolerance, the device's stiffness cap, the whole displacement
        range and :data:`DEFAULT_MIN_MARGIN_N`."""
        alpha = float(self.config.contact.friction_angle_rad)
        mass = float(self.config.object.mass_kg)
        return {'friction_angle': (alpha, alpha), 'mass': (mass, mass),
                'position_tolerance': 0.0, 'k_theta_max': self.device_k_max,
                'delta_theta_p': (0.0, float(self.config.task.delta_theta_p_max_rad)),
                'min_margin': DEFAULT_MIN_MARGIN_N}

    def plan(self, ranges: PlanRanges, stop: Callable[[], bool] | None = None) -> PlanResult:
        """The robust pairs for ``ranges`` (module docstring).

        ``stop`` is asked before each position node's analysis is built (0.5 s each) and
        before each node is evaluated; when it returns True the plan ends with
        :class:`~dam_analysis.errors.Interrupted` (a node that is stopping must not wait for
        seconds of work).
        """
        def check_stop() -> None:
            if stop is not None and stop():
                raise Interrupted('planning interrupted: the server is stopping')

        g = float(self.config.task.gravity_m_per_s2)
        weight_max = ranges.mass[1] * g
        alpha_max = ranges.friction_angle[1]
        offsets = position_nodes(ranges.position_tolerance)
        analyzers = []
        for x in offsets:
            check_stop()
            analyzers.append(self.analyzer_at(float(x)))
        failed = [(x, a) for x, a in zip(offsets, analyzers, strict=True)
                  if isinstance(a, NoSolutionError)]
        method = self._method(ranges, offsets)
        if failed:
            x, exc = failed[0]
            nan = math.nan
            return PlanResult(False, nan, nan, nan, nan, nan, nan, nan, nan, nan, nan, False,
                              nan, f'with the object {x * 1e3:+.3g} mm along x the fingers '
                              f'make no first contact: {exc}', method, offsets)
        lo = math.ceil(ranges.delta_theta_p[0] / DP_STEP_RAD - 1e-9)
        hi = math.floor(ranges.delta_theta_p[1] / DP_STEP_RAD + 1e-9)
        dps = np.arange(lo, hi + 1) * DP_STEP_RAD
        if dps.size == 0:
            dps = np.array([ranges.delta_theta_p[0]])
        dps = dps[dps > 0.0] if np.any(dps > 0.0) else dps
        # per offset node at alpha_max and k_theta = 1: the slope A of margin = k A - m g
        # (-inf: eq. 18 holds for no stiffness) and the largest |tau_s| per unit k_theta
        slopes = np.full((offsets.size, dps.size), -np.inf)
        torque_per_k = np.full((offsets.size, dps.size), np.nan)
        for j, analyzer in enumerate(analyzers):
            check_stop()
            weight_0 = analyzer.model.object_weight
            for d, dp in enumerate(dps):
                unit = analyzer.check_lift(1.0, float(dp), alpha_max)
                if unit.beyond_branch.any():
                    continue
                if all(st == STATUS_BOUNDED for st in unit.sufficient_status):
                    slopes[j, d] = unit.worst_case_margin + weight_0
                torque_per_k[j, d] = float(np.max(np.abs(unit.compliant_torque)))
        slope_min, slope_step = _bounded_min(slopes)
        with np.errstate(divide='ignore', invalid='ignore'):
            torque_k = self._torque_limit / _bounded_max(torque_per_k)
        cap = np.minimum(min(ranges.k_theta_max, self.device_k_max), torque_k)
        cap = np.where(np.isfinite(cap), cap, np.nan)
        slope_eff = slope_min - slope_step
        with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
            k_needed = np.where(slope_eff > 0.0, (weight_max + ranges.min_margin) / slope_eff,
                                np.inf)
            # where the margin rises with k_theta its best is at the cap
            margin_at_cap = np.where((slope_eff > 0.0) & np.isfinite(cap),
                                     cap * slope_eff - weight_max, -np.inf)
        feasible = np.isfinite(k_needed) & np.isfinite(cap) & (k_needed <= cap)
        rolling = ''
        if np.any(feasible) and not analyzers[0].model.fingers[0].is_circle:
            feasible, rolling = self._rolling_filter(analyzers, dps, k_needed, feasible,
                                                     alpha_max, ranges, check_stop)
        best = int(np.argmax(margin_at_cap))
        best_exists = bool(np.isfinite(margin_at_cap[best]))
        csm = self._csm_pair(analyzers, dps, cap, ranges)
        if np.any(feasible):
            d = int(np.argmin(np.where(feasible, k_needed, np.inf)))
            k = float(k_needed[d])
            found = True
            margin = k * float(slope_min[d]) - weight_max
            error = k * float(slope_step[d])
            reason = ''
        else:
            d = best
            k, found, margin, error = math.nan, False, math.nan, math.nan
            reason = rolling or self._reason(dps, k_needed, cap, alpha_max, ranges)
        return PlanResult(
            found=found, k_theta=k, delta_theta_p=float(dps[d]) if found else math.nan,
            worst_case_margin=margin, position_error_bound=error,
            best_k_theta=float(cap[best]) if best_exists else math.nan,
            best_delta_theta_p=float(dps[best]) if best_exists else math.nan,
            best_worst_case_margin=float(margin_at_cap[best]) if best_exists else math.nan,
            csm_k_theta=csm[0], csm_delta_theta_p=csm[1], csm_margin=csm[2],
            csm_in_domain=csm[3], k_theta_cap=float(cap[d]), reason=reason, method=method,
            offsets=offsets)

    def _rolling_filter(self, analyzers: list[LiftAnalyzer], dps: np.ndarray,
                        k_needed: np.ndarray, feasible: np.ndarray, alpha_max: float,
                        ranges: PlanRanges, check_stop: Callable[[], None]
                        ) -> tuple[np.ndarray, str]:
        """Drop the displacements where a section that can turn on the table may rest turned.

        At the pair a displacement would propose (``k_needed``), the rolling check
        (:mod:`dam_analysis.rolling`) of every position node at ``alpha_max`` (a larger cone
        admits more forces) with the weight a variable over the mass range. Returns the
        remaining displacements and, when none remains, why.
        """
        g = float(self.config.task.gravity_m_per_s2)
        weights = (ranges.mass[0] * g, ranges.mass[1] * g)
        kept = feasible.copy()
        first = ''
        # in the order the plan takes them (smallest stiffness first): the reason names the
        # pair it would have proposed
        for d in sorted(np.flatnonzero(feasible), key=lambda i: float(k_needed[i])):
            k1 = float(k_needed[d])
            for analyzer in analyzers:
                check_stop()
                ratios = analyzer.model.stiffness_ratios
                verdict = analyzer.rolling.verdict(
                    [k1 * float(r) / float(ratios[0]) for r in ratios],
                    [float(dps[d])] * analyzer.n_fingers, alpha_max, weights,
                    analyzer.rolling_cos_phi)
                if not verdict.holds:
                    kept[d] = False
                    first = first or (
                        f'eq. 18 holds at rest, but at k_theta {k1:.4g} N*m/rad, '
                        f'delta_theta_p {math.degrees(float(dps[d])):g} deg '
                        f'{verdict.message}')
                    break
        return kept, '' if np.any(kept) else first

    def _csm_pair(self, analyzers: list[LiftAnalyzer], dps: np.ndarray, cap: np.ndarray,
                  ranges: PlanRanges) -> tuple[float, float, float, bool]:
        """The CSM pair at the cap whose smallest margin over the ranges is largest."""
        g = float(self.config.task.gravity_m_per_s2)
        alphas = np.linspace(*ranges.friction_angle, CSM_FRICTION_SAMPLES)
        best = (math.nan, math.nan, -math.inf, False)
        for d, dp in enumerate(dps):
            k = float(cap[d])
            if not math.isfinite(k):
                continue
            worst, inside = math.inf, True
            for analyzer in analyzers:
                for alpha in alphas:
                    r = analyzer.check_lift(k, float(dp), float(alpha))
                    value = r.csm_margin + analyzer.model.object_weight - ranges.mass[1] * g
                    worst = min(worst, value if math.isfinite(value) else -math.inf)
                    inside = inside and r.csm_in_domain
            if worst > best[2]:
                best = (k, float(dp), worst, inside)
        if not best[2] > 0.0:  # the CSM lifts with no pair: none to propose
            return math.nan, math.nan, math.nan, False
        return best

    @staticmethod
    def _reason(dps: np.ndarray, k_needed: np.ndarray, cap: np.ndarray, alpha_max: float,
                ranges: PlanRanges) -> str:
        lo, hi = (math.degrees(v) for v in ranges.delta_theta_p)
        if not np.any(np.isfinite(k_needed)):
            return (f'no delta_theta_p in [{lo:g}, {hi:g}] deg has a worst case that rises '
                    f'with k_theta at alpha_max = {math.degrees(alpha_max):g} deg (eq. 18 '
                    'holds for no stiffness there)')
        usable = np.isfinite(k_needed) & np.isfinite(cap)
        if not np.any(usable):
            return (f'no delta_theta_p in [{lo:g}, {hi:g}] deg has both a worst case that rises '
                    f'with k_theta and a torque the hand can give at alpha_max = '
                    f'{math.degrees(alpha_max):g} deg')
        with np.errstate(divide='ignore', invalid='ignore'):
            d = int(np.argmin(np.where(usable, k_needed / cap, np.inf)))  # nearest to its cap
        return (f'the smallest stiffness eq. 18 needs, {k_needed[d]:.4g} N*m/rad at '
                f'delta_theta_p {math.degrees(dps[d]):g} deg, is above the cap there, '
                f'{cap[d]:.4g} N*m/rad (k_theta_max, the device\'s largest stiffness or the '
                "hand's torque limit)")

    @staticmethod
    def _method(ranges: PlanRanges, offsets: np.ndarray) -> str:
        a0, a1 = (math.degrees(v) for v in ranges.friction_angle)
        spacing = float(offsets[1] - offsets[0]) if offsets.size > 1 else 0.0
        position = ('the configured position only' if offsets.size == 1 else
                    f'{offsets.size} positions from {offsets[0] * 1e3:g} to '
                    f'{offsets[-1] * 1e3:g} mm along x (spacing {spacing * 1e3:.3g} mm; '
                    'between them the slope of the margin in k_theta is taken as its '
                    'smallest node value less its largest change between neighbouring '
                    'nodes)')
        return (f'friction: worst case at alpha_max = {a1:g} deg of [{a0:g}, {a1:g}] (a '
                f'larger cone contains a smaller one); mass: at m_max = '
                f'{ranges.mass[1]:g} kg; position: {position}; delta_theta_p: grid of '
                f'{math.degrees(DP_STEP_RAD):g} deg')


def _bounded_min(values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per column: the smallest node value and the largest change between neighbouring nodes
    (0 for one node); a column with a -inf node has -inf."""
    low = values.min(axis=0)
    if values.shape[0] == 1:
        return low, np.zeros(values.shape[1])
    with np.errstate(invalid='ignore'):
        step = np.abs(np.diff(values, axis=0)).max(axis=0)
    step = np.where(np.isfinite(low), step, 0.0)
    return low, step


def _bounded_max(values: np.ndarray) -> np.ndarray:
    """Per column: the largest node value plus the largest change between neighbours."""
    low, step = _bounded_min(-values)
    return -(low - step)


def plan_verdict(plan: PlanResult) -> str:
    """One line: the guaranteed pair, or why there is none and the best available; and when
    the CSM predicts a lift for no pair, that too."""
    if plan.found:
        between = (f', {plan.position_error_bound:.2g} N less at most between the position '
                   'nodes' if plan.offsets.size > 1 else '')
        text = (f'guaranteed over the ranges: k_theta {plan.k_theta:.4g} N*m/rad at '
                f'delta_theta_p {math.degrees(plan.delta_theta_p):.4g} deg (worst-case margin '
                f'{plan.worst_case_margin:.4g} N{between})')
    else:
        text = f'no pair is guaranteed over the ranges: {plan.reason}'
        if math.isfinite(plan.best_worst_case_margin):
            text += (f'; best available: k_theta {plan.best_k_theta:.4g} N*m/rad at '
                     f'delta_theta_p {math.degrees(plan.best_delta_theta_p):.4g} deg, '
                     f'worst-case margin {plan.best_worst_case_margin:.4g} N')
    if math.isnan(plan.csm_margin):
        text += '; the contact stiffness model predicts a lift for no pair under the cap'
    return text
