"""Cross-sections of column objects lying on the table: circle, ellipse, convex polygon.

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

This module is pure Python (math and numpy); it does not import rclpy.
"""

from __future__ import annotations

import math
import numbers
import operator
from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

#: Points closer than this to a boundary count as on it [m] (well below any tolerance used).
_EPS_M = 1e-15
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
        _check_length('radius', self.radius)

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
        _check_length('factor', factor, '')
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
        _check_length('semi_axis_x', self.semi_axis_x)
        _check_length('semi_axis_z', self.semi_axis_z)

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
        _check_length('factor', factor, '')
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


class ConvexPolygon(CrossSection):
    """A convex polygon given by its vertices [m], moved so that its centroid is the origin.

    Parameters
    ----------
    vertices : (m, 2) ``(x, z)`` in order around the polygon (either sense), m >= 3.
    name : how :meth:`describe` calls it (e.g. ``'hexagon, 7 mm across flats'``).

    Raises
    ------
    ValueError
        Fewer than 3 vertices, a non-finite value, two equal neighbours, three in a row on one
        line, or a polygon that is not convex; the message names the vertex.
    """

    kind = 'polygon'

    def __init__(self, vertices: Sequence[Sequence[float]] | np.ndarray, name: str = '',
                 symmetry_period: float = 2.0 * math.pi) -> None:
        v = check_convex_polygon(vertices)
        self._symmetry_period = float(symmetry_period)
        self.vertices: np.ndarray = v - polygon_centroid(v)
        self.vertices.setflags(write=False)
        self.name = name
        nxt = np.roll(self.vertices, -1, axis=0)
        edge = nxt - self.vertices
        length = np.linalg.norm(edge, axis=1)
        normal = np.stack([edge[:, 1], -edge[:, 0]], axis=1) / length[:, None]
        self._verts = [tuple(map(float, p)) for p in self.vertices]
        self._edges = [tuple(map(float, e)) for e in edge]
        self._edge_len2 = [float(x) ** 2 for x in length]
        self._normals = [tuple(map(float, n)) for n in normal]
        self._offsets = [float(n @ p) for n, p in zip(normal, self.vertices, strict=True)]

    def __repr__(self) -> str:
        return f'ConvexPolygon({self.vertices.tolist()!r}, name={self.name!r})'

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, ConvexPolygon)
                and np.array_equal(self.vertices, other.vertices))

    def __hash__(self) -> int:
        return hash(self.vertices.tobytes())

    def distance(self, pu: float, pz: float) -> tuple[float, float, float, float, float]:
        inside_depth = -math.inf
        face = 0
        for k, ((nu, nz), off) in enumerate(zip(self._normals, self._offsets, strict=True)):
            s = nu * pu + nz * pz - off
            if s > inside_depth:
                inside_depth, face = s, k
        if inside_depth <= 0.0:  # inside: the nearest face is the least violated half-plane
            nu, nz = self._normals[face]
            return inside_depth, pu - inside_depth * nu, pz - inside_depth * nz, nu, nz
        best = math.inf
        best_q = (0.0, 0.0)
        for (vu, vz), (eu, ez), len2 in zip(self._verts, self._edges, self._edge_len2,
                                            strict=True):
            t = ((pu - vu) * eu + (pz - vz) * ez) / len2
            t = 0.0 if t < 0.0 else (1.0 if t > 1.0 else t)
            qu, qz = vu + t * eu, vz + t * ez
            d = math.hypot(pu - qu, pz - qz)
            if d < best:
                best, best_q = d, (qu, qz)
        qu, qz = best_q
        if best == 0.0:  # on an edge, to rounding: the least violated face's normal
            nu, nz = self._normals[face]
            return 0.0, qu, qz, nu, nz
        return best, qu, qz, (pu - qu) / best, (pz - qz) / best

    def support(self, du: float, dz: float) -> tuple[float, float]:
        return max(self._verts, key=lambda p: p[0] * du + p[1] * dz)

    def line_interval(self, au: float, az: float, eu: float, ez: float
                      ) -> tuple[float, float] | None:
        t0, t1 = -math.inf, math.inf
        for (nu, nz), off in zip(self._normals, self._offsets, strict=True):
            # half-plane n . (a + t e) <= off
            rate = nu * eu + nz * ez
            slack = off - (nu * au + nz * az)
            if rate == 0.0:
                if slack < 0.0:
                    return None
                continue
            bound = slack / rate
            if rate > 0.0:
                t1 = min(t1, bound)
            else:
                t0 = max(t0, bound)
            if t0 > t1:
                return None
        return t0, t1

    def mirrored(self) -> ConvexPolygon:
        return ConvexPolygon(self.vertices[::-1] * np.array([-1.0, 1.0]), self.name,
                             self._symmetry_period)

    def scaled(self, factor: float) -> ConvexPolygon:
        _check_length('factor', factor, '')
        return ConvexPolygon(self.vertices * factor, self.name, self._symmetry_period)

    def outline(self, faces: int) -> np.ndarray:
        return self.vertices.copy()

    def describe(self) -> str:
        return self.name or f'convex polygon of {len(self._verts)} vertices'

    @property
    def area(self) -> float:
        x, z = self.vertices[:, 0], self.vertices[:, 1]
        return 0.5 * float(np.sum(x * np.roll(z, -1) - np.roll(x, -1) * z))

    @property
    def second_moments(self) -> tuple[float, float]:
        x, z = self.vertices[:, 0], self.vertices[:, 1]
        x1, z1 = np.roll(x, -1), np.roll(z, -1)
        cross = x * z1 - x1 * z
        return (float(np.sum(cross * (x * x + x * x1 + x1 * x1))) / 12.0,
                float(np.sum(cross * (z * z + z * z1 + z1 * z1))) / 12.0)

    @property
    def symmetry_period(self) -> float:
        """``2 pi / sides`` for :func:`regular_polygon`; 2 pi otherwise."""
        return self._symmetry_period

    @property
    def product_moment(self) -> float:
        x, z = self.vertices[:, 0], self.vertices[:, 1]
        x1, z1 = np.roll(x, -1), np.roll(z, -1)
        cross = x * z1 - x1 * z
        return float(np.sum(cross * (x * z1 + 2.0 * x * z + 2.0 * x1 * z1 + x1 * z))) / 24.0

    @property
    def bottom(self) -> float:
        return float(self.vertices[:, 1].min())

    @property
    def inradius(self) -> float:
        return float(min(self._offsets))

    @property
    def circumradius(self) -> float:
        return float(np.linalg.norm(self.vertices, axis=1).max())

    @property
    def min_width(self) -> float:
        # the width of a convex polygon is smallest across one of its edges
        return float(max(0.0, min(
            max(float(np.asarray(n) @ p) for p in self.vertices) - min(
                float(np.asarray(n) @ p) for p in self.vertices)
            for n in self._normals)))


