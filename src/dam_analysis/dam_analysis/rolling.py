"""Rolling on the table: what eq. 18 leaves out for a section that is not a circle.

Eq. 18 (paper section 3.2) holds the object fixed in its resting pose and asks whether every
admissible contact force lifts it, ``c_z^T f_o > m_B g``: then the table cannot balance the
object there. A circle cannot raise its centroid while it touches the table, so for the
paper's cylinder that is lift-off. A polygon can: it turns onto an edge of the face it rests
on, its centroid rises by up to circumradius minus apothem, and it still touches the table; an
ellipse does the same as it turns off its flat side. Fingers that squeeze opposite vertices
turn it. Measured in the stand-in: a hexagonal bar guaranteed by eq. 18 at rest (alpha 5 deg,
k_theta 7 N*m/rad, delta_theta_p 5 deg, margin +0.81 N) turned +25 deg and came to rest on
the table, its centroid 1.35 mm higher and 0.11 mm to the side.

The condition added here (docs/analysis.md section 11): the object leaves the table if
eq. 18 holds at rest **and no admissible contact force lets it rest in any pose it can turn
into while it touches the table**. Quasi-static, as the paper's analysis: at the end of the
displacement the object rests somewhere; on the table in a turned pose it stands on one pivot
(a polygon's vertex, an ellipse's lowest point), where the table pushes up, ``N >= 0``, with
friction, through the pivot. A rest there needs, for some admissible force (eqs. 7-9 with the
contacts of that pose):

* ``c_z^T f_o + N = m_B g`` with ``N >= 0``, i.e. ``c_z^T f_o <= m_B g``;
* the balance of moments about the pivot, ``sum_i (p_Ci - P) x f_ci + (c - P) x m_B g = 0``
  (the table's force has no moment about it);
* the horizontal balance is left to the table's friction, without a bound (which can only
  admit more rests, so the condition stays sufficient).

:func:`pose_margin` solves the linear program ``min c_z^T f_o`` under these constraints; a
positive ``min - m_B g`` (or no solution at all) means the object cannot rest in that pose.
Where the object has turned until a face lies flat on the table again, two supports carry any
moment and only the vertical balance is asked (eq. 18 in that pose).

In each pose the fingers have followed the object: each compliant joint settles where its
distal link touches the turned section (the closure of eqs. 2-4 with the object moved),
``tau_s = -k_theta_i (theta_s - theta_s0)``; a finger that does not reach the object at its
spring's rest angle gives no force; one that cannot follow it (a proximal link or the table in
the way, a joint limit, no solution of the closure) leaves the pose undecided, and lift is not
guaranteed.

The poses (:func:`roll_poses`): the section turned in place both ways, its centroid above the
same point of the table and lowered until it touches it, on a grid of turns (2 deg by default)
up to where the next face lands (a polygon) or a quarter turn (an ellipse, its narrow side
down). The centroid's horizontal position is held by the fingers on either side; translations
along the table (rolling without slipping, sliding) are left out, as the paper leaves them out
for the cylinder (:func:`roll_poses` can add slides). A circle turned in place is the same
circle, so the cylinder's answers are eq. 18's. The verdict is taken on the grid of turns.

Pure numpy/scipy; no rclpy.
"""

from __future__ import annotations

import math
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from dam_analysis.model import FingerGeometry, HandModel, distal_gap, finger_geometries
from dam_analysis.spcm import SpcmPath, newton_theta_s, plane_contact, posture_problem
from dam_common.config import DamConfig
from dam_common.cross_section import Circle, CrossSection, Ellipse
from dam_common.polygon_section import ConvexPolygon

#: Default grid step of the turns [rad].
ROLL_STEP_RAD = math.radians(2.0)
#: Default grid step of the slides along the table [m].
SLIDE_STEP_M = 0.5e-3
#: States kept per analyzer (one entry per requested displacement vector).
_CACHE_SIZE = 256
#: Kinds of a finger's state in a rolled pose.
ROLL_CONTACT, ROLL_FREE, ROLL_BLOCKED = 'contact', 'free', 'blocked'


