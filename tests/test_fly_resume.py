"""``fly --resume``: a campaign stopped part-way, or asked for more missions, flies on from its results file, only
the missions it has not flown, and ends as the campaign one run would have flown; a file of other settings, or not
fly's, is refused in one line and left as it is."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from sitl_helpers import quick_strike_scenario

from mavlink_bridge.fly import cli as fly

KEYS = ("index", "seed", "success", "end", "steps", "sim_time_s", "cost", "task_done")


def quick_scenario(tmp: Path) -> Path:
    """One short mission per seed."""
    return quick_strike_scenario(tmp)


def flown(path: Path) -> list[dict[str, Any]]:
    return [{k: m[k] for k in KEYS} for m in json.loads(path.read_text())["missions"]]


def sitl_pids(path: Path) -> list[int]:
    return [m["pids"]["sitl"] for m in json.loads(path.read_text())["missions"]]


@pytest.mark.sitl
@pytest.mark.timeout(300)
def test_a_resumed_campaign_flies_only_what_it_lacks_and_ends_as_one_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    args = ["--scenario", str(quick_scenario(tmp_path)), "--pilot", "guidance", "--seed", "41", "--no-progress"]
    whole, part = tmp_path / "whole.json", tmp_path / "part.json"
    assert fly.main([*args, "--episodes", "3", "--json", str(whole)]) == 0
    # A campaign of two asked for a third: its two missions kept as they are (the same processes flew them).
    assert fly.main([*args, "--episodes", "2", "--json", str(part), "--resume"]) == 0  # no file yet: from the start
    before = sitl_pids(part)
    capsys.readouterr()
    assert fly.main([*args, "--episodes", "3", "--json", str(part), "--resume"]) == 0
    assert "resuming: 2 missions flown, 1 to fly" in capsys.readouterr().err
    assert flown(part) == flown(whole) and sitl_pids(part)[:2] == before
    assert json.loads(part.read_text())["episodes"] == 3
    # A campaign interrupted after missions 0 and 2 whose mission 1 crashed (a row without its cost, which pooling
    # refuses): only mission 1 flies again.
    data = json.loads(whole.read_text())
    crashed = {"index": 1, "seed": 42, "success": False, "end": "error", "cost": None}
    stopped = dict(data, missions=[data["missions"][0], crashed, data["missions"][2]], interrupted=True, episodes=3)
    part.write_text(json.dumps(stopped))
    assert fly.main([*args, "--episodes", "3", "--json", str(part), "--resume"]) == 0
    resumed = json.loads(part.read_text())
    assert flown(part) == flown(whole) and resumed["interrupted"] is False
    kept = [data["missions"][k]["pids"]["sitl"] for k in (0, 2)]
    assert [sitl_pids(part)[k] for k in (0, 2)] == kept and sitl_pids(part)[1] not in kept
    assert resumed["success_rate"] == data["success_rate"] and resumed["mean_cost"] == data["mean_cost"]


def test_resume_refuses_another_campaigns_file_or_not_fly_s_in_one_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Refused before anything flies, the file left as it was: one of other settings (another seed here), one that
    is not JSON, and ``--resume`` without ``--json``."""
    args = ["--scenario", str(quick_scenario(tmp_path)), "--pilot", "guidance", "--episodes", "3", "--no-progress"]
    other = tmp_path / "other.json"
    text = json.dumps({"missions": [], "interrupted": True, "resume_key": "0" * 64})
    other.write_text(text)
    assert fly.main([*args, "--seed", "41", "--json", str(other), "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "flown with other settings than this command's" in err[0], err
    assert other.read_text() == text
    other.write_text("{not json")
    assert fly.main([*args, "--json", str(other), "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a fly results file" in err[0], err
    assert fly.main([*args, "--resume"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--resume flies on from a campaign's --json FILE" in err[0], err


def test_the_key_changes_with_what_decides_a_mission_and_not_with_how_many_fly_at_once(tmp_path: Path) -> None:
    from mavlink_bridge.fly.config import config_from_args
    from mavlink_bridge.fly.resume import campaign_key

    base = ["--scenario", str(quick_scenario(tmp_path)), "--pilot", "guidance", "--json", str(tmp_path / "a.json")]
    key = campaign_key(config_from_args(base))
    assert campaign_key(config_from_args([*base, "--workers", "2", "--episodes", "5"])) == key
    for changed in (["--seed", "7"], ["--shield"], ["--pilot", "straight"], ["--speedup", "20"]):
        assert campaign_key(config_from_args([*base, *changed])) != key, changed
