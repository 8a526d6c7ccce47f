"""The contact stiffness model's path verdict for ``check_lift``.

``/check_lift``'s ``csm_margin`` is the CSM margin at the end of the displacement (the paper's
verdict, ``'end'``). A grasp drives the position joints from 0 to ``delta_theta_p`` and the
object lifts as soon as the margin first turns positive on the way; the *path verdict* is the
largest margin on the way (docs/analysis.md section 10):

    csm_path_margin = max( max_{nodes d_j < delta_theta_p} margin(d_j), margin(delta_theta_p) )

over the nodes of the cached SPCM grid (0.05 deg) below the displacement, all fingers moving
together (one ``delta_theta_p`` for all). A node where a contact would open counts as no lift
there; the nodes end where a finger's SPCM branch ends, so a displacement beyond the branch
end still has the verdict of the way up to it.

The forces at every node are the CSM's of :mod:`dam_analysis.regions` (play operator in
closed form: at node ``j`` the spring's stretch is ``s_j + min_{i <= j} (k gamma_i - s_i)``).
Fast path: when every node below the displacement slides on the cone's edge, the margin is
linear in each finger's stiffness, ``sum_i k_i B_i(d_j) - m_B g``, and its running maximum is
kept per friction angle; the nodes all slide when ``k_i max_j (gamma_j - gamma_{j-1})^+ <=
min_j (s_j - s_{j-1})`` (then ``k gamma_j - s_j`` never rises, so each node attains the running
minimum), a sufficient test. Otherwise the nodes are evaluated with numpy, and fingers with
different displacements (their nodes do not line up) or a slip that reverses go through
:func:`dam_analysis.regions.csm_evaluate` at nodes 0.5 deg apart along the common fraction of
the displacement.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np

from dam_analysis.regions import PathTable, contacts_at, csm_evaluate, finger_table

#: Spacing of the fraction nodes of the slow path, in finger 1's displacement [rad].
SLOW_STEP_RAD = math.radians(0.5)
#: Friction angles whose data are kept.
_CACHE_SIZE = 64


@dataclass(frozen=True)
class PathVerdict:
    """The CSM's path verdict of one request.

    Attributes
    ----------
    lift : the largest margin on the way is positive.
    margin : that margin [N] (``-inf`` when no node of the way has an equilibrium).
    delta_theta_p : finger 1's displacement where it is reached [rad] (NaN when none).
    """

    lift: bool
    margin: float
    delta_theta_p: float


@dataclass(frozen=True)
class _Finger:
    """One finger's CSM quantities on the valid grid nodes (monotone slip)."""

    grid: list[float]
    tau_hat: np.ndarray
    h_n: np.ndarray
    h_t: np.ndarray
    cz_n: np.ndarray
    cz_t: np.ndarray
    s: np.ndarray  # sign * slip, non-decreasing
    sign: float


@dataclass(frozen=True)
class _AlphaData:
    gamma: list[np.ndarray]
    slide_b: list[np.ndarray]  # vertical force per unit k_i when sliding (NaN: cannot slide)
    k_all_slide: list[np.ndarray]  # per node J: nodes 0..J all slide for k_i <= this
    ratio_prefix: np.ndarray  # running max of sum_i (r_i / r_0) B_i (all-slide, one k)
    ratio_argmax: np.ndarray


