"""``ros2 run dam_experiments sweep_report DIR -o docs/results.md``: the results document.

::

    ros2 run dam_experiments sweep_report DIR [-o FILE.md] [--config YAML]

Reads what ``sweep`` wrote into ``DIR`` (a sweep still running or interrupted is reported as
far as it got, and the document says how many trials are present), computes the numbers
(:func:`dam_experiments.sweep_report.compute_report`) with the analysis of the configuration,
writes the Markdown document (:func:`dam_experiments.sweep_report_markdown.render_markdown`)
and its figures into a directory beside it named after it (``docs/results.md`` ->
``docs/results/fig7.png`` and ``docs/results/boundaries.png``, linked relatively), and prints a
short summary. Default output: ``DIR/results.md``.

Exit status: 0 written; 2 bad input (a missing directory, no ``trials.csv`` or ``sweep.json``,
an empty or malformed table, a column the report needs missing, a bad configuration, an
output that cannot be written), with one line on stderr naming the problem.
"""

from __future__ import annotations

import argparse
import math
import os
import shlex
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from dam_common.command_line import CommandLineParser
from dam_common.ros_args import strip_ros_args
from dam_common.words import counted
from dam_experiments.errors import SweepPlotError
from dam_experiments.sweep_plot import (
    CSM_LABEL,
    DEFAULT_BOUNDARY_POINTS,
    SUFFICIENT_LABEL,
    X_LABEL,
    Y_LABEL,
    k_limits,
    sweep_figure,
)
from dam_experiments.sweep_report import SweepReport, compute_report
from dam_experiments.sweep_report_markdown import decades, render_markdown, share
from dam_experiments.sweep_results import one_object, output_path, read_sweep
from dam_experiments.sweep_table import PARAMS_FILE, TABLE_FILE

PROG = 'sweep_report'
#: Document written into DIR when ``-o`` is not given.
DEFAULT_OUTPUT = 'results.md'
#: File names of the figures in the figure directory.
FIGURES = {'fig7': 'fig7.png', 'boundaries': 'boundaries.png'}


def figure_directory(output: Path) -> Path:
    """The directory of the document's figures: beside it, named after it without ``.md``."""
    return output.with_suffix('')


def check_output(output: Path) -> None:
    """Refuse an output the document or its figures cannot be written to.

    Raises
    ------
    SweepPlotError
        Not a ``.md`` name, a directory, a parent that is missing, not a directory or not
        writable, or a figure directory that exists as a file.
    """
    if output.suffix.lower() != '.md':
        raise SweepPlotError(f'output {str(output)!r}: the document must be a .md file')
    if output.is_dir():
        raise SweepPlotError(f'output {str(output)!r} is a directory')
    parent = output.parent
    if not parent.exists():
        raise SweepPlotError(f'output {str(output)!r}: directory {str(parent)!r} does not '
                             f'exist')
    if not parent.is_dir():
        raise SweepPlotError(f'output {str(output)!r}: {str(parent)!r} is not a directory')
    if not os.access(parent, os.W_OK) or (output.exists() and not os.access(output, os.W_OK)):
        raise SweepPlotError(f'output {str(output)!r} is not writable')
    figures = figure_directory(output)
    if figures.exists() and not figures.is_dir():
        raise SweepPlotError(f'output {str(output)!r}: its figure directory {str(figures)!r} '
                             f'exists and is not a directory')


