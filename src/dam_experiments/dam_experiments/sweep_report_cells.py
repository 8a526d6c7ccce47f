"""Cells and columns of the results document: a sweep cell's trials, whether it lifts, and
the simulated lift boundary of a ``delta_theta_p`` column against the CSM's.

:mod:`dam_experiments.sweep_report` builds its cells (:class:`CellRow`) and compares the
boundaries of its columns (:func:`column_boundary`) with the configured CSM's;
:mod:`dam_experiments.sweep_report_calibration` does the same with the CSM fitted to the sweep.
Ground truth per cell: the share of its trials whose object lifted, ``p_lift``; the cell lifts
when ``p_lift >= LIFT_PROBABILITY``. No rclpy, no analysis.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from dam_experiments.sweep_report_rows import TrialRow

#: A cell lifts when at least this share of its trials lifted [-].
LIFT_PROBABILITY = 0.5


@dataclass(frozen=True)
class CellRow:
    """The trials of one cell with the analysis' boundaries at its ``delta_theta_p``.

    Attributes
    ----------
    friction_angle_deg, k_theta, delta_theta_p_deg
        The cell [deg, N*m/rad, deg].
    trials
        Its trials.
    k_sufficient, k_csm
        eq. (18) and CSM boundaries ``k_theta*`` at the cell's ``delta_theta_p`` [N*m/rad]
        (NaN: no stiffness lifts there).
    """

    friction_angle_deg: float
    k_theta: float
    delta_theta_p_deg: float
    trials: tuple[TrialRow, ...]
    k_sufficient: float
    k_csm: float

    @property
    def n_lifted(self) -> int:
        return sum(t.lifted for t in self.trials)

    @property
    def p_lift(self) -> float:
        """Share of the cell's trials that lifted [-]."""
        return self.n_lifted / len(self.trials)

    @property
    def lifts(self) -> bool:
        """Ground truth of the cell: ``p_lift >= LIFT_PROBABILITY``."""
        return self.p_lift >= LIFT_PROBABILITY

    @property
    def guaranteed(self) -> bool:
        return self.trials[0].guaranteed

    @property
    def csm_lift(self) -> bool:
        return self.trials[0].csm_lift

    @property
    def csm_path_lift(self) -> bool | None:
        """The CSM's path verdict (None: the table does not record it)."""
        return self.trials[0].csm_path_lift

    @property
    def worst_case_margin_n(self) -> float:
        return self.trials[0].worst_case_margin_n

    @property
    def csm_margin_n(self) -> float:
        return self.trials[0].csm_margin_n


@dataclass(frozen=True)
class ColumnBoundary:
    """The simulated lift boundary of one ``delta_theta_p`` column against the CSM's.

    Attributes
    ----------
    friction_angle_deg, delta_theta_p_deg
        The column [deg].
    status
        ``'compared'``; ``'no lift'`` or ``'lifts at the lowest k_theta'`` (censored: the
        boundary lies above or at/below the grid); ``'no CSM boundary'`` (the CSM lifts at no
        stiffness there).
    transitions
        Changes between lifting and not lifting along ascending ``k_theta`` (1: one boundary).
    k_below, k_lift
        Highest non-lifting ``k_theta`` below the lowest lifting one, and that lowest lifting
        one [N*m/rad] (NaN when censored).
    k_sim
        ``sqrt(k_below k_lift)`` [N*m/rad] (NaN when censored).
    k_csm
        CSM boundary at the column's ``delta_theta_p`` [N*m/rad] (NaN: none).
    step_dec
        The column's ``k_theta`` step at the boundary, ``log10(k_lift / k_below)`` [decades].
    distance_dec
        ``log10(k_sim / k_csm)`` [decades], positive when the simulation needs more stiffness
        than the CSM (NaN unless compared).
    """

    friction_angle_deg: float
    delta_theta_p_deg: float
    status: str
    transitions: int
    k_below: float
    k_lift: float
    k_sim: float
    k_csm: float
    step_dec: float
    distance_dec: float

    @property
    def within_step(self) -> bool:
        """Compared and ``|distance_dec| <= step_dec``."""
        return self.status == 'compared' and abs(self.distance_dec) <= self.step_dec


def column_boundary(cells: Sequence[CellRow]) -> ColumnBoundary:
    """The simulated boundary of one column (cells of one alpha and ``delta_theta_p``).

    With the cells ascending in ``k_theta``: the lowest lifting ``k_lift`` and the grid value
    just below it ``k_below`` (not lifting, since ``k_lift`` is the lowest lifting one) give
    ``k_sim = sqrt(k_below k_lift)``; a column with more than one transition uses the lowest
    lifting ``k_theta`` all the same (counted in :attr:`ColumnBoundary.transitions`).
    """
    ordered = sorted(cells, key=lambda c: c.k_theta)
    first = ordered[0]
    lifts = [c.lifts for c in ordered]
    transitions = sum(a != b for a, b in zip(lifts, lifts[1:], strict=False))
    nan = math.nan
    k_csm = first.k_csm
    base = (first.friction_angle_deg, first.delta_theta_p_deg)
    if not any(lifts):
        return ColumnBoundary(*base, 'no lift', transitions, nan, nan, nan, k_csm, nan, nan)
    if lifts[0]:
        return ColumnBoundary(*base, 'lifts at the lowest k_theta', transitions, nan, nan, nan,
                              k_csm, nan, nan)
    j = lifts.index(True)
    k_below, k_lift = ordered[j - 1].k_theta, ordered[j].k_theta
    k_sim = math.sqrt(k_below * k_lift)
    step = math.log10(k_lift / k_below)
    if not (math.isfinite(k_csm) and k_csm > 0.0):
        return ColumnBoundary(*base, 'no CSM boundary', transitions, k_below, k_lift, k_sim,
                              k_csm, step, nan)
    return ColumnBoundary(*base, 'compared', transitions, k_below, k_lift, k_sim, k_csm, step,
                          math.log10(k_sim / k_csm))
