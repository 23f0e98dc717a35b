"""The evaluation record (tssac_core.common.evaluation_record): one JSON round trip for the batched world's and fly's
figures, the files written before it still read, and what no version reads refused in one line."""

from __future__ import annotations

import copy
import json
from pathlib import Path

import pytest

from tssac_core.common.cli import run
from tssac_core.common.evaluation_record import (
    RECORD_VERSION,
    BatchedRun,
    EvaluationRecord,
    FlownDynamics,
    FlownWind,
    RecordError,
    RoleFigures,
    RoleMonitorFigures,
    SitlMonitorFigures,
    SitlRun,
    WorldMonitorFigures,
    WorstMission,
)
from tssac_core.evaluate import main as evaluate_main

ROOT = Path(__file__).resolve().parent.parent

FIGURES = {
    "success_rate": 0.9,
    "success_interval95": (0.7, 0.97),
    "mean_cost": 1.5,
    "mean_cost_interval95": (0.2, 3.1),
    "episodes": 10,
    "mean_mission_time_s": 250.5,
    "roles": {
        "decoy": RoleFigures(mean_cost=0.5, max_cost=5.0, within_cost_limit=0.9, cvar95_cost=5.0),
        "strike": RoleFigures(task_success_rate=0.9, latency_p50_ms=0.4, latency_p99_ms=2.0),
    },
    "worst_missions": [WorstMission(mission=3, seed=103, role="decoy", cost=5.0)],
}
WORLD_MONITOR = WorldMonitorFigures(
    interventions_per_uav_mission=1.2,
    max_interventions_per_uav_mission=4,
    max_switches_per_uav_mission=9,
    backup_time_fraction=0.02,
    unprotected_time_fraction=0.0,
    uav_missions_with_cost=0,
    uavs_left_area=0,
    roles={"decoy": RoleMonitorFigures(interventions_per_mission=1.0, backup_time_fraction=0.01)},
)
SITL_RUN = SitlRun(
    episodes_requested=12,
    pilot="models/tssac",
    setpoints="arduplane",
    scenario="scenarios/random.yaml",
    dynamics=FlownDynamics("jsbsim", "f16"),
    wind=FlownWind(10.0, 270.0, "light"),
    seed=9000,
    clock="lockstep",
    cost_limit=3.0,
    signing=True,
)
SITL_MONITOR = SitlMonitorFigures(
    uav_missions=30,
    interventions_per_uav_mission=None,
    max_interventions_per_uav_mission=None,
    backup_time_fraction=None,
    unprotected_time_fraction=None,
    decisions=0,
    resets=0,
    max_margin_m=None,
    uav_missions_with_cost=None,
    uavs_left_area=None,
    guarantee=False,
    scope="wind 10 m/s: no guarantee",
)


@pytest.mark.parametrize(
    "record",
    [
        EvaluationRecord(**FIGURES),
        EvaluationRecord(
            **FIGURES,
            monitor=WORLD_MONITOR,
            run=BatchedRun(controller="models/tssac", scenario="scenarios/random.yaml", seed=7, cost_limit=3.0),
        ).with_monitor_config({"margin_m": 100.0, "straight_leads_s": [0.0, 4.0]}),
        EvaluationRecord(**FIGURES, monitor=SITL_MONITOR, run=SITL_RUN),
        EvaluationRecord(**{**FIGURES, "mean_cost": None, "mean_cost_interval95": None}, run=SITL_RUN),
    ],
    ids=["figures", "batched with the monitor", "fly with the monitor", "fly without a cost"],
)
def test_a_record_survives_its_json_round_trip(record):
    data = json.loads(json.dumps(record.to_json()))
    assert data["record_version"] == RECORD_VERSION
    assert EvaluationRecord.from_json(data) == record
    assert data["roles"]["strike"] == {"task_success_rate": 0.9, "latency_p50_ms": 0.4, "latency_p99_ms": 2.0}
    assert "mean_cost" in data and "mean_cost_interval95" in data  # an unknown cost is an explicit null


