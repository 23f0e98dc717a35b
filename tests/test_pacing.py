"""A paced SITL world's real-time schedule (sim_vehicles.clock.pacing)."""

from __future__ import annotations

import pytest

from sim_vehicles.clock.pacing import MAX_LAG_S, PacedSchedule


def test_a_step_is_due_dt_over_speedup_after_the_one_before():
    pacing = PacedSchedule(dt_s=0.1, speedup=10.0)
    pacing.anchor(wall_s=100.0, sim_s=5.0)
    assert pacing.next_step_wall(5.0) == pytest.approx(100.01)
    assert not pacing.step_due(100.009, 5.0)
    assert pacing.step_due(100.01, 5.0)
    assert pacing.next_step_wall(5.1) == pytest.approx(100.02)  # the schedule, not the last step's wall time


def test_a_world_too_far_behind_is_re_anchored_rather_than_made_to_race():
    pacing = PacedSchedule(dt_s=0.1, speedup=1.0)
    pacing.anchor(wall_s=0.0, sim_s=0.0)
    late = MAX_LAG_S + 0.1 + 0.5  # simulated seconds behind at this wall time: beyond the lag allowed
    assert pacing.step_due(late, 0.0)  # due at once, and the schedule now counts from here
    assert pacing.next_step_wall(0.0) == pytest.approx(late + 0.1)
    assert not pacing.step_due(late + 0.05, 0.0)
