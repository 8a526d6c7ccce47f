"""The lift-off rule (``dam_sim_bridge.lift_off``) and the world's tracker of it.

The rule is checked against a brute-force reading of random contact records (every window of
every start): lifted once a lift-off happened, whatever follows; off the table at the end only
over the last 0.1 s. The world's tracker is checked against free fall, whose time the test
computes from Bullet's integrator: an object dropped from 20 mm is off the table for about
64 ms (a lift-off at the start: lifted, though it lies on the table again), one dropped from
5 mm for 32 ms (no lift-off: as short as a bounce).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from dam_common.config import DamConfig, load_config
from dam_sim_bridge.lift_off import (
    AT_END_WINDOW_S,
    LIFT_OFF_MIN_S,
    TOUCH_DISTANCE_M,
    LiftOffTracker,
    lift_off_of_samples,
)
from dam_sim_bridge.world import HandWorld

DT = 0.002  # one device cycle [s]


def _record(pattern: list[tuple[int, int]]) -> list[tuple[float, int]]:
    """Samples every DT from runs of (samples, contacts)."""
    out: list[tuple[float, int]] = []
    for count, contacts in pattern:
        out += [(round(len(out) * DT, 9), contacts) for _ in range(count)]
    return [(round(i * DT, 9), n) for i, (_, n) in enumerate(out)]


def test_a_bounce_is_no_lift_off_and_fifty_ms_off_is_one() -> None:
    bounce = lift_off_of_samples(_record([(10, 3), (20, 0), (10, 2)]))  # 38 ms off
    assert math.isnan(bounce.lift_off_time) and not bounce.lifted
    assert not bounce.off_table_at_end and bounce.on_table and bounce.off_table_s == 0.0
    # 26 samples 2 ms apart span exactly 50 ms: the first lift-off; back on the table after
    short = lift_off_of_samples(_record([(5, 1), (25, 0), (5, 1)]))
    exact = lift_off_of_samples(_record([(5, 1), (26, 0), (5, 1)]))
    assert not short.lifted
    assert exact.lifted and exact.lift_off_time == pytest.approx(5 * DT)
    assert not exact.off_table_at_end
    # off for 0.1 s at the end: lifted and off at the end; a bounce before does not count
    held = lift_off_of_samples(_record([(5, 1), (10, 0), (5, 1), (51, 0)]))
    assert held.lifted and held.off_table_at_end
    assert held.lift_off_time == pytest.approx(20 * DT)
    assert held.off_table_s == pytest.approx(50 * DT) and not held.on_table
    # off 0.098 s at the end: lifted, not yet off the table at the end
    almost = lift_off_of_samples(_record([(5, 1), (50, 0)]))
    assert almost.lifted and not almost.off_table_at_end
    # lifted, then back on the table (fell back, or one end rests on it): still lifted
    fell = lift_off_of_samples(_record([(5, 1), (60, 0), (5, 4)]))
    assert fell.lifted and fell.lift_off_time == pytest.approx(5 * DT)
    assert not fell.off_table_at_end
    assert fell.table_contacts == 4 and fell.samples == 70
    # a second, later stretch off the table does not move the lift-off
    twice = lift_off_of_samples(_record([(5, 1), (30, 0), (5, 1), (60, 0)]))
    assert twice.lift_off_time == pytest.approx(5 * DT) and twice.off_table_at_end


def _brute_force(samples: list[tuple[float, int]]) -> tuple[bool, float]:
    """Off the table at the end, and the lift-off time, by trying every start and every
    window."""
    t = [s[0] for s in samples]
    clear = [s[1] == 0 for s in samples]
    lift_off = math.nan
    for i in range(len(samples)):
        starts_a_run = clear[i] and (i == 0 or not clear[i - 1])
        covered = [j for j in range(i, len(samples)) if t[j] <= t[i] + LIFT_OFF_MIN_S + 1e-12]
        if starts_a_run and t[covered[-1]] >= t[i] + LIFT_OFF_MIN_S - 1e-12 and all(
                clear[j] for j in covered):
            lift_off = t[i]
            break
    end = t[-1]
    # off at the end: from some sample at least 0.1 s before the end on, no sample touches
    at_end = any(t[j] <= end - AT_END_WINDOW_S + 1e-12 and all(clear[j:])
                 for j in range(len(samples)))
    return at_end, lift_off


def test_the_rule_agrees_with_a_brute_force_reading_of_random_records() -> None:
    rng = np.random.default_rng(7)
    for _ in range(300):
        runs = [(int(rng.integers(1, 70)), int(rng.integers(0, 2) * rng.integers(1, 5)))
                for _ in range(int(rng.integers(1, 8)))]
        samples = _record(runs)
        state = lift_off_of_samples(samples)
        at_end, lift_off = _brute_force(samples)
        assert state.off_table_at_end == at_end, runs
        assert state.lifted == (not math.isnan(lift_off)), runs
        if math.isnan(lift_off):
            assert math.isnan(state.lift_off_time), runs
        else:
            assert state.lift_off_time == pytest.approx(lift_off, abs=1e-12), runs


def test_bad_samples_are_refused_by_name() -> None:
    tracker = LiftOffTracker()
    tracker.update(1.0, 2)
    with pytest.raises(ValueError, match=r'sample time 0\.5 s .* before the previous'):
        tracker.update(0.5, 0)
    with pytest.raises(ValueError, match=r'table_contacts must be >= 0, got -1'):
        tracker.update(1.1, -1)
    with pytest.raises(ValueError, match=r'sample time nan'):
        tracker.update(math.nan, 0)
    with pytest.raises(ValueError, match=r'lift_off_min_s must be a positive .* got 0'):
        LiftOffTracker(lift_off_min_s=0)
    with pytest.raises(ValueError, match=r'at_end_window_s must be a positive .* got -0\.1'):
        LiftOffTracker(at_end_window_s=-0.1)
    tracker.reset()
    assert tracker.state().samples == 0 and tracker.state().on_table


@pytest.fixture(scope='module')
def cfg() -> DamConfig:
    return load_config()


def _fall_steps(height_m: float, g: float, dt: float) -> int:
    """Steps of Bullet's semi-implicit Euler until a body dropped from rest has fallen
    ``height_m``: after n steps it has fallen g dt^2 n (n + 1) / 2."""
    n = 0
    while g * dt * dt * n * (n + 1) / 2.0 < height_m:
        n += 1
    return n


@pytest.mark.parametrize('drop_mm', [20.0, 5.0])
def test_the_world_tracks_a_dropped_object(cfg: DamConfig, drop_mm: float) -> None:
    with HandWorld(cfg) as world:
        start = np.asarray(cfg.object.position_m, dtype=float).copy()
        assert world.lift_off.state().on_table and world.object_table_contacts() > 0
        start[2] += drop_mm * 1e-3
        world.reset(object_position=start)
        assert world.object_table_contacts() == 0  # sampled at the reset: in the air
        landed = math.nan
        for _ in range(200):
            world.step(2)  # a device cycle
            if math.isnan(landed) and world.lift_off.table_contacts > 0:
                landed = world.sim_time
        state = world.lift_off.state()
        closest = world.client.getClosestPoints(world.object_id, world.table_id, 0.01)
    g, dt = cfg.task.gravity_m_per_s2, world.time_step_s
    fall = _fall_steps(drop_mm * 1e-3 - TOUCH_DISTANCE_M, g, dt) * dt  # [s]
    assert landed == pytest.approx(fall, abs=3 * DT)
    assert state.on_table and not state.off_table_at_end
    assert min(c[8] for c in closest) <= TOUCH_DISTANCE_M  # it lies on the table again
    if fall >= LIFT_OFF_MIN_S + 3 * DT:
        # off the table from the reset on: lifted, though it lies on the table again
        assert state.lift_off_time == 0.0 and state.lifted
    else:
        assert fall < LIFT_OFF_MIN_S - 3 * DT and not state.lifted


def test_contacts_are_counted_within_the_touch_distance(cfg: DamConfig) -> None:
    """A resting object touches; 0.3 mm above the table Bullet still reports a manifold point
    (every point: ``max_distance_m=None``), which does not touch."""
    with HandWorld(cfg) as world:
        world.step(20)
        assert world.object_table_contacts() > 0 and world.lift_off.state().on_table
        world.set_gravity((0.0, 0.0, 0.0))
        start = np.asarray(cfg.object.position_m, dtype=float).copy()
        start[2] += 3e-4
        world.reset(object_position=start)
        world.step(1)
        points = world.client.getContactPoints(world.object_id, world.table_id)
        assert points and all(p[8] > TOUCH_DISTANCE_M for p in points)
        assert world.object_table_contacts(max_distance_m=None) == len(points)
        assert world.object_table_contacts() == 0 and not world.lift_off.state().on_table
