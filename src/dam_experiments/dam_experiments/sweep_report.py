"""The numbers of the results document: a sweep's simulated lifts against the lift analysis.

The pure core of ``ros2 run dam_experiments sweep_report`` (:mod:`dam_experiments.sweep_report_cli`
writes the document, :mod:`dam_experiments.sweep_report_markdown` renders it). From a sweep
directory (:func:`~dam_experiments.sweep_results.read_sweep`) and the analysis of the
configuration, :func:`compute_report` answers, per friction angle alpha:

1. false guarantees: cells the sufficient condition (eq. 18) guarantees that do not lift;
2. how close the contact stiffness model's (CSM) boundary ``k_theta*(delta_theta_p)`` is to the
   simulated lift boundary: the share of cells where the CSM verdict equals the simulation's,
   and per ``delta_theta_p`` column the distance in decades between the two boundaries;
3. the share of the lifting cells the sufficient condition does not guarantee;
4. where the two disagree, with the evidence the table's columns hold.

Ground truth per cell: the share of its trials whose object lifted (column ``lifted``: it left
the table during the grasp, :mod:`dam_sim_bridge.lift_off`, whatever it did after), ``p_lift``;
the cell lifts when ``p_lift >= LIFT_PROBABILITY`` (:mod:`dam_experiments.sweep_report_cells`,
which also finds the simulated boundary of a column). The analysis columns
(``check_lift_guaranteed``, ``csm_lift`` and the margins) are the cell's ``/check_lift``
answer, the same for every trial of a cell; the first trial's are used. The rows come from
:mod:`dam_experiments.sweep_report_rows`. No rclpy, no matplotlib: numpy and the analysis.
"""

from __future__ import annotations

import math
import statistics
from collections import Counter
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from dam_experiments.errors import SweepPlotError
from dam_experiments.sweep import config_digest
from dam_experiments.sweep_report_cells import CellRow, ColumnBoundary, column_boundary
from dam_experiments.sweep_report_rows import (
    CHECKS_LIFTING,
    CHECKS_NOT_LIFTING,
    Limits,
    TrialRow,
    checks,
    ending,
    read_rows,
    rise_class,
    trial_label,
)
from dam_experiments.sweep_results import SweepData, analysis_config, k_axis_is_log, one_object

#: Disagreement categories of section 4: key, title, the boundary they are compared with, and
#: whether the simulation lifts in them.
CATEGORIES = (
    ('csm_not_sim', 'CSM lifts, simulation does not', 'csm', False),
    ('sim_not_csm', 'simulation lifts, CSM does not', 'csm', True),
    ('suff_not_sim', 'eq. 18 guarantees, simulation does not lift', 'sufficient', False),
)


# ------------------------------------------------------------------------------------------
# Per friction angle and per disagreement category


def _share(part: int, whole: int) -> float | None:
    return part / whole if whole else None


@dataclass(frozen=True)
class AngleNumbers:
    """The report's numbers at one friction angle.

    Attributes
    ----------
    friction_angle_deg
        alpha [deg].
    n_trials, n_cells, n_lifting, n_guaranteed, n_csm_lift
        Trials, cells, lifting cells (ground truth), cells eq. (18) guarantees, cells the CSM
        lifts.
    n_false_guarantees
        Cells guaranteed and not lifting.
    n_agree, agreement
        Cells where ``csm_lift`` equals the ground truth, and their share of the cells [-].
    n_path_agree, path_agreement
        The same for the CSM's path verdict ``csm_path_lift`` (None: not recorded).
    columns
        One :class:`ColumnBoundary` per ``delta_theta_p`` column.
    median_distance_dec, median_signed_dec
        Median ``|log10(k_sim / k_csm)|`` and median ``log10(k_sim / k_csm)`` over the
        compared columns [decades] (None: none compared).
    n_within_step, within_step_share
        Compared columns with ``|distance| <= step``, and their share of the compared ones.
    n_missed, missed_share
        Lifting cells without a guarantee, and their share of the lifting cells.
    sufficient_exists
        Whether eq. (18) has a finite boundary anywhere on the dense ``delta_theta_p`` grid.
    """

    friction_angle_deg: float
    n_trials: int
    n_cells: int
    n_lifting: int
    n_guaranteed: int
    n_csm_lift: int
    n_false_guarantees: int
    n_agree: int
    agreement: float | None
    n_path_agree: int | None
    path_agreement: float | None
    columns: tuple[ColumnBoundary, ...]
    median_distance_dec: float | None
    median_signed_dec: float | None
    n_within_step: int
    within_step_share: float | None
    n_missed: int
    missed_share: float | None
    sufficient_exists: bool

    @property
    def n_compared(self) -> int:
        return sum(c.status == 'compared' for c in self.columns)

    def n_status(self, status: str) -> int:
        """Columns with this :attr:`ColumnBoundary.status`."""
        return sum(c.status == status for c in self.columns)

    @property
    def n_multi_transition(self) -> int:
        return sum(c.transitions > 1 for c in self.columns)


