"""The evaluation command and the guidance controller over random layouts."""

from __future__ import annotations

import json

import numpy as np

from tssac_core.common.cli import run
from tssac_core.common.stats import wilson_interval
from tssac_core.evaluate import main
from tssac_core.sim.missions import MissionResults, fly_missions
from tssac_core.sim.pilots import GUIDANCE
from tssac_core.sim.scenario import load


def test_guidance_solves_random_layouts(random_path):
    s = load(random_path)
    results = fly_missions(s, [GUIDANCE] * 3, episodes=30, seed=2024)
    summary = results.record(s.cost_limit).to_json()
    assert summary["success_rate"] >= 0.9
    assert summary["mean_cost"] <= 0.5
    assert summary["episodes"] == 30
    assert all(role["left_area_rate"] == 0.0 for role in summary["roles"].values())


def test_evaluate_writes_json(tmp_path, strike_path, capsys):
    out = tmp_path / "r" / "eval.json"
    assert (
        main(
            [
                "--controller",
                "guidance",
                "--scenario",
                str(strike_path),
                "--episodes",
                "2",
                "--seed",
                "1",
                "--json",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
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
    roles = results.record(s.cost_limit).to_json()["roles"]
    assert (roles["decoy"]["left_area_rate"], roles["strike"]["left_area_rate"]) == (0.0, 1.0)


def test_each_mission_flies_its_own_seed_so_one_can_be_flown_again_alone(random_path):
    s = load(random_path)
    run = fly_missions(s, [GUIDANCE] * 3, episodes=3, seed=100)
    alone = fly_missions(s, [GUIDANCE] * 3, episodes=1, seed=100, indices=[2])
    shifted = fly_missions(s, [GUIDANCE] * 3, episodes=1, seed=102)  # mission k of seed S is mission 0 of S + k
    assert run.seeds == [100, 101, 102] and alone.seeds == [102] and alone.indices == [2]
    assert run.layouts[2] == alone.layouts[0] == shifted.layouts[0] != run.layouts[1]
    assert run.time_s[2] == alone.time_s[0] == shifted.time_s[0]
    assert (run.cost[2] == alone.cost[0]).all() and run.success[2] == alone.success[0]


def test_the_summary_has_intervals_tails_and_the_worst_missions_by_index_and_seed():
    n = 40
    cost = np.zeros((n, 3))
    cost[7, 2], cost[31, 0] = 640.0, 2.0
    success = np.ones(n, dtype=bool)
    success[7] = False
    results = MissionResults(
        success=success,
        cost=cost,
        returns=np.zeros((n, 3)),
        task_done=np.ones((n, 3), dtype=bool),
        time_s=np.full(n, 300.0),
        out_of_area=np.zeros((n, 3), dtype=bool),
        seeds=[5000 + k for k in range(10, 10 + n)],
        indices=list(range(10, 10 + n)),
    )
    summary = results.record(3.0).to_json()
    assert summary["success_rate"] == 39 / 40
    assert summary["success_interval95"] == [wilson_interval(39, 40).low, wilson_interval(39, 40).high]
    low, high = summary["mean_cost_interval95"]
    assert low == 0.0 < summary["mean_cost"] < high
    strike = summary["roles"]["strike"]
    assert (strike["within_cost_limit"], strike["max_cost"], strike["cvar95_cost"]) == (
        39 / 40,
        640.0,
        320.0,
    )  # worst 2 of 40
    assert summary["roles"]["decoy"]["within_cost_limit"] == 1.0  # 2.0 is within C
    assert summary["worst_missions"] == [
        {"mission": 17, "seed": 5017, "role": "strike", "cost": 640.0},
        {"mission": 41, "seed": 5041, "role": "decoy", "cost": 2.0},
    ]


def test_evaluate_flies_one_mission_again_with_mission(tmp_path, random_path, capsys):
    out = tmp_path / "one.json"
    assert (
        main(
            [
                "--controller",
                "guidance",
                "--scenario",
                str(random_path),
                "--seed",
                "100",
                "--mission",
                "2",
                "--json",
                str(out),
                "--no-progress",
            ]
        )
        == 0
    )
    data = json.loads(out.read_text())
    s = load(random_path)
    again = fly_missions(s, [GUIDANCE] * 3, episodes=1, seed=102).record(s.cost_limit).to_json()
    assert data["episodes"] == 1 and data["mean_mission_time_s"] == again["mean_mission_time_s"]
    for key in ("success_interval95", "mean_cost_interval95", "worst_missions"):
        assert key in data
    assert "95% interval" in capsys.readouterr().out
    assert run(main, ["--controller", "guidance", "--mission", "-1", "--no-progress"]) == 2
    assert "--mission must be >= 0" in capsys.readouterr().err
