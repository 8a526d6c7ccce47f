"""Cross-sections of column objects (dam_common.cross_section) against independent references.

Nothing here reuses the module's formulas. Every shape is re-described in this file: a circle
or an ellipse by its parametric boundary ``(a cos s, b sin s)`` (sampled densely, the nearest
sample refined by a root search on the derivative of the squared distance), a polygon by its
vertex list (the exact distance to every edge, an own point-in-convex-polygon test, an own
centroid and moments by exact triangle quadrature). Closed forms are the textbook ones
(area and second moments of a disc, an ellipse, a regular polygon).
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import brentq, minimize_scalar

from dam_common.cross_section import Circle, Ellipse, SegmentDistance
from dam_common.polygon_section import ConvexPolygon, check_convex_polygon, regular_polygon

#: An asymmetric convex pentagon resting on its face z = 0 [m] (not centred on purpose).
ASYMMETRIC = [(0.0, 0.0), (0.024, 0.0), (0.019, 0.011), (0.006, 0.015), (-0.004, 0.007)]


# --------------------------------------------------------------------------------------------
# Independent references


class CurveRef:
    """Boundary ``(a cos s, b sin s)``: dense samples ``pts``; the nearest point is the best
    of a coarser sampling refined by a root search on the derivative of the squared
    distance."""

    def __init__(self, a: float, b: float, samples: int = 20000, coarse: int = 2000) -> None:
        self.a, self.b = a, b
        self.s = np.linspace(0.0, 2.0 * math.pi, samples, endpoint=False)
        self.pts = np.column_stack([a * np.cos(self.s), b * np.sin(self.s)])
        self.ds = 2.0 * math.pi / samples
        self._cs = np.linspace(0.0, 2.0 * math.pi, coarse, endpoint=False)
        self._cpts = np.column_stack([a * np.cos(self._cs), b * np.sin(self._cs)])
        self._cds = 2.0 * math.pi / coarse

    def point(self, s: float) -> np.ndarray:
        return np.array([self.a * math.cos(s), self.b * math.sin(s)])

    def inside(self, p: np.ndarray) -> bool | np.ndarray:
        p = np.asarray(p)
        return (p[..., 0] / self.a) ** 2 + (p[..., 1] / self.b) ** 2 < 1.0

    def nearest(self, p: np.ndarray) -> tuple[float, np.ndarray]:
        """Unsigned distance from ``p`` to the boundary and the foot point."""
        d2 = np.sum((self._cpts - p) ** 2, axis=1)
        i = int(np.argmin(d2))
        a, b = self.a, self.b
        px, pz = float(p[0]), float(p[1])

        def slope(s: float) -> float:  # d/ds of |P(s) - p|^2 / 2
            return ((a * math.cos(s) - px) * (-a * math.sin(s))
                    + (b * math.sin(s) - pz) * (b * math.cos(s)))

        lo, hi = self._cs[i] - self._cds, self._cs[i] + self._cds
        best = self._cs[i]
        if slope(lo) < 0.0 < slope(hi):
            best = brentq(slope, lo, hi, xtol=1e-15, rtol=1e-15)
        foot = self.point(best)
        return float(np.hypot(*(p - foot))), foot


class PolygonRef:
    """A convex polygon by its counter-clockwise vertices: exact edge distances."""

    def __init__(self, vertices: np.ndarray, per_edge: int = 2000) -> None:
        self.v = np.asarray(vertices, dtype=float)
        self.e = np.roll(self.v, -1, axis=0) - self.v
        frac = np.arange(per_edge) / per_edge
        self.pts = (self.v[:, None, :] + frac[None, :, None] * self.e[:, None, :]).reshape(-1, 2)

    def inside(self, p: np.ndarray) -> bool | np.ndarray:
        p = np.asarray(p)
        rel = p[..., None, :] - self.v  # (..., m, 2)
        cross = self.e[:, 0] * rel[..., 1] - self.e[:, 1] * rel[..., 0]
        return np.all(cross > 0.0, axis=-1)

    def nearest(self, p: np.ndarray) -> tuple[float, np.ndarray]:
        t = np.clip(np.sum((p - self.v) * self.e, axis=1) / np.sum(self.e ** 2, axis=1), 0, 1)
        feet = self.v + t[:, None] * self.e
        d = np.hypot(*(p - feet).T)
        k = int(np.argmin(d))
        return float(d[k]), feet[k]


def signed(ref, p: np.ndarray) -> float:
    dist, _ = ref.nearest(p)
    return -dist if ref.inside(p) else dist


def foot_is_unique(ref, p: np.ndarray, spread: float = 1e-3) -> bool:
    """All boundary samples within 1 um of the best one are close together."""
    d = np.hypot(*(ref.pts - p).T)
    near = ref.pts[d <= d.min() + 1e-6]
    return float(np.ptp(near, axis=0).max()) < spread


def shoelace_area(v: np.ndarray) -> float:
    total = 0.0
    for k in range(len(v)):
        (x0, z0), (x1, z1) = v[k], v[(k + 1) % len(v)]
        total += x0 * z1 - x1 * z0
    return 0.5 * total


def triangle_moments(v: np.ndarray) -> tuple[float, float, float, float, float]:
    """(area, int x, int z, int x^2, int z^2) of a convex polygon by a fan of triangles from
    its first vertex, each integrated by the edge-midpoint rule (exact up to degree 2)."""
    out = np.zeros(5)
    p0 = v[0]
    for k in range(1, len(v) - 1):
        p1, p2 = v[k], v[k + 1]
        area = 0.5 * ((p1[0] - p0[0]) * (p2[1] - p0[1]) - (p2[0] - p0[0]) * (p1[1] - p0[1]))
        mids = [(p0 + p1) / 2, (p1 + p2) / 2, (p2 + p0) / 2]
        out[0] += area
        for m in mids:
            out[1:] += area / 3.0 * np.array([m[0], m[1], m[0] ** 2, m[1] ** 2])
    return tuple(float(x) for x in out)


def centred(vertices) -> np.ndarray:
    v = np.asarray(vertices, dtype=float)
    area, mx, mz, _, _ = triangle_moments(v)
    return v - np.array([mx, mz]) / area


def face_line_polygon(sides: int, across_flats: float) -> np.ndarray:
    """Regular polygon as the intersection of its face lines: face k has the outward normal at
    -90 deg + k 360/sides (face 0 on the table) at distance across_flats / 2."""
    r = across_flats / 2.0
    normals = [(math.cos(-math.pi / 2 + 2 * math.pi * k / sides),
                math.sin(-math.pi / 2 + 2 * math.pi * k / sides)) for k in range(sides)]
    verts = []
    for k in range(sides):
        n1, n2 = normals[k], normals[(k + 1) % sides]
        verts.append(np.linalg.solve(np.array([n1, n2]), np.array([r, r])))
    return np.array(verts)


def same_vertex_set(a: np.ndarray, b: np.ndarray, atol: float) -> bool:
    if a.shape != b.shape:
        return False
    return all(np.min(np.hypot(*(b - p).T)) < atol for p in a)


# --------------------------------------------------------------------------------------------
# The sections under test, each with its reference


def _cases():
    """name -> (section, reference, circumradius from the test's own description)."""
    cases = {
        'circle': (Circle(0.010), CurveRef(0.010, 0.010), 0.010),
        'ellipse': (Ellipse(0.012, 0.008), CurveRef(0.012, 0.008), 0.012),
        'ellipse_tall': (Ellipse(0.008, 0.012), CurveRef(0.008, 0.012), 0.012),
        'ellipse_round': (Ellipse(0.010, 0.010 * (1 - 1e-9)), CurveRef(0.010, 0.010 * (1 - 1e-9)),
                          0.010),
    }
    for sides, flats in ((3, 0.020), (4, 0.016), (5, 0.020), (6, 0.007)):
        v = face_line_polygon(sides, flats)
        cases[f'polygon{sides}'] = (regular_polygon(sides, flats), PolygonRef(v),
                                    flats / 2 / math.cos(math.pi / sides))
    v = centred(ASYMMETRIC)
    cases['asymmetric'] = (ConvexPolygon(ASYMMETRIC, 'pentagon'), PolygonRef(v),
                           float(np.hypot(*v.T).max()))
    return cases


CASES = _cases()
NAMES = list(CASES)


def _test_points(name: str, ref, rc: float, n_random: int = 150, n_near: int = 40):
    rng = np.random.default_rng(NAMES.index(name) + 101)
    pts = list(rng.uniform(-1.8 * rc, 1.8 * rc, size=(n_random, 2)))
    pts += list(rng.uniform(-0.3 * rc, 0.3 * rc, size=(20, 2)))
    idx = rng.integers(0, len(ref.pts), n_near)
    for j, i in enumerate(idx):
        q = ref.pts[i]
        # a point off the boundary along the direction away from the centroid
        direction = q / np.hypot(*q)
        offset = [1e-9, -1e-9, 1e-6, -1e-6, 1e-4, -1e-4, 3e-3, -2e-3][j % 8]
        pts.append(q + offset * direction)
    pts += [np.array([0.0, 0.0]), np.array([0.0, 0.5 * rc]), np.array([0.7 * rc, 0.0]),
            np.array([0.0, -3.0 * rc]), np.array([2.5 * rc, 0.0]), np.array([-2.5 * rc, 1e-3])]
    return pts


@pytest.mark.parametrize('name', NAMES)
def test_signed_distance_closest_point_and_normal(name):
    section, ref, rc = CASES[name]
    checked_foot = 0
    for p in _test_points(name, ref, rc):
        d, qu, qz, nu, nz = section.distance(float(p[0]), float(p[1]))
        q, n = np.array([qu, qz]), np.array([nu, nz])
        expected = signed(ref, p)
        assert d == pytest.approx(expected, abs=1e-11), (name, p.tolist())
        # q is a boundary point at |d| from p, so it is a closest point
        assert ref.nearest(q)[0] < 1e-11, (name, p.tolist(), q.tolist())
        assert np.hypot(*(p - q)) == pytest.approx(abs(d), abs=1e-12)
        assert np.hypot(nu, nz) == pytest.approx(1.0, abs=1e-12)
        assert float(n @ q) > 0.0  # outward: the centroid lies behind the boundary
        if abs(d) > 1e-7:
            # p - q = d n (outside: n points from q to p; inside: from p through q)
            np.testing.assert_allclose(p - q, d * n, atol=1e-12 * (1 + abs(d) * 1e3))
        if abs(d) > 1e-7 and foot_is_unique(ref, p):
            _, foot = ref.nearest(p)
            np.testing.assert_allclose(q, foot, atol=2e-9, err_msg=f'{name} {p.tolist()}')
            np.testing.assert_allclose(n, (p - foot) / expected, atol=1e-6)
            checked_foot += 1
    assert checked_foot > 100


@pytest.mark.parametrize('name', NAMES)
def test_normal_is_the_gradient_of_the_distance(name):
    section, ref, rc = CASES[name]
    h = 1e-8
    checked = 0
    for p in _test_points(name, ref, rc, n_random=80, n_near=16):
        d, _, _, nu, nz = section.distance(float(p[0]), float(p[1]))
        if abs(d) < 1e-5 or not foot_is_unique(ref, p):
            continue
        u, z = float(p[0]), float(p[1])
        grad = [(section.distance(u + h, z)[0] - section.distance(u - h, z)[0]) / (2 * h),
                (section.distance(u, z + h)[0] - section.distance(u, z - h)[0]) / (2 * h)]
        np.testing.assert_allclose(grad, [nu, nz], atol=2e-6, err_msg=f'{name} {p.tolist()}')
        checked += 1
    assert checked > 40


def test_circle_centre_has_a_valid_closest_point():
    d, qu, qz, nu, nz = Circle(0.01).distance(0.0, 0.0)
    assert d == -0.01
    assert math.hypot(qu, qz) == pytest.approx(0.01)
    assert (nu, nz) == pytest.approx((qu / 0.01, qz / 0.01))


def test_ellipse_distance_inside_near_the_major_axis():
    """Inside points a hair off the major axis, where the closest point is off the axis
    (|x| < (a^2 - b^2) / a): the distance is continuous there, so it must match the
    reference (and the on-axis value) to the precision of any other point."""
    failures = []
    for a, b in ((0.012, 0.008), (0.008, 0.012)):
        section, ref = Ellipse(a, b), CurveRef(a, b)
        big, small = max(a, b), min(a, b)
        for frac in (-0.8, -0.3, 0.2, 0.5, 0.9):
            for off in (1e-16, 1e-14, 1e-13, 1e-12, 1e-10):
                along = frac * (big * big - small * small) / big
                p = np.array([along, off]) if a > b else np.array([off, along])
                d, qu, qz = section.distance(*p)[:3]
                expected = signed(ref, p)
                if abs(d - expected) > 1e-11 or abs((qu / a) ** 2 + (qz / b) ** 2 - 1) > 1e-12:
                    failures.append((a, b, p.tolist(), d, expected))
    assert not failures, (f'{len(failures)} points, e.g. (a, b, p, got, expected) = '
                          f'{failures[:3]}')


@pytest.mark.parametrize('name', NAMES)
def test_support_point(name):
    section, ref, _ = CASES[name]
    rng = np.random.default_rng(5)
    for ang in list(rng.uniform(0, 2 * math.pi, 60)) + [0.0, math.pi / 2, math.pi, -math.pi / 2]:
        direction = np.array([math.cos(ang), math.sin(ang)])
        s = np.array(section.support(*direction))
        assert ref.nearest(s)[0] < 1e-12
        best = float(np.max(ref.pts @ direction))
        assert float(s @ direction) >= best - 1e-15
        assert float(s @ direction) == pytest.approx(best, abs=5e-10)


@pytest.mark.parametrize('name', NAMES)
def test_line_interval(name):
    section, ref, rc = CASES[name]
    rng = np.random.default_rng(17)
    hits = misses = 0
    for _ in range(80):
        a = rng.uniform(-1.5 * rc, 1.5 * rc, 2)
        ang = rng.uniform(0, 2 * math.pi)
        e = rng.uniform(0.3, 3.0) * np.array([math.cos(ang), math.sin(ang)])
        span = (np.hypot(*a) + 2 * rc) / np.hypot(*e)
        ts = np.linspace(-span, span, 40001)
        inside = ref.inside(a + ts[:, None] * e)
        interval = section.line_interval(float(a[0]), float(a[1]), float(e[0]), float(e[1]))
        if not inside.any():
            # nowhere inside (at most a tangent touch)
            if interval is not None:
                t0, t1 = interval
                assert t1 - t0 < 2 * (ts[1] - ts[0])
            misses += 1
            continue
        assert interval is not None, (name, a.tolist(), e.tolist())
        t0, t1 = interval
        for t in (t0, t1):
            assert ref.nearest(a + t * e)[0] < 1e-12
        assert ref.inside(a + 0.5 * (t0 + t1) * e)
        ins = ts[inside]
        step = ts[1] - ts[0]
        assert t0 <= ins.min() <= t0 + step and t1 - step <= ins.max() <= t1
        hits += 1
    assert hits > 20 and misses > 5


def _segment_reference(ref, a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
    """Minimum over the segment of the reference signed distance and its parameter.

    A grid over t, then a golden-section search on the values in the two grid cells around
    the best node (the signed distance of a convex set is convex along a line, so the
    minimum lies there).
    """
    def f(t: float) -> float:
        return signed(ref, a + t * (b - a))

    ts = np.linspace(0.0, 1.0, 101)
    values = [f(t) for t in ts]
    j = int(np.argmin(values))
    lo, hi = float(ts[max(j - 1, 0)]), float(ts[min(j + 1, len(ts) - 1)])
    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    f1, f2 = f(x1), f(x2)
    while hi - lo > 1e-13:
        if f1 <= f2:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - ratio * (hi - lo)
            f1 = f(x1)
        else:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + ratio * (hi - lo)
            f2 = f(x2)
    return min((values[j], float(ts[j])), (f1, x1), (f2, x2))


@pytest.mark.parametrize('name', NAMES)
def test_segment_distance_against_sampling_along_the_segment(name):
    section, ref, rc = CASES[name]
    rng = np.random.default_rng(23)
    segments = [rng.uniform(-2 * rc, 2 * rc, (2, 2)) for _ in range(30)]
    segments += [rng.uniform(-0.4 * rc, 0.4 * rc, (2, 2)) for _ in range(6)]  # inside
    for _ in range(6):  # one end inside, one far outside
        segments.append(np.array([rng.uniform(-0.3 * rc, 0.3 * rc, 2),
                                  rng.uniform(1.5 * rc, 2.0 * rc, 2) * rng.choice([-1, 1], 2)]))
    for _ in range(6):  # outside, parallel-ish to the boundary near a boundary point
        q = ref.pts[rng.integers(len(ref.pts))]
        out = q / np.hypot(*q)
        tangent = np.array([-out[1], out[0]])
        c = q + rng.uniform(1e-5, 2e-3) * out
        segments.append(np.array([c - 0.4 * rc * tangent, c + 0.7 * rc * tangent]))
    for _ in range(8):  # well clear of the section
        centre = rng.uniform(1.3 * rc, 2.0 * rc) * np.array([1.0, 0.0])
        turn = rng.uniform(0, 2 * math.pi)
        rot = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
        segments.append((centre + rng.uniform(-0.2 * rc, 0.2 * rc, (2, 2))) @ rot.T)
    kinds = {'inside': 0, 'outside': 0}
    for a, b in segments:
        sd = section.segment_distance(float(a[0]), float(a[1]), float(b[0]), float(b[1]))
        assert isinstance(sd, SegmentDistance)
        expected, _ = _segment_reference(ref, a, b)
        assert sd.distance == pytest.approx(expected, abs=1e-10), (name, a.tolist(), b.tolist())
        assert 0.0 <= sd.t <= 1.0
        sp, qp, n = np.array(sd.segment_point), np.array(sd.section_point), np.array(sd.normal)
        np.testing.assert_allclose(sp, a + sd.t * (b - a), atol=1e-13)
        assert signed(ref, sp) == pytest.approx(expected, abs=1e-10)
        assert ref.nearest(qp)[0] < 1e-11
        assert np.hypot(*(sp - qp)) == pytest.approx(abs(sd.distance), abs=1e-11)
        assert np.hypot(*n) == pytest.approx(1.0, abs=1e-12)
        if abs(sd.distance) > 1e-6:
            # the normal points from the section towards the segment (out of the section)
            np.testing.assert_allclose(sp - qp, sd.distance * n, atol=1e-10)
        kinds['inside' if expected < 0.0 else 'outside'] += 1
    assert kinds['inside'] >= 15 and kinds['outside'] >= 15, kinds


def test_segment_distance_crossing_is_the_deepest_point():
    """A horizontal chord through a 16 mm square at height z: depth min(8 - |z|, 8) mm at the
    middle; a diagonal through the centre of a disc: depth R at the centre."""
    square = regular_polygon(4, 0.016)
    for z in (0.0, 0.002, -0.005):
        sd = square.segment_distance(-0.03, z, 0.02, z)
        assert sd.distance == pytest.approx(-(0.008 - abs(z)), abs=1e-12)
        assert abs(sd.segment_point[0]) <= 0.008 - (0.008 - abs(z)) + 1e-9
    sd = Circle(0.01).segment_distance(-0.02, -0.02, 0.01, 0.01)
    assert sd.distance == pytest.approx(-0.01, abs=1e-12)
    np.testing.assert_allclose(sd.segment_point, (0.0, 0.0), atol=1e-8)
    assert sd.t == pytest.approx(2.0 / 3.0, abs=1e-6)
    sd = Ellipse(0.012, 0.008).segment_distance(-0.03, 0.0, 0.03, 0.0)
    assert sd.distance == pytest.approx(-0.008, abs=1e-12)


def test_segment_distance_flat_face_and_end_cases():
    square = regular_polygon(4, 0.016)
    # parallel to the top face, overlapping it: 2 mm above it
    for x0, x1 in ((-0.02, 0.02), (0.005, 0.03), (-0.03, -0.005)):
        assert square.segment_distance(x0, 0.010, x1, 0.010).distance == pytest.approx(0.002)
    # beyond the top right corner: the nearer end, distance to the corner
    sd = square.segment_distance(0.011, 0.012, 0.05, 0.012)
    assert sd.distance == pytest.approx(math.hypot(0.003, 0.004))
    assert sd.t == 0.0
    np.testing.assert_allclose(sd.section_point, (0.008, 0.008), atol=1e-15)
    # the line crosses the square but the segment stops short of it
    sd = square.segment_distance(0.03, 0.0, 0.012, 0.0)
    assert sd.distance == pytest.approx(0.004) and sd.t == 1.0
    # touching a face
    assert square.segment_distance(-0.02, 0.008, 0.02, 0.008).distance == pytest.approx(
        0.0, abs=1e-15)
    assert Circle(0.01).segment_distance(-0.02, 0.01, 0.02, 0.01).distance == pytest.approx(
        0.0, abs=1e-15)


@pytest.mark.parametrize('section', [Circle(0.01), Ellipse(0.012, 0.008),
                                     regular_polygon(6, 0.007)])
def test_segment_of_zero_length_is_refused(section):
    with pytest.raises(ValueError, match='zero length'):
        section.segment_distance(0.02, 0.01, 0.02, 0.01)


# --------------------------------------------------------------------------------------------
# Area, moments and extents


def _regular_closed_form(sides: int, across_flats: float) -> tuple[float, float]:
    """Area and int x^2 dA (= int z^2 dA) of a regular polygon: J = A (6 R^2 - s^2) / 12."""
    r = across_flats / 2
    big_r = r / math.cos(math.pi / sides)
    side = 2 * big_r * math.sin(math.pi / sides)
    area = sides * r * r * math.tan(math.pi / sides)
    return area, area * (6 * big_r ** 2 - side ** 2) / 24


@pytest.mark.parametrize('sides,flats', [(3, 0.02), (4, 0.016), (5, 0.02), (6, 0.007),
                                         (7, 0.011), (64, 0.02), (256, 0.02)])
def test_regular_polygon_area_and_second_moments(sides, flats):
    poly = regular_polygon(sides, flats)
    area, moment = _regular_closed_form(sides, flats)
    assert poly.area == pytest.approx(area, rel=1e-12)
    assert poly.second_moments == pytest.approx((moment, moment), rel=1e-11)
    if sides == 4:
        assert poly.area == pytest.approx(flats ** 2)
        assert poly.second_moments[0] == pytest.approx(flats ** 4 / 12, rel=1e-12)
    if sides == 6:
        s = flats / math.sqrt(3.0)
        assert poly.area == pytest.approx(1.5 * math.sqrt(3.0) * s * s, rel=1e-12)
        assert poly.second_moments[1] == pytest.approx(5 * math.sqrt(3.0) / 16 * s ** 4,
                                                       rel=1e-12)
    # the same from an independent quadrature of the polygon's own vertices
    a, mx, mz, ixx, izz = triangle_moments(poly.vertices)
    assert (a, ixx, izz) == pytest.approx((poly.area, *poly.second_moments), rel=1e-10)
    assert abs(mx) < 1e-12 * a * flats and abs(mz) < 1e-12 * a * flats


def test_circle_and_ellipse_area_and_second_moments():
    c = Circle(0.01)
    assert c.area == pytest.approx(math.pi * 1e-4, rel=1e-14)
    assert c.second_moments == pytest.approx((math.pi * 1e-8 / 4,) * 2, rel=1e-14)
    for a, b in ((0.012, 0.008), (0.008, 0.012)):
        e = Ellipse(a, b)
        assert e.area == pytest.approx(math.pi * a * b, rel=1e-14)
        assert e.second_moments == pytest.approx((math.pi * a ** 3 * b / 4,
                                                  math.pi * a * b ** 3 / 4), rel=1e-14)
    # Monte-Carlo-free check of the ellipse moments: a fine inscribed polygon's quadrature
    s = np.linspace(0, 2 * math.pi, 20000, endpoint=False)
    v = np.column_stack([0.012 * np.cos(s), 0.008 * np.sin(s)])
    area, _, _, ixx, izz = triangle_moments(v)
    e = Ellipse(0.012, 0.008)
    assert (area, ixx, izz) == pytest.approx((e.area, *e.second_moments), rel=1e-7)


def test_asymmetric_polygon_is_centred_and_integrates():
    poly = ConvexPolygon(ASYMMETRIC, 'pentagon')
    expected = centred(ASYMMETRIC)
    np.testing.assert_allclose(poly.vertices, expected, atol=1e-15)
    area, mx, mz, ixx, izz = triangle_moments(poly.vertices)
    assert abs(mx) < 1e-18 and abs(mz) < 1e-18
    assert poly.area == pytest.approx(area, rel=1e-12)
    assert poly.area == pytest.approx(shoelace_area(np.array(ASYMMETRIC)), rel=1e-12)
    assert poly.second_moments == pytest.approx((ixx, izz), rel=1e-11)
    # vertices may not be written to (the section is a value)
    with pytest.raises(ValueError):
        poly.vertices[0, 0] = 1.0
    # clockwise input gives the same counter-clockwise polygon
    cw = ConvexPolygon(ASYMMETRIC[::-1])
    assert shoelace_area(cw.vertices) > 0.0
    assert same_vertex_set(cw.vertices, poly.vertices, 1e-15)
    assert cw.area == pytest.approx(poly.area)


def _width_reference(pts: np.ndarray) -> float:
    def width(ang: float) -> float:
        proj = pts @ np.array([math.cos(ang), math.sin(ang)])
        return float(proj.max() - proj.min())

    angs = np.linspace(0, math.pi, 3601)
    j = int(np.argmin([width(x) for x in angs]))
    res = minimize_scalar(width, bounds=(angs[max(j - 1, 0)], angs[min(j + 1, 3600)]),
                          method='bounded', options={'xatol': 1e-12})
    return min(width(angs[j]), float(res.fun))


@pytest.mark.parametrize('name', NAMES)
def test_bottom_inradius_circumradius_min_width(name):
    section, ref, rc = CASES[name]
    pts = ref.pts
    assert section.bottom == pytest.approx(float(pts[:, 1].min()), abs=1e-10)
    assert section.rest_height == pytest.approx(-section.bottom)
    assert section.circumradius == pytest.approx(rc, abs=1e-12)
    assert section.circumradius == pytest.approx(float(np.hypot(*pts.T).max()), abs=1e-10)
    assert section.inradius == pytest.approx(ref.nearest(np.zeros(2))[0], abs=1e-12)
    ref_pts = ref.v if isinstance(ref, PolygonRef) else pts
    assert section.min_width == pytest.approx(_width_reference(ref_pts), abs=1e-9)


@pytest.mark.parametrize('sides,flats', [(3, 0.02), (4, 0.016), (5, 0.02), (6, 0.007),
                                         (7, 0.011), (8, 0.01), (32, 0.02), (256, 0.02)])
def test_regular_polygon_geometry(sides, flats):
    poly = regular_polygon(sides, flats)
    assert isinstance(poly, ConvexPolygon) and poly.kind == 'polygon'
    assert poly.vertices.shape == (sides, 2)
    assert same_vertex_set(poly.vertices, face_line_polygon(sides, flats), 1e-15)
    assert poly.inradius == pytest.approx(flats / 2, rel=1e-13)
    assert poly.circumradius == pytest.approx(flats / 2 / math.cos(math.pi / sides), rel=1e-13)
    assert poly.bottom == pytest.approx(-flats / 2, rel=1e-13)
    # lying on a face: exactly two vertices (neighbours) on the table, the face centred
    low = np.flatnonzero(poly.vertices[:, 1] < poly.bottom + 1e-12 * flats)
    assert len(low) == 2 and (low[1] - low[0]) % (sides - 2) in (1, 0)
    assert poly.vertices[low, 0].sum() == pytest.approx(0.0, abs=1e-15)
    width = flats if sides % 2 == 0 else flats / 2 * (1 + 1 / math.cos(math.pi / sides))
    assert poly.min_width == pytest.approx(width, rel=1e-12)
    assert 'across flats' in poly.describe()


def test_regular_polygon_names():
    assert regular_polygon(6, 0.007).describe() == 'hexagon, 7 mm across flats'
    assert regular_polygon(4, 0.016).describe() == 'square, 16 mm across flats'


# --------------------------------------------------------------------------------------------
# Outline, mirror, scale


@pytest.mark.parametrize('a,b', [(0.01, 0.01), (0.012, 0.008), (0.008, 0.012)])
@pytest.mark.parametrize('faces', [3, 4, 7, 8, 64])
def test_outline_of_a_curve_contains_it_and_rests_on_a_face(a, b, faces):
    section = Circle(a) if a == b else Ellipse(a, b)
    ref = CurveRef(a, b, samples=4000)
    out = section.outline(faces)
    assert out.shape == (faces, 2)
    assert shoelace_area(out) > 0.0  # counter-clockwise
    edges = np.roll(out, -1, axis=0) - out
    turns = edges[:, 0] * np.roll(edges, -1, axis=0)[:, 1] - edges[:, 1] * np.roll(
        edges, -1, axis=0)[:, 0]
    assert np.all(turns > 0.0)  # convex
    for k in range(faces):
        n = np.array([edges[k, 1], -edges[k, 0]]) / np.hypot(*edges[k])
        gap = float(n @ out[k]) - ref.pts @ n
        assert gap.min() > -1e-15  # the curve is inside the face's half-plane
        # and touches it (tangent): the closest curve point, refined on the parameter
        j = int(np.argmin(gap))
        res = minimize_scalar(lambda s, n=n, k=k: float(n @ out[k] - n @ ref.point(s)),
                              bounds=(ref.s[j] - ref.ds, ref.s[j] + ref.ds), method='bounded',
                              options={'xatol': 1e-12})
        assert -1e-15 < res.fun < 1e-15
    # one face on the table z = bottom, the others above
    low = np.flatnonzero(out[:, 1] <= section.bottom + 1e-15)
    assert len(low) == 2
    assert np.all(np.abs(out[low, 1] - section.bottom) < 1e-15)
    assert low[1] - low[0] in (1, faces - 1)
    if a == b:  # vertices of a tangent polygon of a circle lie at R / cos(pi / faces)
        np.testing.assert_allclose(np.hypot(*out.T), a / math.cos(math.pi / faces), rtol=1e-13)


def test_outline_faces_below_three_refused():
    for section in (Circle(0.01), Ellipse(0.012, 0.008)):
        with pytest.raises(ValueError, match='faces'):
            section.outline(2)


def test_outline_of_a_polygon_is_its_vertices():
    poly = ConvexPolygon(ASYMMETRIC)
    out = poly.outline(64)
    np.testing.assert_array_equal(out, poly.vertices)
    out[0, 0] = 1.0  # a copy
    assert poly.vertices[0, 0] != 1.0
    low = np.flatnonzero(poly.vertices[:, 1] <= poly.bottom + 1e-15)
    assert len(low) == 2  # the pentagon rests on its face z = 0 of the input


def test_mirrored_asymmetric_polygon():
    poly = ConvexPolygon(ASYMMETRIC, 'pentagon')
    mirror = poly.mirrored()
    assert isinstance(mirror, ConvexPolygon)
    assert same_vertex_set(mirror.vertices, poly.vertices * np.array([-1.0, 1.0]), 1e-15)
    assert shoelace_area(mirror.vertices) > 0.0
    assert mirror.area == pytest.approx(poly.area)
    assert mirror.second_moments == pytest.approx(poly.second_moments)
    assert mirror.bottom == pytest.approx(poly.bottom)
    assert mirror.min_width == pytest.approx(poly.min_width)
    assert mirror != poly
    np.testing.assert_allclose(mirror.mirrored().vertices, poly.vertices, atol=1e-17)
    ref = PolygonRef((centred(ASYMMETRIC) * np.array([-1.0, 1.0]))[::-1])
    rng = np.random.default_rng(2)
    for p in rng.uniform(-0.03, 0.03, (100, 2)):
        d, qu, qz, nu, nz = mirror.distance(*p)
        d0, qu0, qz0, nu0, nz0 = poly.distance(-p[0], p[1])
        assert d == pytest.approx(d0, abs=1e-15)
        assert d == pytest.approx(signed(ref, p), abs=1e-12)
        assert (qu, qz, nu, nz) == pytest.approx((-qu0, qz0, -nu0, nz0), abs=1e-12)
        sd = mirror.segment_distance(p[0], p[1], 0.02, 0.015)
        sd0 = poly.segment_distance(-p[0], p[1], -0.02, 0.015)
        assert sd.distance == pytest.approx(sd0.distance, abs=1e-13)
    for section in (Circle(0.01), Ellipse(0.012, 0.008)):
        m = section.mirrored()
        for p in rng.uniform(-0.02, 0.02, (20, 2)):
            assert m.distance(*p)[0] == pytest.approx(section.distance(-p[0], p[1])[0],
                                                      abs=1e-15)


def test_scaled_sections():
    rng = np.random.default_rng(4)
    for section in (Circle(0.01), Ellipse(0.012, 0.008), ConvexPolygon(ASYMMETRIC),
                    regular_polygon(6, 0.007)):
        big = section.scaled(2.5)
        assert big.kind == section.kind
        assert big.area == pytest.approx(2.5 ** 2 * section.area)
        assert big.second_moments == pytest.approx(
            tuple(2.5 ** 4 * m for m in section.second_moments))
        assert big.inradius == pytest.approx(2.5 * section.inradius)
        assert big.circumradius == pytest.approx(2.5 * section.circumradius)
        assert big.min_width == pytest.approx(2.5 * section.min_width)
        assert big.bottom == pytest.approx(2.5 * section.bottom)
        for p in rng.uniform(-0.02, 0.02, (20, 2)):
            assert big.distance(*(2.5 * p))[0] == pytest.approx(
                2.5 * section.distance(*p)[0], abs=1e-14)


# --------------------------------------------------------------------------------------------
# Rejection of bad input


def _pentagram():
    ang = -math.pi / 2 + 2 * math.pi * np.arange(5) / 5
    pts = 0.01 * np.column_stack([np.cos(ang), np.sin(ang)])
    return pts[[0, 2, 4, 1, 3]]


BAD_POLYGONS = [
    ('non-convex', [(0, 0), (0.02, 0), (0.01, 0.005), (0.02, 0.02), (0, 0.02)],
     r'vertex \[0\.01, 0\.005\] makes the polygon non-convex'),
    ('repeated', [(0, 0), (0.01, 0), (0.01, 0), (0.01, 0.01), (0, 0.01)],
     r'vertex \[0\.01, 0\.0\] repeats its neighbour'),
    ('closed ring', [(0, 0), (0.01, 0), (0.01, 0.01), (0, 0.01), (0, 0)],
     r'vertex \[0\.0, 0\.0\] repeats its neighbour'),
    ('collinear', [(0, 0), (0.01, 0), (0.02, 0), (0.02, 0.01), (0, 0.01)],
     r'vertex \[0\.01, 0\.0\] lies on the line of its neighbours'),
    ('bow tie', [(0, 0), (0.01, 0.01), (0.01, 0), (0, 0.01)], r'vertex .* non-convex'),
    ('star', _pentagram(), r'winds 2 times.*self-intersecting'),
    ('nan', [(0, 0), (0.01, 0), (math.nan, 0.01), (0, 0.01)],
     r'vertices\[2\]: expected finite numbers'),
    ('inf', [(0, 0), (0.01, math.inf), (0, 0.01)], r'vertices\[1\]: expected finite numbers'),
    ('two vertices', [(0, 0), (0.01, 0)], r'at least 3'),
    ('one vertex', [(0, 0)], r'at least 3'),
    ('empty', [], r'at least 3'),
    ('triples', [(0, 0, 0), (1, 0, 0), (0, 1, 0)], r'at least 3 \(x, z\) pairs'),
    ('ragged', [(0, 0), (1, 0, 2), (0, 1)], r'vertices'),
    ('text', [('a', 'b'), (1, 0), (0, 1)], r'vertices'),
    ('all collinear', [(0, 0), (0.01, 0), (0.02, 0)], r'line of its neighbours|non-convex'),
]


@pytest.mark.parametrize('label,vertices,pattern', BAD_POLYGONS, ids=[b[0] for b in BAD_POLYGONS])
def test_bad_polygons_are_refused(label, vertices, pattern):
    with pytest.raises(ValueError, match=pattern):
        check_convex_polygon(vertices)
    with pytest.raises(ValueError, match=pattern):
        ConvexPolygon(vertices)


@pytest.mark.parametrize('make,field', [
    (lambda: Circle(0.0), 'radius'),
    (lambda: Circle(-0.01), 'radius'),
    (lambda: Circle(math.nan), 'radius'),
    (lambda: Circle(math.inf), 'radius'),
    (lambda: Circle(True), 'radius'),
    (lambda: Circle('0.01'), 'radius'),
    (lambda: Ellipse(0.0, 0.01), 'semi_axis_x'),
    (lambda: Ellipse(0.01, -0.002), 'semi_axis_z'),
    (lambda: Ellipse(0.01, math.nan), 'semi_axis_z'),
    (lambda: regular_polygon(2, 0.01), 'sides'),
    (lambda: regular_polygon(6.0, 0.01), 'sides'),
    (lambda: regular_polygon(True, 0.01), 'sides'),
    (lambda: regular_polygon(6, 0.0), 'across_flats'),
    (lambda: regular_polygon(6, -0.007), 'across_flats'),
    (lambda: regular_polygon(6, math.inf), 'across_flats'),
])
def test_bad_sizes_are_refused(make, field):
    with pytest.raises(ValueError, match=rf'^{field}: '):
        make()


def test_valid_polygon_is_returned_counter_clockwise():
    cw = [(0, 0), (0, 0.01), (0.01, 0.01), (0.01, 0)]
    v = check_convex_polygon(cw)
    assert v.dtype == np.float64 and v.shape == (4, 2)
    assert shoelace_area(v) > 0.0
    assert same_vertex_set(v, np.array(cw, dtype=float), 0.0 + 1e-18)
