"""``lift_map``: the k_theta - delta_theta_p lift map of Fig. 5(b) as a PNG and a CSV.

For each friction angle the tool draws both lower region boundaries ``k_theta*(delta_theta_p)``
(finger 1's stiffness; the other fingers follow the configured ratios): the sufficient condition
of eq. (18) as a thick line with its region hatched, and the contact stiffness model (CSM) as a
thin dashed line, one colour per friction angle. Examples::

    ros2 run dam_analysis lift_map --friction-angles 1deg 5deg 30deg --out map.png
    ros2 run dam_analysis lift_map --friction-angles 5deg --n-delta-theta-p 400 \\
        --delta-theta-p-max 30deg --k-max 20 --out map5.png --csv map5.csv
    ros2 run dam_analysis lift_map --object square_bar --friction-angles 5deg --out bar.png

Friction angles and ``--delta-theta-p-max`` take their unit (``5deg``, ``0.09rad``); a bare number
is radians, as in every command of the suite, and one implausible as radians (``5``) is refused
with what was probably meant. The CSV has the columns
``alpha_deg, delta_theta_p_deg, k_theta_sufficient, k_theta_csm`` [deg, deg, N m/rad, N m/rad];
an empty cell means that no stiffness lifts the object there (including displacements beyond the
end of the SPCM branch). Exit status: 0 on success, 2 on bad arguments or configuration.
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
from dam_common.command_line import CommandLineParser
from dam_common.config import load_config
from dam_common.errors import ConfigError
from dam_common.quantities import ANGLE, argument, in_degrees
from dam_common.ros_args import strip_ros_args

#: Smallest default top of the k_theta axis (and the value when nothing lifts) [N m/rad].
DEFAULT_K_MAX = 10.0
#: The default k_theta axis shows this multiple of the largest per-curve minimum ...
K_MIN_FACTOR = 3.0
#: ... but never more than this multiple of the largest finite boundary.
K_MAX_FACTOR = 1.5
CSV_COLUMNS = ('alpha_deg', 'delta_theta_p_deg', 'k_theta_sufficient', 'k_theta_csm')


def build_parser() -> argparse.ArgumentParser:
    parser = CommandLineParser(
        prog='lift_map',
        description='Plot the lift regions on the k_theta - delta_theta_p plane (Fig. 5(b)): '
                    'sufficient condition (eq. 18) and contact stiffness model.')
    parser.add_argument('--friction-angles', type=in_degrees(argument(ANGLE)), nargs='+',
                        required=True, metavar='ANGLE',
                        help='friction angles alpha, 0 <= alpha < 90 deg (5deg, 0.09rad; '
                             'bare: rad)')
    parser.add_argument('--out', type=Path, default=Path('lift_map.png'), metavar='PNG',
                        help='output image (default: %(default)s)')
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
            parser.error(f'--friction-angles: {alpha:g} deg is outside [0, 90) deg')
    if options.n_delta_theta_p < 2:
        parser.error(f'--n-delta-theta-p: {options.n_delta_theta_p} must be at least 2')
    dp_max = options.delta_theta_p_max
    if dp_max is not None and not (math.isfinite(dp_max) and dp_max > 0.0):
        parser.error(f'--delta-theta-p-max: {dp_max:g} deg must be positive')
    k_max = options.k_max
    if k_max is not None and not (math.isfinite(k_max) and k_max > 0.0):
        parser.error(f'--k-max: {k_max:g} N*m/rad must be positive')


def compute_boundaries(analyzer: LiftAnalyzer, friction_angles_deg: Sequence[float],
                       delta_theta_p: np.ndarray, progress: bool = True) -> list[Boundaries]:
    """Region boundaries for each friction angle.

    Parameters
    ----------
    analyzer : analysis facade of the hand.
    friction_angles_deg : friction angles alpha [deg].
    delta_theta_p : (D,) position-joint displacements [rad], within the configured maximum.
    progress : print one line per friction angle to stderr.

    Returns
    -------
    One :class:`Boundaries` per friction angle (k_theta* [N m/rad], NaN where nothing lifts).
    """
    out = []
    for j, alpha in enumerate(friction_angles_deg, start=1):
        start = time.perf_counter()
        out.append(analyzer.boundaries(math.radians(alpha), delta_theta_p))
        if progress:
            print(f'lift_map: alpha = {alpha:g} deg ({j}/{len(friction_angles_deg)}) done in '
                  f'{time.perf_counter() - start:.2f} s', file=sys.stderr, flush=True)
    return out


def _cell(value: float) -> str:
    return repr(float(value)) if math.isfinite(value) else ''


def write_csv(path: Path, friction_angles_deg: Sequence[float],
              boundaries: Sequence[Boundaries]) -> None:
    """Write the boundaries [deg, deg, N m/rad, N m/rad]; empty cells where nothing lifts."""
    with open(path, 'w', newline='') as stream:
        writer = csv.writer(stream, lineterminator='\n')
        writer.writerow(CSV_COLUMNS)
        for alpha, b in zip(friction_angles_deg, boundaries, strict=True):
            for dp, ks, kc in zip(np.degrees(b.delta_theta_p), b.sufficient, b.csm,
                                  strict=True):
                writer.writerow((f'{alpha:g}', repr(float(dp)), _cell(ks), _cell(kc)))


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


def plot_map(path: Path, friction_angles_deg: Sequence[float],
             boundaries: Sequence[Boundaries], k_max: float, delta_theta_p_max: float,
             object_text: str = '') -> None:
    """Draw the boundaries and hatch the sufficient regions; save to ``path``.

    Parameters
    ----------
    k_max : top of the k_theta axis [N m/rad]; delta_theta_p_max : right end [deg].
    object_text : the object, for the title (e.g. ``'square_bar: square, 16 mm across flats'``).
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5.0), dpi=120)
    colours = plt.rcParams['axes.prop_cycle'].by_key()['color']
    hatches = ('//', '\\\\', '||', '--', 'xx', '++')
    for j, (alpha, b) in enumerate(zip(friction_angles_deg, boundaries, strict=True)):
        colour = colours[j % len(colours)]
        dp = np.degrees(b.delta_theta_p)
        ax.plot(dp, b.sufficient, color=colour, linewidth=2.6,
                label=f'alpha = {alpha:g} deg: sufficient (eq. 18)')
        ax.plot(dp, b.csm, color=colour, linewidth=1.1, linestyle='--',
                label=f'alpha = {alpha:g} deg: CSM')
        lifts = np.isfinite(b.sufficient) & (b.sufficient < k_max)
        if np.any(lifts):
            # margin = k_theta A - m_B g is increasing in k_theta: the region is above k*
            ax.fill_between(dp, np.where(lifts, b.sufficient, k_max), k_max, where=lifts,
                            facecolor='none', edgecolor=colour, linewidth=0.0,
                            hatch=hatches[j % len(hatches)], alpha=0.6)
        elif not np.any(np.isfinite(b.sufficient)):
            ax.plot([], [], ' ', label=f'alpha = {alpha:g} deg: sufficient region empty')
    ax.set_xlim(0.0, delta_theta_p_max)
    ax.set_ylim(0.0, k_max)
    ax.set_xlabel('position-joint displacement delta_theta_p [deg]')
    ax.set_ylabel('compliant-joint stiffness k_theta (finger 1) [N m/rad]')
    title = 'Lift regions (hatched: sufficient condition holds)'
    ax.set_title(f'{title}\n{object_text}' if object_text else title, fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc='upper right')
    fig.tight_layout()
    fig.savefig(path, format='png')
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
        parser.error(f'--delta-theta-p-max: {dp_max:g} deg exceeds the configured maximum '
                     f'{config_max:g} deg')
    start = time.perf_counter()
    try:
        analyzer = LiftAnalyzer(config)
    except NoSolutionError as exc:
        print(f'lift_map: {unreachable_object(config, exc)}', file=sys.stderr)
        return 2
    print(f'lift_map: SPCM paths cached in {time.perf_counter() - start:.2f} s',
          file=sys.stderr, flush=True)
    dps = np.radians(np.linspace(0.0, dp_max, options.n_delta_theta_p))
    dps = np.minimum(dps, analyzer.model.delta_theta_p_max)
    boundaries = compute_boundaries(analyzer, options.friction_angles, dps)
    csv_path = options.csv if options.csv is not None else options.out.with_suffix('.csv')
    k_max = options.k_max if options.k_max is not None else default_k_max(boundaries)
    try:
        write_csv(csv_path, options.friction_angles, boundaries)
        plot_map(options.out, options.friction_angles, boundaries, k_max, dp_max,
                 f'{config.object.name}: {config.object.section.describe()}')
    except OSError as exc:
        print(f'lift_map: cannot write output: {exc}', file=sys.stderr)
        return 1
    print(f'lift_map: wrote {options.out} and {csv_path}', file=sys.stderr)
    return 0


def entry_point() -> None:
    sys.exit(main())


if __name__ == '__main__':
    entry_point()