class CsmPathVerdict:
    """Path verdicts of one analysis (module docstring).

    Parameters
    ----------
    table : the analysis' SPCM tables.
    stiffness_ratios : (n,) ``k_theta_i / k_theta``.
    tangential_stiffness : the CSM's ``k_t`` [N/m].
    """

    def __init__(self, table: PathTable, stiffness_ratios: list[float],
                 tangential_stiffness: float) -> None:
        self.table = table
        self.ratios = [float(r) for r in stiffness_ratios]
        self.k_t = float(tangential_stiffness)
        self._fingers: list[_Finger] | None = []
        for i in range(table.model.n_fingers):
            path = table.csm_path(i)
            valid = np.isfinite(path.tau_hat)
            if not path.monotone:
                self._fingers = None
                break
            sign = path.slip_sign
            self._fingers.append(_Finger(
                path.delta_theta_p[valid].tolist(), path.tau_hat[valid], path.h_n[valid],
                path.h_t[valid], path.cz_n[valid], path.cz_t[valid],
                sign * path.slip[valid], sign))
        self._cache: dict[float, _AlphaData] = {}

    def _alpha(self, alpha: float) -> _AlphaData:
        hit = self._cache.get(alpha)
        if hit is not None:
            return hit
        assert self._fingers is not None
        mu = math.tan(alpha)
        gammas, bs, kcs = [], [], []
        for f in self._fingers:
            denom = f.h_n + f.sign * mu * f.h_t
            with np.errstate(divide='ignore', invalid='ignore'):
                gamma = np.where(denom > 0.0, mu * f.tau_hat / (self.k_t * denom), np.inf)
                b = np.where(denom > 0.0,
                             f.tau_hat * (f.cz_n + f.sign * mu * f.cz_t) / denom, np.nan)
            d_s = np.diff(f.s, prepend=f.s[0])
            d_g = np.diff(gamma, prepend=gamma[0])
            with np.errstate(invalid='ignore'):
                rise = np.where(np.isfinite(d_g), np.maximum(d_g, 0.0), np.inf)
            min_ds = np.minimum.accumulate(np.where(np.arange(d_s.size) > 0, d_s, np.inf))
            max_rise = np.maximum.accumulate(rise)
            with np.errstate(divide='ignore', invalid='ignore'):
                kc = np.where(max_rise > 0.0, min_ds / max_rise, np.inf)
            blocked = np.maximum.accumulate(~(denom > 0.0))  # a node that cannot slide
            kc = np.where(blocked, 0.0, np.where(np.isnan(kc), 0.0, kc))
            gammas.append(gamma)
            bs.append(b)
            kcs.append(kc)
        width = min(b.size for b in bs)
        total = np.zeros(width)
        for r, b in zip(self.ratios, bs, strict=True):
            total = total + (r / self.ratios[0]) * b[:width]
        total = np.where(np.isnan(total), -np.inf, total)
        prefix = np.maximum.accumulate(total)
        argmax = np.zeros(width, dtype=np.int64)
        best = 0
        for j in range(width):
            if total[j] > total[best]:
                best = j
            argmax[j] = best
        data = _AlphaData(gammas, bs, kcs, prefix, argmax)
        if len(self._cache) >= _CACHE_SIZE:
            self._cache.clear()
        self._cache[alpha] = data
        return data

    def verdict(self, k_theta: list[float], delta_theta_p: list[float], alpha: float,
                weight: float, end_margin: float) -> PathVerdict:
        """The path verdict of one validated request.

        Parameters
        ----------
        k_theta : per finger [N m/rad]; delta_theta_p : per finger [rad]; alpha : [rad];
        weight : m_B g [N]; end_margin : the CSM margin at the end (NaN: no equilibrium, or
            beyond the branch end).
        """
        end = end_margin if math.isfinite(end_margin) else -math.inf
        best, where = end, (delta_theta_p[0] if math.isfinite(end_margin) else math.nan)
        same = all(d == delta_theta_p[0] for d in delta_theta_p)
        if self._fingers is None or not same:
            node, at = self._slow(k_theta, delta_theta_p, alpha, weight)
        else:
            node, at = self._fast(k_theta, delta_theta_p[0], alpha, weight)
        if node > best:
            best, where = node, at
        return PathVerdict(best > 0.0, best, where if best > -math.inf else math.nan)

    def _fast(self, k: list[float], dp: float, alpha: float, weight: float
              ) -> tuple[float, float]:
        fingers = self._fingers
        assert fingers is not None
        grid = fingers[0].grid
        cnt = min(bisect.bisect_left(grid, dp), *(len(f.grid) for f in fingers))
        if cnt == 0:
            return -math.inf, math.nan
        data = self._alpha(alpha)
        j_last = cnt - 1
        all_slide = all(k_i <= kc[j_last] for k_i, kc in zip(k, data.k_all_slide, strict=True))
        proportional = all(abs(k_i * self.ratios[0] - k[0] * r) <= 1e-12 * k_i
                           for k_i, r in zip(k, self.ratios, strict=True))
        if all_slide and proportional and j_last < data.ratio_prefix.size:
            value = k[0] * float(data.ratio_prefix[j_last])
            return value - weight, grid[int(data.ratio_argmax[j_last])]
        total = np.zeros(cnt)
        separated = np.zeros(cnt, dtype=bool)
        mu = math.tan(alpha)
        for f, gamma, k_i in zip(fingers, data.gamma, k, strict=True):
            g, s = gamma[:cnt], f.s[:cnt]
            prefix = np.minimum.accumulate(k_i * np.where(np.isfinite(g), g, np.inf) - s)
            delta = s + prefix
            cap = k_i * g
            tau = k_i * f.tau_hat[:cnt]
            denom = f.h_n[:cnt] + f.sign * mu * f.h_t[:cnt]
            with np.errstate(divide='ignore', invalid='ignore'):
                sliding = (denom > 0.0) & (delta >= cap * (1.0 - 1e-12))
                f_n_slide = tau / denom
                f_t_stick = self.k_t * delta * f.sign
                f_n_stick = (tau - f.h_t[:cnt] * f_t_stick) / f.h_n[:cnt]
            f_n = np.where(sliding, f_n_slide, f_n_stick)
            f_t = np.where(sliding, f.sign * mu * f_n_slide, f_t_stick)
            total += f_n * f.cz_n[:cnt] + f_t * f.cz_t[:cnt]
            separated |= f_n < 0.0
        margin = np.where(separated, -np.inf, total - weight)
        j = int(np.argmax(margin))
        return float(margin[j]), grid[j]

    def _slow(self, k: list[float], dp: list[float], alpha: float, weight: float
              ) -> tuple[float, float]:
        table = self.table
        top = max(dp)
        n = int(math.ceil(top / SLOW_STEP_RAD))
        if n <= 1:
            return -math.inf, math.nan
        fractions = np.arange(1, n) / n  # strictly below the end
        total = np.zeros(fractions.size)
        separated = np.zeros(fractions.size, dtype=bool)
        for i, path in enumerate(table.paths):
            d = fractions * dp[i]
            d = d[d <= path.valid_until]
            if d.size < fractions.size:
                fractions, total, separated = (fractions[:d.size], total[:d.size],
                                               separated[:d.size])
            if d.size == 0:
                return -math.inf, math.nan
            end = finger_table(table.model, i, contacts_at(table.paths, i, d), d)
            ev = csm_evaluate(table, i, end, np.array([k[i]]), alpha, self.k_t)
            total += ev.fz[0, :total.size]
            separated |= ev.separated[0, :total.size]
        margin = np.where(separated, -np.inf, total - weight)
        j = int(np.argmax(margin))
        return float(margin[j]), float(fractions[j] * dp[0])
