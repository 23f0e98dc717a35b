"""Pooling fly campaigns: the pooled figures are those of one campaign of all the missions; campaigns that differ
(team, scenario, clock) or share layout seeds are refused in one line."""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from mavlink_bridge.fly import pool as pool_module
from mavlink_bridge.fly.pool import main
from tssac_core.common.evaluation_record import EvaluationRecord
from tssac_core.common.stats import wilson_interval

HARD50 = Path(__file__).resolve().parents[1] / "results" / "recipe-trials" / "hard50"
A = HARD50 / "sitl_random_200_1900001_seed1.json"


def halves(tmp_path: Path) -> tuple[Path, Path]:
    """One committed campaign as the two fly would have written for its missions 0-119 (``--episodes 120``) and
    120-199 (``--episodes 80 --seed S+120``)."""
    data = json.loads(A.read_text())
    first = dict(data, missions=data["missions"][:120], episodes=120, episodes_requested=120)
    later = [dict(m, index=m["index"] - 120) for m in data["missions"][120:]]
    second = dict(data, missions=later, episodes=80, episodes_requested=80, seed=data["seed"] + 120)
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
    assert pooled["mean_mission_time_s"] == pytest.approx(whole["mean_mission_time_s"])
    assert (
        EvaluationRecord.from_json(pooled).roles["strike"].within_cost_limit
        == whole["roles"]["strike"]["within_cost_limit"]
    )
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


def _set(path: str, value: object) -> Callable[[dict[str, Any]], object]:
    """A mutation of a campaign: ``value`` at ``path`` (keys and mission-list indices, dot-separated)."""

    def mutate(data: dict[str, Any]) -> object:
        *parents, last = path.split(".")
        node: Any = data
        for key in parents:
            node = node[int(key)] if isinstance(node, list) else node[key]
        if value is DELETE:
            del node[last]
        elif isinstance(node, list):
            node[int(last)] = value
        else:
            node[last] = value
        return data

    return mutate


DELETE = object()
MALFORMED: list[tuple[str, Callable[[dict[str, Any]], object], str]] = [
    ("top level a list", lambda d: [d], "a JSON object expected"),
    ("no missions", _set("missions", DELETE), "no list of missions"),
    ("missions an object", _set("missions", {"0": {}}), "no list of missions"),
    ("missions empty", _set("missions", []), "no missions to pool"),
    ("pilot missing", _set("pilot", DELETE), "'pilot' must be a string"),
    ("scenario a number", _set("scenario", 7), "'scenario' must be a string"),
    ("clock null", _set("clock", None), "'clock' must be a string"),
    ("cost limit NaN", _set("cost_limit", float("nan")), "'cost_limit' must be a finite number"),
    ("cost limit a string", _set("cost_limit", "3"), "'cost_limit' must be a finite number"),
    ("campaign seed a string", _set("seed", "1900121"), "'seed' must be a whole number"),
    ("a mission a list", _set("missions.3", [1, 2]), "mission row 3 is not a JSON object"),
    ("a mission without its seed", _set("missions.3.seed", DELETE), "mission row 3 has no 'seed'"),
    ("a crashed mission", _set("missions.3.cost", None), "crashed mission"),
    ("a mission without success", _set("missions.3.success", DELETE), "has no 'success'"),
    ("index negative", _set("missions.3.index", -1), "'index' must be a whole number >= 0"),
    ("index a float", _set("missions.3.index", 3.0), "'index' must be a whole number >= 0"),
    ("seed a float", _set("missions.3.seed", 1900124.5), "'seed' must be a whole number"),
    ("seed not the campaign's", _set("missions.3.seed", 17), "is not the campaign's seed"),
    ('success "false"', _set("missions.3.success", "false"), "'success' must be true or false"),
    ("success 1", _set("missions.3.success", 1), "'success' must be true or false"),
    ("cost a list", _set("missions.3.cost", [0, 0, 0]), "'cost' must be an object"),
    ("cost without a role", _set("missions.3.cost.strike", DELETE), "exactly the roles"),
    ("cost of an unknown role", _set("missions.3.cost.spy", 0.0), "exactly the roles"),
    ("cost NaN", _set("missions.3.cost.detect", float("nan")), "detect's cost must be a finite number"),
    ("cost infinite", _set("missions.3.cost.detect", float("inf")), "detect's cost must be a finite number"),
    ("cost negative", _set("missions.3.cost.detect", -5.0), "detect's cost must be a finite number"),
    ("cost a string", _set("missions.3.cost.detect", "0"), "detect's cost must be a finite number"),
    ("cost a boolean", _set("missions.3.cost.detect", True), "detect's cost must be a finite number"),
    ("episodes not the missions'", _set("episodes", 1000), "'episodes' says 1000"),
    ("episodes requested garbage", _set("episodes_requested", "many"), "'episodes_requested' must be"),
    ("interrupted", _set("interrupted", True), "interrupted after 80 of 80 missions"),
    ("stopped by an error", _set("error", "mission 7 timed out"), "stopped by an error"),
    ("fewer missions than asked", _set("episodes_requested", 90), "80 of 90 missions"),
    ("another team", _set("pilot", "guidance"), "pilot 'guidance' differs"),
    ("another scenario", _set("scenario", "/x/degraded.yaml"), "scenario /x/degraded.yaml differs"),
    ("another cost limit", _set("cost_limit", 5.0), "cost_limit 5.0 differs"),
    ("another clock", _set("clock", "speedup 10"), "clock 'speedup 10' differs"),
    ("other physics", _set("dynamics", {"model": "jsbsim", "aircraft": "f16"}), "physics"),
    ("a wind", _set("wind", {"speed_m_s": 10.0, "from_deg": 0.0, "turbulence": "none"}), "wind"),
    ("with the monitor", _set("shield", {"interventions_per_uav_mission": 0.0}), "monitor (--shield)"),
]


