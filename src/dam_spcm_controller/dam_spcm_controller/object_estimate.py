"""The object from the finger posture: the planar hand geometry and the fit of the object's
pose to the joint angles (step 1 of :mod:`dam_spcm_controller.classification`).

All fingers turn about axes parallel to the object axis, so the problem is planar in the plane
normal to that axis (coordinates ``u`` horizontal, ``z`` up). Every link is a capsule of
radius ``r_l``. A cylinder is fitted by its centre (:func:`estimate_object`); a section of
another shape, which may have turned as it rolled, by its centre and orientation, the lowest
pose the joints allow (:func:`estimate_section`).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from dam_common.cross_section import Circle, CrossSection
from dam_spcm_controller._validate import finite_scalar, finite_vector
from dam_spcm_controller.errors import InputError

if TYPE_CHECKING:  # pragma: no cover
    from dam_common.config import DamConfig


@dataclass(frozen=True)
class HandGeometry:
    """Planar geometry of the fingers and the object in the plane normal to the object axis.

    Attributes
    ----------
    link_lengths
        (3,) link lengths base to tip [m].
    link_radius
        Capsule radius of every link [m].
    base_uz
        (n, 2) compliant-joint axis of each finger in the plane, ``(u, z)`` [m].
    inward_sign
        (n,) +1 if the finger closes towards +u, -1 towards -u.
    object_radius
        Radius of the circle fitted to the object [m]: a cylinder's radius; for any other
        cross-section the mean of its inradius and circumradius.
    object_z0
        Height of the object's centroid resting on the table [m].
    table_z
        Height of the table top [m].
    radius_spread
        Half the difference of the section's circumradius and inradius [m] (zero for a
        cylinder): how far the section's boundary strays from the fitted circle. The first,
        circular fit of :func:`estimate_section` admits fingers this much inside that circle,
        and the inradius ``object_radius - radius_spread`` is the depth the cage is measured
        in and the lowest centre height admitted.
    object_width
        Narrowest width of the section [m] (the diameter of a cylinder; NaN: twice
        ``object_radius``): an opening narrower than it keeps the object caged.
    section
        The cross-section in the plane (``u``, ``z``; its own frame in the pose it rests in),
        None for a cylinder (the closed forms of a disc apply).
    object_u0
        ``u`` of the object's centroid resting on the table before the grasp [m].
    object_mass
        Mass of the object [kg] (the statics of the pose tracker).
    gravity
        Gravitational acceleration [m/s^2].
    link_masses
        (3,) link masses base to tip [kg], centres of mass at the link midpoints: their
        weight is taken out of the compliant-joint torques.
    contact_stiffness
        Normal stiffness of a finger-object contact [N/m]: a pressed contact sinks in by
        force / stiffness (inf: rigid).
    """

    link_lengths: np.ndarray
    link_radius: float
    base_uz: np.ndarray
    inward_sign: np.ndarray
    object_radius: float
    object_z0: float
    table_z: float = 0.0
    radius_spread: float = 0.0
    object_width: float = math.nan
    section: CrossSection | None = None
    object_u0: float = 0.0
    object_mass: float = 0.04
    gravity: float = 9.81
    link_masses: np.ndarray = field(default_factory=lambda: np.zeros(3))
    contact_stiffness: float = math.inf

    def __post_init__(self) -> None:
        object.__setattr__(self, 'link_lengths',
                           finite_vector('link_lengths', self.link_lengths, 3, positive=True))
        object.__setattr__(self, 'link_radius',
                           finite_scalar('link_radius', self.link_radius, positive=True))
        base = np.asarray(self.base_uz, dtype=np.float64)
        if base.ndim != 2 or base.shape[1] != 2 or not np.isfinite(base).all():
            raise InputError(f'base_uz must be a finite (n, 2) array, got {base!r}')
        object.__setattr__(self, 'base_uz', base)
        sign = finite_vector('inward_sign', self.inward_sign, base.shape[0])
        if not np.all(np.abs(sign) == 1.0):
            raise InputError(f'inward_sign must hold +1 or -1, got {sign.tolist()!r}')
        if sign.min() > 0 or sign.max() < 0:
            raise InputError(f'the fingers must close from both sides, got inward_sign '
                             f'{sign.tolist()!r}')
        object.__setattr__(self, 'inward_sign', sign)
        object.__setattr__(self, 'object_radius',
                           finite_scalar('object_radius', self.object_radius, positive=True))
        object.__setattr__(self, 'object_z0', finite_scalar('object_z0', self.object_z0))
        object.__setattr__(self, 'table_z', finite_scalar('table_z', self.table_z))
        spread = finite_scalar('radius_spread', self.radius_spread)
        if not 0.0 <= spread < self.object_radius:
            raise InputError(f'radius_spread must lie in [0, object_radius), got {spread!r}')
        object.__setattr__(self, 'radius_spread', spread)
        width = 2.0 * self.object_radius if math.isnan(self.object_width) else \
            finite_scalar('object_width', self.object_width, positive=True)
        object.__setattr__(self, 'object_width', width)
        object.__setattr__(self, 'object_u0', finite_scalar('object_u0', self.object_u0))
        object.__setattr__(self, 'object_mass',
                           finite_scalar('object_mass', self.object_mass, positive=True))
        object.__setattr__(self, 'gravity', finite_scalar('gravity', self.gravity,
                                                          positive=True))
        object.__setattr__(self, 'link_masses',
                           finite_vector('link_masses', self.link_masses, 3, nonnegative=True))
        stiffness = float(self.contact_stiffness)
        if not stiffness > 0.0:  # inf allowed: a rigid contact
            raise InputError(f'contact_stiffness must be positive, got {self.contact_stiffness!r}')
        object.__setattr__(self, 'contact_stiffness', stiffness)

    @classmethod
    def from_config(cls, config: DamConfig) -> HandGeometry:
        """Geometry of a validated ``dam_common.config.DamConfig``.

        Raises
        ------
        InputError
            A finger does not close in the plane normal to the object axis.
        """
        axis = np.asarray(config.object.axis, dtype=np.float64)
        e_u = config.object.section_x  # the section's x axis: axis x z
        base, sign = [], []
        for finger in config.hand.fingers:
            s = float(np.dot(finger.inward_direction, e_u))
            if abs(abs(s) - 1.0) > 1e-6:
                raise InputError(f'{finger.name} closes along {finger.inward_direction.tolist()}'
                                 f', not normal to the object axis {axis.tolist()}')
            base.append([float(np.dot(finger.base_position_m, e_u)),
                         float(finger.base_position_m[2])])
            sign.append(math.copysign(1.0, s))
        section = config.object.section
        # the plane's u axis is axis x z, the section's x axis: no mirror
        return cls(link_lengths=np.asarray(config.hand.link_lengths_m, dtype=np.float64),
                   link_radius=config.hand.link_radius_m, base_uz=np.array(base),
                   inward_sign=np.array(sign),
                   object_radius=0.5 * (section.inradius + section.circumradius),
                   object_z0=float(config.object.position_m[2]),
                   radius_spread=0.5 * (section.circumradius - section.inradius),
                   object_width=section.min_width,
                   section=None if isinstance(section, Circle) else section,
                   object_u0=float(np.dot(config.object.position_m, e_u)),
                   object_mass=float(config.object.mass_kg),
                   gravity=float(config.task.gravity_m_per_s2),
                   link_masses=np.asarray(config.hand.link_masses_kg, dtype=np.float64),
                   contact_stiffness=float(config.contact.contact_stiffness_n_per_m[0]))

    @property
    def n_fingers(self) -> int:
        return int(self.base_uz.shape[0])

    @property
    def contact_distance(self) -> float:
        """``rho = r + r_l``: distance of the object centre from a touching link's axis [m]."""
        return self.object_radius + self.link_radius

    @property
    def inradius(self) -> float:
        """``object_radius - radius_spread``: the section's inradius [m]."""
        return self.object_radius - self.radius_spread


