"""The CSM's path verdict in check_lift against a brute force of end verdicts.

The path verdict is the largest CSM margin on the way to ``delta_theta_p``: here every node of
the way is asked of ``check_lift`` as a request of its own (its end verdict, the scalar CSM with
the slip history up to that node), and the largest answer must equal the path verdict.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_analysis.analysis import LiftAnalyzer
from dam_analysis.csm_path import SLOW_STEP_RAD
from dam_common.config import load_config


def _as_max(value: float) -> float:
    return value if math.isfinite(value) else -math.inf


@pytest.mark.parametrize('name,count', [('cylinder', 30), ('square_bar', 8)])
def test_path_verdict_is_the_largest_end_verdict_on_the_way(name: str, count: int) -> None:
    an = LiftAnalyzer(load_config().with_object(name))
    grid = an.table.paths[0].delta_theta_p
    rng = np.random.default_rng(3)
    lifted_on_the_way = 0
    for _ in range(count):
        k = float(rng.choice([rng.uniform(0.1, 20.0), rng.uniform(100.0, 3000.0)]))
        dp = math.radians(float(rng.uniform(0.5, 45.0)))
        alpha = math.radians(float(rng.choice([1.0, 5.0, 10.0, 30.0])))
        r = an.check_lift([k], [dp], alpha)
        best, where = _as_max(r.csm_margin), dp
        for d in grid[(grid > 0.0) & (grid < dp)]:
            m = _as_max(an.check_lift([k], [float(d)], alpha).csm_margin)
            if m > best:
                best, where = m, float(d)
        assert r.csm_path_margin == pytest.approx(best, abs=1e-9, rel=1e-9)
        assert r.csm_path_lift == (best > 0.0)
        if best > -math.inf:
            assert r.csm_path_delta_theta_p == pytest.approx(where, abs=1e-12)
        lifted_on_the_way += r.csm_path_lift and not r.csm_lift
    if name == 'cylinder':
        assert lifted_on_the_way > 0  # the verdicts differ somewhere


def test_path_verdict_of_fingers_with_their_own_displacements() -> None:
    an = LiftAnalyzer(load_config())
    for k, dps in (([8.0, 3.0, 5.0], [12.0, 20.0, 16.0]), ([2.0, 1.0, 1.0], [30.0, 10.0, 20.0])):
        dp = [math.radians(d) for d in dps]
        alpha = math.radians(5.0)
        r = an.check_lift(k, dp, alpha)
        n = int(math.ceil(max(dp) / SLOW_STEP_RAD))
        best = _as_max(r.csm_margin)
        for j in range(1, n):
            m = an.check_lift(k, [d * j / n for d in dp], alpha).csm_margin
            best = max(best, _as_max(m))
        assert r.csm_path_margin == pytest.approx(best, abs=1e-9, rel=1e-9)


def test_beyond_the_branch_end_the_way_up_to_it_counts() -> None:
    an = LiftAnalyzer(load_config())
    end = an.table.paths[0].valid_until
    r = an.check_lift([2.0], [math.radians(64.0)], math.radians(30.0))
    assert math.isnan(r.csm_margin) and not r.csm_lift  # no SPCM state at the end
    way = max(_as_max(an.check_lift([2.0], [float(d)], math.radians(30.0)).csm_margin)
              for d in an.table.paths[0].delta_theta_p
              if 0.0 < d <= end)
    assert r.csm_path_margin == pytest.approx(way, abs=1e-9)
    assert r.csm_path_lift == (way > 0.0)
