"""What the analysis assumes of the hand and of the contact, checked against the configuration.

Two of the analysis' idealisations can fail silently for a well-formed request:

* **Torque.** Under SPCM the compliant torque is ``tau_s = -k_theta_i delta_theta_s`` (section
  3.2) and grows without bound with ``k_theta``; the hand gives at most the smaller of the
  controller's cap on the compliant joints (``controller.torque_limit_nm``) and the device's
  actuator limit (``device.torque_limit_nm``, beyond which commands are refused). A pair whose
  guarantee needs more torque than that is guaranteed by eq. (18) but not for this hand: the
  impedance saturates and the contact forces eq. (18) counted on never arise.
* **The contact stiffness model's domain.** The CSM (``docs/analysis.md``, section 4,
  assumption 3) keeps the rigid SPCM kinematics, which holds while the contact springs'
  penetration ``f_n / k_n`` stays far below the geometry. Its domain of validity here:
  ``f_n / k_n <= contact.csm_max_penetration_m`` at every finger (default 0.1 mm, 2 % of the
  fingertip radius: over a lever of about 50 mm about the compliant joint it moves
  ``delta_theta_s`` by about 2 mrad, a few per cent of its value at the configured task pair,
  where the penetration is about 54 um).

:func:`limit_notes` turns both into sentences for the ``/check_lift`` message.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from dam_common.config import DamConfig


@dataclass(frozen=True)
class HandLimits:
    """The limits a lift answer is checked against.

    Attributes
    ----------
    torque_limit : largest compliant-joint torque the hand gives [N m].
    torque_limit_source : the configuration key ``torque_limit`` comes from.
    csm_max_penetration : largest contact penetration ``f_n / k_n`` inside the CSM's
        domain of validity [m].
    """

    torque_limit: float
    torque_limit_source: str
    csm_max_penetration: float

    @classmethod
    def from_config(cls, config: DamConfig) -> HandLimits:
        """The limits of the configured hand: the smaller torque limit of controller and
        device (the controller's when they are equal), the CSM's penetration bound."""
        controller = float(config.controller.torque_limit_nm)
        device = float(config.device.torque_limit_nm)
        if controller <= device:
            limit, source = controller, 'controller.torque_limit_nm'
        else:
            limit, source = device, 'device.torque_limit_nm'
        return cls(torque_limit=limit, torque_limit_source=source,
                   csm_max_penetration=float(config.contact.csm_max_penetration_m))

    def within_torque_limit(self, compliant_torque: Sequence[float]) -> bool:
        """Every finger's ``|tau_s|`` [N m] is at most :attr:`torque_limit` (a finger without
        an SPCM state, NaN, needs no torque)."""
        return all(not abs(tau) > self.torque_limit for tau in compliant_torque)

    def csm_in_domain(self, penetration: Sequence[float]) -> bool:
        """Every finger's CSM penetration [m] is finite and at most
        :attr:`csm_max_penetration` (a negative one, a contact that opens, counts as inside:
        the CSM then answers "no lift" for a reason of its own)."""
        return all(math.isfinite(p) and p <= self.csm_max_penetration for p in penetration)


def csm_penetration(normal_forces: Sequence[float], k_n: float) -> list[float]:
    """``f_n / k_n`` per finger [m] for CSM normal forces [N] and the normal contact
    stiffness [N/m] (NaN stays NaN)."""
    return [float(f) / k_n for f in normal_forces]


def limit_notes(limits: HandLimits, compliant_torque: Sequence[float],
                lift_guaranteed: bool, penetration: Sequence[float], csm_lift: bool
                ) -> list[str]:
    """Sentences for an answer that leaves the hand's torque or the CSM's domain.

    Parameters
    ----------
    limits : the hand's limits.
    compliant_torque : (n,) ``tau_s`` per finger [N m].
    lift_guaranteed : the eq. (18) verdict of the answer.
    penetration : (n,) CSM ``f_n / k_n`` per finger [m].
    csm_lift : the CSM verdict of the answer.

    Returns
    -------
    list of str
        Empty when the answer stays inside both.
    """
    notes = []
    over = [(i, tau) for i, tau in enumerate(compliant_torque, start=1)
            if abs(tau) > limits.torque_limit]
    if over:
        needs = ', '.join(f'finger {i} needs |tau_s| = {abs(tau):.4g} N*m' for i, tau in over)
        verdict = ('guaranteed by eq. 18 but not for this hand' if lift_guaranteed
                   else 'beyond the hand')
        notes.append(f'torque: {verdict}: {needs}, more than the {limits.torque_limit:g} N*m '
                     f'it gives ({limits.torque_limit_source})')
    outside = [(i, p) for i, p in enumerate(penetration, start=1)
               if math.isfinite(p) and p > limits.csm_max_penetration]
    if outside:
        depths = ', '.join(f'finger {i} {p * 1e3:.3g} mm' for i, p in outside)
        what = 'its lift' if csm_lift else 'its answer'
        notes.append(f'CSM outside its domain of validity, {what} is not to be trusted: '
                     f'contact penetration f_n/k_n {depths}, above '
                     f'{limits.csm_max_penetration * 1e3:g} mm '
                     f'(contact.csm_max_penetration_m)')
    return notes
