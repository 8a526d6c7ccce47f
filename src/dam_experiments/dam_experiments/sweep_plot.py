"""``ros2 run dam_experiments sweep_plot DIR -o fig7.png``: a sweep drawn as the paper's Fig. 7.

::

    ros2 run dam_experiments sweep_plot DIR [-o fig7.png] [--config YAML]

Reads what ``sweep`` (:mod:`dam_experiments.sweep_cli`) wrote into ``DIR`` (``trials.csv`` and
``sweep.json``, :func:`dam_experiments.sweep_results.read_sweep`; a sweep still running or
interrupted is drawn as far as it got) and draws one panel per friction angle of the table: x
the position-joint displacement ``delta_theta_p`` [deg], y the finger-1 compliant stiffness
``k_theta`` [N*m/rad] (a log axis when the sweep's ``k_theta`` axis was given as a log range).
Without repeats every trial is one of the paper's three markers, from the controller's
classification (column ``outcome``): ``x`` FAILURE, triangle LIFTED_DAM_FAILED (lifted, no
enveloping grasp), ``o`` SUCCESS; a square ring marks a trial whose ground truth (column
``lifted``: the object left the table during the grasp) disagrees with that classification.
With repeats every cell is a square coloured by its lift probability (ground truth, share of
its trials that lifted) with a colour bar. Over both, the analysis' lower boundaries
``k_theta*(delta_theta_p)`` at the panel's friction angle
(:func:`dam_analysis.lift_map.compute_boundaries`): the sufficient condition (eq. 18) as a
solid line, the contact stiffness model (CSM) dashed. The boundaries are those of the configuration
given with ``--config`` (default: ``DAM_CONFIG`` or the installed ``config/dam.yaml``, as for
``sweep``); ``sweep.json`` records only the SHA-256 of the sweep's configuration, and a
configuration with another digest is named on stderr and in the picture's title.

A short summary goes to stdout: per friction angle the trials, how many lifted (ground truth:
left the table during the grasp) and how many of them were off the table at the end, the
outcome counts and the lowest boundary values. A table of format 2 (its ``lifted`` meant off
the table at the end; ``lifted`` is read from its lift-off times) or of format 1 (its
``lifted`` the old 5 mm rule) is drawn with a note on stderr and in the title.

Exit status: 0 drawn; 2 bad input (a missing directory, no ``trials.csv`` or ``sweep.json``,
an empty or malformed table, a bad configuration, an output that cannot be written), with one
line on stderr naming the problem. No rclpy: numpy, the analysis and matplotlib (Agg canvas).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from dam_common.command_line import CommandLineParser
from dam_common.picture import picture_path
from dam_common.ros_args import strip_ros_args
from dam_common.words import counted
from dam_experiments.errors import SweepPlotError
from dam_experiments.sweep import config_digest
from dam_experiments.sweep_results import (
    OUTCOMES,
    SweepData,
    analysis_config,
    k_axis_is_log,
    one_object,
    output_path,
    read_sweep,
)
from dam_experiments.sweep_table import PARAMS_FILE, TABLE_FILE, outcome_counts

PROG = 'sweep_plot'
#: Picture written into DIR when ``-o`` is not given.
DEFAULT_OUTPUT = 'fig7.png'
#: Default number of ``delta_theta_p`` samples of the boundaries.
DEFAULT_BOUNDARY_POINTS = 200
#: Legend text of each class.
CLASS_LABELS = {'FAILURE': 'failure', 'LIFTED_DAM_FAILED': 'lifted, DAM failed',
                'SUCCESS': 'success'}
_CLASS_STYLES: dict[str, dict[str, Any]] = {
    'FAILURE': {'marker': 'x', 'color': 'tab:red', 'filled': True},
    'LIFTED_DAM_FAILED': {'marker': '^', 'color': 'tab:orange', 'filled': False},
    'SUCCESS': {'marker': 'o', 'color': 'tab:green', 'filled': False},
}
DISAGREE_LABEL = 'outcome disagrees with the ground truth (left the table)'
SUFFICIENT_LABEL = 'sufficient condition (eq. 18)'
CSM_LABEL = 'contact stiffness model (CSM)'
P_LIFT_LABEL = 'lift probability per cell (ground truth) [-]'
X_LABEL = r'position-joint displacement $\Delta\theta_p$ [deg]'
Y_LABEL = r'compliant-joint stiffness $k_\theta$ (finger 1) [N*m/rad]'
#: Right end of the x axis: this multiple of the sweep's largest ``delta_theta_p``.
X_PAD = 1.1
#: The k_theta axis spans the sweep's values times / divided by this factor (log axis) ...
K_PAD_LOG = 1.6
#: ... or from 0 to this multiple of the largest value (linear axis).
K_PAD_LINEAR = 1.1
K_SCALES = ('auto', 'log', 'linear')


# ------------------------------------------------------------------------------------------
# Boundaries and limits


def boundary_grid_deg(delta_theta_p_deg: Sequence[float], delta_theta_p_max_deg: float,
                      n: int) -> np.ndarray:
    """Displacements at which the boundaries are drawn [deg].

    ``numpy.linspace(0, min(X_PAD * max(delta_theta_p_deg), delta_theta_p_max_deg), n)``:
    the x axis of the picture, within the configured maximum (the analysis' domain).
    """
    right = min(X_PAD * max(delta_theta_p_deg), float(delta_theta_p_max_deg))
    return np.linspace(0.0, right, int(n))


def k_limits(k_theta: Sequence[float], log: bool) -> tuple[float, float]:
    """Limits of the k_theta axis [N*m/rad]: the sweep's values divided and multiplied by
    ``K_PAD_LOG`` (log), or 0 to ``K_PAD_LINEAR`` times the largest (linear)."""
    if log:
        return min(k_theta) / K_PAD_LOG, max(k_theta) * K_PAD_LOG
    return 0.0, max(k_theta) * K_PAD_LINEAR


def sweep_boundaries(data: SweepData, analyzer: Any, n: int = DEFAULT_BOUNDARY_POINTS
                     ) -> list[Any]:
    """The analysis' boundaries for the sweep's friction angles and ``delta_theta_p`` range.

    Parameters
    ----------
    data
        The sweep.
    analyzer
        ``dam_analysis.analysis.LiftAnalyzer`` of the configuration.
    n
        Samples of :func:`boundary_grid_deg`.

    Returns
    -------
    list of dam_analysis.regions.Boundaries
        One per :attr:`SweepData.friction_angles_deg` (``delta_theta_p`` [rad],
        ``k_theta*`` [N*m/rad], NaN where no stiffness lifts).
    """
    from dam_analysis.lift_map import compute_boundaries  # noqa: PLC0415 - slow import

    grid = boundary_grid_deg(data.spec.delta_theta_p_deg,
                             math.degrees(analyzer.model.delta_theta_p_max), n)
    return compute_boundaries(analyzer, data.friction_angles_deg, np.radians(grid),
                              progress=False)


def _finite(values: np.ndarray) -> np.ndarray:
    """``values`` with every non-finite entry as NaN (a gap in the line)."""
    values = np.asarray(values, dtype=float)
    return np.where(np.isfinite(values), values, np.nan)


def _lowest(b: Any, field: str) -> tuple[float, float] | None:
    """The lowest ``k_theta*`` of a boundary [N*m/rad] and where [deg]; None if none."""
    values = np.asarray(getattr(b, field), dtype=float)
    finite = np.isfinite(values)
    if not finite.any():
        return None
    j = int(np.nanargmin(np.where(finite, values, np.nan)))
    return float(values[j]), math.degrees(float(b.delta_theta_p[j]))


def _outside_notes(b: Any, y_lim: tuple[float, float]) -> list[str]:
    """Notes for boundaries that exist but lie wholly above or below the k_theta axis."""
    notes = []
    for field, name in (('sufficient', 'eq. 18'), ('csm', 'CSM')):
        values = np.asarray(getattr(b, field), dtype=float)
        finite = values[np.isfinite(values)]
        if finite.size == 0:
            continue
        if finite.min() > y_lim[1]:
            notes.append(f'{name} boundary above the plotted range '
                         f'(lowest k_theta* {finite.min():.3g} N*m/rad)')
        elif finite.max() < y_lim[0]:
            notes.append(f'{name} boundary below the plotted range '
                         f'(highest k_theta* {finite.max():.3g} N*m/rad)')
    return notes


# ------------------------------------------------------------------------------------------
# The picture


def _class_kwargs(outcome: str) -> dict[str, Any]:
    style = _CLASS_STYLES[outcome]
    if style['filled']:
        return {'marker': style['marker'], 'color': style['color'], 'linewidths': 1.4}
    return {'marker': style['marker'], 'facecolors': 'none', 'edgecolors': style['color'],
            'linewidths': 1.4}


def _legend_handles(probability: bool, disagreement: bool) -> list[Any]:
    from matplotlib.lines import Line2D  # noqa: PLC0415

    handles = []
    if not probability:
        for outcome in OUTCOMES:
            style = _CLASS_STYLES[outcome]
            handles.append(Line2D([], [], linestyle='none', marker=style['marker'],
                                  color=style['color'], markersize=7,
                                  markerfacecolor=style['color'] if style['filled'] else 'none',
                                  label=f'{CLASS_LABELS[outcome]} ({outcome})'))
        if disagreement:
            handles.append(Line2D([], [], linestyle='none', marker='s', markersize=11,
                                  markerfacecolor='none', markeredgecolor='tab:purple',
                                  label=DISAGREE_LABEL))
    handles.append(Line2D([], [], color='k', linewidth=2.0, label=SUFFICIENT_LABEL))
    handles.append(Line2D([], [], color='k', linewidth=1.3, linestyle='--', label=CSM_LABEL))
    return handles


def sweep_figure(data: SweepData, boundaries: Sequence[Any], log_k: bool,
                 title_note: str = '') -> Any:
    """Draw the sweep into a new matplotlib Figure (Agg canvas) and return it.

    One Axes per friction angle of :attr:`SweepData.friction_angles_deg` (in that order,
    ``gid='alpha=<deg>'``), then, with repeats, the colour bar's Axes. In each panel:
    without repeats one scatter collection per class (``gid='outcome:<OUTCOME>'``, one point
    per trial at ``(delta_theta_p [deg], k_theta [N*m/rad])``) and, when some trial's ground
    truth disagrees with its class, ``gid='disagree'``; with repeats one collection
    ``gid='p_lift'`` (one square per cell, its array the cells' lift probabilities, colour
    limits 0 and 1); the boundary lines ``gid='sufficient'`` (solid) and ``gid='csm'``
    (dashed): x :func:`boundary_grid_deg` [deg], y ``k_theta*`` [N*m/rad] with non-finite
    values as NaN. The legend (the three classes, the ring and the two boundaries) belongs to
    the last panel of the first row, outside it on the right.

    Parameters
    ----------
    data
        The sweep.
    boundaries
        :func:`sweep_boundaries` of it, one per friction angle.
    log_k
        A log k_theta axis.
    title_note
        Appended to the title (e.g. that the configuration differs from the sweep's).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415

    alphas = data.friction_angles_deg
    probability = data.repeats > 1
    ncols = min(len(alphas), 3)
    nrows = math.ceil(len(alphas) / ncols)
    fig = Figure(figsize=(5.0 * ncols + (1.0 if probability else 0.0) + 2.6, 4.4 * nrows + 0.6),
                 layout='constrained')
    FigureCanvasAgg(fig)
    grid = fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=True)
    panels = list(grid.flat)
    for extra in panels[len(alphas):]:
        fig.delaxes(extra)
    x_max = X_PAD * max(data.spec.delta_theta_p_deg)
    y_lim = k_limits(data.spec.k_theta, log_k)
    mappable = None
    disagreement = False
    for ax, alpha, b in zip(panels, alphas, boundaries, strict=False):
        ax.set_gid(f'alpha={alpha:g}')
        trials = data.at(alpha)
        if probability:
            cells = data.cells(alpha)
            mappable = ax.scatter([c.delta_theta_p_deg for c in cells],
                                  [c.k_theta for c in cells], c=[c.p_lift for c in cells],
                                  cmap='RdYlGn', vmin=0.0, vmax=1.0, marker='s', s=70,
                                  edgecolors='0.35', linewidths=0.5, gid='p_lift', zorder=2)
        else:
            for outcome in OUTCOMES:
                chosen = [t for t in trials if t.outcome == outcome]
                ax.scatter([t.delta_theta_p_deg for t in chosen], [t.k_theta for t in chosen],
                           s=42, gid=f'outcome:{outcome}', zorder=3,
                           label=f'{CLASS_LABELS[outcome]} ({outcome})',
                           **_class_kwargs(outcome))
            odd = [t for t in trials if t.disagrees]
            if odd:
                disagreement = True
                ax.scatter([t.delta_theta_p_deg for t in odd], [t.k_theta for t in odd],
                           marker='s', s=130, facecolors='none', edgecolors='tab:purple',
                           linewidths=1.0, gid='disagree', zorder=4, label=DISAGREE_LABEL)
        dp = np.degrees(b.delta_theta_p)
        ax.plot(dp, _finite(b.sufficient), color='k', linewidth=2.0, gid='sufficient',
                label=SUFFICIENT_LABEL, zorder=5)
        ax.plot(dp, _finite(b.csm), color='k', linewidth=1.3, linestyle='--', gid='csm',
                label=CSM_LABEL, zorder=5)
        if _lowest(b, 'sufficient') is None:
            ax.text(0.03, 0.03, 'sufficient condition: no k_theta guaranteed here',
                    transform=ax.transAxes, fontsize=7, color='0.3', gid='no_sufficient')
        notes = _outside_notes(b, y_lim)
        if notes:
            ax.text(0.03, 0.97, '\n'.join(notes), transform=ax.transAxes, fontsize=7,
                    color='0.3', va='top', gid='outside')
        if log_k:
            ax.set_yscale('log')
        ax.set_xlim(0.0, x_max)
        ax.set_ylim(*y_lim)
        ax.set_title(rf'$\alpha$ = {alpha:g} deg ({counted(len(trials), "trial")})', fontsize=10)
        ax.set_xlabel(X_LABEL)
        ax.set_ylabel(Y_LABEL)
        ax.tick_params(labelbottom=True, labelleft=True)
        ax.grid(True, which='major', linewidth=0.3)
    # beside the first row, clear of the markers (constrained layout makes room for it)
    panels[ncols - 1].legend(handles=_legend_handles(probability, disagreement), fontsize=8,
                             loc='upper left', bbox_to_anchor=(1.03, 1.0), borderaxespad=0.0)
    if mappable is not None:
        fig.colorbar(mappable, ax=panels[:len(alphas)], label=P_LIFT_LABEL, shrink=0.9)
    n = len(data.trials)
    done = (counted(n, 'trial') if n == data.n_planned else
            f'{n} of {counted(data.n_planned, "trial")}')
    per_cell = f', {data.repeats} per cell' if probability else ''
    shown = data.object_label
    fig.suptitle(f'{data.directory.name}: {shown + ", " if shown else ""}{done}{per_cell}: '
                 f'k_theta - delta_theta_p map (paper Fig. 7){title_note}', fontsize=10)
    return fig


# ------------------------------------------------------------------------------------------
# The summary and the whole command


#: The summary's words for the outcomes.
_OUTCOME_WORDS = {'SUCCESS': 'success', 'LIFTED_DAM_FAILED': 'lifted but DAM failed',
                  'FAILURE': 'failure'}


def summary_lines(data: SweepData, boundaries: Sequence[Any], log_k: bool) -> list[str]:
    """The text summary: the sweep, then per friction angle the trials, how many lifted
    (ground truth) and how many were off the table at the end (format 2 on), the outcome
    counts and the lowest boundary values."""
    n = len(data.trials)
    shown = data.object_label
    lines = [f'{PROG}: {data.directory}: {shown + ", " if shown else ""}{n} of '
             f'{counted(data.n_planned, "trial")}, {data.repeats} per '
             f'cell, k_theta axis {"log" if log_k else "linear"}'
             + (f' ({counted(data.skipped, "incomplete row")} left out)' if data.skipped else '')]
    word = ('lifted (left the table)' if data.lift_off_recorded
            else 'lifted (format 1: the old rise rule)')
    for alpha, b in zip(data.friction_angles_deg, boundaries, strict=True):
        trials = data.at(alpha)
        lifted = sum(t.lifted for t in trials)
        held = (f', off the table at the end {sum(bool(t.off_table_at_end) for t in trials)}'
                if data.lift_off_recorded else '')
        bounds = []
        for name, field in (('sufficient condition', 'sufficient'), ('CSM', 'csm')):
            low = _lowest(b, field)
            missing = 'is guaranteed' if field == 'sufficient' else 'lifts'
            bounds.append(f'{name} lowest k_theta* {low[0]:.3g} N*m/rad at {low[1]:.3g} deg'
                          if low else f'{name}: no k_theta {missing}')
        counts = outcome_counts(((t.outcome, bool(t.lifted)) for t in trials), _OUTCOME_WORDS)
        lines.append(f'  alpha {alpha:g} deg: {counted(len(trials), "trial")}, {word} {lifted} '
                     f'({100.0 * lifted / len(trials):.0f} %){held}, {counts}; '
                     + '; '.join(bounds))
    odd = sum(t.disagrees for t in data.trials)
    if odd:
        lines.append(f'{PROG}: {counted(odd, "trial")} '
                     'where the ground truth (lifted: left the table) '
                     f'disagrees with the controller\'s outcome')
    return lines


@dataclass(frozen=True)
class PlotResult:
    """What :func:`plot_sweep` made.

    Attributes
    ----------
    figure
        The matplotlib Figure (:func:`sweep_figure`).
    data
        The sweep read.
    boundaries
        The analysis' boundaries, one per friction angle.
    log_k
        Whether the k_theta axis is logarithmic.
    summary
        The text summary (:func:`summary_lines`).
    config_matches
        Whether the configuration's digest equals ``sweep.json``'s ``config_sha256``.
    """

    figure: Any
    data: SweepData
    boundaries: list[Any]
    log_k: bool
    summary: list[str]
    config_matches: bool


def check_output(path: Path) -> None:
    """Refuse an output the picture cannot be written to, before anything is computed.

    Raises
    ------
    SweepPlotError
        An unknown picture format (by the suffix), a directory, or a parent that is missing,
        not a directory or not writable.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415

    if path.is_dir():
        raise SweepPlotError(f'output {str(path)!r} is a directory')
    formats = FigureCanvasAgg(Figure()).get_supported_filetypes()
    suffix = path.suffix.lower().lstrip('.')
    if suffix not in formats:
        raise SweepPlotError(f'output {str(path)!r}: unknown picture format {suffix!r} '
                             f'(name it by its suffix: {", ".join(sorted(formats))})')
    parent = path.parent
    if not parent.exists():
        raise SweepPlotError(f'output {str(path)!r}: directory {str(parent)!r} does not exist')
    if not parent.is_dir():
        raise SweepPlotError(f'output {str(path)!r}: {str(parent)!r} is not a directory')
    if not os.access(parent, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise SweepPlotError(f'output {str(path)!r} is not writable')


def plot_sweep(sweep: SweepData | str | os.PathLike[str],
               output: str | os.PathLike[str] | None = None, config: Any = None,
               analyzer: Any = None,
               n_points: int = DEFAULT_BOUNDARY_POINTS, k_scale: str = 'auto',
               dpi: int = 120) -> PlotResult:
    """Read a sweep directory, compute the boundaries, draw and (if ``output``) save.

    Parameters
    ----------
    sweep
        The ``sweep --out`` directory, or what :func:`read_sweep` read from it.
    output
        Picture file (PNG, PDF, SVG, ... by its suffix); None: not saved.
    config
        ``DamConfig`` of the boundaries; None: the default configuration.
    analyzer
        A ``LiftAnalyzer`` of ``config`` to reuse (built when None).
    n_points
        Samples of the boundaries (at least 2).
    k_scale
        ``'auto'`` (:func:`k_axis_is_log`), ``'log'`` or ``'linear'``.
    dpi
        Resolution of a raster picture [dots per inch].

    Raises
    ------
    SweepPlotError
        Bad input (see :func:`read_sweep`, :func:`check_output`) or the picture cannot be
        written.
    """
    if k_scale not in K_SCALES:
        raise SweepPlotError(f'k_scale {k_scale!r} must be one of {", ".join(K_SCALES)}')
    if n_points < 2:
        raise SweepPlotError(f'n_points {n_points} must be at least 2')
    data = sweep if isinstance(sweep, SweepData) else read_sweep(sweep)
    data = one_object(data, None)
    out = Path(output) if output is not None else None
    if out is not None:
        check_output(out)
    if config is None:
        from dam_common.config import load_config  # noqa: PLC0415

        config = load_config()
    matches = data.parameters.get('config_sha256') == config_digest(config)
    config = analysis_config(data, config)
    if analyzer is None:
        from dam_analysis.analysis import LiftAnalyzer  # noqa: PLC0415 - slow import

        analyzer = LiftAnalyzer(config)
    log_k = k_axis_is_log(data.parameters) if k_scale == 'auto' else k_scale == 'log'
    boundaries = sweep_boundaries(data, analyzer, n_points)
    note = '' if matches else '\nboundaries of a configuration other than the sweep\'s'
    if data.table_format == 1:
        note += '\nlifted: the old 5 mm rule (a table of format 1), not lift-off'
    elif data.table_format == 2:
        note += '\nlifted: from the lift-off times (a table of format 2)'
    figure = sweep_figure(data, boundaries, log_k, note)
    if out is not None:
        try:
            figure.savefig(out, dpi=dpi)
        except (OSError, ValueError) as exc:
            raise SweepPlotError(f'output {str(out)!r}: cannot write the picture: '
                                 f'{" ".join(str(exc).split())}') from None
    return PlotResult(figure, data, boundaries, log_k,
                      summary_lines(data, boundaries, log_k), matches)


def _parse(argv: Sequence[str]) -> argparse.Namespace:
    p = CommandLineParser(
        prog=PROG,
        description='Draw a sweep directory as the paper\'s Fig. 7: per friction angle the '
                    'trials on the delta_theta_p - k_theta plane (x failure, triangle lifted '
                    'but DAM failed, o success; with repeats the lift probability per cell), '
                    'the sufficient boundary (eq. 18, solid) and the CSM boundary (dashed). '
                    'Prints a summary per friction angle.')
    p.add_argument('directory', type=Path, metavar='DIR',
                   help=f'a sweep --out directory ({TABLE_FILE}, {PARAMS_FILE})')
    p.add_argument('-o', '--output', type=picture_path, default=None, metavar='FILE',
                   help=f'picture, PNG, PDF, SVG, JPG ... by its suffix (another is refused; '
                        f'default: DIR/{DEFAULT_OUTPUT}, '
                        f'with --object DIR/fig7_NAME.png)')
    p.add_argument('--config', type=Path, default=None, metavar='YAML',
                   help='configuration of the boundaries: the sweep\'s (default: DAM_CONFIG or '
                        'the installed config/dam.yaml)')
    p.add_argument('--object', default=None, metavar='NAME',
                   help='the object to draw, of a sweep of several (one picture per object)')
    p.add_argument('--k-scale', choices=K_SCALES, default='auto',
                   help='k_theta axis (default auto: log when the sweep\'s k_theta axis was a '
                        'log range)')
    p.add_argument('--n-delta-theta-p', type=int, default=DEFAULT_BOUNDARY_POINTS, metavar='N',
                   help=f'delta_theta_p samples of the boundaries (default '
                        f'{DEFAULT_BOUNDARY_POINTS})')
    p.add_argument('--dpi', type=int, default=120, help='resolution of a PNG (default 120)')
    args = p.parse_args(argv)
    if args.n_delta_theta_p < 2:
        p.error(f'--n-delta-theta-p: {args.n_delta_theta_p} must be at least 2')
    if args.dpi < 1:
        p.error(f'--dpi: {args.dpi} must be positive')
    return args


def main(argv: Sequence[str] | None = None) -> int:
    """``sweep_plot``: draw a sweep directory; see the module docstring for the exit status.

    Parameters
    ----------
    argv
        Arguments without the program name (``sys.argv[1:]`` when None); ROS arguments
        (``--ros-args ... [--]``) are dropped.
    """
    from dam_common.config import load_config  # noqa: PLC0415
    from dam_common.errors import DamCommonError  # noqa: PLC0415

    args = _parse(strip_ros_args(sys.argv[1:] if argv is None else argv))
    output = output_path(args.output, args.directory, DEFAULT_OUTPUT, args.object)
    try:
        data = one_object(read_sweep(args.directory), args.object)  # named before the config
        check_output(output)
        config = load_config(args.config)
        result = plot_sweep(data, output, config=config,
                            n_points=args.n_delta_theta_p, k_scale=args.k_scale, dpi=args.dpi)
    except (SweepPlotError, DamCommonError) as exc:
        sys.stderr.write(f'{PROG}: {" ".join(str(exc).split())}\n')
        return 2
    if data.lifted_note is not None:
        sys.stderr.write(f'{PROG}: note: {data.lifted_note}\n')
    if not result.config_matches:
        sys.stderr.write(f'{PROG}: note: the configuration {str(config.source)!r} is not the '
                         f'sweep\'s (its config_sha256 differs): the boundaries are this '
                         f'configuration\'s; pass the sweep\'s with --config\n')
    print('\n'.join(result.summary))
    print(f'{PROG}: wrote {output}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