@dataclass(frozen=True)
class RollPose:
    """A pose of the object turned on the table, in the section's frame.

    Attributes
    ----------
    turn : rotation from the resting pose [rad], counter-clockwise in the section's
        ``(x, z)`` plane (``x`` towards ``z``).
    shift : ``(x, z)`` displacement of the centroid from its resting position [m]: the slide
        along the table and the rise.
    pivot : ``x`` of the table contact relative to the resting centroid [m] (a polygon's
        vertex; an ellipse's lowest point).
    resting : a polygon's face lies flat on the table (two supports carry any moment).
    """

    turn: float
    shift: tuple[float, float]
    pivot: float
    resting: bool = False

    def describe(self) -> str:
        """E.g. ``'turned +26.0 deg, centroid 1.37 mm higher'`` (``slid +0.5 mm`` too
        where it slid)."""
        slid = f', slid {self.shift[0] * 1e3:+.1f} mm' if self.shift[0] != 0.0 else ''
        return (f'turned {math.degrees(self.turn):+.1f} deg{slid}, centroid '
                f'{self.shift[1] * 1e3:.2f} mm higher')


def _turn(angle: float, x: float, z: float) -> tuple[float, float]:
    c, s = math.cos(angle), math.sin(angle)
    return c * x - s * z, s * x + c * z


def _turn_grid(end: float, step: float) -> list[float]:
    n = max(1, int(math.ceil(end / step - 1e-9)))
    return [end * j / n for j in range(0, n + 1)]


def _turn_ranges(section: CrossSection) -> tuple[float, float]:
    """How far the section turns each way before it rests on the table again [rad]:
    ``(counter-clockwise, clockwise)``."""
    if isinstance(section, ConvexPolygon):
        v = [tuple(map(float, p)) for p in section.vertices]
        m = len(v)
        bottom = min(p[1] for p in v)
        tol = 1e-12 * max(1.0, abs(bottom)) + 1e-15
        face = [j for j in range(m) if abs(v[j][1] - bottom) <= tol]
        ends = []
        for sign in (1.0, -1.0):  # +1: about the face's -x end, counter-clockwise
            pick = min if sign > 0 else max
            j = pick(face, key=lambda idx: v[idx][0])
            other = [n for n in ((j - 1) % m, (j + 1) % m) if n not in face][0]
            wx, wz = v[other][0] - v[j][0], v[other][1] - v[j][1]
            # the pivot's other edge lands when it lies flat
            ends.append(math.atan2(wz, -wx) if sign > 0 else math.atan2(wz, wx))
        return ends[0], ends[1]
    if isinstance(section, Ellipse):
        return 0.5 * math.pi, 0.5 * math.pi  # up to its narrow side, the centroid highest
    raise ValueError(f'no rolling poses for a {section.describe()}')


