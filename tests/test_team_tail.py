"""The shipped team's tail, in the batched world: a thousand random layouts, so that a failure that comes once in
a hundred missions shows about ten times (DESIGN.md section 6). Fifty layouts would show it about half a time,
which is how the team before this one passed its tests at a mean cost three times the limit.

The layouts are missions 0-999 of seed 880001 (layout seeds 880001-881000): never drawn in training, in epoch
selection, or in the figures models/tssac/README.md reports. The shipped team (configs/safe.yaml's seed 1) flies
them at 100.0% (95% interval 99.6-100.0%) and a mean cost per UAV of 0.02 (0.00-0.06), its worst UAV-mission a
strike crossing of 37 steps (99.8% of the strike UAV's missions within C, every other UAV-mission at 0). The
bounds below are the shipped team's guard, tighter than issue 23's (0.93 and C): a success lower bound of 0.99,
the mean cost's upper bound at 0.5, 99.5% of every role's UAV-missions within C. Cost: about 40 s on one free core.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from tssac_core.deploy.policy import load_team
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.scenario import load

REPO = Path(__file__).resolve().parents[1]
MODELS = REPO / "models" / "tssac"
TAIL_SEED = 880001
MISSIONS = 1000
MIN_SUCCESS_LOW = 0.99
"""The Wilson 95% interval's lower end of the success rate must reach this."""
MAX_COST_HIGH = 0.5
"""The bootstrap 95% interval's upper end of the mean cost per UAV must stay below this."""
MIN_WITHIN_LIMIT = {"decoy": 0.995, "detect": 0.995, "strike": 0.995}
"""Per role, the fraction of UAV-missions within the cost limit C."""


@pytest.mark.slow
@pytest.mark.timeout(900)
def test_the_shipped_team_keeps_the_budget_on_a_thousand_random_layouts(random_path):
    s = load(random_path)
    summary = fly_missions(s, list(load_team(MODELS)), MISSIONS, TAIL_SEED).record(s.cost_limit).to_json()
    worst = ", ".join(f"mission {w['mission']} {w['role']} {w['cost']:.0f}" for w in summary["worst_missions"])
    report = (
        f"success {summary['success_rate']:.3f} {summary['success_interval95']}, mean cost {summary['mean_cost']:.2f} "
        f"{summary['mean_cost_interval95']}; worst: {worst}"
    )
    assert summary["episodes"] == MISSIONS
    assert summary["success_interval95"][0] >= MIN_SUCCESS_LOW, report
    assert summary["mean_cost_interval95"][1] <= MAX_COST_HIGH, report
    for role, floor in MIN_WITHIN_LIMIT.items():
        assert summary["roles"][role]["within_cost_limit"] >= floor, f"{role}: {summary['roles'][role]}; {report}"
