"""The column object's rigid body (module column_body): its inertia against a quadrature, its
visual mesh closed and wound outwards, and the stand-in's hull in the world for any horizontal
axis."""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_common.config import DamConfig, load_config
from dam_sim_bridge.world import HandWorld


@pytest.fixture(scope='module')
def cfg() -> DamConfig:
    return load_config()


#: An asymmetric triangle (its apex off the centre) for the frame and inertia checks.
WEDGE = {'shape': 'convex_polygon', 'length_m': 0.05, 'mass_kg': 0.02,
         'vertices_m': [[-0.012, 0.0], [0.010, 0.0], [0.006, 0.015]]}


def _with_wedge(axis: list[float]) -> DamConfig:
    import copy
    from pathlib import Path

    import yaml

    from dam_common.config import config_from_dict

    raw = yaml.safe_load((Path(__file__).resolve().parents[2] / 'config' /
                          'dam.yaml').read_text(encoding='utf-8'))
    data = copy.deepcopy(raw)
    data['object']['axis'] = axis
    data['object']['library']['wedge'] = WEDGE
    return config_from_dict(data).with_object('wedge')


@pytest.mark.parametrize('axis', [[0.0, 1.0, 0.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0],
                                  [0.6, 0.8, 0.0]])
def test_the_object_rests_as_its_section_for_any_horizontal_axis(axis: list[float]) -> None:
    """The stand-in's hull, seen in the world, is the configured section in the plane normal
    to the axis (x along axis x z, z up) at the resting centroid: apex up, base on the table,
    whatever the axis."""
    config = _with_wedge(axis)
    obj = config.object
    w = HandWorld(config)
    try:
        pb = w._pb
        position, quaternion = pb.getBasePositionAndOrientation(w.object_id)
        rot = np.array(pybullet_matrix(quaternion)).reshape(3, 3)
        _, body_vertices = pb.getMeshData(w.object_id, -1)[:2]
        world_vertices = np.asarray(position) + np.asarray(body_vertices) @ rot.T
    finally:
        w.close()
    x_axis = np.cross(obj.axis, [0.0, 0.0, 1.0])
    x_axis /= np.linalg.norm(x_axis)
    section = np.array(WEDGE['vertices_m'])
    centroid = section.mean(axis=0)  # a triangle's centroid is the mean of its vertices
    half = WEDGE['length_m'] / 2.0
    place = np.array([obj.position_m[0], obj.position_m[1], 0.0])
    expected = [place + (x - centroid[0]) * x_axis + np.array([0.0, 0.0, z])
                + s * half * np.asarray(obj.axis) for x, z in section for s in (-1.0, 1.0)]
    # the centroid rests at its height above the base: vertices at z = 0 and z = 15 mm
    # (it has settled a micrometre into the table under gravity)
    assert world_vertices[:, 2].min() == pytest.approx(0.0, abs=1e-5)
    assert world_vertices[:, 2].max() == pytest.approx(0.015, abs=1e-5)
    for point in expected:
        assert np.min(np.linalg.norm(world_vertices - point, axis=1)) < 1e-5, point


def pybullet_matrix(quaternion) -> list[float]:
    from dam_sim_bridge.pybullet_import import pybullet

    return pybullet.getMatrixFromQuaternion(list(quaternion))


def test_the_prism_inertia_against_a_quadrature() -> None:
    """The homogeneous prism's inertia tensor in the frame with x along the section's x and y
    down (section point (x, z) at (x, -z)), integrated on a fine grid of the triangle, equals
    the returned principal moments turned by the returned angle about z (the product of
    inertia is not zero here)."""
    from dam_common.polygon_section import ConvexPolygon
    from dam_sim_bridge.column_body import prism_inertia

    section = ConvexPolygon(WEDGE['vertices_m'])
    mass, length = WEDGE['mass_kg'], WEDGE['length_m']
    moments, beta = prism_inertia(section, mass, length)
    v = section.vertices
    n = 2000
    xs = np.linspace(v[:, 0].min(), v[:, 0].max(), n)
    zs = np.linspace(v[:, 1].min(), v[:, 1].max(), n)
    gx, gz = np.meshgrid(xs, zs)
    inside = np.ones_like(gx, dtype=bool)
    for k in range(3):  # counter-clockwise: inside is left of every edge
        a, b = v[k], v[(k + 1) % 3]
        inside &= (b[0] - a[0]) * (gz - a[1]) - (b[1] - a[1]) * (gx - a[0]) >= 0.0
    bx, by = gx[inside], -gz[inside]
    axial = length ** 2 / 12.0
    tensor = mass * np.array([
        [np.mean(by ** 2) + axial, -np.mean(bx * by), 0.0],
        [-np.mean(bx * by), np.mean(bx ** 2) + axial, 0.0],
        [0.0, 0.0, np.mean(bx ** 2 + by ** 2)]])
    assert abs(tensor[0, 1]) > 1e-3 * tensor[0, 0]  # a real product of inertia
    c, s = math.cos(beta), math.sin(beta)
    rot = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(rot @ np.diag(moments) @ rot.T, tensor, rtol=0,
                               atol=3e-3 * np.max(tensor))


@pytest.mark.parametrize('name', ['hex_bar', 'elliptic_column'])
def test_the_visual_mesh_faces_outwards(cfg: DamConfig, name: str) -> None:
    """Every triangle of the visual prism, in counter-clockwise order, has its normal pointing
    away from the centroid, and the triangles close the surface (each edge used twice)."""
    from dam_sim_bridge.column_body import prism_triangles, prism_vertices

    obj = cfg.with_object(name).object
    vertices = prism_vertices(obj.section, obj.length_m, 16)
    triangles = np.array(prism_triangles(len(vertices) // 2)).reshape(-1, 3)
    edges: dict[tuple[int, int], int] = {}
    for a, b, c in triangles:
        normal = np.cross(vertices[b] - vertices[a], vertices[c] - vertices[a])
        centre = (vertices[a] + vertices[b] + vertices[c]) / 3.0
        assert normal @ centre > 0.0, (a, b, c)
        for edge in ((a, b), (b, c), (c, a)):
            edges[tuple(sorted(edge))] = edges.get(tuple(sorted(edge)), 0) + 1
    assert set(edges.values()) == {2}