@dataclass(frozen=True)
class Category:
    """Cells of one disagreement category (:data:`CATEGORIES`) with their evidence.

    Attributes
    ----------
    key, title
        Its key and title.
    boundary
        ``'csm'`` or ``'sufficient'``: the boundary its cells are compared with.
    sim_lifts
        Whether the simulation lifts in its cells.
    cells
        Its cells.
    trials
        The trials that side with the simulation's verdict: lifted ones where the
        simulation lifts, the others where it does not.
    counts
        Cells per friction angle, in the order of the sweep's angles.
    endings, rises
        :func:`ending` and :func:`rise_class` of :attr:`trials`, with their counts (most
        frequent first).
    checks
        The checks of the evidence (see :func:`checks`) with the trials they hold for.
    unexplained
        Trials for which no check holds.
    mean_rise_final_mm, mean_rise_max_mm
        Means over :attr:`trials`, NaN values left out (NaN: no trial) [mm].
    max_peak_compliant_nm, max_peak_position_nm
        Largest peak torques of :attr:`trials` [N*m] (NaN: no trial).
    """

    key: str
    title: str
    boundary: str
    sim_lifts: bool
    cells: tuple[CellRow, ...]
    trials: tuple[TrialRow, ...]
    counts: tuple[int, ...]
    endings: tuple[tuple[str, int], ...]
    rises: tuple[tuple[str, int], ...]
    checks: tuple[tuple[str, int], ...]
    unexplained: int
    mean_rise_final_mm: float
    mean_rise_max_mm: float
    max_peak_compliant_nm: float
    max_peak_position_nm: float


