"""Outcome of a DAM grasp from joint signals alone (paper Fig. 7).

The paper marks each trial as one of three outcomes:

* ``SUCCESS``            -- o: the object was lifted and enveloped ("completely success in DAM");
* ``LIFTED_DAM_FAILED``  -- triangle: lifted, but no enveloping grasp;
* ``FAILURE``            -- x: failure.

A real hand only measures joint angles (encoders) and joint torques (torque sensors), so
:func:`classify_from_joints` infers the object from the final, settled posture:

1. **Object estimate.** All fingers turn about axes parallel to the object axis, so the
   problem is planar in the plane normal to that axis (coordinates ``u`` horizontal, ``z`` up).
   Every link is a capsule of radius ``r_l``; a cylinder of radius ``r`` touching link ``k`` has
   its centre at distance ``rho = r + r_l`` from that link's segment. The centre ``c`` is the
   least-squares fit of ``min_k dist(c, link_ik) = rho`` over all fingers ``i``, restricted to
   physically admissible centres: no finger penetrates the object, the object is above the
   table, and every finger touches the object on the *inner* (flexion) side of its nearest
   link -- under a positive (flexing) torque a finger that is at rest must be pushing against
   the object, not resting on its outer side. An object of another cross-section (a polygon,
   an ellipse) may have turned as it rolled: its centre *and* its orientation ``psi`` are
   fitted, with ``d_i`` the distance from the finger's links to the turned section
   (:mod:`dam_spcm_controller.object_estimate`).
2. **In contact** (``contact``): every finger's distance residual is at most
   ``contact_tolerance``.
3. **Load held** (``load_held``): every compliant-joint torque is at least
   ``load_torque_threshold`` (flexion), and no compliant or position joint is within
   ``limit_margin`` of a joint limit (a finger closing on empty space ends at its limit).
4. **Lifted** (``lifted``): the estimated centre is at least ``lift_height`` above its
   initial height (object resting on the table); for a turned section, its lowest point is
   at least ``lift_height`` above the table (a section that only tipped over onto another
   face, its centre higher, is not lifted).
5. **Enveloped** (``enveloped``): the object is caged by the fingers -- every fingertip lies
   at least ``cage_depth_ratio * r`` below the object's centre (``r`` the inradius), and the
   free gap between the innermost fingertips of the two opposing sides is smaller than the
   object's narrowest width (a cylinder's diameter), so
   it cannot drop out without the fingers opening (paper Fig. 6(d)).

``SUCCESS`` = contact and load held and lifted and enveloped; ``LIFTED_DAM_FAILED`` = contact
and load held and lifted, not enveloped; ``FAILURE`` otherwise.

:func:`classify_with_object_height` replaces step 4 by a ground-truth object height (e.g. from
the simulator) to cross-check the joint-only result.
"""

from __future__ import annotations

import enum
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dam_spcm_controller._validate import finite_scalar, finite_vector
from dam_spcm_controller.errors import InputError
from dam_spcm_controller.object_estimate import (
    HandGeometry,
    ObjectEstimate,
    estimate_object,
    estimate_section,
    finger_points,
    section_clearance,
)

if TYPE_CHECKING:  # pragma: no cover
    from dam_common.config import DamConfig


class Outcome(enum.Enum):
    """Trial outcome in the terms of the paper's Fig. 7."""

    SUCCESS = 'success'
    LIFTED_DAM_FAILED = 'lifted_dam_failed'
    FAILURE = 'failure'


@dataclass(frozen=True)
class ClassifierSettings:
    """Thresholds of the joint-signal classifier.

    Attributes
    ----------
    contact_tolerance
        Largest ``|d_i - rho|`` for a finger to count as touching the object [m].
    load_torque_threshold
        Smallest compliant-joint torque that shows a held load [N*m].
    lift_height
        Smallest rise of the object centre that counts as lifted [m].
    limit_margin
        A joint this close to a limit counts as at its limit [rad].
    cage_depth_ratio
        Enveloped needs every fingertip this many object radii below the object centre [-]
        (a fingertip pinch at the object's equator is not an enveloping grasp).
    """

    contact_tolerance: float = 2e-3
    load_torque_threshold: float = 0.01
    lift_height: float = 5e-3
    limit_margin: float = math.radians(1.0)
    cage_depth_ratio: float = 0.5

    @classmethod
    def from_config(cls, config: DamConfig, **overrides: float) -> ClassifierSettings:
        """Settings from the ``classification`` section; the load threshold is the
        controller's contact threshold scaled by the smallest over the largest stiffness ratio
        (the least stiff finger's share). ``overrides`` replace individual attributes."""
        cl = config.classification
        # The weakest finger carries the smallest share of the load: fingers 2 and 3 have
        # half finger 1's stiffness and hold the object with half its torque.
        ratios = [float(f.stiffness_ratio) for f in config.hand.fingers]
        load = config.controller.contact_torque_threshold_nm * min(ratios) / max(ratios)
        values = {'load_torque_threshold': load,
                  'contact_tolerance': cl.contact_tolerance_m,
                  'lift_height': cl.lift_height_m,
                  'cage_depth_ratio': cl.cage_depth_ratio,
                  'limit_margin': cl.limit_margin_rad}
        values.update(overrides)
        return cls(**values)

    def __post_init__(self) -> None:
        for name in ('contact_tolerance', 'load_torque_threshold', 'lift_height',
                     'limit_margin', 'cage_depth_ratio'):
            object.__setattr__(self, name, finite_scalar(name, getattr(self, name),
                                                         positive=True))


@dataclass(frozen=True)
class Classification:
    """Outcome and the criteria it was derived from (see the module docstring)."""

    outcome: Outcome
    contact: bool
    load_held: bool
    lifted: bool
    enveloped: bool
    estimate: ObjectEstimate
    lift_m: float  # estimated rise of the object centre [m] (NaN if no estimate)
    reason: str


