"""``ros2 run dam_analysis csm_dependence -o csm_dependence.png``: what the CSM boundary
depends on.

Draws the CSM's lower boundary ``k_theta*(delta_theta_p)`` (the smallest finger-1 stiffness
the CSM lifts with, :func:`dam_analysis.regions.region_boundaries`) for several effective
tangential stiffnesses ``k_t`` (the contact's in series with the finger's,
``contact.series_stiffness_n_per_m``) at each of the given friction angles, and prints the
boundary at a few displacements. The normal stiffness enters no boundary (the SPCM geometry is
rigid, ``docs/analysis.md`` section 4) and the boundary is proportional to the object's weight
(``k* = m_B g / B(delta_theta_p)`` where every contact slides), so neither gets a panel.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence
from pathlib import Path

from dam_common.command_line import CommandLineParser
from dam_common.picture import picture_path
from dam_common.quantities import ANGLE, argument, in_degrees, number_argument
from dam_common.ros_args import strip_ros_args

PROG = 'csm_dependence'
DEFAULT_K_T = (10.0, 30.0, 100.0, 300.0, 1e3, 1e5)


def build_parser() -> argparse.ArgumentParser:
    p = CommandLineParser(prog=PROG, description='Draw the CSM lift boundary for several '
                                                 'tangential stiffnesses and friction angles.')
    p.add_argument('-o', '--out', type=picture_path, default=Path('csm_dependence.png'),
                   metavar='FILE', help='the figure, its format by its extension (.png, .pdf, '
                                        '.svg, ...; default csm_dependence.png)')
    p.add_argument('--config', type=Path, default=None, metavar='YAML',
                   help='configuration (default: DAM_CONFIG or the installed config/dam.yaml)')
    p.add_argument('--object', default='', metavar='NAME', help='object of the library')
    p.add_argument('--friction-angles', type=in_degrees(argument(ANGLE)), nargs='+',
                   default=[5.0, 30.0], metavar='ANGLE',
                   help='friction angles alpha, 0 <= alpha < 90 deg, one panel each (5deg, '
                        '0.09rad; bare: rad; default 5deg 30deg)')
    p.add_argument('--k-t', type=number_argument(above=0.0, unit='N/m', what='stiffness'),
                   nargs='+',
                   default=list(DEFAULT_K_T), metavar='N_PER_M',
                   help='effective tangential stiffnesses [N/m] (default 10 30 100 300 1000 '
                        '1e5)')
    return p


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; ``argv`` without the program name (``sys.argv[1:]`` if None)."""
    parser = build_parser()
    options = parser.parse_args(strip_ros_args(sys.argv[1:] if argv is None else argv))
    if any(not 0.0 <= a < 90.0 for a in options.friction_angles):
        parser.error(f'--friction-angles: each must lie in [0, 90) deg, got '
                     f'{", ".join(f"{a:g}deg" for a in options.friction_angles)}')
    if options.out.suffix.lower() != '.png':
        parser.error(f'{options.out}: the figure must be a .png file')
    if not options.out.parent.is_dir():
        parser.error(f'{options.out}: the directory {str(options.out.parent)!r} does not exist')
    import numpy as np  # noqa: PLC0415 - after the signal handlers (entry_points)

    from dam_common.config import load_config  # noqa: PLC0415
    from dam_common.errors import ConfigError  # noqa: PLC0415

    try:
        config = load_config(options.config).with_object(options.object)
    except ConfigError as exc:
        print(f'{PROG}: {exc}', file=sys.stderr)
        return 2
    import matplotlib  # noqa: PLC0415

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt  # noqa: PLC0415

    from dam_analysis.model import build_hand_model  # noqa: PLC0415
    from dam_analysis.regions import PathTable, region_boundaries  # noqa: PLC0415

    table = PathTable(build_hand_model(config))
    dp = np.radians(np.linspace(1.0, math.degrees(table.model.delta_theta_p_max), 60))
    fig, axes = plt.subplots(1, len(options.friction_angles), squeeze=False,
                             figsize=(5.5 * len(options.friction_angles), 4.2))
    for ax, alpha_deg in zip(axes[0], options.friction_angles, strict=True):
        for k_t in options.k_t:
            b = region_boundaries(table, math.radians(alpha_deg), dp, tangential_stiffness=k_t)
            ax.semilogy(np.degrees(dp), b.csm, label=f'k_t = {k_t:g} N/m')
            at = [f'{float(np.interp(math.radians(d), dp, b.csm)):.3g}' for d in (10, 20, 30)]
            print(f'{PROG}: alpha {alpha_deg:g} deg, k_t {k_t:g} N/m: k* at 10/20/30 deg = '
                  f'{", ".join(at)} N*m/rad')
        ax.set_title(f'alpha = {alpha_deg:g} deg, {config.object.name}')
        ax.set_xlabel('delta_theta_p [deg]')
        ax.set_ylabel('CSM boundary k_theta* [N*m/rad]')
        ax.grid(True, which='both', alpha=0.3)
        ax.legend(fontsize=8)
    fig.tight_layout()
    try:
        fig.savefig(options.out, dpi=110)  # the format its extension names
    except OSError as exc:
        print(f'{PROG}: cannot write {options.out}: {exc}', file=sys.stderr)
        return 1
    print(f'{PROG}: wrote {options.out}', file=sys.stderr)
    return 0


if __name__ == '__main__':
    sys.exit(main())