def finger_points(geometry: HandGeometry, positions: np.ndarray) -> np.ndarray:
    """Joint and tip points of every finger in the plane.

    Parameters
    ----------
    geometry
        Hand geometry.
    positions
        (3n,) joint angles [rad], finger by finger, base to tip; positive flexes inward.

    Returns
    -------
    numpy.ndarray
        (n, 4, 2): compliant joint, locked joint, position joint, fingertip as ``(u, z)`` [m].
        A finger with all angles zero hangs straight down.
    """
    n = geometry.n_fingers
    q = finite_vector('positions', positions, 3 * n).reshape(n, 3)
    phi = np.cumsum(q, axis=1)  # (n, 3) absolute link angles from the downward vertical
    direction = np.stack([geometry.inward_sign[:, None] * np.sin(phi), -np.cos(phi)], axis=2)
    steps = direction * geometry.link_lengths[None, :, None]
    pts = np.empty((n, 4, 2))
    pts[:, 0] = geometry.base_uz
    pts[:, 1:] = geometry.base_uz[:, None, :] + np.cumsum(steps, axis=1)
    return pts


def _link_inner_normals(geometry: HandGeometry, positions: np.ndarray) -> np.ndarray:
    """(n, 3, 2) unit normals of each link pointing to its flexion side."""
    n = geometry.n_fingers
    phi = np.cumsum(np.asarray(positions, dtype=np.float64).reshape(n, 3), axis=1)
    return np.stack([geometry.inward_sign[:, None] * np.cos(phi), np.sin(phi)], axis=2)


