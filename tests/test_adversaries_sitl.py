"""Adversarial pilots over MAVLink: ``fly --pilot NAME --shield`` (the monitor in each companion, fed by its Kalman
filter) keeps three adversaries out of the radars and inside the area in SITL, on layouts where the same pilots
alone enter a radar or leave within the same 100 s in the batched world. One mission each, to keep CI short;
benchmarks/bench_adversaries.py flies every adversary on many. (The ``nan`` pilot over SITL is not tested here:
the companion flies the hold around the monitor on a non-finite action, a path that is being changed.)"""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tssac_core.sim.adversaries import Adversary, AdversaryPilot
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.scenario import dump, load

REPO = Path(__file__).resolve().parents[1]
SEED = 2_100_001
"""Mission 0 of this seed: the adversaries' own seed range (tests/test_adversaries.py)."""
STEPS = 1000


@pytest.mark.sitl
@pytest.mark.timeout(300)
@pytest.mark.parametrize(
    ("adversary", "scenario_name"),
    [
        (Adversary.AT_RADAR, "random"),  # all three UAVs 476-661 steps in a radar alone
        (Adversary.TURN_RIGHT, "corner"),  # alone, a UAV leaves the area after 20 s
        (Adversary.CHATTER, "degraded"),  # 10% loss and 200 ms each way; alone 313-592 steps in a radar
    ],
    ids=str,
)
def test_adversary_over_sitl_is_kept_out_by_the_monitor(adversary: Adversary, scenario_name: str, tmp_path: Path):
    scenario = dataclasses.replace(load(REPO / "scenarios" / f"{scenario_name}.yaml"), episode_steps=STEPS)
    alone = fly_missions(scenario, [AdversaryPilot(adversary)] * 3, episodes=1, seed=SEED)
    assert (alone.cost > 0).any() or alone.out_of_area.any()  # the mission is a danger without the monitor
    path, out = tmp_path / f"{scenario_name}.yaml", tmp_path / "fly.json"
    dump(scenario, path)
    argv = ["--scenario", str(path), "--pilot", adversary.value, "--shield", "--seed", str(SEED), "--json", str(out)]
    proc = subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.fly", *argv, "--no-progress"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        timeout=280,
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    results = json.loads(out.read_text())
    assert results["pilot"] == adversary.value
    mission = results["missions"][0]
    assert mission["end"] == "episode_cap" and mission["steps"] == STEPS, mission["end"]
    assert all(c == 0 for c in mission["cost"].values()), mission["cost"]
    assert not any(mission["left_area"].values()), mission["left_area"]
    shield = results["shield"]
    assert shield["uav_missions_with_cost"] == 0 and shield["uavs_left_area"] == 0
    assert shield["interventions_per_uav_mission"] > 0 and shield["unprotected_time_fraction"] == 0
