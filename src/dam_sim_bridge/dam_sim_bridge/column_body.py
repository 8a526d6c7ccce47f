"""The column object as a rigid body of the stand-in: its convex mesh, its inertia and its
resting pose, from its cross-section (:mod:`dam_common.cross_section`).

The body frame has its z axis along the column axis and its x and y axes along the section's
principal axes; before the turn to those axes (``beta``, zero for a section symmetric about
its vertical axis) x lies along the section's ``x`` (``axis x z``) and y straight down. So
PyBullet needs no inertial frame of its own, whose pose it would report instead of the mesh's.
This module is pure (math and numpy).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from dam_common.cross_section import CrossSection
from dam_common.forward_kinematics import quaternion_multiply

if TYPE_CHECKING:
    from dam_common.config import ObjectConfig


def resting_quaternion(obj: ObjectConfig) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) of the object's resting pose in the world: the body frame of
    :func:`prism_vertices`. Before the turn to the section's principal axes (``beta`` of
    :func:`prism_inertia`) that frame has its x axis along the section's ``x`` (``axis x
    z``), its y axis straight down and its z axis along the column axis (right-handed for
    every horizontal axis); the body frame is that frame turned by ``beta`` about its z axis.
    """
    _, beta = prism_inertia(obj.section, obj.mass_kg, obj.length_m)
    # R_z(heading) R_x(-90 deg): local z onto the axis, local x onto axis x z, local y down
    heading = math.atan2(-float(obj.axis[0]), float(obj.axis[1]))
    down = (-math.sin(math.pi / 4.0), 0.0, 0.0, math.cos(math.pi / 4.0))
    turn = (0.0, 0.0, math.sin(heading / 2.0), math.cos(heading / 2.0))
    principal = (0.0, 0.0, math.sin(beta / 2.0), math.cos(beta / 2.0))
    return quaternion_multiply(quaternion_multiply(turn, down), principal)


def prism_vertices(section: CrossSection, length_m: float, faces: int, beta: float = 0.0
                   ) -> np.ndarray:
    """Vertices (2m, 3) of the prism of ``section``'s outline in the object's body frame [m].

    The body frame (:func:`resting_quaternion`) has its z axis along the column axis and its
    x and y axes along the section's principal axes: before the turn by ``beta`` [rad] about
    z (:func:`prism_inertia`; zero for a section symmetric about its vertical axis) the x axis
    lies along the section's ``x`` (``axis x z``) and the y axis straight down, so that a
    section point ``(x, z)`` is the point ``(x, -z, +-length/2)``. A circle or an ellipse
    becomes ``faces`` faces tangent to it, one of them on the table
    (:meth:`~dam_common.cross_section.CrossSection.outline`); a polygon keeps its vertices.
    Vertex ``2k`` is outline point ``k`` at ``-length/2``, ``2k + 1`` the same at
    ``+length/2``; the mirror ``z -> -z`` makes the counter-clockwise outline clockwise in the
    body's xy plane (:func:`prism_triangles` winds its faces for that).
    """
    outline = section.outline(faces)
    half = length_m / 2.0
    c, s = math.cos(beta), math.sin(beta)
    # the point (x, -z) in the frame turned by beta: rotate it by -beta
    return np.array([[c * x - s * z, -s * x - c * z, w] for x, z in outline
                     for w in (-half, half)], dtype=np.float64)


def prism_triangles(n_outline: int) -> list[int]:
    """Triangle indices of the closed prism of :func:`prism_vertices`, wound so that every
    face's normal (counter-clockwise order) points outwards; its outline runs clockwise in the
    body's xy plane."""
    tris: list[int] = []
    for k in range(n_outline):
        a0, a1 = 2 * k, 2 * k + 1
        b0, b1 = 2 * ((k + 1) % n_outline), 2 * ((k + 1) % n_outline) + 1
        tris += [a0, b1, b0, a0, a1, b1]
    for k in range(1, n_outline - 1):
        tris += [0, 2 * k, 2 * (k + 1)]  # the end cap at -length/2, facing -z
        tris += [1, 2 * (k + 1) + 1, 2 * k + 1]  # the end cap at +length/2, facing +z
    return tris


def prism_inertia(section: CrossSection, mass_kg: float, length_m: float
                  ) -> tuple[tuple[float, float, float], float]:
    """Principal inertia [kg*m^2] of the homogeneous prism of ``section`` about its centroid,
    and the angle ``beta`` [rad] about the column axis from the frame with x along the
    section's ``x`` and y straight down to the principal axes (zero for a section symmetric
    about its vertical axis). The body frame of :func:`prism_vertices` is the principal one,
    so that PyBullet needs no inertial frame of its own (its base pose would then be that of
    the inertial frame, not of the mesh).

    With ``S_xx = int x^2 dA``, ``S_zz = int z^2 dA``, ``S_xz = int x z dA`` of the section
    and the body point ``(x, -z, w)``: ``I_xx = m (S_zz / A + L^2 / 12)``,
    ``I_yy = m (S_xx / A + L^2 / 12)``, ``I_zz = m (S_xx + S_zz) / A`` and the tensor's
    ``xy`` entry ``m S_xz / A``.
    """
    area = section.area
    s_xx, s_zz = section.second_moments
    s_xz = section.product_moment
    axial = length_m ** 2 / 12.0
    i_xx = mass_kg * (s_zz / area + axial)
    i_yy = mass_kg * (s_xx / area + axial)
    i_zz = mass_kg * (s_xx + s_zz) / area
    # the tensor's xy entry, -int x_b y_b dm with the body's y_b = -z
    i_xy = mass_kg * s_xz / area
    if abs(i_xy) <= 1e-12 * max(i_xx, i_yy):
        return (i_xx, i_yy, i_zz), 0.0
    # principal axes: the frame turned about z by beta, tan(2 beta) = 2 I_xy / (I_xx - I_yy)
    beta = 0.5 * math.atan2(2.0 * i_xy, i_xx - i_yy)
    c, s = math.cos(beta), math.sin(beta)
    j_xx = c * c * i_xx + 2.0 * c * s * i_xy + s * s * i_yy
    j_yy = s * s * i_xx - 2.0 * c * s * i_xy + c * c * i_yy
    return (j_xx, j_yy, i_zz), beta