def test_a_record_keeps_the_keys_in_the_order_the_files_always_had():
    record = EvaluationRecord(**FIGURES, monitor=WORLD_MONITOR, run=BatchedRun("guidance", "s.yaml", 7, 3.0))
    assert list(record.to_json()) == [
        "success_rate",
        "success_interval95",
        "mean_cost",
        "mean_cost_interval95",
        "episodes",
        "mean_mission_time_s",
        "roles",
        "worst_missions",
        "shield",
        "controller",
        "scenario",
        "seed",
        "cost_limit",
        "record_version",
    ]
    assert "config" not in record.to_json()["shield"]  # stated only by a writer that knows it


def test_a_cache_from_before_the_intervals_and_a_fly_file_from_before_the_dialects_still_read():
    old_cache = {
        "success_rate": 0.5,
        "mean_cost": 0.0,
        "episodes": 2,
        "mean_mission_time_s": 100.0,
        "controller": "guidance",
        "scenario": "scenarios/short.yaml",
        "seed": 1,
        "cost_limit": 3.0,
        "cache_key": {"team": "guidance"},
    }
    record = EvaluationRecord.from_json(old_cache)
    assert record.success_interval95 is None and record.roles == {} and record.worst_missions == []
    assert record.run == BatchedRun("guidance", "scenarios/short.yaml", 1, 3.0)
    old_fly = {
        **EvaluationRecord(**FIGURES).to_json(),
        "episodes_requested": 10,
        "pilot": "models/tssac",
        "scenario": "scenarios/strike.yaml",
        "seed": 5,
        "clock": "lockstep",
        "cost_limit": 3.0,
        "signing": False,
    }
    del old_fly["record_version"]
    run_ = EvaluationRecord.from_json(old_fly).run
    assert isinstance(run_, SitlRun)
    assert (run_.setpoints, run_.dynamics, run_.wind) == ("body-rates", None, None)


def test_every_committed_results_file_reads_as_a_record():
    """Old JSON files still read: every evaluation the repository carries (caches, fly campaigns, benchmarks)."""
    read = 0
    for path in sorted([*ROOT.glob("results/**/*.json"), *ROOT.glob("benchmarks/results/**/*.json")]):
        data = json.loads(path.read_text())
        if isinstance(data, dict) and "success_rate" in data:
            EvaluationRecord.from_json(data)
            read += 1
    assert read > 300


@pytest.mark.parametrize(
    ("change", "message"),
    [
        (lambda d: d.update(record_version=RECORD_VERSION + 1), f"record_version {RECORD_VERSION + 1!r}: this version"),
        (lambda d: d.update(record_version="1"), "record_version '1'"),
        (lambda d: d.pop("episodes"), "no 'episodes' in the evaluation record"),
        (lambda d: d["roles"]["decoy"].update(speed=3.0), "not an evaluation record"),
        (lambda d: d.update(success_interval95=[0.1]), "not an evaluation record"),
    ],
    ids=["a newer version", "a version that is no number", "no episodes", "an unknown role figure", "a bad interval"],
)
def test_what_no_version_reads_is_one_line(change, message):
    data = copy.deepcopy(EvaluationRecord(**FIGURES).to_json())
    change(data)
    with pytest.raises(RecordError) as err:
        EvaluationRecord.from_json(data)
    assert message in str(err.value) and "\n" not in str(err.value)


def test_evaluate_writes_a_record_that_reads_back_as_written(tmp_path):
    out = tmp_path / "e.json"
    argv = ["--scenario", str(ROOT / "scenarios" / "strike.yaml"), "--episodes", "2", "--seed", "5", "--shield"]
    assert run(evaluate_main, [*argv, "--no-progress", "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    record = EvaluationRecord.from_json(data)
    assert isinstance(record.monitor, WorldMonitorFigures) and record.monitor.config is not None
    assert record.run == BatchedRun("guidance", str(ROOT / "scenarios" / "strike.yaml"), 5, 3.0)
    assert record.to_json() == data