def regular_polygon(sides: int, across_flats: float) -> ConvexPolygon:
    """A regular polygon lying on a face: ``sides`` >= 3 faces, ``across_flats`` [m] between
    opposite faces (twice the inradius, whatever the number of sides).

    Raises
    ------
    ValueError
        ``sides`` < 3 or ``across_flats`` not a positive finite number.
    """
    try:
        count = operator.index(sides) if not isinstance(sides, bool) else -1
    except TypeError:
        count = -1
    if count < 3:
        raise ValueError(f'sides: expected an integer >= 3, got {sides!r}')
    sides = count
    _check_length('across_flats', across_flats)
    inradius = across_flats / 2.0
    circumradius = inradius / math.cos(math.pi / sides)
    # face normals at -90 deg (the face on the table) + k * 360/sides; vertices between them
    angles = -0.5 * math.pi + (np.arange(sides) + 0.5) * 2.0 * math.pi / sides
    vertices = circumradius * np.stack([np.cos(angles), np.sin(angles)], axis=1)
    names = {3: 'triangle', 4: 'square', 5: 'pentagon', 6: 'hexagon', 8: 'octagon'}
    name = names.get(sides, f'regular {sides}-gon')
    return ConvexPolygon(vertices, f'{name}, {across_flats * 1e3:.4g} mm across flats',
                         2.0 * math.pi / sides)


def check_convex_polygon(vertices: Sequence[Sequence[float]] | np.ndarray) -> np.ndarray:
    """Vertices as a clean counter-clockwise ``(m, 2)`` float64 array of a convex polygon.

    Raises
    ------
    ValueError
        See :class:`ConvexPolygon`.
    """
    try:
        v = np.array(vertices, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'vertices: expected a list of (x, z) pairs, got {vertices!r}') from exc
    if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3:
        raise ValueError(f'vertices: expected at least 3 (x, z) pairs, got {vertices!r}')
    if not np.isfinite(v).all():
        k = int(np.flatnonzero(~np.isfinite(v).all(axis=1))[0])
        raise ValueError(f'vertices[{k}]: expected finite numbers, got {v[k].tolist()!r}')
    x, z = v[:, 0], v[:, 1]
    if float(np.sum(x * np.roll(z, -1) - np.roll(x, -1) * z)) < 0.0:
        v = v[::-1].copy()
    scale = float(np.abs(v).max())
    m = v.shape[0]
    for k in range(m):
        if float(np.hypot(*(v[(k + 1) % m] - v[k]))) <= 1e-12 * scale:
            raise ValueError(f'vertices: vertex {v[(k + 1) % m].tolist()!r} repeats its '
                             'neighbour')
    for k in range(m):
        e1 = v[(k + 1) % m] - v[k]
        e2 = v[(k + 2) % m] - v[(k + 1) % m]
        turn = float(e1[0] * e2[1] - e1[1] * e2[0])
        if turn <= 1e-12 * scale * scale:
            what = 'lies on the line of its neighbours' if turn > -1e-12 * scale * scale \
                else 'makes the polygon non-convex'
            raise ValueError(f'vertices: vertex {v[(k + 1) % m].tolist()!r} {what}')
    # a convex turn at every vertex can still wind around twice (a star): total turn 2 pi
    headings = np.arctan2(*(np.roll(v, -1, axis=0) - v)[:, ::-1].T)
    total = float(np.sum(np.mod(np.diff(np.append(headings, headings[0])), 2.0 * math.pi)))
    if abs(total - 2.0 * math.pi) > 1e-6:
        raise ValueError(f'vertices: the outline winds {total / (2.0 * math.pi):.0f} times '
                         'around (a self-intersecting polygon)')
    return v


def polygon_centroid(vertices: np.ndarray) -> np.ndarray:
    """Area centroid (2,) of a simple polygon [m] (the shoelace formula)."""
    x, z = vertices[:, 0], vertices[:, 1]
    x1, z1 = np.roll(x, -1), np.roll(z, -1)
    cross = x * z1 - x1 * z
    area = 0.5 * float(np.sum(cross))
    return np.array([float(np.sum((x + x1) * cross)), float(np.sum((z + z1) * cross))]) / (
        6.0 * area)


def _check_length(name: str, value: float, unit: str = ' of metres') -> None:
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
