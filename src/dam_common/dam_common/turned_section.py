"""A cross-section turned about its centroid: the pose of a column that has rolled.

:class:`TurnedSection` wraps any :class:`~dam_common.cross_section.CrossSection` and answers
its geometric questions for the section turned by ``angle`` about its centroid (positive:
counter-clockwise in the section's ``(x, z)`` plane, ``x`` towards ``z``). Every answer is the
wrapped section's answer in its own frame, turned back: the point or direction is turned by
``-angle``, the wrapped section answers, and points and normals are turned by ``+angle``. So
the turned section is exactly as accurate as the one it wraps (closed forms stay closed forms).

The lift analysis uses it for the poses a polygon or an ellipse takes when it rolls on the
table (``dam_analysis.rolling``). Pure Python and numpy; no rclpy.
"""

from __future__ import annotations

import math

import numpy as np

from dam_common.cross_section import CrossSection


def _turn(cos_a: float, sin_a: float, u: float, z: float) -> tuple[float, float]:
    return cos_a * u - sin_a * z, sin_a * u + cos_a * z


class TurnedSection(CrossSection):
    """``section`` turned by ``angle`` [rad] about its centroid (counter-clockwise: x -> z).

    Parameters
    ----------
    section : the section in its resting pose.
    angle : the turn [rad]; any finite value.

    Raises
    ------
    ValueError
        ``angle`` is not a finite number.
    """

    def __init__(self, section: CrossSection, angle: float) -> None:
        angle = float(angle)
        if not math.isfinite(angle):
            raise ValueError(f'angle: expected a finite number of radians, got {angle!r}')
        self.section = section
        self.angle = angle
        self.kind = section.kind
        self._c, self._s = math.cos(angle), math.sin(angle)

    def __repr__(self) -> str:
        return f'TurnedSection({self.section!r}, angle={self.angle!r})'

    def _to_body(self, u: float, z: float) -> tuple[float, float]:
        return _turn(self._c, -self._s, u, z)

    def _to_plane(self, u: float, z: float) -> tuple[float, float]:
        return _turn(self._c, self._s, u, z)

    def distance(self, pu: float, pz: float) -> tuple[float, float, float, float, float]:
        dist, qu, qz, nu, nz = self.section.distance(*self._to_body(pu, pz))
        return (dist, *self._to_plane(qu, qz), *self._to_plane(nu, nz))

    def support(self, du: float, dz: float) -> tuple[float, float]:
        return self._to_plane(*self.section.support(*self._to_body(du, dz)))

    def line_interval(self, au: float, az: float, eu: float, ez: float
                      ) -> tuple[float, float] | None:
        # a turn keeps the parameter of every point of the line
        return self.section.line_interval(*self._to_body(au, az), *self._to_body(eu, ez))

    def mirrored(self) -> TurnedSection:
        # reflecting x -> -x turns the other way: M R(a) = R(-a) M
        return TurnedSection(self.section.mirrored(), -self.angle)

    def scaled(self, factor: float) -> TurnedSection:
        return TurnedSection(self.section.scaled(factor), self.angle)

    def outline(self, faces: int) -> np.ndarray:
        v = self.section.outline(faces)
        rot = np.array([[self._c, -self._s], [self._s, self._c]])
        return v @ rot.T

    def describe(self) -> str:
        return f'{self.section.describe()}, turned {math.degrees(self.angle):.4g} deg'

    @property
    def area(self) -> float:
        return self.section.area

    @property
    def second_moments(self) -> tuple[float, float]:
        ixx, izz = self.section.second_moments
        ixz = self.section.product_moment
        c, s = self._c, self._s
        return (c * c * ixx - 2.0 * c * s * ixz + s * s * izz,
                s * s * ixx + 2.0 * c * s * ixz + c * c * izz)

    @property
    def product_moment(self) -> float:
        ixx, izz = self.section.second_moments
        ixz = self.section.product_moment
        c, s = self._c, self._s
        return c * s * (ixx - izz) + (c * c - s * s) * ixz

    @property
    def bottom(self) -> float:
        return self.support(0.0, -1.0)[1]

    @property
    def inradius(self) -> float:
        return self.section.inradius

    @property
    def circumradius(self) -> float:
        return self.section.circumradius

    @property
    def min_width(self) -> float:
        return self.section.min_width

    @property
    def symmetry_period(self) -> float:
        return self.section.symmetry_period
