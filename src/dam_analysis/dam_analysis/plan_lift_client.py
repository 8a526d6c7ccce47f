"""``plan_lift``: a command-line client of ``/plan_lift`` (the robust pair over ranges).

Examples::

    ros2 run dam_analysis plan_lift --friction-angle 3deg:6deg --mass 30g:50g \\
        --position-tolerance 1mm
    ros2 run dam_analysis plan_lift --friction-angle 5deg --k-theta-max 8 \\
        --delta-theta-p 5deg:30deg
    ros2 run dam_analysis plan_lift          # the configured friction angle, mass, position

Ranges are ``MIN:MAX`` or one value. Every angle, length and mass takes its unit
(``3deg``, ``0.05rad``, ``30g``, ``1mm``); a bare number is in SI units (rad, kg, m), as in every
command of the suite, and a bare number implausible for this hand is refused with what was
probably meant (:mod:`dam_common.quantities`). An option left out is left out of the request,
so the server uses its configuration for it (``PlanLift.srv``). Exit status: 0 when the server
answered ``ok`` (whether or not a pair is guaranteed), 2 when it rejected the request or an
argument is malformed, 1 when no answer came, 3 when SIGINT or SIGTERM stopped it first (at any
moment: no traceback; the entry point is ``dam_analysis.entry_points:plan_lift``).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence

from dam_analysis.service_call import call_and_print, user_args
from dam_common.command_line import CommandLineParser
from dam_common.quantities import (
    ANGLE,
    LEAVE_OUT,
    LENGTH,
    MASS,
    RIGHT_ANGLE,
    argument,
    number_argument,
)
from dam_interfaces.srv import PlanLift

PROG = 'plan_lift'


def build_parser() -> argparse.ArgumentParser:
    parser = CommandLineParser(
        prog=PROG,
        description='Ask /plan_lift for the (k_theta, delta_theta_p) pair that lifts the '
                    'object over ranges of friction angle, mass and position.')
    parser.add_argument('--friction-angle',
                        type=argument(ANGLE, low=0.0, why_low=LEAVE_OUT, form='range',
                                      high=RIGHT_ANGLE, high_inclusive=False),
                        default=None, metavar='ANGLE[:ANGLE]',
                        help='friction angle alpha range (3deg:6deg, 0.05rad:0.1rad; bare: rad; '
                             'default: the configured one)')
    parser.add_argument('--mass', type=argument(MASS, low=0.0, low_inclusive=False,
                                                why_low=LEAVE_OUT, form='range'),
                        default=None, metavar='MASS[:MASS]',
                        help='object mass range (30g:50g, 0.03kg:0.05kg; bare: kg; default: '
                             'the configured one)')
    parser.add_argument('--position-tolerance', type=argument(LENGTH, low=0.0, why_low=LEAVE_OUT),
                        default=None, metavar='LENGTH',
                        help="the object's position along the fingers within +-this (1mm, "
                             '0.001m; bare: m; default: 0, the configured position)')
    parser.add_argument('--k-theta-max',
                        type=number_argument(low=0.0, why_low=LEAVE_OUT, above=0.0,
                                             unit='N*m/rad', what='stiffness'),
                        default=None, metavar='N*m/rad',
                        help='largest finger-1 stiffness to propose (default: the largest '
                             'the device accepts)')
    parser.add_argument('--delta-theta-p',
                        type=argument(ANGLE, low=0.0, why_low=LEAVE_OUT, form='range',
                                      high=RIGHT_ANGLE),
                        default=None, metavar='ANGLE:ANGLE',
                        help='displacement range (5deg:40deg; bare: rad; default: all the '
                             'configuration allows)')
    parser.add_argument('--min-margin', type=number_argument(low=0.0, why_low=LEAVE_OUT),
                        default=None, metavar='N',
                        help='smallest worst-case margin a guaranteed pair keeps [N] '
                             '(default: 0.01)')
    parser.add_argument('--object', default='', metavar='NAME',
                        help='column object of the configuration\'s object.library (default: '
                             'the server\'s object.default)')
    parser.add_argument('--service', default='/plan_lift', help='service name')
    parser.add_argument('--timeout', type=number_argument(above=0.0, unit='s'), default=30.0,
                        metavar='S',
                        help='seconds to wait for the service and for the answer (a first '
                             'request with a position tolerance builds an analysis per node; '
                             'default: %(default)s)')
    return parser


def build_request(options: argparse.Namespace) -> PlanLift.Request:
    """The request of the options; an option left out keeps its field's default."""
    request = PlanLift.Request()
    if options.friction_angle is not None:
        request.friction_angle_min, request.friction_angle_max = options.friction_angle
    if options.mass is not None:
        request.mass_min, request.mass_max = options.mass
    if options.position_tolerance is not None:
        request.position_tolerance = float(options.position_tolerance)
    if options.k_theta_max is not None:
        request.k_theta_max = float(options.k_theta_max)
    if options.delta_theta_p is not None:
        request.delta_theta_p_min, request.delta_theta_p_max = options.delta_theta_p
    if options.min_margin is not None:
        request.min_margin = float(options.min_margin)
    request.object = options.object
    return request


def _pair(k_theta: float, delta_theta_p: float) -> str:
    return f'k_theta {k_theta:.4g} N*m/rad at delta_theta_p {math.degrees(delta_theta_p):.4g} deg'


def format_response(response: PlanLift.Response) -> str:
    """Human-readable rendering of a PlanLift answer."""
    if not response.ok:
        return f'REJECTED: {response.message}'
    lines = [f'object                    : {response.object}']
    if response.found:
        pair = _pair(response.k_theta, response.delta_theta_p)
        # the bound is exactly 0 for one position (no tolerance): nothing lies between positions
        between = (f' (at most {response.position_error_bound:.2g} N less between positions)'
                   if response.position_error_bound > 0.0 else '')
        lines.append(f'guaranteed (eq. 18)       : {pair}, worst-case margin '
                     f'{response.worst_case_margin:+.4g} N{between}')
    else:
        lines.append('guaranteed (eq. 18)       : none')
    if math.isfinite(response.best_worst_case_margin):
        lines.append(f'largest worst-case margin : '
                     f'{_pair(response.best_k_theta, response.best_delta_theta_p)}, '
                     f'{response.best_worst_case_margin:+.4g} N')
    if math.isfinite(response.csm_margin):
        domain = 'inside' if response.csm_in_domain else 'OUTSIDE'
        lines.append(f'contact stiffness model   : '
                     f'{_pair(response.csm_k_theta, response.csm_delta_theta_p)}, margin '
                     f'{response.csm_margin:+.4g} N ({domain} its domain)')
    lines.append(f'method: {response.method}')
    lines.append(response.message)
    return '\n'.join(lines)


def main(args: Sequence[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    options = build_parser().parse_args(user_args(PROG, argv))
    return call_and_print('plan_lift', argv, PlanLift, options.service, build_request(options),
                          options.timeout, format_response)


if __name__ == '__main__':
    sys.exit(main())
