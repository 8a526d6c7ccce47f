"""The ``spcm_controller`` node's parameters: their table and the checks of a change.

Pure Python (no rclpy): the node declares the parameters from :data:`DOUBLE_PARAMETERS` and
:data:`BOOL_PARAMETERS` and validates a ``ros2 param set`` with :func:`changed_values`; the
sequence's parameters follow from the values with :func:`sequence_overrides`.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

from dam_common.echo import brief_repr
from dam_spcm_controller.errors import InputError

#: name -> (:class:`~dam_spcm_controller.sequence.SequenceParams` attribute or None,
#: description, lower bound, upper bound). Defaults come from the configuration file.
DOUBLE_PARAMETERS: dict[str, tuple[str | None, str, float, float]] = {
    'damping': ('damping', 'compliant-joint damping d [N*m*s/rad]', 0.0, 1.0),
    'torque_limit': ('torque_limit', '|tau| limit of every torque command [N*m]', 1e-6, 10.0),
    'trajectory_duration': ('trajectory_duration',
                            'position-joint motion time in ROLLING_UP [s]', 0.05, 60.0),
    'envelope_torque': ('envelope_torque', 'torque of the enveloping grasp [N*m]', 1e-6, 10.0),
    'contact_torque_threshold': ('contact_torque_threshold',
                                 'compliant torque that signals contact [N*m]', 1e-6, 10.0),
    'approach_speed': ('approach_speed', 'pre-shape and closing speed [rad/s]', 1e-3, 10.0),
    'phase_timeout': ('phase_timeout', 'longest time of any active phase [s]', 0.1, 600.0),
    'torque_ramp_time': ('torque_ramp_time', 'torque ramp-in/ramp-out time [s]', 0.0, 10.0),
    'settle_speed': ('settle_speed', 'ENVELOPE settled below this speed [rad/s]', 1e-6, 10.0),
    'settle_time': ('settle_time', 'ENVELOPE settled this long: DONE [s]', 1e-3, 10.0),
    'state_timeout': (None, '/joint_states silence that fails a grasp [s]', 1e-3, 10.0),
    'check_lift_timeout': (None, 'time allowed for the /check_lift answer [s]', 0.0, 60.0),
    'status_rate': (None, '/dam/status and feedback rate [Hz] (read at start-up)', 0.1, 1000.0),
}

#: Parameters fixed at start-up.
READ_ONLY = frozenset({'status_rate'})

#: The bool parameters, with their descriptions.
BOOL_PARAMETERS: dict[str, str] = {
    'require_lift_guarantee':
        'refuse (k_theta, delta_theta_p) pairs outside the sufficient-lift region reported by '
        '/check_lift, and pairs whose guarantee needs more compliant torque than the hand '
        'gives',
    'impedance_on_device':
        'true: compliant joints in MODE_IMPEDANCE, the device runs the impedance law; false: '
        'this node computes their torque',
    'envelope_constant_torque':
        'true: ENVELOPE closes the fingers with the constant envelope_torque on the compliant '
        'joints (the paper, Fig. 6(d)); false: ENVELOPE keeps the SPCM impedance '
        '(docs/simulation_grasp.md explains why that is the default)',
}


def changed_values(values: Mapping[str, float], flags: Mapping[str, bool],
                   changes: Iterable[tuple[str, Any]]
                   ) -> tuple[dict[str, float], dict[str, bool]]:
    """The parameter values after ``changes``, each checked for its type.

    Parameters
    ----------
    values : the number parameters' values now, by name (units as in :data:`DOUBLE_PARAMETERS`).
    flags : the bool parameters' values now, by name.
    changes : ``(name, value)`` pairs of one ``set_parameters`` request; names of neither
        table (``use_sim_time``, ...) are left to their owners.

    Returns
    -------
    tuple of dict
        New copies of ``values`` and ``flags`` with the changes applied.

    Raises
    ------
    InputError
        A number parameter given a bool, a non-number, NaN or an infinity, or a bool
        parameter given anything but a bool; the message names the parameter and the value.
    """
    new_values = dict(values)
    new_flags = dict(flags)
    for name, value in changes:
        if name in DOUBLE_PARAMETERS:
            if isinstance(value, bool) or not isinstance(value, (int, float)) \
                    or not math.isfinite(float(value)):
                raise InputError(f'{name} must be a finite number, got {brief_repr(value)}')
            new_values[name] = float(value)
        elif name in BOOL_PARAMETERS:
            if not isinstance(value, bool):
                raise InputError(f'{name} must be a bool, got {brief_repr(value)}')
            new_flags[name] = value
    return new_values, new_flags


def sequence_overrides(values: Mapping[str, float], flags: Mapping[str, bool]
                       ) -> dict[str, float | bool]:
    """The :class:`~dam_spcm_controller.sequence.SequenceParams` fields the parameters set.

    Returns
    -------
    dict
        Field name -> value: every number parameter that has a field, and the flags
        ``impedance_on_device`` and ``envelope_constant_torque`` (same names).
    """
    overrides: dict[str, float | bool] = {
        attr: values[name] for name, (attr, *_rest) in DOUBLE_PARAMETERS.items() if attr}
    for name in ('impedance_on_device', 'envelope_constant_torque'):
        overrides[name] = flags[name]
    return overrides
