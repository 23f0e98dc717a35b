"""The Team asks each pilot for a decision only every ``action_repeat`` steps of the missions still flying."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from tssac_core.sim.missions import fly_missions
from tssac_core.sim.pilots import GuidancePilot
from tssac_core.sim.scenario import load
from tssac_core.sim.world_state import WorldState

ROOT = Path(__file__).resolve().parent.parent


class CountingGuidance:
    """The guidance controller deciding once a second (10 steps), counting the decisions it is asked for."""

    name = "counting guidance"
    action_repeat = 10

    def __init__(self) -> None:
        self.guidance = GuidancePilot()
        self.calls = 0

    def actions(self, state: WorldState, role_index: int) -> np.ndarray:
        self.calls += 1
        return self.guidance.actions(state, role_index)


def test_a_finished_mission_asks_for_no_more_decisions() -> None:
    """Missions that end at different steps: one decision every 10 steps until the last one ends, however many
    missions finished on a multiple of 10 before (their step count stands still; counted, they made a decision due
    at every step)."""
    scenario = load(ROOT / "scenarios" / "short-random.yaml")
    pilot = CountingGuidance()
    results = fly_missions(scenario, [pilot, "guidance", "guidance"], 20, 7)
    steps = np.rint(results.time_s / scenario.dt_s).astype(int)
    assert (steps[steps < steps.max()] % 10 == 0).any()  # the case: a mission ended on a decision step
    assert pilot.calls == math.ceil(steps.max() / 10)
