"""The evaluation command and the guidance controller over random layouts."""

from __future__ import annotations

import json

import numpy as np

from tssac_core.evaluate import main
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.scenario import load
from tssac_core.sim.team import GUIDANCE


def test_guidance_solves_random_layouts(random_path):
    s = load(random_path)
    results = fly_missions(s, [GUIDANCE] * 3, episodes=30, seed=2024)
    summary = results.summary(s.cost_limit)
    assert summary["success_rate"] >= 0.9
    assert summary["mean_cost"] <= 0.5
    assert summary["episodes"] == 30
    assert all(role["left_area_rate"] == 0.0 for role in summary["roles"].values())


def test_evaluate_writes_json(tmp_path, strike_path, capsys):
    out = tmp_path / "r" / "eval.json"
    assert main(["--controller", "guidance", "--scenario", str(strike_path), "--episodes", "2", "--seed", "1", "--json", str(out), "--no-progress"]) == 0
    data = json.loads(out.read_text())
    assert data["success_rate"] == 1.0 and data["episodes"] == 2 and data["mean_cost"] == 0.0
    assert set(data["roles"]) == {"decoy", "detect", "strike"}
    assert data["roles"]["strike"]["task_success_rate"] == 1.0
    assert "success rate 100.0%" in capsys.readouterr().out


def test_parked_team_never_succeeds(strike_path):
    s = load(strike_path)
    results = fly_missions(s, [GUIDANCE, None, GUIDANCE], episodes=1, seed=0)
    assert not results.success.any()  # nobody identifies the target
    assert results.task_done[0].tolist() == [True, False, False]
    assert results.time_s[0] == s.episode_steps * s.dt_s


class TurnAwayThenStraight:
    """A pilot that turns at full rate for its first ``turn_steps`` calls, then flies straight on."""

    def __init__(self, turn_steps: int) -> None:
        self.turn_steps = turn_steps
        self.calls = 0

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        self.calls += 1
        action = np.zeros((len(obs), 2))
        action[:, 0] = 1.0 if self.calls <= self.turn_steps else 0.0
        return action


def test_a_uav_that_flies_out_ends_the_mission_and_is_counted(strike_path):
    s = load(strike_path)
    results = fly_missions(s, [GUIDANCE, GUIDANCE, TurnAwayThenStraight(150)], episodes=1, seed=0)
    assert results.out_of_area[0].tolist() == [False, False, True]
    assert not results.success[0]
    assert results.time_s[0] < s.episode_steps * s.dt_s  # ended by leaving, not by the episode cap
    roles = results.summary(s.cost_limit)["roles"]
    assert (roles["decoy"]["left_area_rate"], roles["strike"]["left_area_rate"]) == (0.0, 1.0)