@pytest.mark.parametrize("case, mutate, needle", MALFORMED, ids=[c[0] for c in MALFORMED])
def test_every_malformed_or_mismatched_campaign_is_one_line_exit_2(
    case: str,
    mutate: Callable[[dict[str, Any]], object],
    needle: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    a, b = halves(tmp_path)
    b.write_text(json.dumps(mutate(json.loads(b.read_text()))))
    out = tmp_path / "pooled.json"
    with pytest.raises(SystemExit) as exc:
        main([str(a), str(b), "--json", str(out)])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and needle in err, err
    assert not out.exists()


def test_campaigns_whose_monitors_predict_differently_are_not_pooled(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Both with the monitor, one predicting with eq. 5 and one with an airframe's response: refused in one line."""
    a, b = halves(tmp_path)
    for path, scope in ((a, None), (b, "the monitor predicts with the airframe response f16.response.yaml: ...")):
        path.write_text(json.dumps(_set("shield", {"interventions_per_uav_mission": 0.0, "scope": scope})(
            json.loads(path.read_text()))))  # fmt: skip
    with pytest.raises(SystemExit) as exc:
        main([str(a), str(b), "--json", str(tmp_path / "pooled.json")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and "monitor (--shield)" in err and "f16.response" in err, err


@pytest.mark.parametrize(
    "content, needle",
    [
        (None, "cannot read it"),  # no such file
        ("dir", "cannot read it"),
        (b"\xff\xfe{}", "not UTF-8"),
        (b"{not json", "not JSON"),
        (b"[" * 100_000, "nested too deeply"),
        (b" " * 2000, "more than"),  # beyond the size limit (lowered here)
    ],
    ids=["missing", "a directory", "not UTF-8", "not JSON", "nested too deeply", "too large"],
)
def test_a_file_that_is_not_a_campaign_is_one_line_exit_2(
    content: bytes | str | None,
    needle: str,
    tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    if needle == "more than":
        monkeypatch.setattr(pool_module, "MAX_FILE_BYTES", 1000)
    a = halves(tmp_path)[0]
    bad = tmp_path / "bad.json"
    if content == "dir":
        bad.mkdir()
    elif isinstance(content, bytes):
        bad.write_bytes(content)
    with pytest.raises(SystemExit) as exc:
        main([str(bad), str(a)])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.count("\n") == 1 and needle in err, err


def test_a_partial_campaign_is_pooled_only_when_asked_and_only_without_a_gap(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The first 120 missions were flown by a campaign of 200 that an error stopped: ``--partial`` pools them with
    the other 80, with a note; without mission 50 (the one in flight when it stopped) it is refused."""
    a, b = halves(tmp_path)
    first = json.loads(a.read_text())
    first.update(error="mission 120 did not end within 900 s", episodes_requested=200)
    a.write_text(json.dumps(first))
    with pytest.raises(SystemExit):
        main([str(a), str(b)])
    assert "--partial" in capsys.readouterr().err
    assert main([str(a), str(b), "--partial"]) == 0
    captured = capsys.readouterr()
    assert "over 200 missions" in captured.out
    note = f"{a}: stopped by an error after 120 of 200 missions: pooling its 120 finished missions"
    assert captured.err == f"python -m mavlink_bridge.fly.pool: note: {note}\n"
    first["missions"] = [m for m in first["missions"] if m["index"] != 50]
    first["episodes"] = 119
    a.write_text(json.dumps(first))
    with pytest.raises(SystemExit):
        main([str(a), str(b), "--partial"])
    assert "mission 50 (seed 1900051) before its last finished one was not flown" in capsys.readouterr().err


def test_an_unwritable_output_is_one_line_exit_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    a, b = halves(tmp_path)
    (tmp_path / "taken").write_text("")
    with pytest.raises(SystemExit) as exc:
        main([str(a), str(b), "--json", str(tmp_path / "taken" / "pooled.json")])
    err = capsys.readouterr().err
    assert exc.value.code == 2 and err.startswith("python -m mavlink_bridge.fly.pool: error:") and err.count("\n") == 1
