"""fly's results JSON carries evaluate's interval and tail keys, and any one mission can be flown again alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from mavlink_bridge.fly.config import config_from_args
from mavlink_bridge.fly.mission_runner import mission_layout as fly_layout
from mavlink_bridge.fly.scoring import summarise
from tssac_core.common.cli import UsageError
from tssac_core.common.stats import wilson_interval
from tssac_core.sim.missions import mission_layout
from tssac_core.sim.scenario import load

REPO = Path(__file__).resolve().parents[1]
RANDOM = REPO / "scenarios" / "random.yaml"


def test_fly_and_evaluate_draw_mission_k_from_the_same_seed():
    s = load(RANDOM)
    assert fly_layout(s, 3, 2) == mission_layout(s, 3, 2) == mission_layout(s, 5, 0) != mission_layout(s, 3, 1)


def test_mission_flies_one_mission_of_the_seed():
    cfg = config_from_args(["--scenario", str(RANDOM), "--pilot", "guidance", "--seed", "3", "--mission", "7"])
    assert list(cfg.indices()) == [7] and cfg.episodes == 1
    assert list(config_from_args(["--scenario", str(RANDOM), "--pilot", "guidance", "--episodes", "3"]).indices()) == [
        0,
        1,
        2,
    ]
    with pytest.raises(UsageError, match="--mission must be >= 0"):
        config_from_args(["--scenario", str(RANDOM), "--pilot", "guidance", "--mission", "-2"])
    with pytest.raises(UsageError, match="--mission flies one mission"):
        config_from_args(["--scenario", str(RANDOM), "--pilot", "guidance", "--mission", "2", "--episodes", "4"])


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
def test_checkpoint_s_must_be_a_finite_time_of_zero_or_more(value: str) -> None:
    base = ["--scenario", str(RANDOM), "--pilot", "guidance"]
    assert config_from_args([*base, "--checkpoint-s", "0"]).checkpoint_s == 0.0
    with pytest.raises(UsageError, match="--checkpoint-s must be a number of seconds >= 0"):
        config_from_args([*base, "--checkpoint-s", value])


def _row(index: int, seed: int, success: bool, decoy: float = 0.0, strike: float = 0.0) -> dict:
    cost = {"decoy": decoy, "detect": 0.0, "strike": strike}
    return {
        "index": index,
        "seed": seed,
        "success": success,
        "sim_time_s": 250.0,
        "cost": cost,
        "task_done": {"decoy": True, "detect": True, "strike": success},
    }


def test_the_summary_has_the_intervals_tails_and_worst_missions_of_evaluate():
    cfg = config_from_args(["--scenario", str(RANDOM), "--pilot", "guidance", "--seed", "9000", "--episodes", "20"])
    rows = [_row(i, 9000 + i, True) for i in range(20)]
    rows[4] = _row(4, 9004, False, strike=523.0)
    rows[11] = _row(11, 9011, True, decoy=2.0)
    out = summarise(rows, cfg).to_json()
    assert out["success_rate"] == 0.95
    assert out["success_interval95"] == [wilson_interval(19, 20).low, wilson_interval(19, 20).high]
    assert out["mean_cost"] == pytest.approx(525.0 / 60)
    low, high = out["mean_cost_interval95"]
    assert low == 0.0 and high > out["mean_cost"]
    strike = out["roles"]["strike"]
    assert (strike["within_cost_limit"], strike["max_cost"], strike["cvar95_cost"]) == (0.95, 523.0, 523.0)
    assert out["worst_missions"] == [
        {"mission": 4, "seed": 9004, "role": "strike", "cost": 523.0},
        {"mission": 11, "seed": 9011, "role": "decoy", "cost": 2.0},
    ]


def test_without_a_truth_log_the_cost_figures_are_unknown():
    cfg = config_from_args(["--scenario", str(RANDOM), "--pilot", "guidance"])
    out = summarise([{"index": 0, "seed": 0, "success": True, "sim_time_s": 200.0, "cost": None}], cfg).to_json()
    assert out["mean_cost"] is None and out["mean_cost_interval95"] is None and out["worst_missions"] == []
    assert out["success_interval95"][0] == pytest.approx(wilson_interval(1, 1).low) and np.isclose(
        out["success_interval95"][1], 1.0
    )
