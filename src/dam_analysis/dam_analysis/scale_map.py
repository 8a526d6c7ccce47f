"""``scale_map``: for which object sizes does DAM work with this hand?

Draws the lift boundaries ``k_theta*`` (finger 1's stiffness) against the object's size (a
cylinder's radius, another column's half height: ``--object NAME``, scaled uniformly) at
chosen displacements (:mod:`dam_analysis.scale_study`): the sufficient condition of eq. (18) as
a solid line, the contact stiffness model dashed, and dotted the stiffness above which the
hand cannot give the SPCM torque. Examples::

    ros2 run dam_analysis scale_map --radius-range 3mm:20mm:35 \\
        --delta-theta-p 10deg 20deg 30deg --friction-angle 5deg --out scale.png
    ros2 run dam_analysis scale_map --radius-range 5mm:15mm:11 --delta-theta-p 15deg \\
        --constant-mass --csv scale.csv
    ros2 run dam_analysis scale_map --object hex_pencil --radius-range 3mm:12mm:10 \\
        --delta-theta-p 10deg --out pencil.png

Radii are ``START:STOP:COUNT``; lengths and angles take their units (``3mm``, ``10deg``), and a
bare number is in SI units (m, rad) as in every command of the suite; one implausible for this
hand (a radius of 3 m) is refused with what was probably meant. The CSV has the columns
``radius_mm`` (``half_height_mm`` for a column that is not a cylinder)``, mass_kg,
delta_theta_p_deg, k_theta_sufficient, k_theta_csm, k_theta_torque_limit, no_first_contact``
[mm, kg, deg, N m/rad x 3, text]; an
empty stiffness cell means none lifts there (or no first contact, then the last column says
why). The summary printed at the end gives, per displacement, the radii at which the
sufficient condition (and the CSM) lifts within the hand's torque. Exit status: 0 written, 1
cannot write, 2 bad arguments or configuration. No ROS needed.
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from dam_analysis.errors import DamAnalysisError
from dam_analysis.scale_study import ScaleStudy, scale_study, size_name, working_ranges
from dam_common.closed_output import quiet_when_output_closed
from dam_common.command_line import CommandLineParser
from dam_common.config import load_config
from dam_common.errors import ConfigError
from dam_common.picture import picture_path
from dam_common.quantities import ANGLE, LENGTH, argument
from dam_common.ros_args import strip_ros_args

CSV_COLUMNS = ('radius_mm', 'mass_kg', 'delta_theta_p_deg', 'k_theta_sufficient', 'k_theta_csm',
               'k_theta_torque_limit', 'no_first_contact')
#: Most radii one run takes (each builds the analysis, about 0.5 s).
MAX_RADII = 400
_RADII = argument(LENGTH, low=0.0, low_inclusive=False, form='linspace', max_count=MAX_RADII)


def parse_radius_range(text: str) -> np.ndarray:
    """``'3mm:20mm:35'`` -> radii [m]: ``COUNT`` values evenly from START to STOP, each a
    positive length (a bare number is metres, :mod:`dam_common.quantities`).

    Raises
    ------
    argparse.ArgumentTypeError
        Not START:STOP:COUNT, a radius that is not a positive length (or a bare number
        implausible in metres), ``COUNT`` not a whole number in [1, MAX_RADII], ``STOP <
        START``, or ``COUNT`` 1 with ``START != STOP``.
    """
    return _RADII(text)


def build_parser() -> argparse.ArgumentParser:
    parser = CommandLineParser(
        prog='scale_map',
        description='Lift boundaries k_theta* against the object size (scale-dependent '
                    'grasp): sufficient condition (eq. 18), contact stiffness model and the '
                    "hand's torque limit.")
    parser.add_argument('--radius-range', type=parse_radius_range, required=True,
                        metavar='START:STOP:COUNT',
                        help='sizes (3mm:20mm:35; bare: m): cylinder radii, or half heights '
                             'of another column (its centroid\'s height on the table)')
    parser.add_argument('--object', default='', metavar='NAME',
                        help='column object of the configuration\'s object.library to scale '
                             '(default: object.default)')
    parser.add_argument('--delta-theta-p', type=argument(ANGLE, low=0.0, low_inclusive=False),
                        nargs='+', required=True, metavar='ANGLE',
                        help='position-joint displacements (10deg, 0.1745rad; bare: rad)')
    parser.add_argument('--friction-angle', type=argument(ANGLE, low=0.0), default=None,
                        metavar='ANGLE',
                        help='friction angle alpha (5deg, 0.09rad; bare: rad; default: the '
                             'configured one)')
    parser.add_argument('--constant-mass', action='store_true',
                        help='keep the configured mass (default: scale it with the '
                             'cross-section, same density and length)')
    parser.add_argument('--out', type=picture_path, default=Path('scale_map.png'),
                        metavar='FILE',
                        help='output picture, its format by its extension (.png, .pdf, .svg, '
                             '.jpg, ...; default: %(default)s)')
    parser.add_argument('--csv', type=Path, default=None, metavar='CSV',
                        help='output table (default: --out with .csv)')
    parser.add_argument('--config', type=Path, default=None, metavar='YAML',
                        help='configuration file (default: the installed config/dam.yaml)')
    return parser


def _cell(value: float) -> str:
    return _number(value) if math.isfinite(value) else ''


def _number(value: float) -> str:
    """12 significant digits: no float noise from degree and millimetre conversions."""
    return f'{float(value):.12g}'


def write_csv(path: Path, study: ScaleStudy) -> None:
    """One row per radius and displacement (:data:`CSV_COLUMNS`)."""
    columns = CSV_COLUMNS if study.size_name == 'radius' else (
        'half_height_mm', *CSV_COLUMNS[1:])
    with open(path, 'w', newline='', encoding='utf-8') as stream:
        writer = csv.writer(stream, lineterminator='\n')
        writer.writerow(columns)
        for j, radius in enumerate(study.radius):
            for d, dp in enumerate(study.delta_theta_p):
                writer.writerow((_number(radius * 1e3), _number(study.mass[j]),
                                 _number(math.degrees(dp)), _cell(study.k_sufficient[j, d]),
                                 _cell(study.k_csm[j, d]), _cell(study.k_torque[j, d]),
                                 study.no_contact[j]))


def plot_study(path: Path, study: ScaleStudy) -> None:
    """Boundaries over radius [mm] on a logarithmic stiffness axis; radii without a first
    contact shaded grey."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(10.0, 5.0), dpi=120)
    colours = plt.rcParams['axes.prop_cycle'].by_key()['color']
    r_mm = study.radius * 1e3
    for d, dp in enumerate(study.delta_theta_p):
        colour = colours[d % len(colours)]
        label = f'delta_theta_p = {math.degrees(dp):g} deg'
        # markers too: a radius alone (or between two without a value) has no line; a curve
        # with no value at all has a legend entry saying so, and no line
        for values, name, width, style, marker, size in (
                (study.k_sufficient[:, d], 'sufficient (eq. 18)', 2.4, '-', 'o', 4),
                (study.k_csm[:, d], 'CSM', 1.1, '--', 's', 3),
                (study.k_torque[:, d], f'torque limit {study.torque_limit:g} N*m', 1.1, ':',
                 'v', 3)):
            if not np.any(np.isfinite(values)):
                ax.plot([], [], ' ', label=f'{label}: {name}: none in this range')
                continue
            ax.plot(r_mm, values, color=colour, linewidth=width, linestyle=style,
                    marker=marker, markersize=size, label=f'{label}: {name}')
    step = float(np.min(np.diff(r_mm))) if r_mm.size > 1 else 1.0
    shaded = False
    for j, reason in enumerate(study.no_contact):
        if reason:
            ax.axvspan(r_mm[j] - step / 2, r_mm[j] + step / 2, color='0.85', linewidth=0.0,
                       label=None if shaded else 'no first contact')
            shaded = True
    values = np.concatenate([a[np.isfinite(a)] for a in (study.k_sufficient, study.k_csm,
                                                         study.k_torque)])
    if values.size:
        ax.set_yscale('log')
        ax.set_ylim(values.min() / 1.5, values.max() * 1.5)
    ax.set_xlim(r_mm.min() - step / 2, r_mm.max() + step / 2)
    ax.set_xlabel('cylinder radius R [mm]' if study.size_name == 'radius' else
                  f'{study.object_name} half height h [mm] (centroid resting on the table)')
    ax.set_ylabel('compliant-joint stiffness k_theta* (finger 1) [N m/rad]')
    mass = ('mass kept' if study.constant_mass else 'mass at the same density')
    ax.set_title(f'DAM over the size of {study.object_name}, alpha = '
                 f'{math.degrees(study.friction_angle):g} deg, '
                 f'{mass}\nlifts above a boundary; the hand gives the torque below the dotted '
                 'line', fontsize=10)
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.01, 1.0))  # outside the curves
    fig.tight_layout()
    fig.savefig(path)  # the format its extension names (dam_common.picture)
    plt.close(fig)