def roll_poses(section: CrossSection, turn_step: float = ROLL_STEP_RAD,
               slide_step: float = SLIDE_STEP_M,
               slide_range: float | None = None) -> tuple[RollPose, ...]:
    """The poses a section can take on the table (module docstring), resting pose left out.

    Each pose is the section turned by ``turn`` (on a grid of at most ``turn_step`` from the
    resting pose to where it rests on the table again, each way), lowered onto the table, its
    centroid moved along the table by a slide on a grid of ``slide_step`` within
    ``+-slide_range``. The table touches it at its lowest point, the pivot.

    Parameters
    ----------
    section : the section in its resting pose (:mod:`dam_common.cross_section`).
    turn_step : largest step of the turn grid [rad], positive.
    slide_step : step of the slide grid [m], positive.
    slide_range : largest slide each way [m]; default 0: the object turns in place, its
        centroid above the same point of the table (module docstring).

    Returns
    -------
    The poses, grouped by slide and way, each way ordered by growing turn (the first of each
    group unturned: the resting pose slid; the unslid resting pose is left out); empty for a
    circle.

    Raises
    ------
    ValueError
        A step not positive and finite, or a section kind this module does not know.
    """
    for name, value in (('turn_step', turn_step), ('slide_step', slide_step)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f'{name}: expected a positive number, got {value!r}')
    if isinstance(section, Circle):
        return ()
    ccw, cw = _turn_ranges(section)
    reach = 0.0 if slide_range is None else float(slide_range)
    n_slide = int(math.floor(reach / slide_step + 1e-9))
    slides = [slide_step * j for j in range(-n_slide, n_slide + 1)]
    rest = section.rest_height
    flat = isinstance(section, ConvexPolygon)
    poses = []
    for slide in slides:
        for sign, end in ((1.0, ccw), (-1.0, cw)):
            grid = _turn_grid(end, turn_step)
            for j, turn in enumerate(grid):
                if j == 0 and (sign < 0 or slide == 0.0):
                    continue  # the unturned pose once per slide; the resting pose is eq. 18's
                beta = sign * turn
                # lowest point of the turned section: its support along R(-beta) (0, -1)
                qx, qz = section.support(-math.sin(beta), -math.cos(beta))
                rx, rz = _turn(beta, qx, qz)
                resting = flat and (j == 0 or j == len(grid) - 1)
                poses.append(RollPose(beta, (slide, -rz - rest), slide + rx, resting))
    return tuple(poses)


@dataclass(frozen=True)
class FingerRoll:
    """One finger in one rolled pose.

    Attributes
    ----------
    kind : ``'contact'``, ``'free'`` (does not reach the object at its rest angle: no force)
        or ``'blocked'`` (cannot follow: ``reason`` says why).
    delta_theta_s : ``theta_s - theta_s0`` [rad] (contact only, else 0).
    contact : ``(p_u, p_z, n_u, n_z)`` contact point relative to the base [m] and the object's
        outward normal, plane coordinates (contact only).
    reason : why a finger is blocked, else ``''``.
    """

    kind: str
    delta_theta_s: float = 0.0
    contact: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    reason: str = ''


@dataclass(frozen=True)
class RollingVerdict:
    """Eq. 18 over the rolled poses for one request.

    Attributes
    ----------
    checked : the section can roll (not a circle) and every finger had an SPCM state at rest.
    holds : eq. 18 holds, with a bounded worst case, in every rolled pose.
    margin : smallest worst-case margin ``c_z^T f_o - m_B g`` over the rolled poses [N]
        (``-inf``: unbounded in some pose; NaN: not checked or a pose undecided).
    pose : the pose of ``margin`` (or the first undecided pose), None if not checked.
    message : why it does not hold (empty when it holds or was not checked).
    """

    checked: bool
    holds: bool
    margin: float
    pose: RollPose | None
    message: str


NOT_CHECKED = RollingVerdict(False, True, math.nan, None, '')


