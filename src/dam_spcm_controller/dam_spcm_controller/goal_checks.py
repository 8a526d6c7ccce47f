"""What a ``/dam_grasp`` goal must satisfy before the hand moves.

Pure Python (no rclpy, no message types): :func:`check_goal` validates the goal's
``(k_theta, delta_theta_p)`` against the hand and the device, :func:`guarantee_refusal` says
why ``require_lift_guarantee`` refuses a pair given the ``/check_lift`` answer.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from dam_analysis.analysis import check_delta_theta_p, check_k_theta
from dam_analysis.errors import DamAnalysisError
from dam_common.echo import brief_repr, brief_text
from dam_common.quantities import ANGLE, both_units
from dam_spcm_controller.errors import InputError


class LiftAnswer(Protocol):
    """The fields of a ``/check_lift`` answer (``dam_interfaces/srv/CheckLift`` response)
    that decide a guarantee."""

    ok: bool
    message: str
    lift_guaranteed: bool
    worst_case_margin: float
    within_torque_limit: bool
    torque_limit: float


def check_goal(k_theta: Sequence[float], delta_theta_p: Sequence[float],
               stiffness_ratios: np.ndarray, default_k_theta: float,
               default_delta_theta_p: float, delta_theta_p_max: float,
               max_device_stiffness: float | None) -> tuple[float, float]:
    """The grasp a goal asks for, or why it cannot run.

    Parameters
    ----------
    k_theta : the goal's stiffnesses [N*m/rad], one per finger or one for finger 1; empty:
        ``default_k_theta``.
    delta_theta_p : the goal's position-joint displacements [rad], one per finger or one for
        all; empty: ``default_delta_theta_p``.
    stiffness_ratios : shape ``(n_fingers,)``; finger ``i`` gets ``ratio_i / ratio_0 *
        k_theta``.
    default_k_theta : the configured ``k_theta`` of finger 1 [N*m/rad] (``task:``).
    default_delta_theta_p : the configured displacement [rad] (``task:``).
    delta_theta_p_max : the largest displacement allowed [rad].
    max_device_stiffness : the device's largest impedance stiffness [N*m/rad], or ``None``
        when the controller computes the torque itself (no device limit).

    Returns
    -------
    tuple of float
        ``(k_theta of finger 1 [N*m/rad], delta_theta_p [rad])``.

    Raises
    ------
    InputError
        The values are malformed (the analysis' checks), do not follow the stiffness ratios,
        differ between fingers, are not positive, or exceed the device's stiffness; the
        message quotes the values in the units typed.
    """
    ratios = np.asarray(stiffness_ratios, dtype=np.float64)
    try:
        k = check_k_theta(list(k_theta) or [default_k_theta], ratios)
        dp = check_delta_theta_p(list(delta_theta_p) or [default_delta_theta_p], ratios.size,
                                 delta_theta_p_max)
    except DamAnalysisError as exc:  # its quotes of the goal are cut already
        raise InputError(brief_text(str(exc))) from exc
    expected = k[0] * ratios / ratios[0]
    if not np.allclose(k, expected, rtol=1e-9, atol=0.0):
        raise InputError(f'k_theta {brief_repr(k)} does not follow the configured stiffness '
                         f'ratios {ratios.tolist()!r}; the controller sets finger i to '
                         'ratio_i * k_theta')
    if not np.allclose(dp, dp[0], rtol=0.0, atol=1e-12):
        raise InputError(f'delta_theta_p {both_units(dp, ANGLE)}: the controller moves every '
                         'position joint by the same displacement')
    if dp[0] <= 0.0:
        raise InputError(f'delta_theta_p must be positive, got {both_units(dp[0], ANGLE)}')
    if max_device_stiffness is not None and float(np.max(k)) > max_device_stiffness:
        raise InputError(f'k_theta {brief_repr(k)} N*m/rad: the device accepts impedance '
                         f'stiffness up to device.max_stiffness_nm_per_rad = '
                         f'{max_device_stiffness:g} N*m/rad')
    return float(k[0]), float(dp[0])


def guarantee_refusal(answer: LiftAnswer | None, k_theta: float, delta_theta_p: float
                      ) -> str | None:
    """Why ``require_lift_guarantee`` refuses the pair, or ``None`` when it may run.

    Parameters
    ----------
    answer : the ``/check_lift`` answer for the pair, ``None`` when none came in time.
    k_theta : finger 1's stiffness [N*m/rad].
    delta_theta_p : the displacement [rad].

    Returns
    -------
    str or None
        The reason, starting ``require_lift_guarantee is set``: no answer, a refused
        request, a pair outside the sufficient-lift region (paper eq. 18 with the rolling
        check), or one guaranteed only with more compliant torque than the hand gives.
    """
    pair = (f'k_theta {k_theta:g} N*m/rad, delta_theta_p '
            f'{math.degrees(delta_theta_p):.4g} deg')
    if answer is None:
        return 'require_lift_guarantee is set but /check_lift did not answer in time'
    if not answer.ok:
        return f'require_lift_guarantee is set and /check_lift rejected the pair: {answer.message}'
    if not answer.lift_guaranteed:
        return (f'require_lift_guarantee is set and {pair} is outside the sufficient-lift '
                f'region (worst-case margin {answer.worst_case_margin:.4g} N): '
                f'{answer.message}')
    if not answer.within_torque_limit:
        return (f'require_lift_guarantee is set and {pair} is guaranteed by eq. 18 only with '
                f'more compliant torque than the hand gives ({answer.torque_limit:g} N*m): '
                f'{answer.message}')
    return None
