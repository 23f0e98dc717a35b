"""Pooling fly campaigns: the pooled figures are those of one campaign of all the missions; campaigns that differ
(team, scenario, clock) or share layout seeds are refused in one line."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from mavlink_bridge.fly.pool import main
from tssac_core.common.stats import wilson_interval

HARD50 = Path(__file__).resolve().parents[1] / "results" / "recipe-trials" / "hard50"
A = HARD50 / "sitl_random_200_1900001_seed1.json"


def halves(tmp_path: Path) -> tuple[Path, Path]:
    """One committed campaign cut in two: missions 0-119 and 120-199."""
    data = json.loads(A.read_text())
    first, second = dict(data, missions=data["missions"][:120]), dict(data, missions=data["missions"][120:])
    a, b = tmp_path / "a.json", tmp_path / "b.json"
    a.write_text(json.dumps(first))
    b.write_text(json.dumps(second))
    return a, b


def test_two_halves_pool_to_the_whole(tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    a, b = halves(tmp_path)
    out = tmp_path / "pooled.json"
    assert main([str(a), str(b), "--json", str(out)]) == 0
    pooled, whole = json.loads(out.read_text()), json.loads(A.read_text())
    assert pooled["episodes"] == 200 and [c["episodes"] for c in pooled["campaigns"]] == [120, 80]
    assert pooled["success_rate"] == whole["success_rate"]
    assert pooled["success_interval95"] == pytest.approx(whole["success_interval95"])
    assert pooled["mean_cost"] == pytest.approx(whole["mean_cost"])
    assert pooled["mean_cost_interval95"] == pytest.approx(whole["mean_cost_interval95"])
    wins = sum(m["success"] for m in whole["missions"])
    assert pooled["success_interval95"][0] == pytest.approx(wilson_interval(wins, 200).low)
    assert "over 200 missions" in capsys.readouterr().out


def test_overlapping_or_different_campaigns_are_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]):
    a, b = halves(tmp_path)
    with pytest.raises(SystemExit) as exc:
        main([str(a), str(a)])
    assert exc.value.code == 2 and "share layout seeds" in capsys.readouterr().err
    other = json.loads(b.read_text())
    other["pilot"] = "guidance"
    b.write_text(json.dumps(other))
    with pytest.raises(SystemExit):
        main([str(a), str(b)])
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "pilot" in err
    b.write_text("{not json")
    with pytest.raises(SystemExit):
        main([str(a), str(b)])
    assert "not a fly results file" in capsys.readouterr().err
