"""The pose of a non-circular column, tracked through the joint history of a grasp.

In the plane normal to the object axis the joints give two contact conditions (finger 1 and
the pair of fingers 2 and 3, which stand side by side along the axis) for three unknowns,
the centroid ``(u, z)`` and the turn ``psi`` of the section: at one instant a one-parameter
family of poses touches the fingers. :func:`track_pose` follows the grasp from the known
resting pose, sample by sample of the recorded joint angles and compliant-joint torques
(:class:`~dam_spcm_controller.joint_history.JointHistory`), and keeps two poses:

* the **table pose**: the pose touching the fingers that still rests on the table (its
  lowest point on the table top: a third condition), nearest the previous one; the finger
  contacts are taken not to slip between samples where that decides between equally
  admissible poses (a polygon tipping onto one vertex or the other);
* the **free equilibrium**: the pose of the family in which the object would hang between
  the fingers without the table. The compliant-joint torques (less the links' own weight)
  fix the moment of each side's contact force about its compliant joint; with the weight
  of the object, the two contact forces and the turn are fixed by the balance of forces and
  moments (five equations). Where a face of the section lies flat along a link the contact
  force may act anywhere on that stretch, and the balance holds for a range of moments. The
  free equilibrium is followed continuously from where it first appears (below the table
  while the table still carries the object).

The object is off the table while its free equilibrium is above the table, and on the table
(the table pose) otherwise: the table can push, never pull. A pressed contact sinks in by
the normal force over ``HandGeometry.contact_stiffness``.

Pure numpy; no rclpy.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from dam_spcm_controller._validate import finite_scalar, finite_vector
from dam_spcm_controller.errors import InputError
from dam_spcm_controller.joint_history import JointHistory
from dam_spcm_controller.object_estimate import FitInterrupted, HandGeometry, finger_points
from dam_spcm_controller.section_contact import (
    LinkAxes,
    SectionPolygon,
    chain_contacts,
    chain_distances,
)

#: Finite-difference steps of (u [m], z [m], psi [rad]).
_STEPS = np.array([1e-6, 1e-6, 1e-4])
#: Weights of the pose fits: distances [m], finger slip between samples [m].
_SIGMA_DISTANCE = 1e-5
_SIGMA_SLIP = 1e-4
#: A side whose mean residual is below this touches the object [m].
_TOUCH = 2e-5
#: Largest change of one Gauss-Newton step: u, z [m], psi [rad].
_STEP_LIMIT = np.array([1e-3, 1e-3, 0.05])


@dataclass(frozen=True)
class TrackerSettings:
    """Tuning of :func:`track_pose`.

    Attributes
    ----------
    load_torque
        A finger whose compliant-joint torque is at least this presses on the object [N*m]
        ...
    contact_gap
        ... when it is less than this from where the object was [m].
    angle_step
        A sample is processed when a joint has turned this far since the last one [rad] ...
    torque_step
        ... or a compliant-joint torque has changed this much [N*m] ...
    max_gap
        ... or this many samples have passed.
    max_samples
        At most this many samples are processed (the two steps above are widened until they
        select no more): the cost of a grasp's end.
    root_window
        The free equilibrium is looked for this far on either side of the last one (or of
        where its contacts would roll it) [rad].
    init_window
        Where it first appears, this far on either side of the table pose [rad].
    grid_step
        Spacing of the turns the equilibrium is bracketed on [rad].
    bisections
        Halvings of the bracket.
    region_tolerance
        Contact stretch of a face lying along a link (:func:`chain_contacts`) [m].
    max_sink
        Largest sinking of a pressed contact that is modelled [m].
    table_margin
        Above this clearance [m] the table pose is not followed (the object is well off the
        table); it is taken up again from the free equilibrium.
    roll_prediction
        Look for the free equilibrium around the pose the contacts roll the object to (the
        least slip since the last sample) instead of around the last one.
    max_friction
        An equilibrium needs contact forces that push the object within this ratio of
        tangential to normal force (tan 45 deg: more than any finger the suite models)
        [-].
    hold_height
        Where no equilibrium is found near the last one, the object stays off the table in
        the last one's turn if that is more than this above the table [m]; nearer, it is
        taken to have come down onto the table (the table pose).
    """

    load_torque: float = 0.004
    angle_step: float = math.radians(0.1)
    torque_step: float = 0.004
    max_gap: int = 50
    max_samples: int = 220
    root_window: float = math.radians(2.5)
    init_window: float = math.radians(30.0)
    grid_step: float = math.radians(0.5)
    bisections: int = 5
    region_tolerance: float = 5e-5
    max_sink: float = 5e-4
    table_margin: float = 1e-3
    roll_prediction: bool = True
    contact_gap: float = 1e-3
    hold_height: float = 1e-3
    max_friction: float = 1.0

    def __post_init__(self) -> None:
        for name in ('load_torque', 'angle_step', 'torque_step', 'root_window',
                     'init_window', 'grid_step', 'region_tolerance', 'max_sink',
                     'table_margin', 'contact_gap', 'hold_height', 'max_friction'):
            object.__setattr__(self, name, finite_scalar(name, getattr(self, name),
                                                         positive=True))
        if not isinstance(self.roll_prediction, bool):
            raise InputError(f'roll_prediction must be a bool, got {self.roll_prediction!r}')
        for name in ('max_gap', 'bisections', 'max_samples'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise InputError(f'{name} must be a positive integer, got {value!r}')


@dataclass(frozen=True)
class TrackedPose:
    """The object's pose at the end of a grasp, as :func:`track_pose` followed it.

    Attributes
    ----------
    centre
        (2,) centroid ``(u, z)`` [m].
    orientation
        Turn of the section from its resting pose [rad], from ``u`` towards ``z``, followed
        continuously (a hexagon turned by 62 deg reads 62 deg, not 2 deg).
    clearance
        Height of the section's lowest point above the table [m] (zero on the table).
    on_table
        The object rests on the table (the table pose); else it hangs in its free
        equilibrium.
    residuals
        (n,) distance of each finger's links from the section less the link radius and the
        contact's sinking [m] (zero for a finger in contact).
    samples
        Samples of the history that were processed.
    """

    centre: np.ndarray
    orientation: float
    clearance: float
    on_table: bool
    residuals: np.ndarray
    samples: int


class _Model:
    """The hand, the section and the statics of one tracking run."""

    def __init__(self, geometry: HandGeometry, settings: TrackerSettings) -> None:
        if geometry.section is None:
            raise InputError('track_pose needs a geometry with a non-circular section')
        self.geo = geometry
        self.s = settings
        self.poly = SectionPolygon.from_section(geometry.section)
        sign = geometry.inward_sign
        self.sign = sign
        self.side_a = np.flatnonzero(sign == sign[0])
        self.side_b = np.flatnonzero(sign != sign[0])
        self.weight = geometry.object_mass * geometry.gravity
        self.link_weights = geometry.link_masses * geometry.gravity
        self.table = geometry.table_z

    # -- geometry ---------------------------------------------------------------------------

    def contacts(self, axes: LinkAxes, x: np.ndarray):
        """Contacts with their stretches at poses ``x`` (P, 3)."""
        return chain_contacts(self.poly, axes, x[:, :2], x[:, 2], self.s.region_tolerance)

    def distances(self, axes: LinkAxes, x: np.ndarray):
        """Distances only at poses ``x`` (P, 3)."""
        return chain_distances(self.poly, axes, x[:, :2], x[:, 2])

    def distance_residuals(self, c, sink: np.ndarray, loaded: np.ndarray) -> np.ndarray:
        """(P, n) distance less link radius and sinking; only penetration for a finger that
        does not press."""
        r = c.distance - self.geo.link_radius + sink[None]
        return np.where(loaded[None], r, np.minimum(r, 0.0))

    # -- statics ----------------------------------------------------------------------------

    def joint_moments(self, pts: np.ndarray, tau_c: np.ndarray) -> np.ndarray:
        """(n,) counter-clockwise moment of each finger's contact force about its compliant
        joint [N*m]: the joint torque (flexion positive) and the links' weight."""
        mid_u = 0.5 * (pts[:, :3, 0] + pts[:, 1:, 0]) - pts[:, 0:1, 0]
        gravity = -(mid_u * self.link_weights[None]).sum(axis=1)
        return self.sign * tau_c + gravity

    def side_forces(self, pts: np.ndarray, moments: np.ndarray, pa: np.ndarray,
                    pb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Forces (P, 2) of side a and side b on the object, contact points ``pa``, ``pb``
        (P, 2), that carry its weight with the measured moments about the compliant joints
        (NaN where the two contacts leave them undetermined)."""
        ra = pa - pts[self.side_a[0], 0]
        rb = pb - pts[self.side_b[0], 0]
        b_a = moments[self.side_a].sum()
        b_b = moments[self.side_b].sum()
        w = self.weight
        # side a pushes with (fu, fz), side b with (-fu, W - fz); their moments about the
        # compliant joints are the measured ones
        det = ra[:, 1] * rb[:, 0] - ra[:, 0] * rb[:, 1]
        det = np.where(np.abs(det) > 1e-12, det, math.nan)
        rhs2 = b_b - rb[:, 0] * w
        fu = (b_a * -rb[:, 0] - ra[:, 0] * rhs2) / det
        fz = (-ra[:, 1] * rhs2 - rb[:, 1] * b_a) / det
        fa = np.column_stack([fu, fz])
        return fa, np.column_stack([-fu, w - fz])

    def moment_residual(self, pts: np.ndarray, moments: np.ndarray, region: np.ndarray,
                        centres: np.ndarray) -> np.ndarray:
        """(P,) how far zero lies outside the range of the unbalanced moment over the
        contact stretches, divided by the object's weight [m]; zero: in equilibrium."""
        lo = np.full(centres.shape[0], math.inf)
        hi = np.full(centres.shape[0], -math.inf)
        for ea in (0, 1):
            pa = region[:, self.side_a, ea].mean(axis=1)  # (P, 2)
            for eb in (0, 1):
                pb = region[:, self.side_b, eb].mean(axis=1)
                fa, fb = self.side_forces(pts, moments, pa, pb)
                ca, cb = pa - centres, pb - centres
                m = (ca[:, 0] * fa[:, 1] - ca[:, 1] * fa[:, 0]
                     + cb[:, 0] * fb[:, 1] - cb[:, 1] * fb[:, 0]) / self.weight
                lo = np.fmin(lo, m)
                hi = np.fmax(hi, m)
        return np.where(lo > 0.0, lo, np.where(hi < 0.0, hi, 0.0))

    def admissible(self, pts: np.ndarray, moments: np.ndarray, region: np.ndarray,
                   link: np.ndarray, centres: np.ndarray) -> np.ndarray:
        """(P,) the contact forces that hold the object push it (towards its centroid,
        normal to the link) within ``max_friction`` of the normal."""
        pa = region[:, self.side_a].mean(axis=(1, 2))
        pb = region[:, self.side_b].mean(axis=(1, 2))
        ok = np.ones(centres.shape[0], dtype=bool)
        fa, fb = self.side_forces(pts, moments, pa, pb)
        for side, p, f in ((self.side_a, pa, fa), (self.side_b, pb, fb)):
            i = side[0]
            e = pts[i, link[:, i] + 1] - pts[i, link[:, i]]  # (P, 2)
            e = e / np.linalg.norm(e, axis=1)[:, None]
            nrm = np.column_stack([-e[:, 1], e[:, 0]])
            inward = np.einsum('pj,pj->p', centres - p, nrm)
            nrm = nrm * np.where(inward < 0.0, -1.0, 1.0)[:, None]
            f_n = np.einsum('pj,pj->p', f, nrm)
            f_t = np.abs(np.einsum('pj,pj->p', f, e))
            ok &= (f_n > 0.0) & (f_t <= self.s.max_friction * f_n)
        return ok

    def sinking(self, pts: np.ndarray, tau_c: np.ndarray, c) -> np.ndarray:
        """(n,) sinking of each contact: its normal force (moment over lever about the
        compliant joint) over the contact stiffness [m]."""
        n = pts.shape[0]
        idx = np.arange(n)
        link = c.link[0]
        p = c.region[0].mean(axis=1)
        e = pts[idx, link + 1] - pts[idx, link]
        e = e / np.linalg.norm(e, axis=1)[:, None]
        rel = p - pts[:, 0]
        lever = np.abs(rel[:, 0] * e[:, 0] + rel[:, 1] * e[:, 1])
        force = np.maximum(self.sign * self.joint_moments(pts, tau_c), 0.0) / \
            np.maximum(lever, 1e-3)
        return np.minimum(force / self.geo.contact_stiffness, self.s.max_sink)


@dataclass
class _Contact:
    """Where the fingers touched the object at the last processed sample."""

    pose: np.ndarray  # (3,) u, z [m], psi [rad]
    point: np.ndarray  # (n, 2) contact points [m]
    link: np.ndarray  # (n,) touching link
    start: np.ndarray  # (n, 2) start of that link's axis [m]
    direction: np.ndarray  # (n, 2) that link's axis (not unit) [m]
    loaded: np.ndarray  # (n,) bool


def _select(q: np.ndarray, tau_c: np.ndarray, s: TrackerSettings) -> list[int]:
    """Indices of the samples to process: where a joint has turned by ``angle_step`` or a
    compliant torque changed by ``torque_step`` since the last one taken, at least every
    ``max_gap`` samples, and the last; the steps widened until at most ``max_samples``."""
    count = q.shape[0]
    scale = 1.0
    while True:
        picked, ref = [0], 0
        da, dt = s.angle_step * scale, s.torque_step * scale
        for k in range(1, count - 1):
            if (k - ref >= s.max_gap or np.abs(q[k] - q[ref]).max() >= da
                    or np.abs(tau_c[k] - tau_c[ref]).max() >= dt):
                picked.append(k)
                ref = k
        if count > 1:
            picked.append(count - 1)
        if len(picked) <= s.max_samples or scale > 64.0:
            return picked
        scale *= 1.5


def _contact_of(pts: np.ndarray, pose: np.ndarray, con, loaded: np.ndarray) -> _Contact:
    idx = np.arange(pts.shape[0])
    link = con.link[0]
    return _Contact(pose=pose.copy(), point=con.region[0].mean(axis=1), link=link,
                    start=pts[idx, link].copy(), direction=pts[idx, link + 1] - pts[idx, link],
                    loaded=loaded.copy())


class _Tracker:
    """The fits of :func:`track_pose` on one sample."""

    def __init__(self, model: _Model) -> None:
        self.m = model

    def fit_family(self, axes, sink, loaded, psis, centres, iters: int = 6,
                   regions: bool = False):
        """Centres touching the fingers at each turn of ``psis`` (K,), from ``centres``
        (K, 2): Gauss-Newton on (u, z). Returns centres, (K, n) residuals, contacts."""
        m = self.m
        k = psis.shape[0]
        c = centres.copy()
        h = 1e-6
        psi3 = np.concatenate([psis, psis, psis])
        for _ in range(iters):
            x = np.concatenate([c, c + [h, 0.0], c + [0.0, h]], axis=0)
            r = m.distance_residuals(m.distances(axes, np.column_stack([x, psi3])), sink,
                                     loaded)
            r0 = r[:k]
            ju, jz = (r[k:2 * k] - r0) / h, (r[2 * k:] - r0) / h
            a11 = (ju * ju).sum(1) + 1e-4
            a12 = (ju * jz).sum(1)
            a22 = (jz * jz).sum(1) + 1e-4
            b1, b2 = -(ju * r0).sum(1), -(jz * r0).sum(1)
            det = a11 * a22 - a12 * a12
            du, dz = (a22 * b1 - a12 * b2) / det, (a11 * b2 - a12 * b1) / det
            size = np.maximum(np.abs(du), np.abs(dz))
            scale = np.where(size > 1e-3, 1e-3 / np.maximum(size, 1e-300), 1.0)
            c = c + np.column_stack([du * scale, dz * scale])
            if size.max() < 1e-7:
                break
        con = m.contacts(axes, np.column_stack([c, psis])) if regions else \
            m.distances(axes, np.column_stack([c, psis]))
        return c, m.distance_residuals(con, sink, loaded), con

    def balance(self, pts, axes, moments, sink, loaded, psis, centres):
        """Moment residual [m] at the family's poses of ``psis``; with the centres, the
        lowest points [m] and whether the fingers touch (K,)."""
        c, r, con = self.fit_family(axes, sink, loaded, psis, centres, regions=True)
        g = self.m.moment_residual(pts, moments, con.region, c)
        # each side touches on the whole (fingers 2 and 3 may straddle a tilted object)
        m = self.m
        touching = ((np.abs(r[:, m.side_a].mean(axis=1)) < _TOUCH)
                    & (np.abs(r[:, m.side_b].mean(axis=1)) < _TOUCH)
                    & (np.abs(r).max(axis=1) < 10.0 * _TOUCH)
                    & m.admissible(pts, moments, con.region, con.link, c))
        return g, c, con.lowest, touching

    def equilibrium(self, pts, axes, moments, sink, loaded, psi0: float, c0: np.ndarray,
                    window: float):
        """The free equilibrium nearest ``psi0`` within ``window`` [rad]: (pose (3,), lowest
        point [m]) or None."""
        s = self.m.s
        near = np.array([psi0 - s.grid_step, psi0, psi0 + s.grid_step])
        g, c, low, ok = self.balance(pts, axes, moments, sink, loaded, near,
                                     np.repeat(c0[None], 3, axis=0))
        if ok[1] and g[1] == 0.0:
            return np.array([c[1, 0], c[1, 1], psi0]), float(low[1])
        if not (ok.all() and (g[0] * g[1] < 0.0 or g[1] * g[2] < 0.0)):
            half = max(1, int(round(window / s.grid_step)))
            ks = np.arange(-half, half + 1)
            psis = psi0 + ks * s.grid_step
            g, c, low, ok = self.balance(pts, axes, moments, sink, loaded, psis,
                                         np.repeat(c0[None], ks.shape[0], axis=0))
        else:
            ks, psis = np.array([-1, 0, 1]), near
        best = None
        for j in range(ks.shape[0]):
            if not ok[j] or math.isnan(g[j]):
                continue
            if g[j] == 0.0:
                cand = (abs(ks[j]), j, j)
            elif j + 1 < ks.shape[0] and ok[j + 1] and g[j] * g[j + 1] < 0.0:
                cand = (abs(ks[j] + 0.5), j, j + 1)
            else:
                continue
            if best is None or cand[0] < best[0]:
                best = cand
        if best is None:
            return None
        _, j, j2 = best
        if j == j2:
            return np.array([c[j, 0], c[j, 1], psis[j]]), float(low[j])
        a, b, ga, ca = psis[j], psis[j2], g[j], c[j]
        pose, lowest = np.array([ca[0], ca[1], a]), float(low[j])
        for _ in range(s.bisections):
            mid = np.array([0.5 * (a + b)])
            gm, cm, lm, _ = self.balance(pts, axes, moments, sink, loaded, mid, ca[None])
            pose, lowest = np.array([cm[0, 0], cm[0, 1], mid[0]]), float(lm[0])
            if gm[0] == 0.0:
                break
            if ga * gm[0] < 0.0:
                b = mid[0]
            else:
                a, ga, ca = mid[0], gm[0], cm[0]
        return pose, lowest

    def slips(self, x: np.ndarray, axes, last: _Contact) -> np.ndarray:
        """(P, n) slip of each finger's contact along its link since ``last`` [m]: the
        object's material point against the link's, both moved rigidly."""
        dpsi = x[:, 2] - last.pose[2]
        cs, sn = np.cos(dpsi), np.sin(dpsi)
        rel = last.point - last.pose[:2]  # (n, 2)
        obj = x[:, None, :2] + np.stack([cs[:, None] * rel[None, :, 0]
                                         - sn[:, None] * rel[None, :, 1],
                                         sn[:, None] * rel[None, :, 0]
                                         + cs[:, None] * rel[None, :, 1]], axis=-1)
        idx = np.arange(last.link.shape[0])
        start = axes.start[idx, last.link]
        direction = axes.direction[idx, last.link]
        turn = (np.arctan2(direction[:, 1], direction[:, 0])
                - np.arctan2(last.direction[:, 1], last.direction[:, 0]))
        r0 = last.point - last.start
        link_point = start + np.column_stack([np.cos(turn) * r0[:, 0] - np.sin(turn) * r0[:, 1],
                                              np.sin(turn) * r0[:, 0] + np.cos(turn) * r0[:, 1]])
        tangent = last.direction / np.linalg.norm(last.direction, axis=1)[:, None]
        return np.einsum('pnj,nj->pn', obj - link_point[None], tangent)

    def table_pose(self, pts, axes, sink, loaded, x0: np.ndarray, last: _Contact | None,
                   iters: int = 8, table: bool = True) -> np.ndarray:
        """The pose resting on the table that touches the fingers, nearest ``x0``; between
        admissible poses the one whose contacts slip least since ``last``. Without
        ``table``: the pose touching the fingers whose contacts slip least (rolling)."""
        m = self.m
        keep = None if last is None else (loaded & last.loaded)
        x = x0.copy()
        for _ in range(iters):
            xs = np.vstack([x, x + np.diag(_STEPS)])
            con = m.distances(axes, xs)
            parts = [m.distance_residuals(con, sink, loaded) / _SIGMA_DISTANCE]
            if table:
                parts.append((con.lowest - m.table)[:, None] / _SIGMA_DISTANCE)
            if keep is not None and keep.any():
                parts.append(self.slips(xs, axes, last)[:, keep] / _SIGMA_SLIP)
            r = np.concatenate(parts, axis=1)
            jac = ((r[1:] - r[0]) / _STEPS[:, None]).T
            jd = np.vstack([jac, np.diag(1.0 / _STEP_LIMIT)])
            rd = np.concatenate([r[0], (x - x0) / _STEP_LIMIT])
            step = -np.linalg.lstsq(jd, rd, rcond=None)[0]
            size = float(np.max(np.abs(step) / _STEP_LIMIT))
            if size > 1.0:
                step = step / size
            x = x + step
            if size < 1e-3:  # 1 um, 5e-5 rad
                break
        return x


def track_pose(geometry: HandGeometry, history: JointHistory, *,
               final_positions: np.ndarray | None = None,
               final_efforts: np.ndarray | None = None,
               settings: TrackerSettings | None = None,
               stop: Callable[[], bool] | None = None) -> TrackedPose:
    """Follow the object's pose through a grasp's joint history (module docstring).

    Parameters
    ----------
    geometry
        Hand and object geometry with a non-circular ``section``
        (:meth:`HandGeometry.from_config`); the object rests on the table at
        ``(object_u0, object_z0)``, unturned, before the first sample.
    history
        The grasp's samples from before the fingers touch the object.
    final_positions, final_efforts
        (3n,) the last state [rad], [N*m], if later than the history's last sample.
    settings
        Tuning; defaults of :class:`TrackerSettings` if ``None``.
    stop
        Polled between samples; when it returns true the tracking ends with
        :class:`~dam_spcm_controller.object_estimate.FitInterrupted`.

    Returns
    -------
    TrackedPose
        The pose at the last sample.

    Raises
    ------
    InputError
        No section, a history of the wrong width or without samples, bad final arrays.
    FitInterrupted
        ``stop()`` returned true.
    """
    s = settings or TrackerSettings()
    model = _Model(geometry, s)
    tracker = _Tracker(model)
    n = geometry.n_fingers
    if history.n_joints != 3 * n:
        raise InputError(f'history has {history.n_joints} joints, the hand {3 * n}')
    q_all, tau_all = history.positions, history.efforts
    if final_positions is not None or final_efforts is not None:
        if final_positions is None or final_efforts is None:
            raise InputError('final_positions and final_efforts go together')
        q_all = np.vstack([q_all, finite_vector('final_positions', final_positions, 3 * n)])
        tau_all = np.vstack([tau_all, finite_vector('final_efforts', final_efforts, 3 * n)])
    if q_all.shape[0] == 0:
        raise InputError('the history holds no sample')
    table_x = np.array([geometry.object_u0, geometry.object_z0, 0.0])
    free_x: np.ndarray | None = None
    free_low = -math.inf
    lost_low = math.nan  # clearance of the free equilibrium when it was lost [m]
    on_table = True
    last: _Contact | None = None  # contacts of the pose taken at the last sample
    last_free: _Contact | None = None  # ... and of the free equilibrium
    sink = np.zeros(n)
    used = 0
    count = q_all.shape[0]
    for k in _select(q_all, tau_all[:, 0::3], s):
        q, tau_c = q_all[k], tau_all[k, 0::3]
        if stop is not None and stop():
            raise FitInterrupted('the object fit was interrupted')
        used += 1
        pts = finger_points(geometry, q)
        axes = LinkAxes.from_points(pts)
        # a finger presses on the object: torque, and near the pose the object had
        near = table_x if on_table or free_x is None else free_x
        gap = model.distance_residuals(model.distances(axes, near[None]), sink,
                                       np.ones(n, dtype=bool))[0]
        loaded = (tau_c >= s.load_torque) & (gap < s.contact_gap)
        both = bool(loaded[model.side_a].any() and loaded[model.side_b].any())
        if not loaded.any() and on_table and k != count - 1 and gap.min() >= 0.0:
            last = None  # nothing presses on the object or enters it: it stays
            continue
        if on_table and table_x[2] == 0.0 and gap.min() < 0.0:
            # a section resting unturned tips away from the finger that pushes into it first
            table_x = table_x.copy()
            table_x[2] = -1e-3 * model.sign[int(np.argmin(gap))]
        if on_table or free_x is None or free_low < model.table + s.table_margin:
            start = table_x if on_table or free_x is None else free_x
            table_x = tracker.table_pose(pts, axes, sink, loaded, start, last)
        if both:
            moments = model.joint_moments(pts, tau_c)
            if free_x is None:
                found = tracker.equilibrium(pts, axes, moments, sink, loaded, table_x[2],
                                            table_x[:2], s.init_window)
            else:  # near where the contacts would roll it
                rolled = tracker.table_pose(pts, axes, sink, loaded, free_x, last_free,
                                            table=False) if s.roll_prediction else free_x
                found = tracker.equilibrium(pts, axes, moments, sink, loaded, rolled[2],
                                            rolled[:2], s.root_window)
            if found is not None:
                free_x, free_low = found
                lost_low = math.nan
            elif free_x is not None:  # no equilibrium near: the turn is kept
                if math.isnan(lost_low):
                    lost_low = free_low if not on_table else -math.inf
                c, _, con = tracker.fit_family(axes, sink, loaded, free_x[2:3],
                                               free_x[None, :2])
                free_x = np.array([c[0, 0], c[0, 1], free_x[2]])
                free_low = float(con.lowest[0])
        else:
            free_x, free_low, found, lost_low = None, -math.inf, None, math.nan
        # off the table while an equilibrium off it is found; one that was lost keeps the
        # object off only if it was well above the table (near it, the object has more likely
        # come down onto the table)
        on_table = not (free_x is not None and free_low > model.table
                        and (found is not None or lost_low > model.table + s.hold_height))
        x = table_x if on_table else free_x
        con = model.contacts(axes, x[None])
        sink = model.sinking(pts, tau_c, con)
        last = _contact_of(pts, x, con, loaded)
        if free_x is None:
            last_free = None
        elif on_table:  # the free equilibrium rolls on from its own contacts
            last_free = _contact_of(pts, free_x, model.contacts(axes, free_x[None]), loaded)
        else:
            last_free = last
    residuals = con.distance[0] - geometry.link_radius + sink
    return TrackedPose(centre=x[:2].copy(), orientation=float(x[2]),
                       clearance=0.0 if on_table else max(float(con.lowest[0]) - model.table,
                                                          0.0),
                       on_table=on_table, residuals=residuals, samples=used)