def _nanmean(values: Sequence[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return math.fsum(finite) / len(finite) if finite else math.nan


def _category(key: str, title: str, boundary: str, sim_lifts: bool, cells: list[CellRow],
              alphas: Sequence[float], k_grid: Sequence[float], limits: Limits) -> Category:
    trials = [(t, c) for c in cells for t in c.trials if t.lifted == sim_lifts]
    found = [checks(t, c.k_csm if boundary == 'csm' else c.k_sufficient, k_grid, sim_lifts,
                    limits) for t, c in trials]
    names = CHECKS_LIFTING if sim_lifts else CHECKS_NOT_LIFTING
    rows = [t for t, _ in trials]
    return Category(
        key=key, title=title, boundary=boundary, sim_lifts=sim_lifts, cells=tuple(cells),
        trials=tuple(rows),
        counts=tuple(sum(c.friction_angle_deg == a for c in cells) for a in alphas),
        endings=tuple(Counter(ending(t) for t in rows).most_common()),
        rises=tuple(Counter(rise_class(t, limits.lift_height_mm) for t in rows).most_common()),
        checks=tuple((name, sum(name in f for f in found)) for name, _ in names),
        unexplained=sum(not f for f in found),
        mean_rise_final_mm=_nanmean([t.rise_final_mm for t in rows]),
        mean_rise_max_mm=_nanmean([t.rise_max_mm for t in rows]),
        max_peak_compliant_nm=max((t.peak_compliant_nm for t in rows), default=math.nan),
        max_peak_position_nm=max((t.peak_position_nm for t in rows), default=math.nan))


# ------------------------------------------------------------------------------------------
# The whole report


@dataclass(frozen=True)
class FalseGuarantee:
    """A trial that did not lift in a cell eq. (18) guarantees and that does not lift.

    Attributes
    ----------
    cell, trial
        The cell and the trial.
    label
        :func:`trial_label` of the trial.
    """

    cell: CellRow
    trial: TrialRow
    label: str


@dataclass(frozen=True)
class SweepReport:
    """Everything the results document states; see the module docstring.

    Attributes
    ----------
    data
        The sweep read.
    limits
        :class:`Limits` of the configuration.
    config_matches
        Whether the configuration's digest equals ``sweep.json``'s ``config_sha256``.
    log_k
        Whether the sweep's ``k_theta`` axis is logarithmic.
    cells
        Every cell with trials, ordered by alpha, ``delta_theta_p``, ``k_theta``.
    angles
        One :class:`AngleNumbers` per friction angle of the table.
    false_guarantees
        The non-lifted trials of the guaranteed cells that do not lift, in table order.
    n_false_guarantee_cells
        Guaranteed cells that do not lift.
    n_guaranteed_unlifted_trials
        Non-lifted trials in guaranteed cells that lift all the same (``p_lift >= 0.5``).
    categories
        The disagreement categories of :data:`CATEGORIES`.
    boundaries
        The analysis' boundaries on the dense ``delta_theta_p`` grid, one per angle
        (``dam_analysis.regions.Boundaries``; what the figures draw).
    dense_right_deg
        Right end of the dense grid [deg].
    contact_stiffness_n_per_m
        The CSM's contact stiffness ``contact.contact_stiffness_n_per_m`` [N/m].
    solver_iterations
        ``sim.solver_iterations``: the simulator's contact solver iterations per step.
    contact_model
        ``sim.contact_model``: the simulator's contacts (``compliant`` or ``rigid``).
    calibration
        Section 6, the CSM calibrated on the sweep
        (:class:`~dam_experiments.sweep_report_calibration.CalibrationSection`); None when
        not asked for.
    """

    data: SweepData
    limits: Limits
    config_matches: bool
    log_k: bool
    cells: tuple[CellRow, ...]
    angles: tuple[AngleNumbers, ...]
    false_guarantees: tuple[FalseGuarantee, ...]
    n_false_guarantee_cells: int
    n_guaranteed_unlifted_trials: int
    categories: tuple[Category, ...]
    boundaries: tuple[Any, ...]
    dense_right_deg: float
    contact_stiffness_n_per_m: tuple[float, ...]
    solver_iterations: int
    contact_model: str = 'rigid'
    calibration: Any = None

    @property
    def n_present(self) -> int:
        return len(self.data.trials)

    @property
    def complete(self) -> bool:
        return self.n_present == self.data.n_planned


def _median(values: list[float]) -> float | None:
    return statistics.median(values) if values else None


def _angle(alpha: float, cells: list[CellRow], sufficient_exists: bool) -> AngleNumbers:
    by_dp: dict[float, list[CellRow]] = {}
    for c in cells:
        by_dp.setdefault(c.delta_theta_p_deg, []).append(c)
    columns = tuple(column_boundary(by_dp[dp]) for dp in sorted(by_dp))
    compared = [c for c in columns if c.status == 'compared']
    lifting = [c for c in cells if c.lifts]
    agree = sum(c.csm_lift == c.lifts for c in cells)
    recorded = all(c.csm_path_lift is not None for c in cells)
    path_agree = sum(c.csm_path_lift == c.lifts for c in cells) if recorded else None
    within = sum(c.within_step for c in compared)
    missed = sum(not c.guaranteed for c in lifting)
    return AngleNumbers(
        friction_angle_deg=alpha, n_trials=sum(len(c.trials) for c in cells),
        n_cells=len(cells), n_lifting=len(lifting),
        n_guaranteed=sum(c.guaranteed for c in cells),
        n_csm_lift=sum(c.csm_lift for c in cells),
        n_false_guarantees=sum(c.guaranteed and not c.lifts for c in cells),
        n_agree=agree, agreement=_share(agree, len(cells)), n_path_agree=path_agree,
        path_agreement=None if path_agree is None else _share(path_agree, len(cells)),
        columns=columns,
        median_distance_dec=_median([abs(c.distance_dec) for c in compared]),
        median_signed_dec=_median([c.distance_dec for c in compared]),
        n_within_step=within, within_step_share=_share(within, len(compared)),
        n_missed=missed, missed_share=_share(missed, len(lifting)),
        sufficient_exists=sufficient_exists)


def compute_report(data: SweepData, config: Any, analyzer: Any = None,
                   n_points: int = 200, calibrate_folds: int | None = None) -> SweepReport:
    """The report's numbers for a sweep.

    Parameters
    ----------
    data
        The sweep (:func:`~dam_experiments.sweep_results.read_sweep`).
    config
        ``DamConfig`` of the analysis and of the limits (the sweep's, to compare like with
        like: :attr:`SweepReport.config_matches` says whether it is).
    analyzer
        A ``LiftAnalyzer`` of ``config`` to reuse (built when None).
    n_points
        Samples of the dense boundaries
        (:func:`~dam_experiments.sweep_plot.sweep_boundaries`), at least 2.
    calibrate_folds
        When given, calibrate the CSM on the sweep (section 6) with this many folds of the
        held-out check (0: none).

    Returns
    -------
    SweepReport

    Raises
    ------
    SweepPlotError
        The table lacks a column the report needs or holds a malformed value
        (:func:`read_rows`), or ``n_points < 2``.
    """
    from dam_analysis.lift_map import compute_boundaries  # noqa: PLC0415 - slow import
    from dam_experiments.sweep_plot import boundary_grid_deg, sweep_boundaries  # noqa: PLC0415

    if n_points < 2:
        raise SweepPlotError(f'n_points {n_points} must be at least 2')
    data = one_object(data, None)
    rows = read_rows(data)
    matches = data.parameters.get('config_sha256') == config_digest(config)
    config = analysis_config(data, config)
    if analyzer is None:
        from dam_analysis.analysis import LiftAnalyzer  # noqa: PLC0415 - slow import

        analyzer = LiftAnalyzer(config)
    limits = Limits.from_config(config, data.spec.impedance)
    alphas = data.friction_angles_deg
    dense = sweep_boundaries(data, analyzer, n_points)
    right = float(boundary_grid_deg(data.spec.delta_theta_p_deg,
                                    math.degrees(analyzer.model.delta_theta_p_max), 2)[-1])
    groups: dict[tuple[float, float, float], list[TrialRow]] = {}
    for r in rows:
        groups.setdefault((r.friction_angle_deg, r.delta_theta_p_deg, r.k_theta), []).append(r)
    columns_dp = sorted({key[1] for key in groups})
    at_columns = compute_boundaries(analyzer, alphas, np.radians(columns_dp), progress=False)
    k_at: dict[tuple[float, float], tuple[float, float]] = {}
    for alpha, b in zip(alphas, at_columns, strict=True):
        for dp, ks, kc in zip(columns_dp, b.sufficient, b.csm, strict=True):
            k_at[(alpha, dp)] = (_finite(ks), _finite(kc))
    cells = tuple(CellRow(a, k, dp, tuple(g), *k_at[(a, dp)])
                  for (a, dp, k), g in sorted(groups.items()))
    k_grid = tuple(sorted(set(data.spec.k_theta) | {c.k_theta for c in cells}))
    angles = tuple(_angle(a, [c for c in cells if c.friction_angle_deg == a],
                          bool(np.any(np.isfinite(np.asarray(b.sufficient, dtype=float)))))
                   for a, b in zip(alphas, dense, strict=True))
    false = [c for c in cells if c.guaranteed and not c.lifts]
    listed = tuple(FalseGuarantee(c, t, trial_label(t, limits.lift_height_mm))
                   for c in false for t in c.trials if not t.lifted)
    others = sum(not t.lifted for c in cells if c.guaranteed and c.lifts for t in c.trials)
    members = {
        'csm_not_sim': [c for c in cells if c.csm_lift and not c.lifts],
        'sim_not_csm': [c for c in cells if c.lifts and not c.csm_lift],
        'suff_not_sim': false,
    }
    categories = tuple(_category(key, title, boundary, lifts, members[key], alphas, k_grid,
                                 limits) for key, title, boundary, lifts in CATEGORIES)
    calibration = None
    if calibrate_folds is not None:
        from dam_experiments.sweep_report_calibration import (  # noqa: PLC0415
            calibration_section,
        )

        def make(key: str, title: str, boundary: str, lifts: bool, members: list) -> Category:
            return _category(key, title, boundary, lifts, members, alphas, k_grid, limits)

        calibration = calibration_section(data, config, cells, make, calibrate_folds)
    return SweepReport(
        data=data, limits=limits,
        config_matches=matches,
        log_k=k_axis_is_log(data.parameters), cells=cells, angles=angles,
        false_guarantees=listed, n_false_guarantee_cells=len(false),
        n_guaranteed_unlifted_trials=others, categories=categories, boundaries=tuple(dense),
        dense_right_deg=right,
        contact_stiffness_n_per_m=tuple(
            float(v) for v in np.ravel(config.contact.contact_stiffness_n_per_m)),
        solver_iterations=int(config.sim.solver_iterations),
        contact_model=str(getattr(config.sim, 'contact_model', 'rigid')),
        calibration=calibration)


def _finite(value: float) -> float:
    value = float(value)
    return value if math.isfinite(value) else math.nan
