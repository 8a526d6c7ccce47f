"""Outcome of a DAM grasp from joint signals alone (paper Fig. 7).

The paper marks each trial as one of three outcomes:

* ``SUCCESS``            -- o: the object was lifted and enveloped ("completely success in DAM");
* ``LIFTED_DAM_FAILED``  -- triangle: lifted, but no enveloping grasp;
* ``FAILURE``            -- x: failure.

A real hand only measures joint angles (encoders) and joint torques (torque sensors), so
:func:`classify_from_joints` infers the object from them:

1. **Object estimate.** All fingers turn about axes parallel to the object axis, so the
   problem is planar in the plane normal to that axis (coordinates ``u`` horizontal, ``z`` up).
   Every link is a capsule of radius ``r_l``; a cylinder of radius ``r`` touching link ``k`` has
   its centre at distance ``rho = r + r_l`` from that link's segment. The centre ``c`` is the
   least-squares fit of ``min_k dist(c, link_ik) = rho`` over all fingers ``i``, restricted to
   physically admissible centres: no finger penetrates the object, the object is above the
   table, and every finger touches the object on the *inner* (flexion) side of its nearest
   link (:mod:`dam_spcm_controller.object_estimate`). An object of another cross-section (a
   polygon, an ellipse) may have turned as it rolled, and the final joints leave a family of
   poses: its pose is followed through the grasp's joint history
   (:mod:`dam_spcm_controller.pose_tracking`: on the table the table contact fixes it; off
   the table the balance of the contact forces the compliant-joint torques give). Without a
   history the lowest pose the final joints allow is taken.
2. **In contact** (``contact``): every finger's distance residual is at most
   ``contact_tolerance``.
3. **Load held** (``load_held``): every compliant-joint torque is at least
   ``load_torque_threshold`` (flexion), and no compliant or position joint is within
   ``limit_margin`` of a joint limit (a finger closing on empty space ends at its limit).
4. **Lifted** (``lifted``): the object left the table: the estimated lowest point of its
   section is more than ``table_clearance`` above the table, the fingers touching it and
   holding the load (without the load the fit has no evidence of an object between them).
   ``lift_m`` is the rise of its centroid above its resting height and ``orientation`` its
   turn from the resting pose (0 for a cylinder).
5. **Enveloped** (``enveloped``): the object is caged by the fingers -- every fingertip lies
   at least ``cage_depth_ratio * r`` below the object's centre (``r`` the inradius), and the
   free gap between the innermost fingertips of the two opposing sides is smaller than the
   object's narrowest width (a cylinder's diameter), so it cannot drop out without the fingers
   opening (paper Fig. 6(d)).

``SUCCESS`` = lifted and enveloped; ``LIFTED_DAM_FAILED`` = lifted, not enveloped;
``FAILURE`` = not lifted.

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
from dam_spcm_controller.joint_history import JointHistory
from dam_spcm_controller.object_estimate import (
    HandGeometry,
    ObjectEstimate,
    estimate_object,
    estimate_section,
    finger_points,
    section_clearance,
)
from dam_spcm_controller.pose_tracking import TrackerSettings, track_pose

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
        Smallest rise of the object centre that counts as lifted for
        :func:`classify_with_object_height` (a ground-truth height) [m].
    limit_margin
        A joint this close to a limit counts as at its limit [rad].
    cage_depth_ratio
        Enveloped needs every fingertip this many object radii below the object centre [-]
        (a fingertip pinch at the object's equator is not an enveloping grasp).
    table_clearance
        The object left the table when its estimated lowest point is more than this above the
        table [m]. 1 mm: a Dynamixel servo's position step (0.088 deg) moves the fingertips by
        about 0.14 mm, and an object of the soft, non-lifting grasp of the Dynamixel
        integration test was estimated 0.39 mm up at 0.3 mm.
    """

    contact_tolerance: float = 2e-3
    load_torque_threshold: float = 0.01
    lift_height: float = 5e-3
    limit_margin: float = math.radians(1.0)
    cage_depth_ratio: float = 0.5
    table_clearance: float = 1e-3

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
                     'limit_margin', 'cage_depth_ratio', 'table_clearance'):
            object.__setattr__(self, name, finite_scalar(name, getattr(self, name),
                                                         positive=True))


