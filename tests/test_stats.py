"""Evaluation statistics (tssac_core.common.stats) against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from tssac_core.common.evaluation_record import RoleFigures, WorstMission
from tssac_core.common.stats import (
    bootstrap_mean_interval,
    cvar,
    pooled_record,
    wilson_interval,
    within_fraction,
    worst_missions,
)


def test_wilson_interval_matches_the_hand_computed_bounds():
    # p = 0.8, n = 10, z = 1.96: centre 0.99208 / 1.38416, half-width 1.96 sqrt(0.025604) / 1.38416.
    rate = wilson_interval(8, 10)
    assert rate.value == 0.8
    assert rate.low == pytest.approx(0.4902, abs=1e-4) and rate.high == pytest.approx(0.9433, abs=1e-4)
    none = wilson_interval(0, 10)  # not degenerate at 0 as the normal approximation is
    assert none.low == 0.0 and none.high == pytest.approx(0.2775, abs=1e-4)
    assert wilson_interval(10, 10).high == 1.0 and wilson_interval(10, 10).low == pytest.approx(1 - 0.2775, abs=1e-4)
    # 990 of 1,000: the interval the regression test's bound (>= 0.93) is checked against.
    big = wilson_interval(990, 1000)
    assert big.low == pytest.approx(0.98169, abs=1e-4) and big.high == pytest.approx(0.99457, abs=1e-4)
    with pytest.raises(ValueError):
        wilson_interval(11, 10)


def test_bootstrap_resamples_whole_missions():
    # One costly mission of ten. Resampling missions, its count is Binomial(10, 0.1), whose 97.5% quantile is 3
    # (P(X <= 2) = 0.930, P(X <= 3) = 0.987).
    cost = np.zeros((10, 3))
    cost[0] = 3.0
    mean = bootstrap_mean_interval(cost)
    assert mean.value == pytest.approx(0.3)
    assert mean.low == 0.0 and mean.high == pytest.approx(0.9)  # 3 x 3 / 10
    # Resampling the 30 UAV-missions independently would give Binomial(30, 0.1)'s quantile 7 (P(X <= 6) = 0.974): 0.7.
    assert bootstrap_mean_interval(cost.reshape(-1)).high == pytest.approx(0.7)
    # Fixed seed: the same interval every time; a constant has a degenerate one.
    assert bootstrap_mean_interval(cost) == mean
    flat = bootstrap_mean_interval(np.full((50, 3), 2.0))
    assert (flat.low, flat.value, flat.high) == (2.0, 2.0, 2.0)


def test_cvar_is_the_mean_of_the_worst_five_percent():
    assert cvar(np.arange(1.0, 101.0)) == pytest.approx(98.0)  # 96..100
    assert cvar(np.r_[np.zeros(29), 60.0]) == pytest.approx(30.0)  # ceil(1.5) = 2 worst: 60 and 0
    assert cvar(np.array([5.0])) == 5.0
    assert within_fraction(np.array([0.0, 3.0, 3.5, 100.0]), 3.0) == 0.5


def test_the_worst_missions_name_their_seed_and_role():
    cost = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 700.0], [0.0, 12.0, 0.0]])
    rows = worst_missions(cost, seeds=[101, 102, 103], roles=["decoy", "detect", "strike"], count=10)
    assert rows == [
        WorstMission(mission=1, seed=102, role="strike", cost=700.0),
        WorstMission(mission=2, seed=103, role="detect", cost=12.0),
        WorstMission(mission=1, seed=102, role="decoy", cost=5.0),
    ]


def test_pooled_record_has_the_intervals_and_every_roles_tail():
    success = np.array([True] * 19 + [False])
    cost = np.zeros((20, 3))
    cost[19, 2] = 400.0
    out = pooled_record(success, cost, 3.0, ["decoy", "detect", "strike"], seeds=list(range(20)))
    assert out.success_interval95 == pytest.approx((wilson_interval(19, 20).low, wilson_interval(19, 20).high))
    assert out.mean_cost_interval95 is not None
    assert out.mean_cost_interval95[0] == 0.0 and out.mean_cost_interval95[1] > 400.0 / 60
    assert out.roles["strike"] == RoleFigures(within_cost_limit=0.95, max_cost=400.0, cvar95_cost=400.0)
    assert out.roles["decoy"].within_cost_limit == 1.0
    assert out.worst_missions == [WorstMission(mission=19, seed=19, role="strike", cost=400.0)]
