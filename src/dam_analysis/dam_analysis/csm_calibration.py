"""Calibration of the contact stiffness model from observed lift / no-lift outcomes.

The model of an outcome (``docs/analysis.md``, "Calibrating the CSM"): the grasp of a cell
lifts with probability

``P(lift) = lapse + (1 - 2 lapse) Phi(margin(alpha, k_t) / sigma)``

where ``margin`` is the CSM margin of the cell (:class:`~dam_analysis.csm_outcomes.CellMargins`,
``'path'`` or ``'end'`` verdict) at friction angle ``alpha`` and tangential stiffness ``k_t``,
``Phi`` the standard normal distribution (a probit link: ``sigma`` [N] is the spread of the
vertical force the model does not capture) and ``lapse`` a fixed small probability of an
outcome against any margin (a controller failure, an object that rolled away), which keeps one
such grasp from dragging the fit.

Parameters: one friction angle per group of cells with the same recorded friction angle (each
group is its own experiment; with ``fit_friction_angle`` False the recorded value is used), one
``log10 k_t`` shared by all cells, one ``sigma``. The fit maximises the likelihood on a grid
(friction angle step ``alpha_step``, ``log10 k_t`` step ``log_kt_step``, ``sigma`` log-spaced):
the likelihood is flat in ``k_t`` over decades (the CSM's stick cap ``mu f_n / k_t`` is microns
against millimetres of slip above ~1e3 N/m) and has plateaus, so a grid is robust where a
gradient method is not. Intervals are profile-likelihood intervals: every value whose profile
log-likelihood lies within ``chi2_1(level) / 2`` of the maximum (Wilks), widened to the first
grid node outside on each side (the grid's step is the resolution of an end). An interval
that reaches an end of its grid is open on that side;
one that covers the whole grid means the data do not determine the parameter, and the fit says
so instead of reporting a value.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import log_ndtr, ndtr
from scipy.stats import chi2

from dam_analysis.csm_outcomes import CellMargins, GraspCells
from dam_analysis.errors import InputError

DEFAULT_LAPSE = 0.02
DEFAULT_LEVEL = 0.90
#: Grid of log10 of the tangential stiffness [log10 N/m].
DEFAULT_LOG_KT_RANGE = (0.0, 6.0)
DEFAULT_SIGMA_RANGE_N = (1e-3, 10.0)


@dataclass(frozen=True)
class Interval:
    """A profile-likelihood interval of one parameter.

    Attributes
    ----------
    estimate : the maximum-likelihood grid value (NaN when not determined); it may lie at an
        end of the grid (:attr:`at_grid_end`).
    low, high : the interval's ends (``-inf``/``inf`` where it reaches the end of the grid).
    grid_low, grid_high : the searched range.
    """

    estimate: float
    low: float
    high: float
    grid_low: float
    grid_high: float

    @property
    def status(self) -> str:
        """``'determined'`` (both ends inside the grid), ``'bounded below'``, ``'bounded
        above'`` or ``'not determined'`` (the interval covers the whole grid)."""
        lo, hi = math.isfinite(self.low), math.isfinite(self.high)
        if lo and hi:
            return 'determined'
        if lo:
            return 'bounded below'
        if hi:
            return 'bounded above'
        return 'not determined'

    @property
    def at_grid_end(self) -> bool:
        """The estimate lies at an end of the searched range (the maximum may lie beyond)."""
        return self.estimate in (self.grid_low, self.grid_high) and \
            self.grid_low != self.grid_high

    @property
    def determined(self) -> bool:
        return self.status == 'determined'

    def contains(self, value: float) -> bool:
        return self.low <= value <= self.high

    def choose(self, configured: float) -> float:
        """The value a configuration should take: the estimate when determined; otherwise
        ``configured`` when the data allow it, else the allowed value nearest to it (the data
        fix one side only: a value past that side would be fitted to noise)."""
        if self.determined:
            return self.estimate
        if self.contains(configured):
            return configured
        return self.low if configured < self.low else self.high


@dataclass(frozen=True)
class MarginCube:
    """CSM margins of every cell over the parameter grid.

    ``margin[g]`` is (A_g, T, N_g) for group ``g``: friction angle node, ``log10 k_t`` node,
    cell of the group. ``alpha[g]`` (A_g,) [rad]; ``log_kt`` (T,); ``members[g]`` the indices
    of the group's cells in the :class:`GraspCells`; ``recorded[g]`` its recorded angle [rad].
    """

    alpha: tuple[np.ndarray, ...]
    log_kt: np.ndarray
    margin: tuple[np.ndarray, ...]
    members: tuple[np.ndarray, ...]
    recorded: tuple[float, ...]