class RollingCheck:
    """Eq. 18 in every pose the object can roll into (module docstring), for one analyzer.

    The finger states of a displacement do not depend on the stiffness or the friction
    angle; they are solved once per displacement vector (continuation in the turn from the
    SPCM state at rest, Newton on the closure) and kept.

    Parameters
    ----------
    config : the configuration the model was built from.
    model : the hand at first contact.
    paths : the SPCM branches at rest (the start of each continuation).
    step : grid step of the turns [rad].
    """

    def __init__(self, config: DamConfig, model: HandModel, paths: tuple[SpcmPath, ...],
                 step: float = ROLL_STEP_RAD) -> None:
        self.model = model
        self.paths = paths
        self.step = float(step)
        self.poses = roll_poses(config.object.section, step)
        self._geometries = [finger_geometries(config, p.turn, p.shift) for p in self.poses]
        # each way's poses follow each other in the list: continuation restarts at a new way
        turns = [p.turn for p in self.poses]
        self._starts = {0} | {j for j in range(1, len(turns))
                              if abs(turns[j]) <= abs(turns[j - 1])
                              or turns[j] * turns[j - 1] < 0.0}
        self._last_failure = 0
        self._cache: OrderedDict[tuple[float, ...], tuple[list[float], list]] = OrderedDict()
        # the pivot of every pose in every finger's plane, and the sign of the plane's u axis
        # along the section's x axis (-1: the finger's plane is the mirror image)
        obj = config.object
        self._signs = [1.0 if float(f.inward_direction @ obj.section_x) > 0.0 else -1.0
                       for f in config.hand.fingers]
        rest_height = obj.section.rest_height
        self._pivots = []
        for pose, geoms in zip(self.poses, self._geometries, strict=True):
            dx, dz = pose.pivot - pose.shift[0], -rest_height - pose.shift[1]
            self._pivots.append([(float(g.object_center[0]) + sgn * dx,
                                  float(g.object_center[1]) + dz)
                                 for g, sgn in zip(geoms, self._signs, strict=True)])
        # gravity's moment about each pivot, per newton of weight (section frame, x -> z)
        self._gravity_arm = [-(pose.shift[0] - pose.pivot) for pose in self.poses]

    @property
    def active(self) -> bool:
        """The section can roll: there are poses to check."""
        return bool(self.poses)

    def pose_states(self, delta_theta_p: list[float], j: int) -> list[FingerRoll]:
        """Finger states of pose ``j`` at one displacement per finger [rad], solved on demand.

        Newton starts from the nearest pose solved before it in its group (continuation in
        the turn), or from the SPCM state at rest; a finger it does not bring onto the object
        is found by a scan (:meth:`_scan`).

        Raises
        ------
        dam_analysis.errors.NoSolutionError
            A finger has no SPCM state at rest (beyond its branch end).
        """
        key = tuple(float(d) for d in delta_theta_p)
        entry = self._cache.get(key)
        if entry is None:
            rest = [path.plane_state(d)[0] for path, d in zip(self.paths, key, strict=True)]
            entry = (rest, [None] * len(self.poses))
            self._cache[key] = entry
            if len(self._cache) > _CACHE_SIZE:
                self._cache.popitem(last=False)
        else:
            self._cache.move_to_end(key)
        rest, solved = entry
        hit = solved[j]
        if hit is not None:
            return hit
        start = j
        while start not in self._starts and solved[start - 1] is None:
            start -= 1
        model = self.model
        for jj in range(start, j + 1):
            before = solved[jj - 1] if jj not in self._starts else None
            states = []
            for i, path in enumerate(self.paths):
                guess = rest[i]
                if before is not None and before[i].kind == ROLL_CONTACT:
                    guess = path.theta_s0 + before[i].delta_theta_s
                states.append(self._finger(self._geometries[jj][i],
                                           model.theta_p0 + key[i], path.theta_s0, guess))
            solved[jj] = states
        return solved[j]

    def _finger(self, geometry: FingerGeometry, theta_p: float, theta_s0: float,
                guess: float) -> FingerRoll:
        model = self.model
        theta_l = model.theta_l0
        if distal_gap(geometry, theta_s0, theta_l, theta_p)[0] > 0.0:
            return FingerRoll(ROLL_FREE)
        theta = newton_theta_s(geometry, theta_l, theta_p, guess)
        if theta is None or theta > theta_s0 + 1e-12:
            theta = self._scan(geometry, theta_p, theta_s0)
        if theta is None:
            return FingerRoll(ROLL_BLOCKED, reason='the distal link cannot follow the object '
                              '(no solution of the contact closure, eqs. 2-4)')
        problem = posture_problem(geometry, theta, theta_l, theta_p, theta_s0,
                                  model.limits_s, model.limits_p)
        if problem is not None:
            return FingerRoll(ROLL_BLOCKED, reason=problem)
        p_u, p_z, n_u, n_z, _ = plane_contact(geometry, theta, theta_l, theta_p)
        return FingerRoll(ROLL_CONTACT, theta - theta_s0, (p_u, p_z, n_u, n_z))

    def _scan(self, geometry: FingerGeometry, theta_p: float, theta_s0: float
              ) -> float | None:
        """The largest compliant angle below the rest angle where the distal link touches:
        the finger opens from its rest angle until it no longer penetrates the object."""
        theta_l = self.model.theta_l0
        lower = self.model.limits_s[0]
        step = math.radians(0.25)
        hi = theta_s0
        lo = hi - step
        while lo >= lower - step:
            if distal_gap(geometry, max(lo, lower), theta_l, theta_p)[0] >= 0.0:
                lo = max(lo, lower)
                for _ in range(60):
                    mid = 0.5 * (lo + hi)
                    if distal_gap(geometry, mid, theta_l, theta_p)[0] >= 0.0:
                        lo = mid
                    else:
                        hi = mid
                return lo
            hi, lo = lo, lo - step
        return None

    def verdict(self, k_theta: list[float], delta_theta_p: list[float],
                friction_angle: float, weight: float | tuple[float, float],
                cos_phi: list[float], complete: bool = True) -> RollingVerdict:
        """Whether the object can rest in any rolled or slid pose, for one request.

        Parameters
        ----------
        k_theta : per finger [N m/rad]; delta_theta_p : per finger [rad];
        friction_angle : alpha [rad]; weight : m_B g [N], or its range (the object rests
        for some weight in it); cos_phi : the cone's ``cos(2 pi k / L)``.
        complete : evaluate every pose: the smallest margin and its pose, the same answer
            for the same request (default); False stops at the first pose where the object
            can rest, trying the pose that failed last first (the same verdict, the margin and
            pose of that pose: for maps, which need the verdict only).

        Raises
        ------
        dam_analysis.errors.NoSolutionError
            A finger has no SPCM state at rest.
        """
        if not self.active:
            return NOT_CHECKED
        n = len(self.poses)
        order = range(n) if complete else [(self._last_failure + j) % n for j in range(n)]
        worst, worst_j = math.inf, -1
        for j in order:
            pose, fingers = self.poses[j], self.pose_states(delta_theta_p, j)
            for i, state in enumerate(fingers):
                if state.kind == ROLL_BLOCKED:
                    self._last_failure = j
                    return RollingVerdict(
                        True, False, math.nan, pose,
                        f'the object may roll: {pose.describe()}, finger {i + 1} cannot '
                        f'follow it ({state.reason}): not decided')
            margin = pose_margin(fingers, k_theta, friction_angle, cos_phi, weight,
                                 self._pivots[j], self._signs, self._gravity_arm[j],
                                 not pose.resting)
            if margin < worst:
                worst, worst_j = margin, j
            if margin <= 0.0 and not complete:
                self._last_failure = j
                break
        holds = worst > 0.0
        pose = self.poses[worst_j]
        message = '' if holds else (
            f'the object may roll: it can rest {pose.describe()} on the table, '
            f'{_shortfall(worst)}')
        return RollingVerdict(True, holds, worst, pose, message)


