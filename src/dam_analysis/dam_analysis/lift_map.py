"""``lift_map``: the k_theta - delta_theta_p lift map of Fig. 5(b) as a PNG and a CSV.

For each friction angle the tool draws both lower region boundaries ``k_theta*(delta_theta_p)``
(finger 1's stiffness; the other fingers follow the configured ratios): the sufficient condition
of eq. (18) as a thick line with its region hatched, and the contact stiffness model (CSM) as a
thin dashed line, one colour per friction angle. A dotted line is the hand's torque ceiling:
above it some finger's SPCM torque exceeds the torque limit (``/check_lift``: "exceeds the
torque limit"), so that part is shaded and not hatched. A boundary that stops inside the plot
ends in an ``x`` with a note (the SPCM branch ends, or no stiffness lifts beyond); an empty
region is named in the legend, with no line. Examples::

    ros2 run dam_analysis lift_map --friction-angles 1deg 5deg 30deg --out map.png
    ros2 run dam_analysis lift_map --friction-angles 5deg --n-delta-theta-p 400 \\
        --delta-theta-p-max 30deg --k-max 20 --out map5.png --csv map5.csv
    ros2 run dam_analysis lift_map --object square_bar --friction-angles 5deg --out bar.png

Friction angles and ``--delta-theta-p-max`` take their unit (``5deg``, ``0.09rad``); a bare number
is radians, as in every command of the suite, and one implausible as radians (``5``) is refused
with what was probably meant. The CSV has the columns ``alpha_deg, delta_theta_p_deg,
k_theta_sufficient, k_theta_csm, k_theta_torque_limit`` [deg, deg, N m/rad x 3]; an empty cell
means that no stiffness lifts the object there (including displacements beyond the end of the
SPCM branch). Exit status: 0 on success, 2 on bad arguments or configuration.
It needs no ROS: only the analysis core and matplotlib (Agg backend).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dam_analysis.analysis import LiftAnalyzer, unreachable_object
from dam_analysis.errors import NoSolutionError
from dam_analysis.regions import Boundaries
from dam_common.closed_output import quiet_when_output_closed
from dam_common.command_line import CommandLineParser
from dam_common.config import load_config
from dam_common.errors import ConfigError
from dam_common.picture import picture_path
from dam_common.progress import Progress
from dam_common.quantities import ANGLE, argument, in_degrees
from dam_common.ros_args import strip_ros_args

#: Smallest default top of the k_theta axis (and the value when nothing lifts) [N m/rad].
DEFAULT_K_MAX = 10.0
#: The default k_theta axis shows this multiple of the largest per-curve minimum ...
K_MIN_FACTOR = 3.0
#: ... but never more than this multiple of the largest finite boundary.
K_MAX_FACTOR = 1.5
CSV_COLUMNS = ('alpha_deg', 'delta_theta_p_deg', 'k_theta_sufficient', 'k_theta_csm',
               'k_theta_torque_limit')


def build_parser() -> argparse.ArgumentParser:
    parser = CommandLineParser(
        prog='lift_map',
        description='Plot the lift regions on the k_theta - delta_theta_p plane (Fig. 5(b)): '
                    'sufficient condition (eq. 18) and contact stiffness model.')
    parser.add_argument('--friction-angles', type=in_degrees(argument(ANGLE)), nargs='+',
                        required=True, metavar='ANGLE',
                        help='friction angles alpha, 0 <= alpha < 90 deg (5deg, 0.09rad; '
                             'bare: rad)')
    parser.add_argument('--out', type=picture_path, default=Path('lift_map.png'),
                        metavar='FILE',
                        help='output picture, its format by its extension (.png, .pdf, .svg, '
                             '.jpg, ...; default: %(default)s)')
    parser.add_argument('--csv', type=Path, default=None, metavar='CSV',
                        help='output table of the boundaries (default: --out with .csv)')
    parser.add_argument('--n-delta-theta-p', type=int, default=200, metavar='N',
                        help='number of delta_theta_p samples (default: %(default)s)')
    parser.add_argument('--delta-theta-p-max', type=in_degrees(argument(ANGLE)), default=None,
                        metavar='ANGLE',
                        help='largest delta_theta_p (30deg; bare: rad; default: the configured '
                             'maximum)')
    parser.add_argument('--k-max', type=float, default=None, metavar='N*m/rad',
                        help='top of the k_theta axis (default: from the boundaries, at least '
                             f'{DEFAULT_K_MAX:g}, see default_k_max)')
    parser.add_argument('--object', default='', metavar='NAME',
                        help='column object of the configuration\'s object.library (default: '
                             'object.default)')
    parser.add_argument('--config', type=Path, default=None, metavar='YAML',
                        help='configuration file (default: the installed config/dam.yaml)')
    return parser


def check_options(parser: argparse.ArgumentParser, options: argparse.Namespace) -> None:
    """Reject values argparse cannot check by type; ``parser.error`` exits with status 2."""
    for alpha in options.friction_angles:
        if not (math.isfinite(alpha) and 0.0 <= alpha < 90.0):
            parser.error(f'--friction-angles: {alpha:.4g} deg is outside [0, 90) deg')
    if options.n_delta_theta_p < 2:
        parser.error(f'--n-delta-theta-p: {options.n_delta_theta_p} must be at least 2')
    dp_max = options.delta_theta_p_max
    if dp_max is not None and not (math.isfinite(dp_max) and dp_max > 0.0):
        parser.error(f'--delta-theta-p-max: {dp_max:.4g} deg must be positive')
    k_max = options.k_max
    if k_max is not None and not (math.isfinite(k_max) and k_max > 0.0):
        parser.error(f'--k-max: {k_max:.4g} N*m/rad must be positive')


def compute_boundaries(analyzer: LiftAnalyzer, friction_angles_deg: Sequence[float],
                       delta_theta_p: np.ndarray, progress: bool = True) -> list[Boundaries]:
    """Region boundaries for each friction angle.

    Parameters
    ----------
    analyzer : analysis facade of the hand.
    friction_angles_deg : friction angles alpha [deg].
    delta_theta_p : (D,) position-joint displacements [rad], within the configured maximum.
    progress : print one line per friction angle to stderr, and while one takes longer than
        a few seconds a line every few seconds (:mod:`dam_common.progress`).

    Returns
    -------
    One :class:`Boundaries` per friction angle (k_theta* [N m/rad], NaN where nothing lifts).
    """
    out = []
    for j, alpha in enumerate(friction_angles_deg, start=1):
        start = time.perf_counter()
        with Progress('lift_map', f'alpha = {alpha:g} deg ({j}/{len(friction_angles_deg)})',
                      period=None if progress else 0.0):
            out.append(analyzer.boundaries(math.radians(alpha), delta_theta_p))
        if progress:
            print(f'lift_map: alpha = {alpha:g} deg ({j}/{len(friction_angles_deg)}) done in '
                  f'{time.perf_counter() - start:.2f} s', file=sys.stderr, flush=True)
    return out


def _cell(value: float) -> str:
    return repr(float(value)) if math.isfinite(value) else ''


def write_csv(path: Path, friction_angles_deg: Sequence[float],
              boundaries: Sequence[Boundaries], ceiling: np.ndarray | None = None) -> None:
    """Write the boundaries and the torque ceiling [deg, deg, N m/rad x 3] (:data:`CSV_COLUMNS`);
    empty cells where nothing lifts (or, for the ceiling, beyond the SPCM branch)."""
    with open(path, 'w', newline='') as stream:
        writer = csv.writer(stream, lineterminator='\n')
        writer.writerow(CSV_COLUMNS)
        for alpha, b in zip(friction_angles_deg, boundaries, strict=True):
            tops = np.full(b.delta_theta_p.shape, np.nan) if ceiling is None else ceiling
            for dp, ks, kc, kt in zip(np.degrees(b.delta_theta_p), b.sufficient, b.csm, tops,
                                      strict=True):
                writer.writerow((f'{alpha:g}', repr(float(dp)), _cell(ks), _cell(kc),
                                 _cell(kt)))


def torque_ceiling(analyzer: LiftAnalyzer, delta_theta_p: np.ndarray) -> np.ndarray:
    """The finger-1 stiffness [N m/rad] above which the SPCM torque ``|tau_s|`` of some finger
    exceeds the hand's torque limit, per displacement (:func:`~dam_analysis.scale_study.
    torque_stiffness`: under SPCM ``delta_theta_s`` does not depend on ``k_theta`` or the
    friction angle, so one curve serves every friction angle); NaN beyond the SPCM branch.

    Returns
    -------
    (D,) float64 array, the same the ``/check_lift`` answer's ``within_torque_limit`` flips at.
    """
    from dam_analysis.scale_study import torque_stiffness  # noqa: PLC0415

    return np.array([torque_stiffness(analyzer, float(dp)) for dp in delta_theta_p])


def default_k_max(boundaries: Sequence[Boundaries]) -> float:
    """Top of the k_theta axis [N m/rad].

    The boundaries diverge where a region ends (``k* -> inf`` at ``delta_theta_p -> 0`` and at
    the far end), so their maximum would squash the plot. The default shows
    ``max(DEFAULT_K_MAX, K_MIN_FACTOR x the largest per-curve minimum)``, capped at
    ``K_MAX_FACTOR x the largest finite boundary``; DEFAULT_K_MAX when nothing lifts.
    """
    curves = [c[np.isfinite(c)] for b in boundaries for c in (b.sufficient, b.csm)]
    curves = [c for c in curves if c.size]
    if not curves:
        return DEFAULT_K_MAX
    wanted = max(DEFAULT_K_MAX, K_MIN_FACTOR * max(float(c.min()) for c in curves))
    return min(wanted, K_MAX_FACTOR * max(float(c.max()) for c in curves))


def _curve_ends(k: np.ndarray) -> list[int]:
    """Indices of the last finite sample of each stretch of ``k`` that stops inside the
    plotted range (the next sample is NaN: no stiffness lifts from there on)."""
    finite = np.isfinite(k)
    return [int(i) for i in np.flatnonzero(finite[:-1] & ~finite[1:])]


def draw_map(ax, friction_angles_deg: Sequence[float], boundaries: Sequence[Boundaries],
             k_max: float, delta_theta_p_max: float, ceiling: np.ndarray | None = None,
             torque_limit: float = math.nan, branch_end_deg: float = math.inf) -> None:
    """Draw the lift map on the matplotlib axes ``ax``.

    Both boundaries per friction angle (sufficient: thick, its region hatched up to the torque
    ceiling; CSM: dashed); the torque ceiling dotted with what lies above it shaded (pairs the
    hand cannot drive: ``/check_lift`` says the torque limit is exceeded); an ``x`` and a note
    where a boundary stops inside the plot; a legend entry only for what is drawn.

    Parameters
    ----------
    k_max : top of the k_theta axis [N m/rad]; delta_theta_p_max : right end [deg].
    ceiling : (D,) torque ceiling [N m/rad] on the boundaries' displacements, or None.
    torque_limit : the hand's compliant torque limit [N m], for the legend.
    branch_end_deg : where the SPCM branch ends [deg], to say why a boundary stops there.
    """
    colours = ['#1f77b4', '#ff7f0e', '#2ca02c', '#d62728', '#9467bd', '#8c564b', '#e377c2']
    hatches = ('//', '\\\\', '||', '--', 'xx', '++')
    top = np.full(boundaries[0].delta_theta_p.shape, k_max) if boundaries else np.array([])
    if ceiling is not None and boundaries:
        dp = np.degrees(boundaries[0].delta_theta_p)
        top = np.where(np.isfinite(ceiling), np.minimum(ceiling, k_max), k_max)
        beyond = np.isfinite(ceiling) & (ceiling < k_max)
        if np.any(beyond):
            ax.fill_between(dp, top, k_max, where=beyond, facecolor='0.55', alpha=0.25,
                            linewidth=0.0)
        finite = ceiling[np.isfinite(ceiling)]
        if np.any(beyond):
            ax.plot(dp, ceiling, color='black', linewidth=1.2, linestyle=':',
                    label=f'torque ceiling |tau_s| = {torque_limit:g} N*m '
                          '(shaded above: beyond the hand)')
        elif finite.size:  # all of it above the plot: said, not drawn
            ax.plot([], [], ' ', label=f'torque ceiling |tau_s| = {torque_limit:g} N*m: above '
                                       f'the plot (from {finite.min():.3g} N*m/rad)')
    for j, (alpha, b) in enumerate(zip(friction_angles_deg, boundaries, strict=True)):
        colour = colours[j % len(colours)]
        dp = np.degrees(b.delta_theta_p)
        for name, k, width, style in (('sufficient (eq. 18)', b.sufficient, 2.6, '-'),
                                      ('CSM', b.csm, 1.1, '--')):
            short = 'sufficient' if name.startswith('sufficient') else name
            if not np.any(np.isfinite(k)):
                ax.plot([], [], ' ', label=f'alpha = {alpha:g} deg: {short} region empty')
                continue
            if not np.any(k[np.isfinite(k)] < k_max):  # all of it above the plot
                ax.plot([], [], ' ', label=f'alpha = {alpha:g} deg: {name}: above the plot '
                                           f'(from {np.nanmin(k):.3g} N*m/rad)')
                continue
            ax.plot(dp, k, color=colour, linewidth=width, linestyle=style,
                    label=f'alpha = {alpha:g} deg: {name}')
            for i in _curve_ends(k):
                if k[i] >= k_max:
                    continue  # it leaves through the top of the plot first
                why = ('the SPCM branch ends' if dp[i + 1] >= branch_end_deg - 1e-9
                       else 'no stiffness lifts beyond')
                ax.plot([dp[i]], [k[i]], marker='x', color=colour, markersize=7)
                left = dp[i] < 0.5 * delta_theta_p_max  # the note stays inside the axes
                ax.annotate(f'{short} ends at {dp[i]:.3g} deg: {why}', (dp[i], k[i]),
                            textcoords='offset points', xytext=(6 if left else -6, 6),
                            ha='left' if left else 'right', fontsize=6, color=colour,
                            bbox={'facecolor': 'white', 'edgecolor': 'none', 'alpha': 0.85,
                                  'pad': 0.6}, zorder=5)
        lifts = np.isfinite(b.sufficient) & (b.sufficient < top)
        if np.any(lifts):
            # margin = k_theta A - m_B g is increasing in k_theta: the region is above k*, up
            # to what the hand can drive
            ax.fill_between(dp, np.where(lifts, b.sufficient, top), top, where=lifts,
                            facecolor='none', edgecolor=colour, linewidth=0.0,
                            hatch=hatches[j % len(hatches)], alpha=0.6)
    if branch_end_deg < delta_theta_p_max:
        ax.axvspan(branch_end_deg, delta_theta_p_max, facecolor='white', edgecolor='0.7',
                   hatch='..', linewidth=0.0,
                   label=f'beyond the SPCM branch ({branch_end_deg:.3g} deg): nothing lifts')
    ax.set_xlim(0.0, delta_theta_p_max)
    ax.set_ylim(0.0, k_max)
    ax.set_xlabel('position-joint displacement delta_theta_p [deg]')
    ax.set_ylabel('compliant-joint stiffness k_theta (finger 1) [N m/rad]')
    ax.grid(True, alpha=0.3)
    # Below the axes: inside, it hid the curves' ends and their notes.
    ax.legend(fontsize=7, loc='upper center', bbox_to_anchor=(0.5, -0.12), ncol=2,
              frameon=False)


def plot_map(path: Path, friction_angles_deg: Sequence[float],
             boundaries: Sequence[Boundaries], k_max: float, delta_theta_p_max: float,
             object_text: str = '', ceiling: np.ndarray | None = None,
             torque_limit: float = math.nan, branch_end_deg: float = math.inf) -> None:
    """Draw the map (:func:`draw_map`) with its title; save it to ``path`` (the format its
    extension names: :mod:`dam_common.picture`).

    Parameters
    ----------
    object_text : the object, for the title (e.g. ``'square_bar: square, 16 mm across flats'``).
    The others as for :func:`draw_map`.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 6.4), dpi=120)
    draw_map(ax, friction_angles_deg, boundaries, k_max, delta_theta_p_max, ceiling,
             torque_limit, branch_end_deg)
    title = 'Lift regions (hatched: sufficient condition holds within the torque limit)'
    ax.set_title(f'{title}\n{object_text}' if object_text else title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)  # the format its extension names (dam_common.picture)
    plt.close(fig)


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; ``argv`` without the program name (``sys.argv[1:]`` if None)."""
    parser = build_parser()
    options = parser.parse_args(strip_ros_args(sys.argv[1:] if argv is None else argv))
    check_options(parser, options)
    try:
        config = load_config(options.config).with_object(options.object)
    except ConfigError as exc:
        print(f'lift_map: {exc}', file=sys.stderr)
        return 2
    config_max = math.degrees(config.task.delta_theta_p_max_rad)
    dp_max = config_max if options.delta_theta_p_max is None else options.delta_theta_p_max
    if dp_max > config_max + 1e-9:
        parser.error(f'--delta-theta-p-max: {dp_max:.4g} deg exceeds the configured maximum '
                     f'{config_max:.4g} deg')
    start = time.perf_counter()
    try:
        with Progress('lift_map', 'caching the SPCM paths'):  # a line every few seconds
            analyzer = LiftAnalyzer(config)
    except NoSolutionError as exc:
        print(f'lift_map: {unreachable_object(config, exc)}', file=sys.stderr)
        return 2
    print(f'lift_map: SPCM paths cached in {time.perf_counter() - start:.2f} s',
          file=sys.stderr, flush=True)
    dps = np.radians(np.linspace(0.0, dp_max, options.n_delta_theta_p))
    dps = np.minimum(dps, analyzer.model.delta_theta_p_max)
    boundaries = compute_boundaries(analyzer, options.friction_angles, dps)
    ceiling = torque_ceiling(analyzer, dps)
    branch_end = math.degrees(min(path.valid_until for path in analyzer.table.paths))
    csv_path = options.csv if options.csv is not None else options.out.with_suffix('.csv')
    k_max = options.k_max if options.k_max is not None else default_k_max(boundaries)
    try:
        write_csv(csv_path, options.friction_angles, boundaries, ceiling)
        plot_map(options.out, options.friction_angles, boundaries, k_max, dp_max,
                 f'{config.object.name}: {config.object.section.describe()}', ceiling,
                 analyzer.limits.torque_limit, branch_end)
    except OSError as exc:
        print(f'lift_map: cannot write output: {exc}', file=sys.stderr)
        return 1
    print(f'lift_map: wrote {options.out} and {csv_path}', file=sys.stderr)
    return 0


@quiet_when_output_closed  # `| head`: status 141, no traceback
def entry_point() -> None:
    sys.exit(main())


if __name__ == '__main__':
    entry_point()
