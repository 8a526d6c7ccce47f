"""Scale study: the lift boundaries ``k_theta*`` against the size of the object.

The paper's authors switch grasp strategies with the object's size ("scale-dependent grasp",
refs. [6]-[11]); DAM is their strategy for objects about as small as a fingertip. This module
asks, for the configured hand, for which cylinder radii DAM works: for each radius the object
is the configured cylinder scaled to that radius, resting on the table at the same place (its
axis at height ``R``), and both region boundaries of section 3 (:meth:`LiftAnalyzer.boundaries`)
are computed at the chosen displacements, with the stiffness at which finger ``i``'s SPCM
torque reaches the hand's limit (:mod:`dam_analysis.hand_limits`),

    ``k_torque = min_i torque_limit / (r_i |delta_theta_si|)``  (finger 1's stiffness),

above which the hand cannot give what eq. (18) counts on. DAM works with this hand at a
radius and displacement where ``k* < k_torque``.

A column of another cross-section (a polygon, an ellipse) is scaled the same way, uniformly
about its centroid; its size is then its half height ``h``, the height of its centroid resting
on the table (half the width across flats of a polygon lying on a face with a parallel one
opposite, the vertical semi-axis of an ellipse, a third of a triangle's height; a cylinder's
``h`` is its radius). The mass follows the size at the
configured object's density (``m = m_0 (h / h_0)^2``, the same length) unless it is kept
constant. A radius at which the fingers cannot make the first
contact of the analysis (the hanging finger already overlaps the object, a proximal link
touches first, the joint limit is reached first) has no boundary; the reason is kept.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from dam_analysis.analysis import LiftAnalyzer
from dam_analysis.errors import InputError, NoSolutionError
from dam_analysis.hand_limits import HandLimits
from dam_common.config import DamConfig
from dam_common.cross_section import Circle, CrossSection


@dataclass(frozen=True)
class ScaleStudy:
    """Boundaries over object radius and displacement.

    Attributes
    ----------
    friction_angle : alpha [rad].
    radius : (R,) sizes [m]: the cylinder's radius, another column's half height (see
        :func:`size_name`).
    mass : (R,) object masses [kg].
    delta_theta_p : (D,) position-joint displacements [rad].
    k_sufficient, k_csm : (R, D) lower boundaries of the sufficient and CSM regions
        (finger 1's stiffness) [N m/rad]; NaN where no stiffness lifts or no first contact.
    k_torque : (R, D) finger-1 stiffness at which some finger's ``|tau_s|`` reaches the hand's
        torque limit [N m/rad]; NaN beyond the end of the SPCM branch or without first contact.
    torque_limit : the hand's compliant torque limit [N m].
    no_contact : (R,) why the analysis has no first contact at that radius ('' where it has).
    constant_mass : the configured mass at every radius (else scaled at the same density).
    object_name : the library object that was scaled.
    size_name : ``'radius'`` for a cylinder, ``'half height'`` for another column.
    """

    friction_angle: float
    radius: np.ndarray
    mass: np.ndarray
    delta_theta_p: np.ndarray
    k_sufficient: np.ndarray
    k_csm: np.ndarray
    k_torque: np.ndarray
    torque_limit: float
    no_contact: tuple[str, ...]
    constant_mass: bool = False
    object_name: str = 'cylinder'
    size_name: str = 'radius'

    def works(self, which: str = 'sufficient') -> np.ndarray:
        """(R, D) bool: the boundary ``which`` ('sufficient' or 'csm') exists and lies below
        ``k_torque`` (NaN comparisons are False)."""
        k = self.k_sufficient if which == 'sufficient' else self.k_csm
        with np.errstate(invalid='ignore'):
            return np.isfinite(k) & (k < self.k_torque)


def size_name(section: CrossSection) -> str:
    """What the scale study calls a section's size: ``'radius'`` for a disc, ``'half height'``
    (the centroid's height resting on the table) for any other section."""
    return 'radius' if isinstance(section, Circle) else 'half height'


def scaled_config(config: DamConfig, radius_m: float, constant_mass: bool = False
                  ) -> DamConfig:
    """The configuration with the object scaled to the size ``radius_m`` [m] (a cylinder's
    radius, another column's half height): uniformly about its centroid, resting on the
    table at the same horizontal place, mass at the configured density (``m_0 (h / h_0)^2``)
    or kept.

    Raises
    ------
    InputError
        ``radius_m`` is not a positive finite number (the value is named).
    """
    if not (math.isfinite(radius_m) and radius_m > 0.0):
        raise InputError(f'radius: expected a positive number of metres, got {radius_m!r}')
    obj = config.object
    factor = radius_m / obj.section.rest_height
    section = Circle(float(radius_m)) if isinstance(obj.section, Circle) else \
        obj.section.scaled(factor)
    position = np.array(obj.position_m, dtype=np.float64)
    position[2] = section.rest_height
    mass = obj.mass_kg if constant_mass else obj.mass_kg * factor ** 2
    return dataclasses.replace(config, object=dataclasses.replace(
        obj, section=section, position_m=position, mass_kg=float(mass)))


def torque_stiffness(analyzer: LiftAnalyzer, delta_theta_p: float) -> float:
    """Finger-1 stiffness [N m/rad] at which some finger's ``|tau_s| = k_theta_i
    |delta_theta_si|`` reaches :attr:`HandLimits.torque_limit`; NaN beyond the end of the
    SPCM branch. Under SPCM ``delta_theta_s`` does not depend on ``k_theta`` (section 3.2)."""
    try:
        states = analyzer.spcm(delta_theta_p)
    except NoSolutionError:
        return math.nan
    ratios = np.asarray(analyzer.model.stiffness_ratios, dtype=np.float64)
    per_k = [ratio / ratios[0] * abs(fc.delta_theta_s) for fc, ratio in zip(states, ratios,
                                                                            strict=True)]
    largest = max(per_k)
    return analyzer.limits.torque_limit / largest if largest > 0.0 else math.inf


def scale_study(config: DamConfig, radii_m: Sequence[float], delta_theta_p: Sequence[float],
                friction_angle: float, constant_mass: bool = False,
                progress: Callable[[int, float, str], None] | None = None) -> ScaleStudy:
    """Both region boundaries and the torque ceiling over radius and displacement.

    Parameters
    ----------
    config : the validated configuration (its object is scaled, nothing else changes).
    radii_m : (R,) sizes [m], positive: the cylinder's radius or another column's half height.
    delta_theta_p : (D,) displacements [rad], in ``[0, task.delta_theta_p_max]``.
    friction_angle : alpha [rad], ``0 <= alpha < pi/2``.
    constant_mass : keep the configured mass instead of scaling it with the cross-section.
    progress : called after each radius with (index, radius [m], '' or the no-contact reason).

    Raises
    ------
    InputError
        A radius, displacement or friction angle out of range (the value is named).
    """
    dps = np.asarray(delta_theta_p, dtype=np.float64).reshape(-1)
    dp_max = float(config.task.delta_theta_p_max_rad)
    for dp in dps:
        if not (math.isfinite(dp) and 0.0 <= dp <= dp_max + 1e-12):
            raise InputError(f'delta_theta_p: {math.degrees(dp):.4g} deg is outside [0, '
                             f'{math.degrees(dp_max):.4g}] deg')
    if not (math.isfinite(friction_angle) and 0.0 <= friction_angle < math.pi / 2):
        raise InputError(f'friction_angle: {math.degrees(friction_angle):.4g} deg is outside '
                         '[0, 90) deg')
    radii = np.asarray(radii_m, dtype=np.float64).reshape(-1)
    shape = (radii.size, dps.size)
    k_suf, k_csm, k_tau = (np.full(shape, np.nan) for _ in range(3))
    masses, reasons = [], []
    limit = math.nan
    for j, radius in enumerate(radii):
        scaled = scaled_config(config, float(radius), constant_mass)
        masses.append(scaled.object.mass_kg)
        try:
            analyzer = LiftAnalyzer(scaled)
        except NoSolutionError as exc:
            reasons.append(str(exc))
        else:
            reasons.append('')
            limit = analyzer.limits.torque_limit
            bounds = analyzer.boundaries(friction_angle, dps)
            k_suf[j], k_csm[j] = bounds.sufficient, bounds.csm
            k_tau[j] = [torque_stiffness(analyzer, float(dp)) for dp in dps]
        if progress is not None:
            progress(j, float(radius), reasons[-1])
    if not math.isfinite(limit):  # no radius had a first contact
        limit = HandLimits.from_config(config).torque_limit
    return ScaleStudy(friction_angle=float(friction_angle), radius=radii,
                      mass=np.array(masses), delta_theta_p=dps, k_sufficient=k_suf,
                      k_csm=k_csm, k_torque=k_tau, torque_limit=limit,
                      no_contact=tuple(reasons), constant_mass=constant_mass,
                      object_name=config.object.name,
                      size_name=size_name(config.object.section))


def working_ranges(study: ScaleStudy, which: str = 'sufficient') -> list[list[tuple[float,
                                                                                    float]]]:
    """Per displacement, the radius intervals [m] (runs of consecutive sampled radii, each as
    (first, last)) where :meth:`ScaleStudy.works` holds."""
    works = study.works(which)
    out = []
    for d in range(study.delta_theta_p.size):
        runs, start = [], None
        for j in range(study.radius.size):
            if works[j, d] and start is None:
                start = j
            if start is not None and (not works[j, d] or j == study.radius.size - 1):
                end = j if works[j, d] else j - 1
                runs.append((float(study.radius[start]), float(study.radius[end])))
                start = None
        out.append(runs)
    return out
