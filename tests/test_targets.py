"""`python -m tssac_core.experiments.targets`: issue 23's batched targets checked for trained teams."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tssac_core.common.evaluation_record import EvaluationRecord, RoleFigures
from tssac_core.experiments.targets import TARGETS, misses

REPO = Path(__file__).resolve().parents[1]
RANDOM = TARGETS[0]


def summary(success: float, cost: float, within: dict[str, float]) -> EvaluationRecord:
    return EvaluationRecord(
        success_rate=success,
        success_interval95=None,
        mean_cost=cost,
        mean_cost_interval95=None,
        episodes=1000,
        mean_mission_time_s=None,
        roles={role: RoleFigures(within_cost_limit=value) for role, value in within.items()},
    )


def test_a_team_at_the_thresholds_meets_the_target_and_one_below_misses_each_named_part():
    at = summary(RANDOM.min_success, RANDOM.max_mean_cost, dict.fromkeys(("decoy", "detect", "strike"), 0.995))
    assert misses(RANDOM, at) == []
    below = summary(0.949, 1.01, {"decoy": 1.0, "detect": 0.994, "strike": 1.0})
    assert misses(RANDOM, below) == ["success 94.9% < 95%", "mean cost 1.01 > 1", "detect within C 99.4% < 99.5%"]
    # the generalization target has no within-C floor
    assert misses(TARGETS[1], summary(0.9, 0.5, dict.fromkeys(("decoy", "detect", "strike"), 0.0))) == []


@pytest.mark.slow
def test_the_command_flies_disjoint_seeds_per_target_and_writes_its_verdict(tmp_path):
    out = tmp_path / "targets.json"
    cmd = [sys.executable, "-m", "tssac_core.experiments.targets", str(REPO / "models" / "tssac"), "--seed", "5000"]
    proc = subprocess.run([*cmd, "--scale", "0.01", "--json", str(out)], capture_output=True, text=True, cwd=REPO)
    assert proc.returncode == 0, proc.stderr
    data = json.loads(out.read_text())
    rows = data["teams"][0]["targets"]
    assert [r["summary"]["episodes"] for r in rows] == [10, 5]
    assert [r["seed"] for r in rows] == [5000, 5010]  # random: layouts 5000-5009, generalization: 5010-5014
    assert data["teams_meeting"] == int(data["teams"][0]["meets_every_target"])
    assert f"{data['teams_meeting']} of 1 teams meet every target (scale 0.01)" in proc.stdout


def test_a_directory_without_checkpoints_is_one_line_and_exit_2(tmp_path):
    proc = subprocess.run(
        [sys.executable, "-m", "tssac_core.experiments.targets", str(tmp_path), "--seed", "1"],
        capture_output=True,
        text=True,
        cwd=REPO,
    )
    assert proc.returncode == 2 and proc.stderr.startswith("error: ") and len(proc.stderr.strip().splitlines()) == 1