@dataclass(frozen=True)
class CsmFit:
    """Result of :func:`fit_outcomes`.

    Attributes
    ----------
    recorded_friction_angle : (G,) the groups' recorded friction angles [rad].
    friction_angle : per group, its interval [rad] (a point, the recorded angle, when not
        fitted).
    log10_tangential_stiffness : interval of ``log10 k_t`` [log10 N/m].
    sigma : interval of the link's spread [N].
    log_likelihood : at the maximum.
    level : the intervals' confidence level.
    cells : the number of cells fitted.
    fitted_friction_angle : whether the friction angles were fitted.
    """

    recorded_friction_angle: tuple[float, ...]
    friction_angle: tuple[Interval, ...]
    log10_tangential_stiffness: Interval
    sigma: Interval
    log_likelihood: float
    level: float
    cells: int
    fitted_friction_angle: bool

    def tangential_stiffness(self, configured: float) -> float:
        """``k_t`` [N/m] for a configuration whose value is ``configured`` (Interval.choose)."""
        return 10.0 ** self.log10_tangential_stiffness.choose(math.log10(configured))

    def friction_angle_of(self, recorded: float) -> float:
        """The friction angle [rad] of the group recorded at ``recorded`` (Interval.choose,
        the recorded value standing for the configured one)."""
        for rec, interval in zip(self.recorded_friction_angle, self.friction_angle,
                                 strict=True):
            if math.isclose(rec, recorded, abs_tol=1e-9):
                return interval.choose(rec)
        raise InputError(f'no group recorded at {math.degrees(recorded):.6g} deg')


def friction_groups(cells: GraspCells) -> list[tuple[float, np.ndarray]]:
    """The cells grouped by recorded friction angle (to 1e-9 rad), ascending."""
    angles = np.round(cells.friction_angle, 9)
    return [(float(cells.friction_angle[angles == a][0]), np.flatnonzero(angles == a))
            for a in np.unique(angles)]


#: A recorded friction angle's search: this far on either side of it [rad] ...
ALPHA_HALF_WIDTH = math.radians(20.0)
#: ... within these bounds [rad]: so the searched range differs per angle (5 deg: [0.25, 25]
#: deg; 30 deg: [10, 50] deg), and ``calibrate_csm`` says it per angle.
ALPHA_SEARCH_BOUNDS = (math.radians(0.25), math.radians(80.0))


def margin_cube(cells: GraspCells, margins: CellMargins, fit_friction_angle: bool = True,
                alpha_half_width: float = ALPHA_HALF_WIDTH,
                alpha_step: float = math.radians(0.25),
                log_kt_range: tuple[float, float] = DEFAULT_LOG_KT_RANGE,
                log_kt_step: float = 0.25, verdict: str = 'path') -> MarginCube:
    """Evaluate the margins of every cell on the parameter grid (the expensive part).

    ``margins`` are the :class:`CellMargins` of the same cells. A group's friction-angle grid
    is ``recorded +- alpha_half_width`` [rad] clipped to [0.25, 80] deg; ``log_kt_range`` and
    ``log_kt_step`` [log10 N/m] the grid of the tangential stiffness.
    """
    log_kt = np.arange(log_kt_range[0], log_kt_range[1] + 0.5 * log_kt_step, log_kt_step)
    alphas, cubes, members, recorded = [], [], [], []
    cache: dict[tuple[float, float], np.ndarray] = {}
    for angle, index in friction_groups(cells):
        if fit_friction_angle:
            lo = max(ALPHA_SEARCH_BOUNDS[0], angle - alpha_half_width)
            hi = min(ALPHA_SEARCH_BOUNDS[1], angle + alpha_half_width)
            grid = np.arange(lo, hi + 0.5 * alpha_step, alpha_step)
        else:
            grid = np.array([angle])
        cube = np.empty((grid.size, log_kt.size, index.size))
        for a, alpha in enumerate(grid):
            for t, lk in enumerate(log_kt):
                key = (round(float(alpha), 12), float(lk))
                if key not in cache:
                    cache[key] = margins.margins(float(alpha), 10.0 ** lk, verdict)
                cube[a, t] = cache[key][index]
        alphas.append(grid)
        cubes.append(cube)
        members.append(index)
        recorded.append(angle)
    return MarginCube(alpha=tuple(alphas), log_kt=log_kt, margin=tuple(cubes),
                      members=tuple(members), recorded=tuple(recorded))


def _log_lik(margin: np.ndarray, lifted: np.ndarray, sigma: np.ndarray, lapse: float
             ) -> np.ndarray:
    """Sum over the last axis of log P(outcome); ``margin`` (..., N), returns (..., S).

    One ``sigma`` at a time: the memory is that of ``margin``, not S times it.
    """
    sign = np.where(lifted > 0.5, 1.0, -1.0)
    signed = margin * sign  # log P(lift) for lifted, log P(no lift) otherwise, through Phi
    log_lapse, log_rest = math.log(lapse), math.log1p(-2.0 * lapse)
    out = np.empty(margin.shape[:-1] + (sigma.size,))
    for j, s in enumerate(sigma):
        # lapse + (1 - 2 lapse) Phi, in logs
        value = np.logaddexp(log_lapse, log_rest + log_ndtr(signed / s))
        out[..., j] = value.sum(axis=-1)
    return out