def _distances(pts: np.ndarray, normals: np.ndarray,
               centres: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Distance of candidate centres to each finger and whether they are on the inner side.

    Returns ``d`` (M, n) -- distance to the nearest link of each finger -- and ``inner``
    (M, n) -- the centre lies on the flexion side of that nearest link.
    """
    a = pts[:, :-1, :]  # (n, 3, 2)
    ab = pts[:, 1:, :] - a
    ab2 = np.einsum('nkj,nkj->nk', ab, ab)
    rel = centres[:, None, None, :] - a[None]  # (M, n, 3, 2)
    t = np.clip(np.einsum('mnkj,nkj->mnk', rel, ab) / ab2[None], 0.0, 1.0)
    offset = rel - t[..., None] * ab[None]  # centre minus closest point
    dist = np.linalg.norm(offset, axis=3)  # (M, n, 3)
    nearest = np.argmin(dist, axis=2)  # (M, n)
    d = np.take_along_axis(dist, nearest[..., None], axis=2)[..., 0]
    off = np.take_along_axis(offset, nearest[..., None, None], axis=2)[:, :, 0, :]
    nrm = normals[np.arange(pts.shape[0])[None, :], nearest]  # (M, n, 2)
    inner = np.einsum('mnj,mnj->mn', off, nrm) > 0.0
    return d, inner


@dataclass(frozen=True)
class ObjectEstimate:
    """Least-squares object centre from the finger posture.

    Attributes
    ----------
    centre
        (2,) estimated centre ``(u, z)`` [m]; NaN if no admissible centre exists.
    residuals
        (n,) ``d_i - rho`` per finger [m] (NaN if no admissible centre).
    orientation
        Angle the section has turned by from its resting pose [rad] (about the object axis,
        from ``u`` towards ``z``); NaN for a cylinder.
    """

    centre: np.ndarray
    residuals: np.ndarray
    orientation: float = math.nan

    @property
    def found(self) -> bool:
        return bool(np.isfinite(self.centre).all())

    @property
    def max_residual(self) -> float:
        """Largest ``|d_i - rho|`` [m] (inf if no admissible centre)."""
        return float(np.max(np.abs(self.residuals))) if self.found else math.inf


def estimate_object(geometry: HandGeometry, positions: np.ndarray, *,
                    grid_step: float = 1e-3, tolerance: float = 1e-7,
                    penetration_tolerance: float | None = None) -> ObjectEstimate:
    """Fit the object centre to the finger posture (step 1 of the module's criteria).

    Parameters
    ----------
    geometry
        Hand and object geometry.
    positions
        (3n,) joint angles [rad].
    grid_step
        Spacing of the initial grid search [m].
    tolerance
        Final step of the pattern-search refinement [m].
    penetration_tolerance
        How far a finger may sit inside the circle [m]; default 2 % of ``rho``.
    """
    pts = finger_points(geometry, positions)
    normals = _link_inner_normals(geometry, positions)
    rho = geometry.contact_distance
    r = geometry.inradius
    lo = pts.reshape(-1, 2).min(axis=0) - rho
    hi = pts.reshape(-1, 2).max(axis=0) + rho
    lo[1] = max(lo[1], geometry.table_z + r)
    if hi[1] <= lo[1]:
        return ObjectEstimate(np.full(2, np.nan), np.full(geometry.n_fingers, np.nan))
    us = np.arange(lo[0], hi[0] + grid_step, grid_step)
    zs = np.arange(lo[1], hi[1] + grid_step, grid_step)
    grid = np.stack(np.meshgrid(us, zs, indexing='ij'), axis=-1).reshape(-1, 2)
    pen_tol = 0.02 * rho if penetration_tolerance is None else penetration_tolerance

    def cost(centres: np.ndarray) -> np.ndarray:
        d, inner = _distances(pts, normals, centres)
        ok = (inner.all(axis=1) & (d >= rho - pen_tol).all(axis=1)
              & (centres[:, 1] >= geometry.table_z + r - 1e-12))
        c = np.sum((d - rho) ** 2, axis=1)
        return np.where(ok, c, np.inf)

    costs = cost(grid)
    best = int(np.argmin(costs))
    if not np.isfinite(costs[best]):
        return ObjectEstimate(np.full(2, np.nan), np.full(geometry.n_fingers, np.nan))
    centre = grid[best].copy()
    best_cost = costs[best]
    step = grid_step / 2.0
    moves = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]],
                     dtype=np.float64)
    while step >= tolerance:
        trial = centre[None, :] + step * moves
        c = cost(trial)
        k = int(np.argmin(c))
        if c[k] < best_cost:
            centre, best_cost = trial[k], c[k]
        else:
            step /= 2.0
    d, _ = _distances(pts, normals, centre[None, :])
    return ObjectEstimate(centre, d[0] - rho)


class FitInterrupted(InputError):
    """:func:`estimate_section` was asked to stop."""


#: Step of the orientations :func:`estimate_section` fits the centre at [rad] (5 deg).
_SECTION_ANGLE_STEP = math.radians(5.0)


def _section_distances(geometry: HandGeometry, pts: np.ndarray, normals: np.ndarray,
                       centre: np.ndarray, psi: float) -> tuple[np.ndarray, bool]:
    """Distance from each finger's nearest link axis to the section turned by ``psi`` about
    ``centre``, ``(n,)`` [m], and whether the pose is admissible (every finger on the inner
    side of its nearest link, the section above the table, or in it by at most 2 % of
    ``rho`` as a simulated object sinks a little)."""
    section = geometry.section
    assert section is not None
    c, s = math.cos(psi), math.sin(psi)
    cu, cz = float(centre[0]), float(centre[1])
    # lowest point: the support along world -z, seen in the section's frame
    low_u, low_z = section.support(-s, -c)  # world (0, -1) turned by -psi
    if cz + s * low_u + c * low_z < geometry.table_z - 0.02 * geometry.contact_distance:
        return np.full(pts.shape[0], math.nan), False
    d = np.empty(pts.shape[0])
    for i in range(pts.shape[0]):
        best, inner = math.inf, False
        for k in range(3):
            au, az = pts[i, k, 0] - cu, pts[i, k, 1] - cz
            bu, bz = pts[i, k + 1, 0] - cu, pts[i, k + 1, 1] - cz
            # into the section's frame: turn by -psi
            sd = section.segment_distance(c * au + s * az, -s * au + c * az,
                                          c * bu + s * bz, -s * bu + c * bz)
            if sd.distance < best:
                nu, nz = sd.normal
                world_n = (c * nu - s * nz, s * nu + c * nz)
                best = sd.distance
                # the object lies on the inner side: the link's inner normal points at it
                inner = float(normals[i, k, 0] * world_n[0] + normals[i, k, 1] * world_n[1]) < 0
        d[i] = best
        if not inner:
            return d, False
    return d, True


def estimate_section(geometry: HandGeometry, positions: np.ndarray, *,
                     contact_tolerance: float = 2e-3, tolerance: float = 1e-5,
                     stop: Callable[[], bool] | None = None) -> ObjectEstimate:
    """Fit a non-circular section to the finger posture: the lowest pose the joints allow.

    The joints do not fix a turned section's pose: fingers 2 and 3 stand side by side, so the
    plane holds two contact conditions (finger 1 and the pair) for three unknowns, the centre
    ``(u, z)`` and the orientation ``psi``. For every 5 deg of ``psi`` over one period of the
    section's symmetry (60 deg for a hexagon, 180 deg for an ellipse) the centre is fitted
    (least squares of ``d_i - r_l``, a pattern search down to ``tolerance`` [m] from the
    circle fit's centre and from the section resting on the table below it; admissible: no
    finger penetrates by more than ``contact_tolerance`` (a simulated or soft contact sinks
    in), every finger on the inner side of its nearest link, the section above the table).
    Of the poses whose residuals are all within
    ``contact_tolerance`` [m] the one nearest the table (:func:`section_clearance`) is taken
    -- "lifted" then holds only when every pose the joints allow is off the table; without
    such a pose, the best fit.

    Parameters
    ----------
    geometry
        Hand and object geometry with a ``section``.
    positions
        (3n,) joint angles [rad].

    stop
        Polled between orientations; when it returns true the fit ends with
        :class:`FitInterrupted` (a node that is asked to stop).

    Raises
    ------
    InputError
        ``geometry`` has no section (use :func:`estimate_object`).
    FitInterrupted
        ``stop()`` returned true.
    """
    if geometry.section is None:
        raise InputError('estimate_section needs a geometry with a section')
    # a finger on a face sits up to radius_spread inside the circle of the mean radius
    first = estimate_object(geometry, positions, penetration_tolerance=0.02 * (
        geometry.contact_distance) + geometry.radius_spread)
    n = geometry.n_fingers
    if not first.found:
        return first
    pts = finger_points(geometry, positions)
    normals = _link_inner_normals(geometry, positions)
    r_l = geometry.link_radius
    pen_tol = contact_tolerance
    moves = np.array([[1, 0], [-1, 0], [0, 1], [0, -1], [1, 1], [1, -1], [-1, 1], [-1, -1]],
                     dtype=np.float64)

    def cost(centre: np.ndarray, psi: float) -> float:
        d, ok = _section_distances(geometry, pts, normals, centre, psi)
        if not ok or np.any(d < r_l - pen_tol):
            return math.inf
        return float(np.sum((d - r_l) ** 2))

    def fit(centre: np.ndarray, psi: float) -> tuple[np.ndarray, float]:
        value = cost(centre, psi)
        step = 1e-3 if not math.isfinite(value) else 2.5e-4
        if not math.isfinite(value):  # find an admissible start on a coarse ring first
            for radius in (1e-3, 2e-3, 4e-3):
                for move in moves:
                    trial = centre + radius * move
                    c = cost(trial, psi)
                    if c < value:
                        best, value = trial, c
                if math.isfinite(value):
                    centre = best
                    break
            if not math.isfinite(value):
                return centre, value
        while step >= tolerance:
            values = [cost(centre + step * move, psi) for move in moves]
            k = int(np.argmin(values))
            if values[k] < value:
                centre, value = centre + step * moves[k], values[k]
            else:
                step /= 2.0
        return centre, value

    section = geometry.section
    period = section.symmetry_period or 2.0 * math.pi
    poses = []
    for psi in np.arange(0.0, period - 1e-9, _SECTION_ANGLE_STEP):
        if stop is not None and stop():
            raise FitInterrupted('the object fit was interrupted')
        psi = float(psi)
        # two starts: the circle fit's centre, and below it the section resting on the table
        # (the lowest pose is wanted, and a higher local fit must not hide it)
        low_u, low_z = section.support(-math.sin(psi), -math.cos(psi))
        resting = geometry.table_z - (math.sin(psi) * low_u + math.cos(psi) * low_z)
        for start in (first.centre, np.array([first.centre[0], resting])):
            centre, value = fit(start.copy(), psi)
            if math.isfinite(value):
                d, _ = _section_distances(geometry, pts, normals, centre, psi)
                poses.append((float(np.max(np.abs(d - r_l))),
                              section_clearance(geometry, centre, psi), value,
                              centre.copy(), psi, d - r_l))
    if not poses:
        return ObjectEstimate(np.full(2, np.nan), np.full(n, np.nan))
    fitting = [p for p in poses if p[0] <= contact_tolerance]
    chosen = min(fitting, key=lambda p: p[1]) if fitting else min(poses, key=lambda p: p[2])
    return ObjectEstimate(chosen[3], chosen[5], chosen[4])


def section_clearance(geometry: HandGeometry, centre: np.ndarray, psi: float) -> float:
    """Height of the lowest point of the section, turned by ``psi`` [rad] about ``centre``,
    above the table [m]: how far the object is off the table.

    Raises
    ------
    InputError
        ``geometry`` has no section.
    """
    if geometry.section is None:
        raise InputError('section_clearance needs a geometry with a section')
    s, c = math.sin(psi), math.cos(psi)
    low_u, low_z = geometry.section.support(-s, -c)  # world (0, -1) turned by -psi
    return float(centre[1]) + s * low_u + c * low_z - geometry.table_z