def summary_lines(study: ScaleStudy) -> list[str]:
    """Per displacement, the radius runs [mm] where each boundary lifts within the torque."""
    def runs_text(runs: list[tuple[float, float]]) -> str:
        if not runs:
            return f'no {study.size_name}'
        return ', '.join(f'{a * 1e3:g} mm' if a == b else f'{a * 1e3:g}-{b * 1e3:g} mm'
                         for a, b in runs)

    lines = []
    for d, (suf, csm) in enumerate(zip(working_ranges(study, 'sufficient'),
                                       working_ranges(study, 'csm'), strict=True)):
        lines.append(f'delta_theta_p {math.degrees(study.delta_theta_p[d]):g} deg: within '
                     f'{study.torque_limit:g} N*m, guaranteed (sufficient condition) at '
                     f'{runs_text(suf)}; CSM lift at {runs_text(csm)}')
    reasons: dict[str, list[str]] = {}
    for radius, why in zip(study.radius, study.no_contact, strict=True):
        if why:
            reasons.setdefault(why.split(': ', 1)[-1], []).append(f'{radius * 1e3:g}')
    for why, radii in reasons.items():
        lines.append(f'no first contact at {study.size_name} {", ".join(radii)} mm: {why}')
    return lines


def main(argv: Sequence[str] | None = None) -> int:
    """Run the tool; ``argv`` without the program name (``sys.argv[1:]`` if None)."""
    parser = build_parser()
    options = parser.parse_args(strip_ros_args(sys.argv[1:] if argv is None else argv))
    try:
        config = load_config(options.config).with_object(options.object)
    except ConfigError as exc:
        print(f'scale_map: {exc}', file=sys.stderr)
        return 2
    alpha = (config.contact.friction_angle_rad if options.friction_angle is None
             else options.friction_angle)
    csv_path = options.csv if options.csv is not None else options.out.with_suffix('.csv')
    for path in (options.out, csv_path):  # before a minute of work, not after
        if not path.parent.is_dir():
            parser.error(f'{path}: the directory {str(path.parent)!r} does not exist')

    def progress(j: int, radius: float, reason: str) -> None:
        note = f': no first contact ({reason})' if reason else ''
        print(f'scale_map: {size_name(config.object.section)} {radius * 1e3:g} mm '
              f'({j + 1}/{options.radius_range.size}){note}', file=sys.stderr, flush=True)

    try:
        study = scale_study(config, options.radius_range,
                            np.asarray(options.delta_theta_p), alpha,
                            constant_mass=options.constant_mass, progress=progress)
    except DamAnalysisError as exc:
        parser.error(str(exc))
    try:
        write_csv(csv_path, study)
        plot_study(options.out, study)
    except OSError as exc:
        print(f'scale_map: cannot write output: {exc}', file=sys.stderr)
        return 1
    for line in summary_lines(study):
        print(line)
    print(f'scale_map: wrote {options.out} and {csv_path}', file=sys.stderr)
    return 0


@quiet_when_output_closed  # `| head`: status 141, no traceback
def entry_point() -> None:
    sys.exit(main())


if __name__ == '__main__':
    entry_point()
