"""The contact stiffness model's verdict on observed grasps: many cells, many parameters.

A *cell* is one observed grasp (or a group of them with the same pair): finger 1's stiffness
``k_theta``, the position-joint displacement ``delta_theta_p`` (every finger), the friction
angle the grasp ran at, the object mass and whether the object lifted. The calibration
(:mod:`dam_analysis.csm_calibration`) needs the CSM margin of every cell for many values of the
friction angle and of the tangential stiffness; this module evaluates them in bulk from one
:class:`~dam_analysis.regions.PathTable` (the SPCM states do not depend on either parameter).

Two verdicts (``docs/analysis.md``, "What the CSM boundary depends on"):

* ``'end'``: the margin ``c_z^T f_o - m_B g`` at the end of the displacement, the paper's
  verdict and ``/check_lift``'s ``csm_margin``.
* ``'path'``: the largest margin on the way there, ``max_{0 < d <= delta_theta_p} margin(d)``
  (a separated contact counts as no lift at that ``d``). The paper's analysis holds the object
  fixed until it lifts; a grasp that drives the position joints from 0 to ``delta_theta_p``
  lifts the object as soon as the margin first turns positive, whatever the margin at the
  end would have been with the object still on the table.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from dam_analysis.errors import InputError
from dam_analysis.regions import PathTable, csm_evaluate, end_tables

VERDICTS = ('end', 'path')
#: Step of the displacement grid the ``'path'`` verdict takes its maximum over [rad].
PATH_VERDICT_STEP_RAD = math.radians(0.5)


@dataclass(frozen=True)
class GraspCells:
    """Observed grasps, one entry per cell (all (N,) float64 arrays, SI).

    Attributes
    ----------
    friction_angle : the friction angle the grasp ran at, as recorded [rad].
    k_theta : finger 1's compliant-joint stiffness [N m/rad] (the others by the ratios).
    delta_theta_p : the position-joint displacement, the same for every finger [rad].
    object_mass : the object's mass [kg].
    lifted : 1.0 when the object lifted, 0.0 when not.
    """

    friction_angle: np.ndarray
    k_theta: np.ndarray
    delta_theta_p: np.ndarray
    object_mass: np.ndarray
    lifted: np.ndarray

    def __post_init__(self) -> None:
        n = np.asarray(self.k_theta).shape
        for name in ('friction_angle', 'k_theta', 'delta_theta_p', 'object_mass', 'lifted'):
            value = np.asarray(getattr(self, name), dtype=np.float64)
            if value.ndim != 1 or value.shape != n:
                raise InputError(f'{name}: expected shape {n}, got {value.shape}')
            if not np.all(np.isfinite(value)):
                raise InputError(f'{name}: every value must be finite, got {value!r}')
            object.__setattr__(self, name, value)
        if n[0] == 0:
            raise InputError('no grasps: a calibration needs at least one')
        if np.any(self.k_theta <= 0.0) or np.any(self.object_mass <= 0.0):
            raise InputError('k_theta and object_mass must be positive')
        if np.any(self.delta_theta_p <= 0.0):
            raise InputError('delta_theta_p must be positive')
        if not np.all((self.lifted == 0.0) | (self.lifted == 1.0)):
            raise InputError(f'lifted: expected 0 or 1, got {np.unique(self.lifted)!r}')

    @property
    def size(self) -> int:
        return int(self.k_theta.size)


class CellMargins:
    """CSM margins of a fixed set of cells for any friction angle and tangential stiffness.

    Parameters
    ----------
    table : SPCM branch of the hand and object (its model's weight is not used: each cell
        brings its own mass).
    k_theta, delta_theta_p : (N,) the cells' pairs [N m/rad], [rad].
    object_mass : (N,) [kg].
    gravity : [m/s^2].

    Raises
    ------
    InputError
        A displacement beyond the configured ``delta_theta_p_max``.
    """

    def __init__(self, table: PathTable, k_theta: np.ndarray, delta_theta_p: np.ndarray,
                 object_mass: np.ndarray, gravity: float) -> None:
        self.table = table
        dp = np.asarray(delta_theta_p, dtype=np.float64)
        if dp.size and float(dp.max()) > table.model.delta_theta_p_max + 1e-12:
            raise InputError(f'delta_theta_p {math.degrees(float(dp.max())):.6g} deg is beyond '
                             f'task.delta_theta_p_max_deg '
                             f'({math.degrees(table.model.delta_theta_p_max):.6g} deg)')
        self._k, self._k_index = np.unique(np.asarray(k_theta, dtype=np.float64),
                                           return_inverse=True)
        top = float(dp.max())
        fine = np.arange(1, int(math.ceil(top / PATH_VERDICT_STEP_RAD)) + 1) \
            * PATH_VERDICT_STEP_RAD
        self._nodes, inverse = np.unique(np.concatenate([dp, fine[fine < top]]),
                                         return_inverse=True)
        self._dp_index = inverse[:dp.size]
        self._ends = end_tables(table, self._nodes)
        self._weight = np.asarray(object_mass, dtype=np.float64) * float(gravity)
        self._ratios = np.asarray(table.model.stiffness_ratios, dtype=np.float64)

    def vertical_force(self, friction_angle: float, tangential_stiffness: float
                       ) -> np.ndarray:
        """``c_z^T f_o`` on the (k values, displacement nodes) grid, NaN on separation [N]."""
        total = np.zeros((self._k.size, self._nodes.size))
        separated = np.zeros(total.shape, dtype=bool)
        for i, end in enumerate(self._ends):
            ev = csm_evaluate(self.table, i, end, self._ratios[i] * self._k,
                              float(friction_angle), float(tangential_stiffness))
            total += ev.fz
            separated |= ev.separated
        return np.where(separated, np.nan, total)

    def margins(self, friction_angle: float, tangential_stiffness: float,
                verdict: str = 'path') -> np.ndarray:
        """(N,) CSM margin of every cell [N]; ``-inf`` where the CSM gives no equilibrium.

        Parameters
        ----------
        friction_angle : alpha [rad]. tangential_stiffness : the CSM's ``k_t`` [N/m].
        verdict : ``'end'`` or ``'path'`` (module docstring).
        """
        if verdict not in VERDICTS:
            raise InputError(f'verdict {verdict!r} is not one of {VERDICTS}')
        fz = self.vertical_force(friction_angle, tangential_stiffness)
        picked = fz[self._k_index, :]  # (N, D)
        margin = picked - self._weight[:, None]
        margin = np.where(np.isnan(margin), -np.inf, margin)
        if verdict == 'path':
            margin = np.maximum.accumulate(margin, axis=1)
        return margin[np.arange(self._k_index.size), self._dp_index]
