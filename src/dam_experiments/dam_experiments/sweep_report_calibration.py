"""Section 6 of the results document: the CSM calibrated on the sweep itself.

``sweep_report --calibrate`` fits the CSM to the sweep's outcomes
(:func:`dam_experiments.csm_calibration_run.calibrate`) and reports its agreement with the
fitted parameters beside the configured ones, and where the fitted CSM still disagrees, classed
as section 4 classes the configured CSM's disagreements.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from dam_experiments.csm_calibration_run import Calibration, calibrate, interval_text
from dam_experiments.sweep_report_cells import column_boundary

#: The disagreement categories of the fitted CSM (key, title, boundary, simulation lifts).
FITTED_CATEGORIES = (
    ('fitted_csm_not_sim', 'fitted CSM lifts, simulation does not', 'csm', False),
    ('sim_not_fitted_csm', 'simulation lifts, fitted CSM does not', 'csm', True),
)


@dataclass(frozen=True)
class CalibrationSection:
    """The calibration of a report.

    Attributes
    ----------
    calibration : the fit and its agreements (one calibration cell per trial).
    categories : section 4's categories for the fitted CSM's verdict (``Category``).
    columns : per friction angle, the
        :class:`~dam_experiments.sweep_report_cells.ColumnBoundary` of every
        ``delta_theta_p`` column against the fitted CSM's boundary (section 2's definitions).
    """

    calibration: Calibration
    categories: tuple[Any, ...]
    columns: tuple[tuple[Any, ...], ...] = ()

    def distances(self, index: int) -> tuple[int, int, float | None]:
        """Of friction angle ``index``: compared columns, those within one k step, and the
        median ``|d|`` [decades] (None: none compared)."""
        import statistics  # noqa: PLC0415

        compared = [c for c in self.columns[index] if c.status == 'compared']
        median = (statistics.median(abs(c.distance_dec) for c in compared) if compared
                  else None)
        return len(compared), sum(c.within_step for c in compared), median


def calibration_section(data: Any, config: Any, cells: Sequence[Any],
                        make_category: Callable[..., Any], folds: int) -> CalibrationSection:
    """Fit the CSM to the sweep ``data`` and class the fitted verdict's disagreements.

    ``cells`` are the report's :class:`~dam_experiments.sweep_report_cells.CellRow`
    objects, ``make_category(key, title, boundary, sim_lifts, cells)`` builds a section 4
    category.
    """
    import dataclasses  # noqa: PLC0415

    from dam_experiments.calibrate_csm import cells_of_sweep  # noqa: PLC0415

    grasps, config = cells_of_sweep(data, config)
    result = calibrate(grasps, config, folds=min(folds, grasps.size))
    fitted_by_trial: dict[int, bool] = {}
    for group, members in zip(result.groups, result.members, strict=True):
        for lift, member in zip(group.fitted_lift, members, strict=True):
            fitted_by_trial[data.trials[int(member)].index] = bool(lift)

    def fitted(cell: Any) -> bool:
        votes = [fitted_by_trial[t.index] for t in cell.trials]
        return sum(votes) * 2 > len(votes)

    k_fit: dict[tuple[float, float], float] = {}
    columns = []
    for recorded, alpha in zip(result.fit.recorded_friction_angle, result.friction_angles,
                               strict=True):
        mine = [c for c in cells if math.isclose(math.radians(c.friction_angle_deg), recorded,
                                                 abs_tol=1e-9)]
        per_column = []
        for dp in sorted({c.delta_theta_p_deg for c in mine}):
            key = (mine[0].friction_angle_deg, dp)
            k_fit[key] = result.boundary(alpha, math.radians(dp), config.object.mass_kg,
                                         config.task.gravity_m_per_s2)
            per_column.append(column_boundary(
                [dataclasses.replace(c, k_csm=k_fit[key]) for c in mine
                 if c.delta_theta_p_deg == dp]))
        columns.append(tuple(per_column))
    # the fitted CSM's boundary stands in for the configured one ("next to the boundary")
    refitted = [dataclasses.replace(c, k_csm=k_fit[(c.friction_angle_deg, c.delta_theta_p_deg)])
                for c in cells]
    members = {
        'fitted_csm_not_sim': [c for c in refitted if fitted(c) and not c.lifts],
        'sim_not_fitted_csm': [c for c in refitted if c.lifts and not fitted(c)],
    }
    categories = tuple(make_category(key, title, boundary, lifts, members[key])
                       for key, title, boundary, lifts in FITTED_CATEGORIES)
    return CalibrationSection(calibration=result, categories=categories,
                              columns=tuple(columns))


def calibration_lines(section: CalibrationSection,
                      category_lines: Callable[[Any], list[str]],
                      share: Callable[[int, int], str]) -> list[str]:
    """Markdown of section 6; ``category_lines`` renders a category as section 4 does."""
    result = section.calibration
    fit = result.fit
    kt = fit.log10_tangential_stiffness
    lines = [
        '## 6. The CSM calibrated on this sweep', '',
        'The paper: the CSM matches the experiments "when the contact stiffness is chosen '
        'properly". `calibrate_csm` (`docs/analysis.md`, "Calibrating the CSM") fits, by '
        'maximum likelihood of lift / no lift with a probit link on the CSM margin, the '
        'friction angle of each recorded friction angle (the analysis is told nothing of it) '
        'and the effective tangential stiffness `k_t`, with '
        f'{fit.level:.0%} profile-likelihood intervals, on the `{result.verdict}` verdict '
        '(the largest margin on the way to `delta_theta_p`: the object lifts as soon as the '
        'margin turns positive). Agreement counts trials whose verdict equals `lifted`; '
        '"held out" predicts each trial with a fit that did not see it '
        f'({result.folds}-fold). The fitted boundary of a `delta_theta_p` column is the lowest '
        '`k_theta` whose fitted verdict is a lift (361 log-spaced values from 1e-3 to 1e3 '
        'N*m/rad); its distance to the simulated boundary and "within one k step" are section '
        '2\'s.', '',
        f'* Tangential stiffness `k_t` [N/m]: configured '
        f'{result.configured_tangential_stiffness:.3g}; fitted '
        f'{interval_text(kt, log10=True)} ({kt.status}); the fitted verdicts below take '
        f'{result.tangential_stiffness:.3g}.',
        f'* Link spread sigma (the vertical force the CSM does not capture) [N]: '
        f'{interval_text(fit.sigma)}.',
        '* An interval\'s ends are grid nodes (0.25 deg, 0.25 decade); `<`/`>` an end of the '
        'searched range: the data bound that side no further. A friction angle the data do '
        'not determine enters the fitted verdicts as the allowed value nearest the recorded '
        'one.', '',
    ]
    header = ('alpha recorded [deg]', 'alpha fitted [deg] (interval)', 'status', 'trials',
              'configured, end verdict', 'configured, path verdict', 'fitted',
              'fitted, held out', 'fitted boundary: median distance [decades] (compared)',
              'columns within one k step')
    rows = []
    for index, (iv, g) in enumerate(zip(fit.friction_angle, result.groups, strict=True)):
        compared, within, median = section.distances(index) if section.columns else (0, 0,
                                                                                      None)
        rows.append((f'{g.recorded_deg:g}', interval_text(iv, scale=180.0 / math.pi),
                     iv.status if fit.fitted_friction_angle else 'not fitted', str(g.cells),
                     share(g.configured_end, g.cells), share(g.configured_path, g.cells),
                     share(g.fitted, g.cells),
                     share(g.held_out, g.cells) if g.held_out >= 0 else '-',
                     f'{median:.3f} ({compared})' if median is not None else f'- ({compared})',
                     share(within, compared)))
    lines += ['| ' + ' | '.join(header) + ' |', '|' + '---|' * len(header)]
    lines += ['| ' + ' | '.join(r) + ' |' for r in rows] + ['']
    lines += ['### Where the fitted CSM still disagrees', '',
              'Classed by the checks of section 4; "next to the boundary" and the column "k* '
              'here" use the fitted CSM\'s boundary, the columns `csm_margin_n` and '
              '`worst_case_margin_n` are the configured analysis\' (`/check_lift`\'s).', '']
    for category in section.categories:
        lines += ['#' + line if line.startswith('### ') else line
                  for line in category_lines(category)]
    return lines
