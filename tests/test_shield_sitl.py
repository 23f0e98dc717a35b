"""The runtime-assurance monitor over MAVLink: a pilot that flies straight into a radar, flown by the companions
with ``--shield`` against the SITL world in lockstep, never enters it; each hand-over reaches the world's truth log
as the companion's STATUSTEXT, relayed by the vehicle, and ``--plot`` draws the backup."""

from __future__ import annotations

import dataclasses
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from sitl_helpers import kept_out

from mavlink_bridge.fly.mission_log import read_mission
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.scenario import dump, load

REPO = Path(__file__).resolve().parents[1]


class Straight:
    """The batched world's twin of ``--pilot straight``: heading and speed held."""

    action_repeat = 10

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        return np.zeros((len(obs), 2))


def fly(args: list[str]) -> subprocess.CompletedProcess[str]:
    """``python -m mavlink_bridge.fly ARGS --shield --lockstep --no-progress`` from the repository."""
    return subprocess.run(
        [sys.executable, "-m", "mavlink_bridge.fly", *args, "--shield", "--lockstep", "--no-progress"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=dict(os.environ, PYTHONPATH=str(REPO)),
        timeout=580,
    )


@pytest.mark.sitl
@pytest.mark.timeout(600)
def test_straight_pilot_into_a_radar_is_kept_out_by_the_monitor(tmp_path: Path) -> None:
    # The strike mission's three UAVs start heading 45 deg, straight at the radar at (38, 44) km; 150 s suffice.
    scenario = dataclasses.replace(load(REPO / "scenarios" / "strike.yaml"), episode_steps=1500)
    alone = fly_missions(scenario, [Straight()] * 3, episodes=1, seed=0)
    assert alone.cost.min() > 0  # without the monitor every UAV flies into the radar
    path = tmp_path / "straight.yaml"
    dump(scenario, path)
    out, logs, plot = tmp_path / "fly.json", tmp_path / "logs", tmp_path / "mission.png"
    proc = fly(
        [
            "--scenario",
            str(path),
            "--pilot",
            "straight",
            "--json",
            str(out),
            "--logs",
            str(logs),
            "--plot",
            str(plot),
        ]
    )
    assert proc.returncode == 0, proc.stderr[-2000:]
    results = json.loads(out.read_text())
    mission = results["missions"][0]
    assert mission["end"] == "episode_cap"
    assert all(c == 0 for c in mission["cost"].values()), mission["cost"]
    assert not any(mission["left_area"].values())
    shield = results["shield"]
    assert shield["uav_missions"] == 3 and shield["interventions_per_uav_mission"] >= 1
    assert shield["uav_missions_with_cost"] == 0 and shield["uavs_left_area"] == 0
    assert 0 < shield["backup_time_fraction"] < 1
    record = read_mission(next(logs.rglob("truth.jsonl")))
    texts = [e["text"] for e in record.events if e.get("event") == "STATUSTEXT"]
    assert any(t.startswith("decoy: shield on") for t in texts), texts
    segments = record.backup_segments_km()
    assert set(segments) == {"decoy", "detect", "strike"} and all(len(s) >= 1 for s in segments.values())
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def nan_team(out: Path) -> Path:
    """Actors with finite weights whose every action is NaN: the first layer saturates float32 (3e38), the second
    overflows to inf, and the last adds +inf to -inf (the loader refuses non-finite weights, not such ones)."""
    out.mkdir()
    for role in ("decoy", "detect", "strike"):
        with np.load(REPO / "models" / "tssac" / f"{role}.npz") as arrays:
            poisoned = dict(arrays)
        poisoned["w0"] = np.zeros_like(poisoned["w0"])
        poisoned["b0"] = np.full_like(poisoned["b0"], 3e38)
        poisoned["w1"] = np.full_like(poisoned["w1"], 10.0)
        poisoned["b1"] = np.zeros_like(poisoned["b1"])
        poisoned["w2"] = np.tile(np.array([1.0, -1.0], dtype=np.float32), poisoned["w2"].shape[1] // 2)[None].repeat(
            poisoned["w2"].shape[0], axis=0
        )
        poisoned["b2"] = np.zeros_like(poisoned["b2"])
        np.savez(out / f"{role}.npz", **poisoned)
    return out


@pytest.mark.sitl
@pytest.mark.timeout(600)
def test_a_nan_policy_is_flown_by_the_backup_over_sitl(tmp_path: Path) -> None:
    """Every action of a NaN policy is a proposal that fails: the companion's monitor flies its backup (no hold
    around it), on the strike mission whose straight line runs into a radar: no radar step, no UAV out."""
    scenario = dataclasses.replace(load(REPO / "scenarios" / "strike.yaml"), episode_steps=1500)
    path = tmp_path / "strike.yaml"
    dump(scenario, path)
    out = tmp_path / "fly.json"
    proc = fly(["--scenario", str(path), "--models", str(nan_team(tmp_path / "nan")), "--json", str(out)])
    assert proc.returncode == 0, proc.stderr[-2000:]
    _, shield = kept_out(json.loads(out.read_text()))
    assert shield["backup_time_fraction"] > 0.99  # the policy never flies: the backup does, from the first decision
    assert shield["interventions_per_uav_mission"] >= 1


def held_team(out: Path, repeat: int) -> Path:
    """Actors whose every action is [0, 0] (zero weights: straight on), deciding every ``repeat`` ticks."""
    out.mkdir()
    for role in ("decoy", "detect", "strike"):
        with np.load(REPO / "models" / "tssac" / f"{role}.npz") as arrays:
            actor = {k: (v if k == "meta" else np.zeros_like(v)) for k, v in arrays.items()}
        meta = json.loads(str(actor["meta"]))
        meta["action_repeat"] = repeat
        actor["meta"] = np.array(json.dumps(meta))
        np.savez(out / f"{role}.npz", **actor)
    return out


@pytest.mark.sitl
@pytest.mark.timeout(600)
def test_a_team_deciding_every_40_s_is_kept_out_from_an_admitted_start_over_sitl(tmp_path: Path) -> None:
    """Issue 61, item 1, over MAVLink: a team whose actors decide every 400 ticks, from the corridor start that
    only a backup with a straight lead of 8-16 s protects (tests/test_assurance.py): cost 0, no step unprotected.
    Before, the leads were multiples of the decision interval (0 and 40 s: neither clear) and the strike UAV spent
    about 140 steps inside the radar ahead."""
    sys.path.insert(0, str(REPO / "tests"))
    from test_assurance import corridor

    from tssac_core.sim.scenario import from_dict

    scenario = dataclasses.replace(from_dict(corridor(str(REPO / "scenarios" / "strike.yaml"))), episode_steps=900)
    path = tmp_path / "corridor.yaml"
    dump(scenario, path)
    out = tmp_path / "fly.json"
    proc = fly(["--scenario", str(path), "--models", str(held_team(tmp_path / "held", 400)), "--json", str(out)])
    assert proc.returncode == 0, proc.stderr[-2000:]
    results = json.loads(out.read_text())
    mission = results["missions"][0]
    assert all(c == 0 for c in mission["cost"].values()), mission["cost"]
    assert not any(mission["left_area"].values())
    assert results["shield"]["unprotected_time_fraction"] == 0.0


@pytest.mark.slow
@pytest.mark.sitl
@pytest.mark.timeout(600)
def test_before_its_first_fix_a_shielded_companion_flies_the_monitor_over_sitl(tmp_path: Path) -> None:
    """Issue 61, item 2: from the nearest admitted start heading at a radar, with 90% of the fixes lost (the first
    one may come seconds late), a straight pilot behind the monitor never enters the radar: before its first fix the
    companion asks the monitor too, from the start it knows flown through what it sent. Before, it sent the hold
    around the monitor and the strike UAV spent 24-190 steps inside."""
    sys.path.insert(0, str(REPO / "tests"))
    from test_assurance import head_on, nearest_admitted_gap_km

    from tssac_core.sim.scenario import from_dict

    strike = str(REPO / "scenarios" / "strike.yaml")
    data = head_on(strike, "strike", nearest_admitted_gap_km(strike))
    data["link"]["gps_dropout_prob"] = 0.9
    scenario = dataclasses.replace(from_dict(data), episode_steps=600)
    path = tmp_path / "dropout.yaml"
    dump(scenario, path)
    for seed in ("1", "2"):
        out = tmp_path / f"fly-{seed}.json"
        proc = fly(["--scenario", str(path), "--pilot", "straight", "--seed", seed, "--json", str(out)])
        assert proc.returncode == 0, proc.stderr[-2000:]
        mission = json.loads(out.read_text())["missions"][0]
        assert all(c == 0 for c in mission["cost"].values()), (seed, mission["cost"])
        assert not any(mission["left_area"].values())
