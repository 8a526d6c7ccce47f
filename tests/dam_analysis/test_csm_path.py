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


def test_an_object_calibrated_tangential_stiffness_is_its_csm(tmp_path) -> None:
    """object.library.<name>.csm_tangential_stiffness_n_per_m (an overlay of calibrate_csm's
    values for one object) gives that object the CSM of a contact section whose k_t it is,
    and leaves the other objects and eq. 18 alone."""
    from dam_common.config import load_config as load
    from dam_common.errors import ConfigError
    overlay = tmp_path / 'square.yaml'
    overlay.write_text('object:\n  library:\n    square_bar:\n'
                       '      csm_tangential_stiffness_n_per_m: 31.6\n', encoding='utf-8')
    global_kt = tmp_path / 'contact.yaml'
    global_kt.write_text('contact:\n  contact_stiffness_n_per_m: [1.0e+5, 31.6, 1.0e+5]\n',
                         encoding='utf-8')
    per_object = load(None, [overlay])
    everywhere = load(None, [global_kt])
    square = LiftAnalyzer(per_object.with_object('square_bar'))
    reference = LiftAnalyzer(everywhere.with_object('square_bar'))
    plain = LiftAnalyzer(load().with_object('square_bar'))
    changed = 0
    for k, dp_deg, a_deg in ((5.0, 10.0, 10.0), (3.0, 30.0, 30.0), (10.0, 15.0, 5.0)):
        args = ([k], [math.radians(dp_deg)], math.radians(a_deg))
        got, ref, before = (an.check_lift(*args) for an in (square, reference, plain))
        assert got.csm_margin == ref.csm_margin
        assert got.csm_path_margin == ref.csm_path_margin
        assert got.worst_case_margin == before.worst_case_margin
        changed += got.csm_margin != before.csm_margin
    assert changed > 0
    cylinder = per_object.with_object('cylinder')
    assert cylinder.object.csm_tangential_stiffness_n_per_m is None
    bad = tmp_path / 'bad.yaml'
    bad.write_text('object:\n  library:\n    square_bar:\n'
                   '      csm_tangential_stiffness_n_per_m: -3.0\n', encoding='utf-8')
    with pytest.raises(ConfigError, match='square_bar.csm_tangential_stiffness_n_per_m'):
        load(None, [bad])
