"""Cross-sections of column objects lying on the table: the interface, the circle, the ellipse.

A column object is a prism (or cylinder) whose axis lies horizontally on the table. Every
finger joint turns about an axis parallel to the column's, so the contact problem lives in the
plane normal to the axis. In that plane a cross-section is written in its own frame: ``x``
horizontal (world ``axis x z``), ``z`` up, origin at the centroid (the centre of gravity of a
homogeneous column), in the pose it rests in on the table.

Every class answers the same geometric questions in plain float arithmetic (the SPCM solver
calls them thousands of times per path):

* :meth:`CrossSection.distance`: signed distance of a point (negative inside), the closest
  boundary point and the outward unit normal there;
* :meth:`CrossSection.support`: the boundary point farthest along a direction;
* :meth:`CrossSection.line_interval`: where a line runs inside the section;
* :meth:`CrossSection.segment_distance`: signed distance of a segment, built from the three.

The convex polygon (and the regular polygon lying on a face) is in
:mod:`dam_common.polygon_section`. This module is pure Python (math and numpy); it does not
import rclpy.
"""

from __future__ import annotations

import math
import numbers
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

#: Golden-section steps for the deepest point of a segment that crosses a section.
_GOLDEN_STEPS = 80
_GOLDEN = (math.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class SegmentDistance:
    """Closest pair between a segment and a cross-section.

    Attributes
    ----------
    distance : signed distance [m]; negative: the segment enters the section this deep.
    segment_point : (u, z) closest point of the segment [m].
    section_point : (u, z) closest point of the section's boundary [m].
    normal : (u, z) unit outward normal of the section at ``section_point``: the direction
        from the section towards the segment (eq. 4's ``n_CB``).
    t : parameter of ``segment_point`` on the segment, in [0, 1].
    """

    distance: float
    segment_point: tuple[float, float]
    section_point: tuple[float, float]
    normal: tuple[float, float]
    t: float


class CrossSection(ABC):
    """A convex cross-section in its own frame (centroid at the origin, resting pose)."""

    #: ``'circle'``, ``'ellipse'`` or ``'polygon'``.
    kind: str

    @abstractmethod
    def distance(self, pu: float, pz: float
                 ) -> tuple[float, float, float, float, float]:
        """Signed distance of the point ``(pu, pz)`` [m] (negative inside).

        Returns
        -------
        (distance, qu, qz, nu, nz): the distance [m], the closest boundary point [m] and the
        unit outward normal there.
        """

    @abstractmethod
    def support(self, du: float, dz: float) -> tuple[float, float]:
        """Boundary point farthest along the unit direction ``(du, dz)`` [m]."""

    @abstractmethod
    def line_interval(self, au: float, az: float, eu: float, ez: float
                      ) -> tuple[float, float] | None:
        """Parameters ``(t0, t1)`` where ``a + t e`` lies inside the section, None: nowhere."""

    @abstractmethod
    def mirrored(self) -> CrossSection:
        """The section reflected in its vertical axis (``x -> -x``)."""

    @abstractmethod
    def scaled(self, factor: float) -> CrossSection:
        """The section scaled by ``factor`` about its centroid."""

    @abstractmethod
    def outline(self, faces: int) -> np.ndarray:
        """(m, 2) counter-clockwise vertices of a polygon for a mesh [m].

        A circle or an ellipse gives ``faces`` vertices whose faces are tangent to it (the
        mesh contains the curve; a corner stands off it by ``1 / cos(pi / faces) - 1`` of
        the radius there); a polygon gives its own vertices.
        """

    @abstractmethod
    def describe(self) -> str:
        """One line for messages, e.g. ``'hexagon, 7 mm across flats'``."""

    @property
    @abstractmethod
    def area(self) -> float:
        """Area [m^2]."""

    @property
    @abstractmethod
    def second_moments(self) -> tuple[float, float]:
        """``(integral x^2 dA, integral z^2 dA)`` about the centroid [m^4]."""

    @property
    def product_moment(self) -> float:
        """``integral x z dA`` about the centroid [m^4]; zero for a section symmetric about
        either axis."""
        return 0.0

    @property
    @abstractmethod
    def bottom(self) -> float:
        """Lowest ``z`` of the section [m] (negative: the centroid rests ``-bottom`` above the
        table)."""

    @property
    @abstractmethod
    def inradius(self) -> float:
        """Radius of the largest circle about the centroid inside the section [m]."""

    @property
    @abstractmethod
    def circumradius(self) -> float:
        """Radius of the smallest circle about the centroid containing the section [m]."""

    @property
    @abstractmethod
    def min_width(self) -> float:
        """Smallest width over all directions [m]: the narrowest slot the column fits
        through."""

    @property
    def symmetry_period(self) -> float:
        """Smallest turn [rad] that maps the section onto itself (2 pi: no symmetry; 0: every
        turn, a circle)."""
        return 2.0 * math.pi

    @property
    def rest_height(self) -> float:
        """Height of the centroid above the table when the section rests on it [m]."""
        return -self.bottom

    def segment_distance(self, au: float, az: float, bu: float, bz: float
                         ) -> SegmentDistance:
        """Signed distance between the segment ``[a, b]`` and the section.

        The signed distance of a convex set is a convex function along any line, so on a
        segment its minimum is at the line's own minimum clamped to the segment. Three cases:

        * the line misses the section: with the segment's unit normal ``n`` oriented from the
          section to the line, the line's closest point lies above the support point
          ``support(n)``, at distance ``n . a - h(n)``;
        * the line crosses the section but the segment does not: the nearer end;
        * the segment crosses the section: the deepest point, by golden-section search.

        Raises
        ------
        ValueError
            The segment has zero length.
        """
        eu, ez = bu - au, bz - az
        length2 = eu * eu + ez * ez
        if not length2 > 0.0:
            raise ValueError(f'segment of zero length at ({au!r}, {az!r})')
        interval = self.line_interval(au, az, eu, ez)
        if interval is None:
            length = math.sqrt(length2)
            nu, nz = -ez / length, eu / length
            if nu * au + nz * az < 0.0:  # orient n from the section (origin inside) to the line
                nu, nz = -nu, -nz
            qu, qz = self.support(nu, nz)
            t = ((qu - au) * eu + (qz - az) * ez) / length2
            if 0.0 <= t <= 1.0:
                offset = nu * (au - qu) + nz * (az - qz)
                return SegmentDistance(offset, (qu + offset * nu, qz + offset * nz),
                                       (qu, qz), (nu, nz), t)
            return self._point_on_segment(au, az, eu, ez, 0.0 if t < 0.0 else 1.0)
        t0, t1 = interval
        if t1 < 0.0:
            return self._point_on_segment(au, az, eu, ez, 0.0)
        if t0 > 1.0:
            return self._point_on_segment(au, az, eu, ez, 1.0)
        lo, hi = max(0.0, t0), min(1.0, t1)
        # golden-section search of the convex signed distance on [lo, hi]
        x1 = hi - _GOLDEN * (hi - lo)
        x2 = lo + _GOLDEN * (hi - lo)
        f1 = self.distance(au + x1 * eu, az + x1 * ez)[0]
        f2 = self.distance(au + x2 * eu, az + x2 * ez)[0]
        for _ in range(_GOLDEN_STEPS):
            if f1 <= f2:
                hi, x2, f2 = x2, x1, f1
                x1 = hi - _GOLDEN * (hi - lo)
                f1 = self.distance(au + x1 * eu, az + x1 * ez)[0]
            else:
                lo, x1, f1 = x1, x2, f2
                x2 = lo + _GOLDEN * (hi - lo)
                f2 = self.distance(au + x2 * eu, az + x2 * ez)[0]
        return self._point_on_segment(au, az, eu, ez, 0.5 * (lo + hi))

    def _point_on_segment(self, au: float, az: float, eu: float, ez: float, t: float
                          ) -> SegmentDistance:
        pu, pz = au + t * eu, az + t * ez
        dist, qu, qz, nu, nz = self.distance(pu, pz)
        return SegmentDistance(dist, (pu, pz), (qu, qz), (nu, nz), t)


@dataclass(frozen=True)
class Circle(CrossSection):
    """A disc of ``radius`` [m] (a circular cylinder)."""

    radius: float
    kind = 'circle'

    def __post_init__(self) -> None:
        check_length('radius', self.radius)

    def distance(self, pu: float, pz: float) -> tuple[float, float, float, float, float]:
        rho = math.hypot(pu, pz)
        if rho == 0.0:
            return -self.radius, 0.0, -self.radius, 0.0, -1.0
        nu, nz = pu / rho, pz / rho
        return rho - self.radius, self.radius * nu, self.radius * nz, nu, nz

    def support(self, du: float, dz: float) -> tuple[float, float]:
        return self.radius * du, self.radius * dz

    def line_interval(self, au: float, az: float, eu: float, ez: float
                      ) -> tuple[float, float] | None:
        return _quadratic_interval(eu * eu + ez * ez, au * eu + az * ez,
                                   au * au + az * az - self.radius ** 2)

    def mirrored(self) -> Circle:
        return self

    def scaled(self, factor: float) -> Circle:
        check_length('factor', factor, '')
        return Circle(self.radius * factor)

    def outline(self, faces: int) -> np.ndarray:
        return _tangent_polygon(self.radius, self.radius, faces)

    def describe(self) -> str:
        return f'circle, radius {self.radius * 1e3:.4g} mm'

    @property
    def area(self) -> float:
        return math.pi * self.radius ** 2

    @property
    def second_moments(self) -> tuple[float, float]:
        moment = math.pi * self.radius ** 4 / 4.0
        return moment, moment

    @property
    def bottom(self) -> float:
        return -self.radius

    @property
    def inradius(self) -> float:
        return self.radius

    @property
    def circumradius(self) -> float:
        return self.radius

    @property
    def min_width(self) -> float:
        return 2.0 * self.radius

    @property
    def symmetry_period(self) -> float:
        return 0.0


@dataclass(frozen=True)
class Ellipse(CrossSection):
    """An ellipse of semi-axes ``semi_axis_x`` (horizontal) and ``semi_axis_z`` [m].

    Lying on its flat side means ``semi_axis_x >= semi_axis_z``; the closest point of a point
    is found as in D. Eberly, "Distance from a Point to an Ellipse, an Ellipsoid, or a
    Hyperellipsoid" (Geometric Tools, 2013): the one root of a monotone convex function, here
    by Newton's method from the left, finished by bisection.
    """

    semi_axis_x: float
    semi_axis_z: float
    kind = 'ellipse'

    def __post_init__(self) -> None:
        check_length('semi_axis_x', self.semi_axis_x)
        check_length('semi_axis_z', self.semi_axis_z)

    def distance(self, pu: float, pz: float) -> tuple[float, float, float, float, float]:
        a, b = self.semi_axis_x, self.semi_axis_z
        swap = b > a  # the method wants the larger semi-axis first
        if swap:
            a, b, pu, pz = b, a, pz, pu
        y0, y1 = abs(pu), abs(pz)
        x0, x1 = _ellipse_closest(a, b, y0, y1)
        inside = (y0 / a) ** 2 + (y1 / b) ** 2 < 1.0
        dist = math.hypot(x0 - y0, x1 - y1)
        qu, qz = math.copysign(x0, pu), math.copysign(x1, pz)
        gu, gz = qu / (a * a), qz / (b * b)  # outward normal: gradient of the implicit form
        norm = math.hypot(gu, gz)
        nu, nz = gu / norm, gz / norm
        if swap:
            qu, qz, nu, nz = qz, qu, nz, nu
        return (-dist if inside else dist), qu, qz, nu, nz

    def support(self, du: float, dz: float) -> tuple[float, float]:
        a2, b2 = self.semi_axis_x ** 2, self.semi_axis_z ** 2
        scale = math.sqrt(a2 * du * du + b2 * dz * dz)
        return a2 * du / scale, b2 * dz / scale

    def line_interval(self, au: float, az: float, eu: float, ez: float
                      ) -> tuple[float, float] | None:
        ia2, ib2 = 1.0 / self.semi_axis_x ** 2, 1.0 / self.semi_axis_z ** 2
        return _quadratic_interval(eu * eu * ia2 + ez * ez * ib2, au * eu * ia2 + az * ez * ib2,
                                   au * au * ia2 + az * az * ib2 - 1.0)

    def mirrored(self) -> Ellipse:
        return self

    def scaled(self, factor: float) -> Ellipse:
        check_length('factor', factor, '')
        return Ellipse(self.semi_axis_x * factor, self.semi_axis_z * factor)

    def outline(self, faces: int) -> np.ndarray:
        return _tangent_polygon(self.semi_axis_x, self.semi_axis_z, faces)

    def describe(self) -> str:
        return (f'ellipse, {2e3 * self.semi_axis_x:.4g} mm wide and '
                f'{2e3 * self.semi_axis_z:.4g} mm high')

    @property
    def area(self) -> float:
        return math.pi * self.semi_axis_x * self.semi_axis_z

    @property
    def second_moments(self) -> tuple[float, float]:
        a, b = self.semi_axis_x, self.semi_axis_z
        return math.pi * a ** 3 * b / 4.0, math.pi * a * b ** 3 / 4.0

    @property
    def bottom(self) -> float:
        return -self.semi_axis_z

    @property
    def inradius(self) -> float:
        return min(self.semi_axis_x, self.semi_axis_z)

    @property
    def circumradius(self) -> float:
        return max(self.semi_axis_x, self.semi_axis_z)

    @property
    def min_width(self) -> float:
        return 2.0 * min(self.semi_axis_x, self.semi_axis_z)

    @property
    def symmetry_period(self) -> float:
        return math.pi


def check_length(name: str, value: float, unit: str = ' of metres') -> None:
    """Refuse anything but a positive finite number, naming ``name`` and the value.

    Raises
    ------
    ValueError
        ``value`` is a bool, not a real number, not finite or not positive.
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not math.isfinite(value) or value <= 0.0:
        raise ValueError(f'{name}: expected a positive number{unit}, got {value!r}')


def _quadratic_interval(qa: float, qb: float, qc: float) -> tuple[float, float] | None:
    """Where ``qa t^2 + 2 qb t + qc <= 0`` (qa > 0), None if nowhere (a tangent counts as
    nowhere)."""
    disc = qb * qb - qa * qc
    if disc <= 0.0:
        return None
    root = math.sqrt(disc)
    # the numerically stable pair of roots
    q = -(qb + math.copysign(root, qb)) if qb != 0.0 else root
    r1, r2 = q / qa, (qc / q if q != 0.0 else -q / qa)
    return (r1, r2) if r1 <= r2 else (r2, r1)


def _tangent_polygon(a: float, b: float, faces: int) -> np.ndarray:
    """Counter-clockwise polygon of ``faces`` faces tangent to the ellipse of semi-axes
    ``a``, ``b``, one face on the table (its normal straight down)."""
    if faces < 3:
        raise ValueError(f'faces: expected at least 3, got {faces!r}')
    # tangent lines at the points of eccentric angle psi_k; vertex k between lines k and k+1
    psi = -0.5 * math.pi + np.arange(faces) * 2.0 * math.pi / faces
    half = math.pi / faces
    mid = psi + half
    return np.stack([a * np.cos(mid) / math.cos(half), b * np.sin(mid) / math.cos(half)],
                    axis=1)


def _ellipse_closest(a: float, b: float, y0: float, y1: float) -> tuple[float, float]:
    """Closest point ``(x0, x1)`` of the ellipse ``(x/a)^2 + (z/b)^2 = 1`` (``a >= b``) to
    ``(y0, y1)`` in the first quadrant (Eberly 2013, inside and outside points alike)."""
    if y1 > 0.0:
        if y0 > 0.0:
            z0, z1 = y0 / a, y1 / b
            g = z0 * z0 + z1 * z1 - 1.0
            if g == 0.0:
                return y0, y1
            r0 = (a / b) ** 2
            u = _ellipse_root(r0, z0, z1, g)
            return r0 * y0 / (u - 1.0 + r0), y1 / u
        return 0.0, b
    numer = a * y0
    denom = a * a - b * b
    if numer < denom:
        ratio = numer / denom
        return a * ratio, b * math.sqrt(max(0.0, 1.0 - ratio * ratio))
    return a, 0.0


def _ellipse_root(r0: float, z0: float, z1: float, g: float) -> float:
    """Root ``u = s + 1`` of ``F(u) = (r0 z0 / (u - 1 + r0))^2 + (z1 / u)^2 - 1``.

    Eberly's root ``s`` tends to -1 for a point near the major axis; solving for ``u``
    instead keeps its relative precision there, so that ``x1 = y1 / u`` stays exact. ``F`` is
    convex and decreasing for ``u > 0`` and ``F(z1) >= 0``, so Newton's method from ``z1``
    climbs to the root without overshooting; a bisection of the bracket finishes what it
    leaves (a flat start far from the root).
    """
    n0 = r0 * z0
    lo, hi = z1, (1.0 if g < 0.0 else math.hypot(n0, z1))
    u = lo
    for _ in range(100):  # Newton from the left: F(u) >= 0 all the way
        a, b = n0 / (u - 1.0 + r0), z1 / u
        value = a * a + b * b - 1.0
        if value < 0.0:  # rounding put u past the root: it lies in [lo, u]
            hi = u
            break
        lo = u
        step = value / (2.0 * (a * a / (u - 1.0 + r0) + b * b / u))
        if not step > 4e-16 * u:
            return u
        u = min(u + step, hi)
    for _ in range(1100):  # bisection to the floating-point spacing at u
        u = 0.5 * (lo + hi)
        if u in (lo, hi):
            break
        a, b = n0 / (u - 1.0 + r0), z1 / u
        value = a * a + b * b - 1.0
        if value > 0.0:
            lo = u
        elif value < 0.0:
            hi = u
        else:
            break
    return u
