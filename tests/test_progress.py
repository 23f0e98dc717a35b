"""evaluate's time left (tssac_core.reporting.progress): a bound from a fitted step cost, not from the rate of finished
missions."""

from __future__ import annotations

import pytest

from tssac_core.reporting.progress import StepCostModel, TimeLeft, format_seconds


def schedule(missions: int, cap: int, ends: list[int]) -> list[tuple[int, int]]:
    """(flying, still flying) per step until the last mission ends; ``ends`` = each mission's last step."""
    steps = []
    for t in range(1, max(ends) + 1):
        flying = sum(e >= t for e in ends)
        steps.append((flying, sum(e > t for e in ends)))
    return steps


def test_the_fit_recovers_overhead_and_share_per_mission():
    model = StepCostModel()
    for running in (100, 100, 60, 20, 5, 1):
        model.add(running, 0.002 + 0.0001 * running)
    assert model.step_s(1) == pytest.approx(0.0021)
    assert model.step_s(50) == pytest.approx(0.007)


def test_time_left_is_a_bound_that_tracks_a_bursty_batch():
    """100 missions: 90 end around step 1,500, a tail of 10 runs to 3,800; a step costs 2 ms + 0.1 ms per mission.
    Once missions have ended, the estimate is never below the truth and never far above it in the tail; a rate of
    finished missions (what tqdm used) says seconds where minutes are left."""
    cap = 4000
    ends = [1400 + i for i in range(90)] + [3800] * 10
    steps = schedule(100, cap, ends)
    cost = [0.002 + 0.0001 * flying for flying, _ in steps]
    truth = [sum(cost[k + 1 :]) for k in range(len(steps))]
    left = TimeLeft(100, cap)
    elapsed = 0.0
    for k, ((flying, still), dt) in enumerate(zip(steps, cost)):
        left.step(flying, still, dt)
        elapsed += dt
        assert left.seconds >= truth[k] - 1e-9
        if k == 1600:  # the burst is over, the tail of 10 flies on
            assert left.seconds <= 1.2 * truth[k]
            finished = 100 - still
            by_mission_rate = elapsed / finished * still
            assert by_mission_rate < 0.3 * truth[k]  # the old estimate: far too short
    assert left.seconds == 0.0


def test_format_seconds():
    assert [format_seconds(s) for s in (11.4, 185, 3723)] == ["11 s", "3:05", "1:02:03"]
