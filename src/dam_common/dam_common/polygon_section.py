"""The convex polygon cross-section: a prism column of any convex outline, and the regular
polygon lying on a face (a hexagonal pencil, a square bar).

Vertices are validated at the boundary (:func:`check_convex_polygon`: convex, no repeated or
collinear vertex, no self-intersection) and moved so that the centroid is the origin, as every
:class:`~dam_common.cross_section.CrossSection` is. This module is pure Python (math and
numpy); it does not import rclpy.
"""

from __future__ import annotations

import math
import operator
from collections.abc import Sequence

import numpy as np

from dam_common.cross_section import CrossSection, check_length
from dam_common.echo import brief_repr

#: Most vertices a convex polygon may have (a column's section, not a mesh).
MAX_VERTICES = 256


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
        check_length('factor', factor, '')
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
    check_length('across_flats', across_flats)
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
    count = len(vertices) if hasattr(vertices, '__len__') else 0
    if count > MAX_VERTICES:  # before converting them all
        raise ValueError(f'vertices: {count} vertices, at most {MAX_VERTICES}')
    try:
        v = np.array(vertices, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'vertices: expected a list of (x, z) pairs, got '
                         f'{brief_repr(vertices)}') from exc
    if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3:
        raise ValueError(f'vertices: expected at least 3 (x, z) pairs, got '
                         f'{brief_repr(vertices)}')
    if v.shape[0] > MAX_VERTICES:  # the checks below loop over them in Python
        raise ValueError(f'vertices: {v.shape[0]} vertices, at most {MAX_VERTICES}')
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