@dataclass(frozen=True)
class Classification:
    """Outcome and the criteria it was derived from (see the module docstring).

    Attributes
    ----------
    lifted
        The object left the table (estimated).
    lift_m
        Estimated rise of the object's centroid above its resting height [m] (NaN if no
        estimate).
    orientation
        Estimated turn of the section from its resting pose [rad] (0 for a cylinder, NaN if
        no estimate).
    clearance
        Estimated height of the object's lowest point above the table [m] (NaN if no
        estimate).
    """

    outcome: Outcome
    contact: bool
    load_held: bool
    lifted: bool
    enveloped: bool
    estimate: ObjectEstimate
    lift_m: float
    reason: str
    orientation: float = math.nan
    clearance: float = math.nan


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
                         stop: Callable[[], bool] | None = None,
                         history: JointHistory | None = None,
                         tracker: TrackerSettings | None = None) -> Classification:
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
        Polled by the pose fit of a non-circular section; when it returns true the fit ends.
    history
        The grasp's joint samples from before the first contact
        (:attr:`DamSequence.history <dam_spcm_controller.sequence.DamSequence.history>`):
        the pose of a non-circular section is followed through them
        (:func:`~dam_spcm_controller.pose_tracking.track_pose`, the final state appended).
        Without it (or empty) the lowest pose the final joints allow is taken, which may be
        on the table for an object that left it. A cylinder needs none.
    tracker
        Tuning of the pose tracking; its defaults if ``None``.

    Raises
    ------
    InputError
        An array of the wrong length or with NaN/inf, or joint names of the wrong count.
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
    if geometry.section is None:
        est = estimate_object(geometry, q)
        orientation = 0.0 if est.found else math.nan
        clearance = float(est.centre[1]) - geometry.inradius - geometry.table_z \
            if est.found else math.nan
    elif history is not None and len(history) > 0:
        tracked = track_pose(geometry, history, final_positions=q, final_efforts=tau,
                             settings=tracker, stop=stop)
        est = ObjectEstimate(tracked.centre, tracked.residuals, tracked.orientation)
        orientation = tracked.orientation
        clearance = 0.0 if tracked.on_table else tracked.clearance
    else:
        est = estimate_section(geometry, q, contact_tolerance=s.contact_tolerance, stop=stop)
        orientation = est.orientation
        clearance = section_clearance(geometry, est.centre, est.orientation) \
            if est.found else math.nan
    pts = finger_points(geometry, q)
    contact = est.found and est.max_residual <= s.contact_tolerance
    moving = np.zeros(3 * n, dtype=bool)
    moving[0::3] = True
    moving[2::3] = True
    at_limit = moving & ((q <= lo + s.limit_margin) | (q >= hi - s.limit_margin))
    loaded = tau[0::3] >= s.load_torque_threshold
    load_held = bool(loaded.all() and not at_limit.any())
    lift = float(est.centre[1] - geometry.object_z0) if est.found else math.nan
    # an object held off the table presses on every finger: without that load the fit has
    # no evidence of an object between the fingers (they may have closed on empty space)
    lifted = bool(contact and load_held and clearance > s.table_clearance)
    enveloped = bool(contact and _enveloped(
        geometry, pts, est.centre, s.cage_depth_ratio * geometry.inradius))
    if lifted:
        outcome = Outcome.SUCCESS if enveloped else Outcome.LIFTED_DAM_FAILED
    else:
        outcome = Outcome.FAILURE
    reasons = []
    if not est.found:
        reasons.append('no admissible object centre fits the finger posture')
    else:
        where = 'object left the table' if lifted else 'object on the table'
        turned = '' if geometry.section is None else \
            f', turned {math.degrees(orientation):.3g} deg'
        reasons.append(f'{where}: rise {lift * 1e3:.3g} mm{turned} (estimated from the '
                       f'joints)')
        if not contact:
            reasons.append(f'fingers off the object by up to {est.max_residual * 1e3:.3g} mm')
    if at_limit.any():
        j = int(np.flatnonzero(at_limit)[0])
        reasons.append(f'{names[j]} at {math.degrees(q[j]):.4g} deg is at its limit')
    if not loaded.all():
        j = 3 * int(np.flatnonzero(~loaded)[0])
        pulling = ' (it pulls away from the object)' if tau[j] < 0.0 else ''
        reasons.append(f'{names[j]} torque {tau[j]:.3g} N*m{pulling} shows no load (a held '
                       f'object needs at least +{s.load_torque_threshold:g} N*m of flexion)')
    if lifted and not enveloped:
        reasons.append('object not caged by the fingertips')
    if outcome is Outcome.SUCCESS:
        reasons.append('enveloped')
    return Classification(outcome=outcome, contact=bool(contact), load_held=load_held,
                          lifted=lifted, enveloped=enveloped, estimate=est, lift_m=lift,
                          reason='; '.join(reasons), orientation=orientation,
                          clearance=clearance)


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
