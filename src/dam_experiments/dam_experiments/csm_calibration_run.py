"""One calibration of the CSM against observed grasps: fit, k-fold check, agreement, overlay.

The fit itself is :mod:`dam_analysis.csm_calibration`; this module gathers what a user asks of
a calibration (``docs/analysis.md``, "Calibrating the CSM"): the parameters with their
intervals, the CSM's agreement with the outcomes before and after (in-sample and on held-out
folds), how many grasps a given interval width needs, and the configuration overlay with the
fitted values. ``calibrate_csm`` prints and writes it; ``sweep_report --calibrate`` puts it in
the results document.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
import yaml

from dam_analysis.csm_calibration import (
    DEFAULT_LAPSE,
    DEFAULT_LEVEL,
    CsmFit,
    fit_outcomes,
    margin_cube,
)
from dam_analysis.csm_outcomes import CellMargins, GraspCells
from dam_common.words import counted
from dam_experiments.errors import SweepPlotError

DEFAULT_FOLDS = 5


@dataclass(frozen=True)
class GroupAgreement:
    """The CSM's agreement with the outcomes of one friction-angle group.

    Attributes
    ----------
    recorded_deg : the group's recorded friction angle [deg].
    cells : its cells.
    configured_end, configured_path : cells whose verdict equals the outcome with the
        configured parameters, ``'end'`` and ``'path'`` verdict.
    fitted : with the fitted parameters (in-sample, the calibration's verdict).
    held_out : the same on held-out folds (each cell predicted by a fit without it); -1 when
        no k-fold check ran.
    overlay_end : cells whose end verdict (``/check_lift``'s) with the overlay's values
        equals the outcome.
    fitted_lift : (N_g,) bool, the fitted verdict of each cell of the group (table order).
    """

    recorded_deg: float
    cells: int
    configured_end: int
    configured_path: int
    fitted: int
    held_out: int
    fitted_lift: np.ndarray
    overlay_end: int


@dataclass(frozen=True)
class Calibration:
    """What :func:`calibrate` found.

    Attributes
    ----------
    fit : the maximum-likelihood fit on all cells.
    verdict : ``'path'`` or ``'end'``.
    configured_tangential_stiffness : the configuration's effective ``k_t`` [N/m].
    tangential_stiffness : the value the overlay takes [N/m] (``CsmFit.tangential_stiffness``).
    friction_angles : per group, the value a configuration takes [rad].
    groups : per group, the agreements.
    folds : folds of the k-fold check (0: none).
    members : per group, the indices of its cells.
    table : the analysis' ``PathTable`` the margins came from.
    overlay_tangential_stiffness, overlay_friction_angle : the values an overlay would hold
        (the determined ones, [N/m], [rad]); None: the configured value stays.
    """

    fit: CsmFit
    verdict: str
    configured_tangential_stiffness: float
    tangential_stiffness: float
    friction_angles: tuple[float, ...]
    groups: tuple[GroupAgreement, ...]
    folds: int
    members: tuple[np.ndarray, ...]
    table: Any
    overlay_tangential_stiffness: float | None
    overlay_friction_angle: float | None

    @property
    def cells(self) -> int:
        return sum(g.cells for g in self.groups)

    @property
    def end_agreement_configured(self) -> int:
        """Grasps ``/check_lift``'s end verdict gets right with the configured values."""
        return sum(g.configured_end for g in self.groups)

    @property
    def end_agreement_overlay(self) -> int:
        """The same with the overlay's values."""
        return sum(g.overlay_end for g in self.groups)

    @property
    def overlay_helps(self) -> bool:
        """Whether the overlay's values make ``/check_lift``'s end verdict agree with more of
        the grasps than the configured ones do (else the overlay writes nothing)."""
        return self.end_agreement_overlay > self.end_agreement_configured

    def boundary(self, friction_angle: float, delta_theta_p: float, object_mass: float,
                 gravity: float, k_range: tuple[float, float] = (1e-3, 1e3),
                 nodes: int = 361) -> float:
        """The fitted CSM's lift boundary: the lowest finger-1 ``k_theta`` [N*m/rad] of a
        log-spaced grid whose verdict (this calibration's, with its tangential stiffness) is
        a lift at ``friction_angle`` [rad] and ``delta_theta_p`` [rad]; NaN when none lifts."""
        k = np.geomspace(k_range[0], k_range[1], nodes)
        margins = CellMargins(self.table, k, np.full(nodes, delta_theta_p),
                              np.full(nodes, object_mass), gravity)
        lifts = margins.margins(friction_angle, self.tangential_stiffness, self.verdict) > 0.0
        return float(k[int(np.argmax(lifts))]) if lifts.any() else math.nan


def calibrate(cells: GraspCells, config: Any, verdict: str = 'path',
              fit_friction_angle: bool = True, lapse: float = DEFAULT_LAPSE,
              level: float = DEFAULT_LEVEL, folds: int = DEFAULT_FOLDS, seed: int = 0
              ) -> Calibration:
    """Fit the CSM to ``cells`` with the analysis of ``config`` (its object); see the module.

    Raises
    ------
    SweepPlotError
        ``folds`` is 1 or more than the cells, or the analysis refuses a cell.
    """
    from dam_analysis.errors import InputError  # noqa: PLC0415
    from dam_analysis.model import build_hand_model  # noqa: PLC0415 - slow import
    from dam_analysis.regions import PathTable  # noqa: PLC0415

    if folds < 0 or folds == 1 or folds > cells.size:
        raise SweepPlotError(f'folds {folds} must be 0 (none) or from 2 to the number of cells '
                             f'({cells.size})')
    try:
        table = PathTable(build_hand_model(config))
        margins = CellMargins(table, cells.k_theta, cells.delta_theta_p, cells.object_mass,
                              config.task.gravity_m_per_s2)
        cube = margin_cube(cells, margins, fit_friction_angle=fit_friction_angle,
                           verdict=verdict)
        fit = fit_outcomes(cube, cells.lifted, lapse=lapse, level=level)
    except InputError as exc:
        raise SweepPlotError(f'calibration: {exc}') from exc
    k_conf = float(config.contact.tangential_stiffness_n_per_m)
    k_fit = fit.tangential_stiffness(k_conf)
    angles = tuple(fit.friction_angle_of(a) for a in fit.recorded_friction_angle)
    held = np.full(cells.size, -1, dtype=int)  # held-out verdict per cell (1/0), -1 none
    if folds:
        order = np.random.default_rng(seed).permutation(cells.size)
        for part in np.array_split(order, folds):
            train = np.setdiff1d(order, part)
            sub = fit_outcomes(cube, cells.lifted, lapse=lapse, level=level, cells=train)
            k_sub = sub.tangential_stiffness(k_conf)
            for rec, members in zip(cube.recorded, cube.members, strict=True):
                test = np.intersect1d(members, part)
                if test.size == 0:
                    continue
                alpha = sub.friction_angle_of(rec)
                m = margins.margins(alpha, k_sub, verdict)
                held[test] = (m[test] > 0.0).astype(int)
    # the values an overlay would hold, and what /check_lift (end verdict) answers with them
    kt = fit.log10_tangential_stiffness
    k_overlay = 10.0 ** kt.estimate if kt.determined else None
    alpha_iv = fit.friction_angle[0]
    a_overlay = (alpha_iv.estimate if len(fit.friction_angle) == 1 and fit_friction_angle
                 and alpha_iv.determined else None)
    groups = []
    for rec, members, alpha in zip(cube.recorded, cube.members, angles, strict=True):
        truth = cells.lifted[members] > 0.5

        def agree(a: float, k_t: float, which: str, truth: np.ndarray = truth,
                  members: np.ndarray = members) -> tuple[int, np.ndarray]:
            lift = margins.margins(a, k_t, which)[members] > 0.0
            return int(np.sum(lift == truth)), lift

        fitted, fitted_lift = agree(alpha, k_fit, verdict)
        groups.append(GroupAgreement(
            recorded_deg=math.degrees(rec), cells=int(members.size),
            configured_end=agree(rec, k_conf, 'end')[0],
            configured_path=agree(rec, k_conf, 'path')[0], fitted=fitted,
            held_out=int(np.sum((held[members] == 1) == truth)) if folds else -1,
            fitted_lift=fitted_lift,
            overlay_end=agree(rec if a_overlay is None else a_overlay,
                              k_conf if k_overlay is None else k_overlay, 'end')[0]))
    return Calibration(fit=fit, verdict=verdict, configured_tangential_stiffness=k_conf,
                       tangential_stiffness=k_fit, friction_angles=angles,
                       groups=tuple(groups), folds=folds, members=cube.members, table=table,
                       overlay_tangential_stiffness=k_overlay,
                       overlay_friction_angle=a_overlay)


def grasps_for_width(cells: int, width: float, target: float) -> float:
    """Grasps an interval of ``target`` width needs, from one of ``width`` with ``cells``.

    A profile-likelihood interval narrows as ``1 / sqrt(n)`` (the Fisher information grows
    linearly with the number of grasps of the same design): ``n (width / target)^2``.
    """
    if not (math.isfinite(width) and width > 0.0 and target > 0.0):
        return math.nan
    return cells * (width / target) ** 2


def overlay(calibration: Calibration, config: Any, source: str, object_name: str) -> str:
    """The configuration overlay (YAML text) with the values the data determine.

    Only a parameter whose interval is closed on both sides is written (one the data bound on
    one side only, or not at all, keeps the configuration's value), and only when the written
    values make ``/check_lift``'s end verdict agree with more of the grasps than the
    configured ones (:attr:`Calibration.overlay_helps`; otherwise the overlay is ``{}``):
    the fitted effective tangential stiffness goes to the grasped object,
    ``object.library.<object_name>.csm_tangential_stiffness_n_per_m`` (the fit is of the
    series combination of the contact and the finger, for that object; the other objects and
    the stand-in keep the ``contact`` section); ``contact.friction_angle_deg`` is written only
    when the grasps hold one
    recorded friction angle (a sweep over several angles sets each). The comments say what
    was fitted, on which verdict and object, and what was left out.
    """
    fit = calibration.fit
    kt = fit.log10_tangential_stiffness
    helps = calibration.overlay_helps
    contact: dict[str, Any] = {}
    document: dict[str, Any] = {}
    if helps and calibration.overlay_tangential_stiffness is not None:
        value = float(f'{calibration.overlay_tangential_stiffness:.6g}')
        document['object'] = {'library': {object_name: {
            'csm_tangential_stiffness_n_per_m': value}}}
    alpha = fit.friction_angle[0]
    one_group = len(fit.friction_angle) == 1 and fit.fitted_friction_angle
    if helps and calibration.overlay_friction_angle is not None:
        contact['friction_angle_deg'] = float(
            f'{math.degrees(calibration.overlay_friction_angle):.6g}')
    lines = [
        '# CSM calibration overlay (calibrate_csm): merge it over the configuration with',
        '# load_config(path, [THIS]) or check_lift_server --ros-args -p config_overlay:=THIS.',
        f'# Fitted from {source}, object {object_name!r}: {counted(fit.cells, "grasp")}, verdict '
        f'{calibration.verdict!r}, {fit.level:.0%} profile-likelihood intervals.',
        f'# k_t [N/m]: {interval_text(kt, log10=True)} ({kt.status}).',
    ]
    for rec, iv in zip(fit.recorded_friction_angle, fit.friction_angle, strict=True):
        text = (f'{interval_text(iv, scale=180.0 / math.pi)} deg ({iv.status})'
                if fit.fitted_friction_angle else 'not fitted')
        lines.append(f'# friction angle recorded {math.degrees(rec):g} deg: {text}.')
    if not kt.determined:
        lines.append('# k_t is not determined by these grasps: the configured value stays.')
        if not kt.contains(math.log10(calibration.configured_tangential_stiffness)):
            lines.append(f'# (the configured k_t, '
                         f'{calibration.configured_tangential_stiffness:.4g} N/m, lies outside '
                         f'the interval: these grasps disagree with it)')
    if fit.fitted_friction_angle and not one_group:
        lines.append('# several recorded friction angles: contact.friction_angle_deg stays.')
    elif one_group and not alpha.determined:
        lines.append('# the friction angle is not determined by these grasps: the configured '
                     'value stays.')
    lines.append(f'# /check_lift (end verdict) agrees with {calibration.end_agreement_configured}'
                 f' of the {counted(calibration.cells, "grasp")} as configured, with '
                 f'{calibration.end_agreement_overlay} with the fitted values'
                 + ('.' if helps else ': no better, so none is written.'))
    if calibration.verdict == 'path':
        lines.append('# The values were fitted to the path verdict (/check_lift: csm_path_lift; '
                     '--verdict end fits csm_lift, the end verdict the overlay is judged by).')
    if contact:
        document['contact'] = contact
    body = yaml.safe_dump(document, sort_keys=False) if document else '{}\n'
    return '\n'.join(lines) + '\n' + body


def interval_text(interval: Any, scale: float = 1.0, log10: bool = False) -> str:
    """``estimate [low, high]`` of an :class:`~dam_analysis.csm_calibration.Interval`; an
    open side shows the end of the searched range (``<`` or ``>`` it), an estimate at an end
    of the range is marked, a parameter not determined says so. ``log10``: the values are
    logarithms, shown as powers of ten; ``scale`` multiplies them (e.g. rad to deg)."""
    def value(v: float) -> float:
        return 10.0 ** v if log10 else v * scale

    if math.isnan(interval.estimate):
        return (f'not determined in [{value(interval.grid_low):.4g}, '
                f'{value(interval.grid_high):.4g}]')
    low = (f'<{value(interval.grid_low):.4g}' if math.isinf(interval.low)
           else f'{value(interval.low):.4g}')
    high = (f'>{value(interval.grid_high):.4g}' if math.isinf(interval.high)
            else f'{value(interval.high):.4g}')
    edge = ' (at the end of the searched range)' if interval.at_grid_end else ''
    return f'{value(interval.estimate):.4g}{edge} [{low}, {high}]'