def _enveloped(geometry: HandGeometry, pts: np.ndarray, centre: np.ndarray,
               cage_depth: float) -> bool:
    tips = pts[:, 3, :]
    if not np.all(tips[:, 1] <= centre[1] - cage_depth):
        return False
    # innermost tip of each side: the side closing towards +u sits at small u, and vice versa
    plus = geometry.inward_sign > 0
    tip_plus_side = float(tips[plus, 0].max())  # fingers coming from -u: their largest u
    tip_minus_side = float(tips[~plus, 0].min())  # fingers coming from +u: their smallest u
    gap = tip_minus_side - tip_plus_side - 2.0 * geometry.link_radius
    return gap < geometry.object_width


def classify_from_joints(geometry: HandGeometry, lower: np.ndarray, upper: np.ndarray,
                         positions: np.ndarray, efforts: np.ndarray,
                         settings: ClassifierSettings | None = None,
                         joint_names: Sequence[str] | None = None,
                         stop: Callable[[], bool] | None = None) -> Classification:
    """Classify the settled final state of a grasp from joint angles and torques.

    Parameters
    ----------
    geometry
        Hand and object geometry (:meth:`HandGeometry.from_config`).
    lower, upper
        (3n,) joint limits [rad].
    positions
        (3n,) final joint angles [rad].
    efforts
        (3n,) final joint torques [N*m] (positive = flexion).
    settings
        Thresholds; defaults of :class:`ClassifierSettings` if ``None``.
    joint_names
        (3n,) names used in :attr:`Classification.reason`; indices if ``None``.
    stop
        Passed to :func:`estimate_section` (a non-circular section only).

    Raises
    ------
    FitInterrupted
        ``stop()`` returned true during the fit of a non-circular section.
    """
    s = settings or ClassifierSettings()
    n = geometry.n_fingers
    names = list(joint_names) if joint_names is not None else [
        f'joint {j}' for j in range(3 * n)]
    if len(names) != 3 * n:
        raise InputError(f'joint_names must have {3 * n} entries, got {len(names)}')
    q = finite_vector('positions', positions, 3 * n)
    tau = finite_vector('efforts', efforts, 3 * n)
    lo = finite_vector('lower', lower, 3 * n)
    hi = finite_vector('upper', upper, 3 * n)
    est = estimate_object(geometry, q) if geometry.section is None else \
        estimate_section(geometry, q, contact_tolerance=s.contact_tolerance, stop=stop)
    pts = finger_points(geometry, q)
    contact = est.found and est.max_residual <= s.contact_tolerance
    moving = np.zeros(3 * n, dtype=bool)
    moving[0::3] = True
    moving[2::3] = True
    at_limit = moving & ((q <= lo + s.limit_margin) | (q >= hi - s.limit_margin))
    loaded = tau[0::3] >= s.load_torque_threshold
    load_held = bool(loaded.all() and not at_limit.any())
    if not est.found:
        lift = math.nan
    elif geometry.section is None:
        lift = float(est.centre[1] - geometry.object_z0)
    else:  # a turned section: how far its lowest point is off the table
        lift = section_clearance(geometry, est.centre, est.orientation)
    lifted = bool(est.found and lift >= s.lift_height)
    enveloped = bool(contact and _enveloped(geometry, pts, est.centre,
                                            s.cage_depth_ratio * geometry.inradius))
    if contact and load_held and lifted:
        outcome = Outcome.SUCCESS if enveloped else Outcome.LIFTED_DAM_FAILED
    else:
        outcome = Outcome.FAILURE
    reasons = []
    if not est.found:
        reasons.append('no admissible object centre fits the finger posture')
    elif not contact:
        reasons.append(f'fingers off the object by up to {est.max_residual * 1e3:.3g} mm')
    if at_limit.any():
        j = int(np.flatnonzero(at_limit)[0])
        reasons.append(f'{names[j]} at {math.degrees(q[j]):.4g} deg is at its limit')
    if not loaded.all():
        j = 3 * int(np.flatnonzero(~loaded)[0])
        pulling = ' (it pulls away from the object)' if tau[j] < 0.0 else ''
        reasons.append(f'{names[j]} torque {tau[j]:.3g} N*m{pulling} shows no load (a held '
                       f'object needs at least +{s.load_torque_threshold:g} N*m of flexion)')
    if est.found and not lifted:
        reasons.append(f'object raised only {lift * 1e3:.3g} mm (estimated from the joints)')
    if contact and lifted and not enveloped:
        reasons.append('object not caged by the fingertips')
    return Classification(outcome=outcome, contact=bool(contact), load_held=load_held,
                          lifted=lifted, enveloped=enveloped, estimate=est, lift_m=lift,
                          reason='; '.join(reasons) or 'lifted and enveloped')


def classify_with_object_height(joint_result: Classification, object_z: float,
                                object_z0: float, lift_height: float = 5e-3) -> Outcome:
    """Outcome using a ground-truth object height (e.g. the simulator's) for "lifted".

    Parameters
    ----------
    joint_result
        Result of :func:`classify_from_joints` (supplies ``enveloped`` and ``load_held``).
    object_z, object_z0
        Final and initial height of the object's centre [m].
    lift_height
        Smallest rise that counts as lifted [m].
    """
    z = finite_scalar('object_z', object_z)
    z0 = finite_scalar('object_z0', object_z0)
    h = finite_scalar('lift_height', lift_height, positive=True)
    if z - z0 < h:
        return Outcome.FAILURE
    if joint_result.enveloped and joint_result.load_held:
        return Outcome.SUCCESS
    return Outcome.LIFTED_DAM_FAILED