def _interval(grid: np.ndarray, profile: np.ndarray, best: float, threshold: float,
              estimate: float) -> Interval:
    """The nodes whose profile lies within ``threshold`` of ``best``, widened to the first
    node outside on each side (the crossing lies between them: no finer claim than the grid
    is made); a side that reaches the end of the grid is open (``-inf``/``inf``)."""
    inside = profile >= best - threshold
    lo_grid, hi_grid = float(grid[0]), float(grid[-1])
    if grid.size == 1:
        return Interval(estimate, estimate, estimate, lo_grid, hi_grid)
    if bool(inside.all()):
        return Interval(math.nan, -math.inf, math.inf, lo_grid, hi_grid)
    idx = np.flatnonzero(inside)
    first, last = int(idx[0]), int(idx[-1])
    low = -math.inf if first == 0 else float(grid[first - 1])
    high = math.inf if last == grid.size - 1 else float(grid[last + 1])
    return Interval(estimate, low, high, lo_grid, hi_grid)


def fit_outcomes(cube: MarginCube, lifted: np.ndarray, lapse: float = DEFAULT_LAPSE,
                 level: float = DEFAULT_LEVEL,
                 sigma_range: tuple[float, float] = DEFAULT_SIGMA_RANGE_N,
                 sigma_nodes: int = 121, cells: np.ndarray | None = None) -> CsmFit:
    """Maximum-likelihood fit with profile-likelihood intervals (module docstring).

    Parameters
    ----------
    cube : margins on the parameter grid (:func:`margin_cube`).
    lifted : (N,) outcomes of all the cells the cube was built for (1 lifted, 0 not).
    lapse : probability of an outcome against any margin, in [0, 0.5).
    level : confidence level of the intervals, in (0, 1).
    sigma_range, sigma_nodes : the log-spaced grid of the link's spread [N].
    cells : indices of the cells to fit (k-fold training sets); all when None.

    Raises
    ------
    InputError
        ``lapse`` or ``level`` out of range, or no cell to fit.
    """
    if not 0.0 < lapse < 0.5:
        raise InputError(f'lapse {lapse!r} must lie in (0, 0.5)')
    if not 0.0 < level < 1.0:
        raise InputError(f'level {level!r} must lie in (0, 1)')
    lifted = np.asarray(lifted, dtype=np.float64)
    sigma = np.geomspace(sigma_range[0], sigma_range[1], sigma_nodes)
    keep = None if cells is None else np.zeros(lifted.size, dtype=bool)
    if keep is not None:
        keep[np.asarray(cells)] = True
    per_group = []  # (A_g, T, S) log-likelihood of each group
    for margin, members in zip(cube.margin, cube.members, strict=True):
        sel = np.ones(members.size, dtype=bool) if keep is None else keep[members]
        if not sel.any():
            per_group.append(np.zeros((margin.shape[0], margin.shape[1], sigma.size)))
            continue
        per_group.append(_log_lik(margin[:, :, sel], lifted[members[sel]], sigma, lapse))
    if keep is not None and not keep.any():
        raise InputError('no cell to fit')
    best_alpha = [g.max(axis=0) for g in per_group]  # (T, S) each
    total = np.sum(best_alpha, axis=0)  # (T, S)
    best = float(total.max())
    t_best, s_best = np.unravel_index(int(np.argmax(total)), total.shape)
    threshold = 0.5 * float(chi2.ppf(level, 1))
    fitted = len(cube.alpha[0]) > 1
    intervals = []
    for g, grid in enumerate(cube.alpha):
        others = total - best_alpha[g]  # (T, S)
        profile = (per_group[g] + others[None]).max(axis=(1, 2))
        a_best = int(np.argmax(per_group[g][:, t_best, s_best]))
        intervals.append(_interval(grid, profile, best, threshold, float(grid[a_best])))
    kt = _interval(cube.log_kt, total.max(axis=1), best, threshold,
                   float(cube.log_kt[t_best]))
    sg = _interval(sigma, total.max(axis=0), best, threshold, float(sigma[s_best]))
    return CsmFit(recorded_friction_angle=cube.recorded, friction_angle=tuple(intervals),
                  log10_tangential_stiffness=kt, sigma=sg, log_likelihood=best, level=level,
                  cells=int(lifted.size if keep is None else keep.sum()),
                  fitted_friction_angle=fitted)


def draw_outcomes(margin: np.ndarray, sigma: float, lapse: float,
                  rng: np.random.Generator) -> np.ndarray:
    """Outcomes drawn from the outcome model at known margins [N] (synthetic data)."""
    p = lapse + (1.0 - 2.0 * lapse) * ndtr(np.asarray(margin) / sigma)
    return (rng.random(p.shape) < p).astype(np.float64)