def boundary_figure(report: SweepReport) -> Any:
    """The simulated boundary of every column against the analysis' boundaries.

    One panel per friction angle (``gid='alpha=<deg>'``): the dense eq. (18) and CSM
    boundaries (``gid='sufficient'``, ``'csm'``), the compared and uncompared columns' ``k_sim``
    with a bar from ``k_below`` to ``k_lift`` (``gid='k_sim'``), and the censored columns as
    triangles at the grid's edge (``gid='no_lift'`` up at the largest ``k_theta``,
    ``gid='lifts_lowest'`` down at the smallest).
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # noqa: PLC0415
    from matplotlib.figure import Figure  # noqa: PLC0415

    angles = report.angles
    ncols = min(len(angles), 3)
    nrows = math.ceil(len(angles) / ncols)
    fig = Figure(figsize=(5.0 * ncols + 2.6, 4.4 * nrows + 0.6), layout='constrained')
    FigureCanvasAgg(fig)
    panels = list(fig.subplots(nrows, ncols, squeeze=False, sharex=True, sharey=True).flat)
    for extra in panels[len(angles):]:
        fig.delaxes(extra)
    spec = report.data.spec
    k_min, k_max = min(spec.k_theta), max(spec.k_theta)
    for ax, a, b in zip(panels, angles, report.boundaries, strict=False):
        ax.set_gid(f'alpha={a.friction_angle_deg:g}')
        dp = np.degrees(b.delta_theta_p)
        for values, gid, style in ((b.sufficient, 'sufficient', {'linewidth': 2.0}),
                                   (b.csm, 'csm', {'linewidth': 1.3, 'linestyle': '--'})):
            values = np.asarray(values, dtype=float)
            ax.plot(dp, np.where(np.isfinite(values), values, np.nan), color='k', gid=gid,
                    label=SUFFICIENT_LABEL if gid == 'sufficient' else CSM_LABEL, **style)
        found = [c for c in a.columns if math.isfinite(c.k_sim)]
        if found:
            y = np.array([c.k_sim for c in found])
            err = np.array([[c.k_sim - c.k_below for c in found],
                            [c.k_lift - c.k_sim for c in found]])
            ax.errorbar([c.delta_theta_p_deg for c in found], y, yerr=err, fmt='o',
                        color='tab:blue', capsize=3, gid='k_sim',
                        label='simulated boundary k_sim (bar: k_below to k_lift)')
        for status, gid, marker, k, label in (
                ('no lift', 'no_lift', '^', k_max, 'no lift in the column'),
                ('lifts at the lowest k_theta', 'lifts_lowest', 'v', k_min,
                 'lifts at the lowest k_theta')):
            chosen = [c.delta_theta_p_deg for c in a.columns if c.status == status]
            if chosen:
                ax.scatter(chosen, [k] * len(chosen), marker=marker, color='tab:gray', s=40,
                           gid=gid, label=label, zorder=3)
        if report.log_k:
            ax.set_yscale('log')
        ax.set_xlim(0.0, report.dense_right_deg)
        ax.set_ylim(*k_limits(spec.k_theta, report.log_k))
        ax.set_title(rf'$\alpha$ = {a.friction_angle_deg:g} deg: median |d| '
                     f'{decades(a.median_distance_dec)} decades', fontsize=10)
        ax.set_xlabel(X_LABEL)
        ax.set_ylabel(Y_LABEL)
        ax.tick_params(labelbottom=True, labelleft=True)
        ax.grid(True, which='major', linewidth=0.3)
        ax.legend(fontsize=7, loc='upper right')
    shown = report.data.object_label
    fig.suptitle(f'{report.data.directory.name}: {shown + ": " if shown else ""}simulated lift '
                 f'boundary against the analysis',
                 fontsize=10)
    return fig


def write_report(report: SweepReport, output: Path, command: str, dpi: int = 120) -> list[Path]:
    """Write the figures and the document; return the files written (figures first).

    Raises
    ------
    SweepPlotError
        A file cannot be written.
    """
    figures_dir = figure_directory(output)
    written = []
    try:
        figures_dir.mkdir(exist_ok=True)
        note = '' if report.config_matches else ('\nboundaries of a configuration other than '
                                                 'the sweep\'s')
        for name, fig in (('fig7', sweep_figure(report.data, report.boundaries, report.log_k,
                                                note)),
                          ('boundaries', boundary_figure(report))):
            path = figures_dir / FIGURES[name]
            fig.savefig(path, dpi=dpi)
            written.append(path)
        links = {name: f'{figures_dir.name}/{file}' for name, file in FIGURES.items()}
        output.write_text(render_markdown(report, command, links), encoding='utf-8')
        written.append(output)
    except (OSError, ValueError) as exc:
        raise SweepPlotError(f'output {str(output)!r}: cannot write it: '
                             f'{" ".join(str(exc).split())}') from None
    return written


def summary_lines(report: SweepReport) -> list[str]:
    """The short summary printed after writing: the sweep, then one line per friction
    angle."""
    data = report.data
    shown = data.object_label
    lines = [f'{PROG}: {data.directory}: {shown + ", " if shown else ""}{report.n_present} of '
             f'{counted(data.n_planned, "trial")}, '
             f'{data.repeats} per cell' + ('' if report.complete else ' (incomplete)')]
    for a in report.angles:
        lines.append(
            f'  alpha {a.friction_angle_deg:g} deg: {counted(a.n_cells, "cell")}, '
            f'{a.n_lifting} lifting; '
            f'false guarantees {a.n_false_guarantees}; CSM agreement '
            f'{share(a.n_agree, a.n_cells)}'
            + ('' if a.n_path_agree is None else
               f', path verdict {share(a.n_path_agree, a.n_cells)}')
            + f'; boundary distance median '
            f'{decades(a.median_distance_dec)} decades over '
            f'{counted(a.n_compared, "column")}, within '
            f'one k step {a.n_within_step}; lifting without a guarantee '
            f'{share(a.n_missed, a.n_lifting)}'
            + ('' if a.sufficient_exists else '; no stiffness is guaranteed'))
    return lines


def _parse(argv: Sequence[str]) -> argparse.Namespace:
    p = CommandLineParser(
        prog=PROG,
        description='Write the results document of a sweep: false guarantees of the '
                    'sufficient condition, the CSM boundary against the simulated lift '
                    'boundary, the lift eq. 18 misses, and where simulation and analysis '
                    'disagree, as Markdown with its figures in a directory beside it.')
    p.add_argument('directory', type=Path, metavar='DIR',
                   help=f'a sweep --out directory ({TABLE_FILE}, {PARAMS_FILE})')
    p.add_argument('-o', '--output', type=Path, default=None, metavar='FILE.md',
                   help=f'the document (default: DIR/{DEFAULT_OUTPUT}, with --object '
                        f'DIR/results_NAME.md); its figures go into '
                        f'FILE/ beside it')
    p.add_argument('--config', type=Path, default=None, metavar='YAML',
                   help='configuration of the analysis: the sweep\'s (default: DAM_CONFIG or '
                        'the installed config/dam.yaml)')
    p.add_argument('--object', default=None, metavar='NAME',
                   help='the object to report on, of a sweep of several (one document per '
                        'object)')
    p.add_argument('--n-delta-theta-p', type=int, default=DEFAULT_BOUNDARY_POINTS, metavar='N',
                   help=f'delta_theta_p samples of the drawn boundaries (default '
                        f'{DEFAULT_BOUNDARY_POINTS})')
    p.add_argument('--dpi', type=int, default=120, help='resolution of the figures (default '
                                                        '120)')
    p.add_argument('--calibrate', action='store_true',
                   help='add section 6: the CSM calibrated on the sweep (calibrate_csm), its '
                        'agreement with the fitted parameters beside the configured ones')
    p.add_argument('--folds', type=int, default=5, metavar='K',
                   help='with --calibrate: folds of the held-out check (default 5; 0: none)')
    args = p.parse_args(argv)
    if args.n_delta_theta_p < 2:
        p.error(f'--n-delta-theta-p: {args.n_delta_theta_p} must be at least 2')
    if args.dpi < 1:
        p.error(f'--dpi: {args.dpi} must be positive')
    if args.folds < 0 or args.folds == 1:
        p.error(f'--folds: {args.folds} must be 0 or at least 2')
    return args


def _command(args: argparse.Namespace, output: Path) -> str:
    parts = ['ros2 run dam_experiments sweep_report', shlex.quote(str(args.directory)), '-o',
             shlex.quote(str(output))]
    if args.config is not None:
        parts += ['--config', shlex.quote(str(args.config))]
    if args.object is not None:
        parts += ['--object', shlex.quote(args.object)]
    if args.n_delta_theta_p != DEFAULT_BOUNDARY_POINTS:
        parts += ['--n-delta-theta-p', str(args.n_delta_theta_p)]
    if args.calibrate:
        parts += ['--calibrate'] + ([] if args.folds == 5 else ['--folds', str(args.folds)])
    return ' '.join(parts)


def main(argv: Sequence[str] | None = None) -> int:
    """``sweep_report``: write a sweep's results document; see the module docstring.

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
        report = compute_report(data, config, n_points=args.n_delta_theta_p,
                                calibrate_folds=args.folds if args.calibrate else None)
        written = write_report(report, output, _command(args, output), dpi=args.dpi)
    except (SweepPlotError, DamCommonError) as exc:
        sys.stderr.write(f'{PROG}: {" ".join(str(exc).split())}\n')
        return 2
    if not report.config_matches:
        sys.stderr.write(f'{PROG}: note: the configuration {str(config.source)!r} is not the '
                         f'sweep\'s (its config_sha256 differs): the analysis is this '
                         f'configuration\'s; pass the sweep\'s with --config\n')
    if data.lifted_note is not None:
        sys.stderr.write(f'{PROG}: note: {data.lifted_note}\n')
    print('\n'.join(summary_lines(report)))
    print(f'{PROG}: wrote {", ".join(str(p) for p in written)}', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
