"""Contacts of the finger links with a convex cross-section, for many object poses at once.

The pose tracker (:mod:`dam_spcm_controller.pose_tracking`) asks, thousands of times per
grasp, how far each finger's links are from the object section at a batch of candidate poses
and where they touch it. This module answers for a whole batch in a few numpy operations.

The section is a convex polygon in its own frame (:class:`SectionPolygon`): a polygon's own
vertices, a circle's or an ellipse's tangent polygon (as the stand-in's mesh). A pose is the
centre ``(u, z)`` [m] of the section's centroid and its turn ``psi`` [rad] from the resting
pose, from ``u`` towards ``z``. A finger is a chain of three link axes (segments); the
capsule radius is added by the caller.

Contact region: where a face of the polygon lies along a link (the face parallel to the link
within ``region_tolerance`` of distance), the contact is not one point but a stretch of the
face; its two ends are returned, so that a statics model can let the contact force act
anywhere between them (a flat face pressed on a link carries a range of moments).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dam_common.cross_section import CrossSection
from dam_spcm_controller.errors import InputError

#: Faces of the tangent polygon of a circle or an ellipse [-].
CURVE_FACES = 24


@dataclass(frozen=True)
class SectionPolygon:
    """A convex cross-section as a counter-clockwise polygon in its own frame.

    Attributes
    ----------
    vertices
        (m, 2) vertices ``(u, z)`` [m], centroid at the origin, resting pose.
    normals
        (m, 2) outward unit normal of edge ``i`` (from vertex ``i`` to ``i + 1``).
    offsets
        (m,) support value of edge ``i``: ``normals[i] . vertices[i]`` [m].
    """

    vertices: np.ndarray
    normals: np.ndarray
    offsets: np.ndarray

    @classmethod
    def from_section(cls, section: CrossSection, curve_faces: int = CURVE_FACES
                     ) -> SectionPolygon:
        """The polygon of ``section``: a polygon's vertices, or the tangent polygon of
        ``curve_faces`` faces of a circle or an ellipse.

        Raises
        ------
        InputError
            ``curve_faces`` is below 8.
        """
        if int(curve_faces) < 8:
            raise InputError(f'curve_faces must be at least 8, got {curve_faces!r}')
        v = np.asarray(section.outline(int(curve_faces)), dtype=np.float64)
        return cls.from_vertices(v)

    @classmethod
    def from_vertices(cls, vertices: np.ndarray) -> SectionPolygon:
        """Polygon of counter-clockwise ``vertices`` (m, 2) [m].

        Raises
        ------
        InputError
            Fewer than three vertices, a non-finite value, or a clockwise outline.
        """
        v = np.asarray(vertices, dtype=np.float64)
        if v.ndim != 2 or v.shape[0] < 3 or v.shape[1] != 2 or not np.isfinite(v).all():
            raise InputError(f'vertices must be a finite (m >= 3, 2) array, got shape '
                             f'{v.shape}')
        edge = np.roll(v, -1, axis=0) - v
        area2 = float(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
        if not area2 > 0.0:
            raise InputError('vertices must run counter-clockwise around a positive area')
        length = np.linalg.norm(edge, axis=1)
        normals = np.stack([edge[:, 1], -edge[:, 0]], axis=1) / length[:, None]
        offsets = np.einsum('ij,ij->i', normals, v)
        for arr in (v, normals, offsets):
            arr.setflags(write=False)
        return cls(v, normals, offsets)


@dataclass(frozen=True)
class LinkAxes:
    """The link axes of every finger at one instant, with what every query needs of them.

    Attributes
    ----------
    start, direction
        (n, 3, 2) start of each link axis and the vector to its end [m].
    length2
        (n, 3) squared lengths [m^2].
    ends
        (n, 3, 2, 2) both ends of each axis [m].
    normal
        (n, 3, 2) unit normal of each axis.
    """

    start: np.ndarray
    direction: np.ndarray
    length2: np.ndarray
    ends: np.ndarray
    normal: np.ndarray

    @classmethod
    def from_points(cls, points: np.ndarray) -> LinkAxes:
        """From :func:`~dam_spcm_controller.object_estimate.finger_points` (n, 4, 2) [m]."""
        start = points[:, :3]
        direction = points[:, 1:] - start
        length2 = np.einsum('nkj,nkj->nk', direction, direction)
        normal = np.stack([-direction[..., 1], direction[..., 0]], -1) / \
            np.sqrt(length2)[..., None]
        return cls(start, direction, length2, np.stack([start, points[:, 1:]], axis=2),
                   normal)


@dataclass(frozen=True)
class ChainContacts:
    """Contacts of every finger with the section at each pose of a batch.

    Attributes
    ----------
    distance
        (P, n) signed distance from each finger's nearest link axis to the section [m]
        (negative: the axis enters the section).
    lowest
        (P,) height of the section's lowest vertex [m].
    link
        (P, n) index of the nearest link (0 proximal .. 2 distal).
    region
        (P, n, 2, 2) the two ends ``(u, z)`` of each finger's contact stretch on the section
        [m] (equal for a point contact); None from :func:`chain_distances`.
    """

    distance: np.ndarray
    lowest: np.ndarray
    link: np.ndarray
    region: np.ndarray | None = None


def _placed(poly: SectionPolygon, centres: np.ndarray, psis: np.ndarray):
    cs, sn = np.cos(psis), np.sin(psis)
    rot = np.stack([np.stack([cs, -sn], -1), np.stack([sn, cs], -1)], -2)  # (P, 2, 2)
    w = centres[:, None, :] + np.einsum('pij,mj->pmi', rot, poly.vertices)  # (P, m, 2)
    nw = np.einsum('pij,mj->pmi', rot, poly.normals)
    hw = poly.offsets[None] + np.einsum('pmj,pj->pm', nw, centres)
    return w, nw, hw


def _distances(poly: SectionPolygon, axes: LinkAxes, centres: np.ndarray, psis: np.ndarray):
    w, nw, hw = _placed(poly, centres, psis)
    e = axes.direction
    # vertices to link axes
    rel = w[:, None, None] - axes.start[None, :, :, None]  # (P, n, 3, m, 2)
    t = np.clip(np.einsum('pnkmj,nkj->pnkm', rel, e) / axes.length2[None, :, :, None],
                0.0, 1.0)
    diff = rel - t[..., None] * e[None, :, :, None]
    dv = np.sqrt(np.einsum('pnkmj,pnkmj->pnkm', diff, diff))  # (P, n, 3, m)
    # ends of the link axes to the edges
    edge = np.roll(w, -1, axis=1) - w
    edge2 = np.einsum('pmj,pmj->pm', edge, edge)
    relp = axes.ends[None, :, :, :, None, :] - w[:, None, None, None]  # (P, n, 3, 2, m, 2)
    s = np.clip(np.einsum('pnkqmj,pmj->pnkqm', relp, edge) / edge2[:, None, None, None],
                0.0, 1.0)
    diffe = relp - s[..., None] * edge[:, None, None, None]
    de = np.sqrt(np.einsum('pnkqmj,pnkqmj->pnkqm', diffe, diffe))  # (P, n, 3, 2, m)
    outside = np.minimum(dv.min(axis=3), de.min(axis=(3, 4)))
    # separating axes: the polygon's normals and each link's normal
    proj = np.einsum('nkqj,pmj->pnkqm', axes.ends, nw) - hw[:, None, None, None]
    sv = np.einsum('pnkmj,nkj->pnkm', rel, axes.normal)
    sep = np.maximum(proj.min(axis=3).max(axis=3),
                     np.maximum(sv.min(axis=3), -sv.max(axis=3)))
    dist = np.where(sep > 0.0, outside, sep)  # (P, n, 3)
    link = dist.argmin(axis=2)
    pi = np.arange(dist.shape[0])[:, None]
    ni = np.arange(dist.shape[1])[None, :]
    return dist[pi, ni, link], w[:, :, 1].min(axis=1), link, (w, dv, de, s, edge, pi, ni)


def chain_distances(poly: SectionPolygon, axes: LinkAxes, centres: np.ndarray,
                    psis: np.ndarray) -> ChainContacts:
    """Distances of the finger link axes to the section at P poses, without the contact
    stretches (see :func:`chain_contacts`)."""
    dist, lowest, link, _ = _distances(poly, axes, centres, psis)
    return ChainContacts(dist, lowest, link)


def chain_contacts(poly: SectionPolygon, axes: LinkAxes, centres: np.ndarray,
                   psis: np.ndarray, region_tolerance: float = 5e-5) -> ChainContacts:
    """Distances and contact stretches of finger link axes to the section at P poses.

    Parameters
    ----------
    poly
        The section.
    axes
        The fingers' link axes (:meth:`LinkAxes.from_points`).
    centres
        (P, 2) centroid positions ``(u, z)`` [m].
    psis
        (P,) turns of the section from its resting pose [rad].
    region_tolerance
        Features of the section within this distance of the nearest one belong to the
        contact stretch [m].

    Returns
    -------
    ChainContacts
        For every pose and finger. The signed distance is exact outside the section (the
        nearest pair of a segment and a convex polygon: a vertex and the segment, or an end
        of the segment and an edge) and, where the axis enters the section, minus the least
        separating-axis overlap (the depth), so that it is continuous through zero.
    """
    dist, lowest, link, (w, dv, de, s, edge, pi, ni) = _distances(poly, axes, centres, psis)
    dvb = dv[pi, ni, link]  # (P, n, m)
    deb = de[pi, ni, link]  # (P, n, 2, m)
    sb = s[pi, ni, link]
    ref = np.minimum(dvb.min(axis=2), deb.min(axis=(2, 3)))
    feet = w[:, None, None] + sb[..., None] * edge[:, None, None]  # (P, n, 2, m, 2)
    n_p, n_f = dvb.shape[0], dvb.shape[1]
    cand = np.concatenate([np.broadcast_to(w[:, None], dvb.shape + (2,)),
                           feet.reshape(n_p, n_f, -1, 2)], axis=2)
    cand_d = np.concatenate([dvb, deb.reshape(n_p, n_f, -1)], axis=2)
    near = cand_d <= ref[..., None] + region_tolerance
    along = np.einsum('pncj,pnj->pnc', cand, axes.direction[ni, link])
    lo = np.where(near, along, math.inf).argmin(axis=2)
    hi = np.where(near, along, -math.inf).argmax(axis=2)
    region = np.stack([cand[pi, ni, lo], cand[pi, ni, hi]], axis=2)
    return ChainContacts(dist, lowest, link, region)
