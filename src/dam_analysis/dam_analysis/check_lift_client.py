"""``check_lift``: a small command-line client of ``/check_lift`` for users without ``ros2``.

Examples::

    ros2 run dam_analysis check_lift --k-theta 0.5 --delta-theta-p 40deg
    ros2 run dam_analysis check_lift --k-theta 0.5 0.25 0.25 --delta-theta-p 0.7 \\
        --friction-angle 5deg
    ros2 run dam_analysis check_lift        # the server's configured task pair
    ros2 run dam_analysis check_lift --object square_bar --delta-theta-p 20deg

Angles take a unit suffix ``deg`` or ``rad``; a bare number is radians, as in every command of
the suite (:mod:`dam_common.quantities`). An option left out
is left out of the request, so the server uses its configuration for it (``CheckLift.srv``).
Exit status: 0 when the server answered ``ok`` (also "no lift" beyond the end of the SPCM
branch), 2 when it rejected the request, 1 when no answer came, 3 when SIGINT or SIGTERM
stopped it first (at any moment: no traceback; the entry point is
``dam_analysis.entry_points:check_lift``).
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Sequence

from dam_analysis.service_call import call_and_print, user_args
from dam_common.command_line import CommandLineParser
from dam_common.quantities import ANGLE, LEAVE_OUT, RIGHT_ANGLE, argument, number_argument
from dam_interfaces.srv import CheckLift

PROG = 'check_lift'


def build_parser() -> argparse.ArgumentParser:
    parser = CommandLineParser(
        prog=PROG,
        description='Ask /check_lift whether a (k_theta, delta_theta_p) pair lifts the object.')
    parser.add_argument('--k-theta', type=number_argument(above=0.0, unit='N*m/rad',
                                                         what='stiffness'), nargs='+',
                        default=[], metavar='N*m/rad',
                        help='compliant-joint stiffness: one value (finger 1, the others from '
                             'the configured ratios) or one per finger (default: the server\'s '
                             'configured task.k_theta_nm_per_rad)')
    parser.add_argument('--delta-theta-p',
                        type=argument(ANGLE, low=0.0, low_inclusive=False, high=RIGHT_ANGLE),
                        nargs='+', default=[],
                        metavar='ANGLE',
                        help='position-joint displacement (40deg, 0.7rad; bare: rad): one for '
                             'all fingers or one per finger (default: the server\'s configured '
                             'task.delta_theta_p_deg)')
    parser.add_argument('--friction-angle', type=argument(ANGLE, low=0.0, why_low=LEAVE_OUT,
                                                          high=RIGHT_ANGLE,
                                                          high_inclusive=False),
                        default=None, metavar='ANGLE',
                        help='friction angle alpha (5deg, 0.09rad; bare: rad; default: the '
                             'server\'s configured value)')
    parser.add_argument('--object', default='', metavar='NAME',
                        help='column object of the configuration\'s object.library (default: '
                             'the server\'s object.default)')
    parser.add_argument('--service', default='/check_lift', help='service name')
    parser.add_argument('--timeout', type=number_argument(above=0.0, unit='s'), default=10.0,
                        metavar='S',
                        help='seconds to wait for the service and for the answer (default: '
                             '%(default)s)')
    return parser


def _newtons(value: float) -> str:
    """A margin [N]; NaN (no contact state, or a contact that opens) as 'none'."""
    return 'none (see below)' if math.isnan(value) else f'{value:+.4g} N'


def format_response(request: CheckLift.Request, response: CheckLift.Response) -> str:
    """Human-readable rendering of a CheckLift answer."""
    if not response.ok:
        return f'REJECTED: {response.message}'
    yes_no = {True: 'yes', False: 'no'}
    configured = 'configured on the server'
    k_text = ', '.join(f'{v:g}' for v in request.k_theta) or configured
    dp_text = ', '.join(f'{math.degrees(v):.4g}' for v in request.delta_theta_p) or configured
    lines = [
        f'object                   : {response.object}',
        f'k_theta         [N*m/rad]: {k_text}',
        f'delta_theta_p   [deg]    : {dp_text}',
        f'lift guaranteed          : {yes_no[bool(response.lift_guaranteed)]}'
        f'   worst-case margin (eq. 18 at rest) {_newtons(response.worst_case_margin)}',
        f'contact stiffness model  : {yes_no[bool(response.csm_lift)]}'
        f'   margin {_newtons(response.csm_margin)}'
        f'   {"inside" if response.csm_in_domain else "OUTSIDE"} its domain',
        f'CSM on the way (path)    : {yes_no[bool(response.csm_path_lift)]}'
        f'   largest margin {_newtons(response.csm_path_margin)}'
        + ('' if math.isnan(response.csm_path_delta_theta_p) else
           f' at {math.degrees(response.csm_path_delta_theta_p):.4g} deg'),
        *([f'turned on the table      : may rest turned '
           f'{math.degrees(response.rolling_turn):+.4g} deg, margin '
           f'{_newtons(response.rolling_margin)}']
          if response.rolling_checked and not response.lift_guaranteed
          and not math.isnan(response.rolling_turn) else []),
        f'torque within the hand   : {yes_no[bool(response.within_torque_limit)]}'
        f'   limit {response.torque_limit:g} N*m',
        'finger  delta_theta_s [deg]  tau_s [N*m]  CSM f_n/k_n [um]',
    ]
    for i, (ds, tau, pen) in enumerate(zip(response.delta_theta_s, response.compliant_torque,
                                           response.csm_penetration, strict=False), start=1):
        lines.append(f'{i:>6}  {math.degrees(ds):>19.4f}  {tau:>11.5f}  {pen * 1e6:>16.2f}')
    lines.append(response.message)
    return '\n'.join(lines)


def main(args: Sequence[str] | None = None) -> int:
    argv = list(sys.argv if args is None else args)
    options = build_parser().parse_args(user_args(PROG, argv))
    request = CheckLift.Request()
    request.k_theta = [float(v) for v in options.k_theta]
    request.delta_theta_p = [float(v) for v in options.delta_theta_p]
    if options.friction_angle is not None:  # otherwise the default: the configured one
        request.friction_angle = float(options.friction_angle)
    request.object = options.object
    return call_and_print('check_lift', argv, CheckLift, options.service, request,
                          options.timeout, lambda response: format_response(request, response))


if __name__ == '__main__':
    sys.exit(main())