def pose_margin(states: list[FingerRoll], k_theta: list[float], friction_angle: float,
                cos_phi: list[float], weight: float | tuple[float, float],
                pivots: list[tuple[float, float]], signs: list[float], gravity_arm: float,
                balance_moment: bool) -> float:
    """Least ``c_z^T f_o - m_B g`` over the admissible forces that balance a turned pose.

    The linear program (eqs. 7-9 with the pose's contacts): minimise ``c_z^T sum_i f_ci``
    over the friction cones' span vectors, ``lambda >= 0``, subject to each finger's torque
    ``J_i^T f_ci = tau_si`` and, where the object stands on a single pivot, the balance of
    moments about it, ``sum_i (p_Ci - P) x f_ci + (c - P) x (-m_B g) = 0`` (the table's force
    acts at the pivot). A rest of the object in this pose needs the table to push up by
    ``N = m_B g - c_z^T f_o >= 0``; a positive result means no admissible force allows it.

    Parameters
    ----------
    states : the fingers in this pose; k_theta : per finger [N m/rad];
    friction_angle : alpha [rad]; cos_phi : the cone's ``cos(2 pi k / L)``; weight : m_B g
    [N], or its range ``(least, largest)``: then the weight is a variable of the program too
    (a rest with any weight in the range); pivots : the pivot ``(u, z)`` in each finger's
    plane [m]; signs : +1 where a finger's
    ``u`` axis is the section's ``x`` axis, -1 where it is mirrored; gravity_arm : moment of
    the weight about the pivot per newton [m] (section frame); balance_moment : False where
    the object rests on a whole face (two supports carry any moment).

    Returns
    -------
    The margin [N]: ``+inf`` when no admissible force balances the object in this pose,
    ``-inf`` when the worst case is unbounded.
    """
    ca, sa = math.cos(friction_angle), math.sin(friction_angle)
    cost: list[float] = []
    rows: list[list[float]] = []
    rhs: list[float] = []
    moment_row: list[float] = []
    n_cols = 0
    blocks = []
    for i, state in enumerate(states):
        if state.kind != ROLL_CONTACT:
            continue
        p_u, p_z, n_u, n_z = state.contact
        piv_u, piv_z = pivots[i]
        block_h, block_m = [], []
        for cphi in cos_phi:
            v_u = -ca * n_u - sa * cphi * n_z
            v_z = -ca * n_z + sa * cphi * n_u
            block_h.append(p_u * v_z - p_z * v_u)
            block_m.append(signs[i] * ((p_u - piv_u) * v_z - (p_z - piv_z) * v_u))
            cost.append(v_z)
        blocks.append((n_cols, block_h, -k_theta[i] * state.delta_theta_s))
        moment_row.extend(block_m)
        n_cols += len(cos_phi)
    low, high = (weight, weight) if isinstance(weight, float | int) else weight
    if n_cols == 0:
        # no finger touches: on a face the object rests under its weight alone; on a pivot
        # only where its weight's line runs through the pivot (a balance, unstable, that the
        # analysis cannot rule out: whether the fingers could have brought it there is not
        # asked; in the stand-in the hexagonal bar rests turned where the model's fingers
        # no longer touch it, at displacements of 1 deg)
        balanced = not balance_moment or abs(gravity_arm) < 1e-9
        return -high if balanced else math.inf
    # the last column is the weight W in [low, high]: minimise c_z^T f_o - W
    cost.append(-1.0)
    for start, block_h, tau in blocks:
        row = [0.0] * (n_cols + 1)
        row[start:start + len(block_h)] = block_h
        rows.append(row)
        rhs.append(tau)
    if balance_moment:  # sum m lambda + W * arm = 0
        rows.append(moment_row + [gravity_arm])
        rhs.append(0.0)
    bounds = [(0.0, None)] * n_cols + [(float(low), float(high))]
    from scipy.optimize import linprog  # noqa: PLC0415 (scipy: start-up time)

    res = linprog(np.array(cost), A_eq=np.array(rows), b_eq=np.array(rhs), bounds=bounds,
                  method='highs')
    if res.status == 2:
        return math.inf
    if res.status == 3:
        return -math.inf
    if res.status != 0:
        raise RuntimeError(f'linear program of a rolled pose failed: {res.message}')
    return float(res.fun)


def _shortfall(margin: float) -> str:
    """Why the object can rest there, from the pose's margin ``min c_z^T f_o - m_B g`` [N]."""
    if margin == -math.inf:
        return 'where an internal force of any size is admissible'
    return (f'where the fingers may lift {-margin:.4g} N less than its weight '
            f'(margin {margin:+.4g} N)')
