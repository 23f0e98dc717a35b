"""The experiment runner: grid files, resumable jobs in their own process groups, Table 4 and the figures."""

from __future__ import annotations

import csv
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tssac_core.common.cli import run
from tssac_core.common.stats import bootstrap_mean_interval, wilson_interval
from tssac_core.experiments.cli import main, train
from tssac_core.experiments.evaluations import (
    EvalLabel,
    EvalSpec,
    LayoutRule,
    PerEpisode,
    TeamEvaluation,
    cache_key,
    cached,
    eval_specs,
)
from tssac_core.experiments.figures import clipped_error, penalty_entries
from tssac_core.experiments.grid import load_grid
from tssac_core.experiments.learning_curves import steps_to_threshold
from tssac_core.experiments.summary import (
    AlgorithmSummary,
    CostPool,
    EvalRow,
    OverSeeds,
    TailPool,
    TailRow,
    pooled_cost,
    pooled_tail,
    transfer_speedup,
    within_limit,
)
from tssac_core.experiments.table import _tail_rate, cascade_row
from tssac_core.train.config import selects_within_limit
from tssac_core.train.jobs.runner import LOG_NAME, Status, job_state
from tssac_core.train.rundir import METRIC_FIELDS
from tssac_core.train.wall_time import (
    WALL_TIME_FILE,
    Ended,
    Invocation,
    begin_invocation,
    read_invocations,
    record_invocation,
    training_wall_s,
)

# One test process runs this file and tests/test_ray.py: the smoke grid (a module fixture) is trained once, and
# one Ray at a time starts on this machine.
pytestmark = pytest.mark.xdist_group("ray")

ROOT = Path(__file__).resolve().parent.parent
SMOKE = ROOT / "experiments" / "smoke.yaml"


@pytest.fixture(autouse=True)
def at_root(monkeypatch):
    """Grid files name scenarios relative to the directory the command runs in: the repository root."""
    monkeypatch.chdir(ROOT)


def write_grid(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def smoke_text(*changes: tuple[str, str]) -> str:
    """experiments/smoke.yaml with the first occurrence of each ``old`` text replaced by ``new``."""
    text = SMOKE.read_text()
    for old, new in changes:
        assert old in text, old
        text = text.replace(old, new, 1)
    return text


# ------------------------------------------------------------------------------------- grid files


def test_paper_grid():
    grid = load_grid("experiments/paper.yaml")
    names = [e.name for e in grid.algos]
    assert names == ["tssac", "sac_lag", "sac", "ppo", "cpo", "ppo_lag", "sac_pen10", "sac_pen15", "sac_pen50"]
    assert [e.penalty for e in grid.algos if e.algo == "sac_penalty"] == [-10.0, -15.0, -50.0]  # penalty 0 is sac
    assert (
        grid.seeds == (0, 1, 2)
        and grid.train.epochs == 25
        and grid.evaluation.episodes == 50
        and grid.evaluation.seed == 12345
    )
    ev = grid.evaluation  # and 500 more layouts, off and on the monitor, on layout seeds of their own (issues 23, 24)
    assert (ev.tail_episodes, ev.tail_seed, ev.tail_monitor) == (500, 990001, True)
    assert grid.train.validation_episodes == 50
    jobs = grid.jobs(Path("results"))
    assert len(jobs) == 27 and jobs[0].out == Path("results/runs/tssac-seed0")
    assert [j.name for j in jobs[:10]] == [f"{n}-seed0" for n in names] + [
        "tssac-seed1"
    ]  # seed-major: a cut-short grid fills every row
    by_name = {j.name: j for j in jobs}
    tssac, ppo, pen = (
        by_name["tssac-seed1"].config,
        by_name["ppo-seed1"].config,
        by_name["sac_pen50-seed2"].config,
    )
    assert tssac.learner == {"hidden_sizes": [128, 128], "alpha_init": 0.2, "beta_lr": 0.001, "gamma": 0.995}
    assert ppo.learner == {"hidden_sizes": [128, 128], "gamma": 0.995}  # on-policy learners get no SacConfig fields
    assert (pen.algo, pen.penalty, pen.seed) == ("sac_penalty", -50.0, 2)
    # each ships its epoch by its own rule: within C where the learner is given C (docs/decisions.md)
    assert [selects_within_limit(by_name[f"{n}-seed0"].config) for n in names] == [
        True,
        True,
        False,
        False,
        True,
        True,
        False,
        False,
        False,
    ]
    assert (
        load_grid("results/earlier/grid-10-epochs/paper.yaml").train.selection == "within_limit"
    )  # pinned: its runs were
    for cfg in (tssac, ppo, pen):  # the shared arguments are the same for every algorithm
        assert (
            cfg.epochs,
            cfg.steps_per_epoch,
            cfg.envs,
            cfg.action_repeat,
            cfg.update_every,
            cfg.start_steps,
            cfg.threads,
        ) == (25, 4000, 1, 10, 2, 0, 1)
    transfer = grid.transfer_jobs(Path("results"))  # the transfer experiment: each role alone, both sides, every seed
    assert [j.name for j in transfer[:4]] == [
        "transfer-detect-tssac-seed0",
        "transfer-detect-sac_lag-seed0",
        "transfer-strike-tssac-seed0",
        "transfer-strike-sac_lag-seed0",
    ] and len(transfer) == 12
    strike = transfer[3]
    cfg = strike.config
    assert strike.out == Path("results/runs/transfer-strike-sac_lag-seed0") and strike.roles == ("strike",)
    assert (cfg.algo, cfg.roles, cfg.teammates, cfg.stop_at_task_success, cfg.epochs, cfg.validation_episodes) == (
        "sac_lag",
        ("strike",),
        "models/tssac",
        0.9,
        25,
        0,
    )
    assert cfg.learner == tssac.learner and (cfg.steps_per_epoch, cfg.action_repeat, cfg.start_steps) == (
        4000,
        10,
        0,
    )  # the grid's settings


@pytest.mark.parametrize(
    "change, message",
    [
        (("seeds: [0]", "seeds: [0, 0]"), "seeds: a seed is listed twice"),
        (("  epochs: 1\n", "  epochs: many\n"), "train.epochs: expected an integer, got 'many'"),
        (("  epochs: 1\n", "  epochs: 0\n"), "train.epochs: must be >= 1"),
        (("  envs: 1\n", "  envs: 1\n  speed: 3\n"), "train.speed: unknown key"),
        (
            ("  envs: 1\n", "  envs: 1\n  selection: best\n"),
            "train.selection: expected one of within_limit, success, tail, got 'best'",
        ),
        (("  scenario: scenarios/strike.yaml", "  scenario: scenarios/nowhere.yaml"), "train.scenario: file not found"),
        (
            ("  - sac_lag\n", "  - {algo: sac_lag, penalty: -10}\n"),
            "algos[1].penalty: only sac_penalty takes a penalty",
        ),
        (("  - sac_lag\n", "  - sarsa\n"), "algos[1].algo: expected one of sac, "),
        (("  - sac_lag\n", "  - {algo: sac_lag, name: tssac}\n"), "algos[1].name: 'tssac' is used twice"),
        (
            ("  - sac_lag\n", "  - {algo: ppo, set: {alpha_init: 0.2}}\n"),
            "algos[1] (ppo): invalid learner settings (--set): unknown OnPolicyConfig field 'alpha_init'",
        ),
        (
            ("batch_size: 8", "batch_sise: 8"),
            "algos[0] (tssac): invalid learner settings (--set): unknown SacConfig field 'batch_sise'",
        ),
        (("  episodes: 2", "  episodes: [2]"), "evaluation.episodes: expected an integer"),
        (("seeds: [0]", "seeds: [0"), "not valid YAML"),
        (
            ("  tail_seed: 990001", "  tail_seed: 12344"),
            "evaluation.tail_seed: its layout seeds 12344-12346 overlap those of evaluation.seed (12345-12346)",
        ),
        (("  tail_monitor: true", "  tail_monitor: yes please"), "evaluation.tail_monitor: expected true or false"),
        (("  tail_episodes: 3\n", ""), "evaluation.tail_seed: needs evaluation.tail_episodes"),
        (("  tail_episodes: 3", "  tail_episodes: 0"), "evaluation.tail_episodes: must be >= 1"),
        (
            ("  generalization_scenario: scenarios/short-random.yaml\n", ""),
            "evaluation.generalization_tail_episodes: needs evaluation.generalization_scenario",
        ),
        (
            ("  generalization_tail_episodes: 3\n", "  generalization_tail_seed: 991001\n"),
            "evaluation.generalization_tail_seed: needs evaluation.generalization_tail_episodes (how many layouts)",
        ),
        (
            ("  generalization_tail_episodes: 3", "  generalization_tail_episodes: 0"),
            "evaluation.generalization_tail_episodes: must be >= 1",
        ),
        (
            ("  generalization_tail_episodes: 3", "  generalization_tail_episodes: [3]"),
            "evaluation.generalization_tail_episodes: expected an integer",
        ),
        (
            (
                "  generalization_tail_episodes: 3\n",
                "  generalization_tail_episodes: 3\n  generalization_tail_seed: -1\n",
            ),
            "evaluation.generalization_tail_seed: must be >= 0",
        ),
        (
            (
                "  generalization_tail_episodes: 3\n",
                "  generalization_tail_episodes: 3\n  generalization_tail_seed: 12343\n",
            ),
            "evaluation.generalization_tail_seed: its layout seeds 12343-12345 overlap those of evaluation.seed "
            "(12345-12346): the generalization tail must fly other layouts",
        ),
        *[
            (("evaluation:", f"transfer: {{{t}}}\nevaluation:"), message)
            for t, message in (
                (
                    "teammates: models/tssac, with: sac_lag, without: tssac",
                    "transfer.with: 'sac_lag' is sac_lag: 'with' needs tssac",
                ),
                (
                    "teammates: models/tssac, with: tssac, without: ppo",
                    "transfer.without: 'ppo' is not an entry of algos (tssac, sac_lag)",
                ),
                (
                    "teammates: models/tssac, with: tssac, without: sac_lag, roles: [decoy]",
                    "transfer.roles: expected a list of detect and/or strike",
                ),
                ("teammates: nowhere, with: tssac, without: sac_lag", "transfer.teammates: nowhere/decoy.pt not found"),
                (
                    "teammates: models/tssac, with: tssac, without: sac_lag, task_success: 1.5",
                    "transfer.task_success: expected a fraction",
                ),
                ("teammates: models/tssac, with: tssac", "transfer.without: missing required field"),
            )
        ],
    ],
)
def test_malformed_grid_is_one_line(tmp_path, capsys, change, message):
    grid = write_grid(tmp_path / "bad.yaml", smoke_text(change))
    assert run(main, ["--grid", str(grid), "--results", str(tmp_path / "r"), "--dry-run"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    assert err.startswith(f"error: {grid}: ") and message in err, err
    assert not (tmp_path / "r").exists()


@pytest.mark.parametrize("mode", ["--report-only", "--compact"])
@pytest.mark.parametrize("chooser", [["--only", "tssac-*"], ["--finish-by", "2099-01-01 00:00"]])
def test_choosing_jobs_for_a_mode_that_trains_none_is_refused(tmp_path, capsys, mode, chooser):
    """--only and --finish-by pick what to train; beside --report-only or --compact they would be ignored in silence."""
    results = tmp_path / "r"
    assert (
        run(main, ["--grid", str(ROOT / "experiments" / "smoke.yaml"), "--results", str(results), mode, *chooser]) == 2
    )
    err = capsys.readouterr().err.strip()
    assert (
        err == f"error: {chooser[0]} chooses jobs to train, and {mode} trains nothing (it works on every finished run)"
    ), err
    assert not results.exists()


def test_missing_grid_file(tmp_path, capsys):
    assert run(main, ["--grid", str(tmp_path / "none.yaml"), "--dry-run"]) == 2
    assert "cannot read file" in capsys.readouterr().err


def test_the_generalization_tail_is_flown_only_when_the_grid_asks_for_it(tmp_path):
    """evaluation.generalization_tail_*: that many layouts of the generalisation scenario, one seed per mission, no
    monitor, cached in a file of its own; a grid without it flies the rest as before, under the same cache keys."""
    grid = load_grid(SMOKE)
    assert (grid.evaluation.generalization_tail_episodes, grid.evaluation.generalization_tail_seed) == (3, 991001)
    specs = {spec.label: spec for spec in eval_specs(grid)}
    assert list(specs) == [
        EvalLabel.RANDOM,
        EvalLabel.GENERALIZATION,
        EvalLabel.TAIL,
        EvalLabel.TAIL_MONITOR,
        EvalLabel.GENERALIZATION_TAIL,
    ]
    gen = specs[EvalLabel.GENERALIZATION_TAIL]
    assert gen == EvalSpec(
        EvalLabel.GENERALIZATION_TAIL, Path("scenarios/short-random.yaml"), 3, 991001, layouts=LayoutRule.PER_MISSION
    )
    assert gen.label.is_tail and not gen.monitor and gen.cache_name() == "eval_generalization_tail.json"
    own = smoke_text(
        (
            "  generalization_tail_episodes: 3\n",
            "  generalization_tail_episodes: 5\n  generalization_tail_seed: 12347\n",
        )
    )  # right after the 50-layout seeds (12345-12346): allowed
    ev = load_grid(write_grid(tmp_path / "own.yaml", own)).evaluation
    assert (ev.generalization_tail_episodes, ev.generalization_tail_seed) == (5, 12347)
    without = load_grid(write_grid(tmp_path / "without.yaml", smoke_text(("  generalization_tail_episodes: 3\n", ""))))
    assert without.evaluation.generalization_tail_episodes is None
    rest = eval_specs(without)
    assert [spec.label for spec in rest] == list(specs)[:-1]
    assert [cache_key(None, spec) for spec in rest] == [cache_key(None, specs[spec.label]) for spec in rest]
    full = load_grid("experiments/paper-full.yaml").evaluation  # drawn after training, used by nothing else
    assert (full.generalization_tail_episodes, full.generalization_tail_seed, full.tail_seed) == (500, 2500001, 2400001)


# ------------------------------------------------------------------------------- the smoke grid


@pytest.fixture(scope="module")
def smoke(tmp_path_factory) -> Path:
    """The smoke grid run once through the command (two jobs at once), from the repository root."""
    results = tmp_path_factory.mktemp("experiments") / "results"
    with pytest.MonkeyPatch.context() as mp:
        mp.chdir(ROOT)
        assert main(["--grid", "experiments/smoke.yaml", "--results", str(results), "--jobs", "2"]) == 0
    return results


def test_smoke_grid_trains_every_job(smoke):
    for name in ("tssac-seed0", "sac_lag-seed0"):
        run_dir = smoke / "runs" / name
        assert all((run_dir / f"{role}.pt").is_file() for role in ("decoy", "detect", "strike")), name
        log = (run_dir / LOG_NAME).read_text()
        assert log.count("runner: ") == 1 and "--no-progress" in log and f"--out {run_dir}" in log
        config = json.loads((run_dir / "config.json").read_text())
        assert config["epochs"] == 1
        assert config["learner"] == {"hidden_sizes": [16, 16], "batch_size": 8, "multiplier_signal": "episode_cost"}


def test_second_invocation_starts_nothing(smoke, capsys):
    logs = {p: p.stat().st_mtime_ns for p in smoke.glob("runs/*/" + LOG_NAME)}
    caches = {p: p.stat().st_mtime_ns for p in smoke.glob("runs/*/eval_*.json")}
    # per run: the 50 layouts, the generalisation scenario's, the tail, with the monitor, and the generalisation tail
    assert len(logs) == 2 and len(caches) == 10
    assert main(["--grid", "experiments/smoke.yaml", "--results", str(smoke)]) == 0
    out = capsys.readouterr().out
    assert "2 jobs: 2 finished, 0 to run" in out and "started" not in out
    assert {p: p.stat().st_mtime_ns for p in logs} == logs  # no job was started
    assert {p: p.stat().st_mtime_ns for p in caches} == caches  # the evaluations came from their caches
    assert train(load_grid("experiments/smoke.yaml"), smoke, 2, report=lambda line: None) == []
    assert main(["--grid", "experiments/smoke.yaml", "--results", str(smoke), "--dry-run"]) == 0
    assert [line.split()[0] for line in capsys.readouterr().out.splitlines()] == ["finished", "finished"]


@pytest.mark.slow
def test_the_smoke_grid_on_ray_gives_the_local_executors_table(smoke, tmp_path, capsys):
    """``--executor ray`` (a Ray of 2 CPUs started inside the command, both jobs at once) trains the same teams:
    the evaluations the local run cached are taken as they are (their key is a digest of the actors' weights),
    and Table 4 and experiments.json are the local run's, but for the training wall times."""
    results = tmp_path / "results"
    for cache in [*smoke.glob("runs/*/eval_*.json"), *smoke.glob("guidance/*.json")]:
        target = results / cache.relative_to(smoke)
        target.parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(cache, target)
    caches = {p: p.read_bytes() for p in results.glob("**/*.json")}
    assert (
        main(["--grid", "experiments/smoke.yaml", "--results", str(results), "--executor", "ray", "--cpus", "2"]) == 0
    )
    out = capsys.readouterr().out
    assert "2 jobs: 0 finished, 2 to run, as many at a time as the CPUs hold on Ray" in out
    assert "Ray: 2 CPUs, 2 jobs at a time, 1 CPU(s) each" in out
    assert re.search(
        r"^started tssac-seed0: on \S+ \(node [0-9a-f]{8}\), Ray worker pid \d+, training pid \d+$", out, re.M
    ), out
    assert {p: p.read_bytes() for p in caches} == caches  # every cached evaluation was still valid: the same actors

    def minutes_masked(path: Path) -> str:
        return re.sub(r"\| \d+ min( ± \d+)? \|", "| (minutes) |", path.read_text())

    assert minutes_masked(results / "table4.md") == minutes_masked(smoke / "table4.md")
    ray_data, local_data = (json.loads((r / "experiments.json").read_text()) for r in (results, smoke))
    for data in (ray_data, local_data):
        for algo in data["algorithms"]:
            algo.pop("training_wall_s")

    def anywhere(data: dict) -> str:
        return json.dumps(data).replace(str(results), "R").replace(str(smoke), "R")

    assert anywhere(ray_data) == anywhere(local_data)


def test_report_writes_table4_json_and_figures(smoke):
    table = (smoke / "table4.md").read_text()
    rows = [line for line in table.splitlines() if line.startswith("| ")]
    assert rows[2].startswith("| tssac | 1 | ") and "| 96% | 3.0 | " in rows[2]  # the paper's Table 4 beside ours
    assert rows[3].startswith("| sac_lag | 1 | ") and "| 96% | 3.0 | " in rows[3]
    assert rows[2].endswith(" min |")  # the training wall time, from the run's wall_time.json
    (finished,) = read_invocations(smoke / "runs" / "tssac-seed0")  # one invocation, recorded by the training
    log = (smoke / "runs" / "tssac-seed0" / LOG_NAME).read_text()
    assert finished == Invocation(int(re.search(r"trained .* in (\d+) s", log).group(1)), Ended.FINISHED)
    assert "## The mean cost against the limit" in table and re.search(
        r"^\| tssac \| 6 \| \d+\.\d\d \| \d+\.\d\d-\d+\.\d\d \| \d \| ", table, re.M
    )
    # it solves the fixed mission safely, with the monitor too; 3 of 3 missions: the Wilson interval's lower end 43.9%
    assert re.fullmatch(
        r"\| guidance controller \| — \| 100.0% \| 0.00 \| 100.0% \| — \| — \| 100.0% \(43.9-100.0\) \| "
        r"0.00 \(0.00-0.00\) \| 100.0% \| 100.0% \(43.9-100.0\) \| 0.00 \(0.00-0.00\) \| \d+\.\d% \| — \|",
        rows[4],
    ), rows[4]
    assert "3 layouts: success rate (95% interval)" in rows[0] and "with monitor: time under backup" in rows[0]
    assert "## 3 layouts per team, with intervals, and with the runtime-assurance monitor" in table
    assert "layout seeds 990001-990003" in table and "--seed 990001 --shield" not in table
    assert "1 epochs x 20 learner decisions per role" in table and "Shrunk from the paper's 50 epochs" in table
    assert "## Transfer inside the grid's curricula" in table and "| detect |" in table and "| strike |" in table
    assert "## Where the missions stop: each role's task, given the one before it" in table and re.search(
        r"^\| guidance controller \| 100\.0% \(43\.9-100\.0; 3 of 3\) \| ", table, re.M
    )
    data = json.loads((smoke / "experiments.json").read_text())
    assert [a["name"] for a in data["algorithms"]] == ["tssac", "sac_lag"]
    tssac = data["algorithms"][0]
    assert tssac["seeds"] == [0] and tssac["paper"] == {"success_rate": 0.96, "mean_cost": 3.0}
    cached = json.loads((smoke / "runs" / "tssac-seed0" / "eval_random.json").read_text())
    assert tssac["random"]["mean_cost"]["per_seed"] == {"0": cached["mean_cost"]}
    within = np.mean(np.asarray(cached["per_episode"]["cost"]) <= cached["cost_limit"])
    assert tssac["random"]["within_cost_limit"]["per_seed"] == {"0": within}
    assert len(cached["per_episode"]["cost"]) == 2 and len(cached["per_episode"]["return"][0]) == 3
    assert data["guidance"]["random"]["success_rate"] == 1.0 and data["guidance"]["generalization"]["episodes"] == 2
    assert set(data["transfer_speedup"]) == {"threshold", "detect", "strike"} and data["left_out"] == []
    for label in ("tail", "tail_monitor"):  # the tail columns: pooled from the cached evaluations, with their intervals
        flown = json.loads((smoke / "runs" / "tssac-seed0" / f"eval_{label}.json").read_text())
        assert (
            flown["seed"] == 990001 and flown["episodes"] == 3 and flown["cache_key"]["layouts"].startswith("mission k")
        )
        k = sum(flown["per_episode"]["success"])
        mean = bootstrap_mean_interval(np.asarray(flown["per_episode"]["cost"]))
        assert tssac[label]["missions"] == 3 and tssac[label]["flown_seeds"] == [0]
        assert tssac[label]["success_interval95"] == list(wilson_interval(k, 3).as_dict().values())[1:]
        assert (
            tssac[label]["mean_cost_interval95"] == [mean.low, mean.high]
            and tssac[label]["per_seed"]["0"]["success_rate"] == k / 3
        )
    assert "shield" in flown and len(flown["per_episode"]["backup_steps"]) == 3 and "return" not in flown["per_episode"]
    assert tssac["tail_monitor"]["backup_time_fraction"] == pytest.approx(
        np.sum(flown["per_episode"]["backup_steps"]) / np.sum(flown["per_episode"]["flown_steps"])
    )
    assert "backup_time_fraction" not in tssac["tail"]
    # the generalisation tail: 3 layouts of the generalisation scenario, pooled like the tail, in a section of its own
    ev = data["evaluation"]
    assert (ev["generalization_tail_episodes"], ev["generalization_tail_seed"]) == (3, 991001)
    flown = json.loads((smoke / "runs" / "tssac-seed0" / "eval_generalization_tail.json").read_text())
    assert (flown["scenario"], flown["seed"], flown["episodes"]) == ("scenarios/short-random.yaml", 991001, 3)
    assert flown["cache_key"]["layouts"].startswith("mission k") and "shield" not in flown
    assert len(flown["per_episode"]["out_of_area"]) == 3 and "return" not in flown["per_episode"]
    gen = tssac["generalization_tail"]
    k = sum(flown["per_episode"]["success"])
    assert gen["missions"] == 3 and gen["flown_seeds"] == [0] and gen["success_rate"] == k / 3
    assert gen["success_interval95"] == list(wilson_interval(k, 3).as_dict().values())[1:]
    mean = bootstrap_mean_interval(np.asarray(flown["per_episode"]["cost"]))
    assert gen["mean_cost_interval95"] == [mean.low, mean.high]
    guide = data["guidance"]["generalization_tail"]
    assert guide["missions"] == 3 and "generalization_tail" in data["algorithms"][1]
    section = table.split("\n## 3 layouts of the generalisation scenario per team, with intervals\n")[1]
    assert "layout seeds 991001-991003" in section and "`runs/<run>/eval_generalization_tail.json`" in section
    assert "--models runs/<run> --scenario scenarios/short-random.yaml --episodes 3 --seed 991001`" in section
    for name, g in (("tssac", gen), ("guidance controller", guide)):
        (lo, hi), (clo, chi) = g["success_interval95"], g["mean_cost_interval95"]
        cells = (
            f"| {name} | {100 * g['success_rate']:.1f}% ({100 * lo:.1f}-{100 * hi:.1f}) | "
            f"{g['mean_cost']:.2f} ({clo:.2f}-{chi:.2f}) | {100 * g['within_cost_limit']:.1f}% | "
        )
        tail = r"(0|—) \| .* \| \d+ of 9 \| \d+\.\d \| .* \| \d+ \|$"  # seeds flown ... UAVs that left the area
        assert re.search("^" + re.escape(cells) + tail, section, re.M), (cells, section)
    assert "3 layouts: success rate" in rows[0] and rows[0].count("success rate (95% interval)") == 2  # not in Table 4
    assert data["training"]["epochs_per_role"] == 1 and tssac["training_wall_s"]["mean"] >= 0
    for fig in ("fig7_training", "fig8_multiplier", "fig9_mission", "fig10_test_boxplots", "fig11_generalization"):
        assert (smoke / f"{fig}.png").stat().st_size > 10_000, fig


def test_a_figure_the_runs_no_longer_allow_is_deleted(smoke, tmp_path, capsys):
    """The smoke grid trains no SAC with a penalty: a figure 12 left from runs since moved away must not stay."""
    results = tmp_path / "results"
    shutil.copytree(smoke, results)
    (results / "fig12_penalty.png").write_bytes(b"a figure of runs that are gone")
    assert main(["--grid", "experiments/smoke.yaml", "--results", str(results), "--report-only"]) == 0
    assert not (results / "fig12_penalty.png").exists() and (results / "fig7_training.png").is_file()


def test_compact_keeps_the_pilots_and_their_evaluations(smoke, tmp_path, capsys):
    from tssac_core.deploy.policy import CheckpointError, learner_state, load_team

    results = tmp_path / "results"
    shutil.copytree(smoke, results)
    run_dir = results / "runs" / "tssac-seed0"
    obs = np.random.default_rng(0).uniform(-1, 1, (5, 24)).astype(np.float32)
    before = [p.act(obs) for p in load_team(run_dir)]
    sizes = {p: p.stat().st_size for p in run_dir.glob("*.pt")}
    caches = {p: p.read_text() for p in results.glob("runs/*/eval_*.json")}
    assert (run_dir / "resume").is_dir() and len(caches) == 10
    assert main(["--grid", "experiments/smoke.yaml", "--results", str(results), "--compact"]) == 0
    assert "compacted 2 finished runs" in capsys.readouterr().out
    assert not (run_dir / "resume").exists()
    assert all(p.stat().st_size < sizes[p] for p in sizes)
    assert all(np.array_equal(a, b) for a, b in zip(before, [p.act(obs) for p in load_team(run_dir)]))
    with pytest.raises(CheckpointError, match="actor only"):
        learner_state(run_dir / "decoy.pt")  # nothing to transfer from any more, said in one line
    # Still finished, and the cached evaluations still belong to these pilots: nothing is trained or flown again.
    assert main(["--grid", "experiments/smoke.yaml", "--results", str(results)]) == 0
    assert "2 jobs: 2 finished, 0 to run" in capsys.readouterr().out
    assert {p: p.read_text() for p in caches} == caches
    assert (
        main(["--grid", "experiments/smoke.yaml", "--results", str(results), "--compact"]) == 0
    )  # again: nothing changes
    assert all(np.array_equal(a, b) for a, b in zip(before, [p.act(obs) for p in load_team(run_dir)]))


def test_a_run_copied_from_another_clone_is_recognised_by_its_task(smoke, tmp_path, capsys):
    """config.json names the scenario file of the clone the run was made in; the grid compares tasks, not paths."""
    results = tmp_path / "results"
    shutil.copytree(smoke, results)
    config_path = results / "runs" / "tssac-seed0" / "config.json"
    config = json.loads(config_path.read_text())
    assert config["scenario"] == "scenarios/strike.yaml"  # as the grid file writes it: portable
    copy = tmp_path / "other-clone" / "scenarios" / "strike.yaml"
    copy.parent.mkdir(parents=True)
    shutil.copy(ROOT / "scenarios" / "strike.yaml", copy)

    def status(scenario: str) -> str:
        config_path.write_text(json.dumps({**config, "scenario": scenario}))
        with pytest.MonkeyPatch.context() as mp:
            mp.chdir(ROOT)
            assert main(["--grid", "experiments/smoke.yaml", "--results", str(results), "--dry-run"]) == 0
        return next(x for x in capsys.readouterr().out.splitlines() if "tssac-seed0" in x)

    assert status(str(copy)).startswith("finished")  # the same task in another file
    copy.unlink()
    assert status(str(copy)).startswith("finished")  # that file is gone: the checkpoints' scenario digest says
    line = status(str(ROOT / "scenarios" / "random.yaml"))  # another task
    assert line.startswith("conflict") and "scenario:" in line


@pytest.mark.slow
def test_transfer_runs_train_their_role_beside_the_teammates_and_are_reported(smoke, tmp_path, capsys):
    results = tmp_path / "results"
    shutil.copytree(smoke, results)
    teammates = results / "runs" / "tssac-seed0"
    text = smoke_text(
        (
            "evaluation:",
            f"transfer: {{teammates: {teammates}, with: tssac, without: sac_lag, roles: [detect], "
            f"epochs: 1}}\nevaluation:",
        )
    )
    grid = write_grid(tmp_path / "g.yaml", text)
    assert main(["--grid", str(grid), "--results", str(results), "--jobs", "2"]) == 0
    assert "4 jobs: 2 finished, 2 to run" in capsys.readouterr().out
    for side in ("tssac", "sac_lag"):
        run_dir = results / "runs" / f"transfer-detect-{side}-seed0"
        assert sorted(p.name for p in run_dir.glob("*.pt")) == [
            "detect.pt"
        ]  # one role; the teammates stay where they are
    log = (results / "runs" / "transfer-detect-tssac-seed0" / LOG_NAME).read_text()
    assert f"transferred 30 tensors from {teammates / 'decoy.pt'}" in log
    assert "## Transfer experiment" in (results / "table4.md").read_text()
    data = json.loads((results / "experiments.json").read_text())["transfer_experiment"]
    assert (
        data["detect"]["with"]["seeds"] == 1 and data["detect"]["without"]["seeds"] == 1 and data["roles"] == ["detect"]
    )
    assert main(["--grid", str(grid), "--results", str(results), "--dry-run"]) == 0
    assert [line.split()[0] for line in capsys.readouterr().out.splitlines()] == ["finished"] * 4
    assert main(["--grid", str(grid), "--results", str(results), "--compact"]) == 0
    assert "compacted 4 finished runs" in capsys.readouterr().out


def test_only_trains_the_jobs_its_patterns_name(smoke, tmp_path, capsys):
    """With tssac-seed0 finished and sac_lag-seed0 new, --only 'tssac-*' starts nothing; a pattern naming no job is
    one line."""
    results = tmp_path / "results"
    shutil.copytree(smoke / "runs" / "tssac-seed0", results / "runs" / "tssac-seed0")
    grid = ["--grid", "experiments/smoke.yaml", "--results", str(results)]
    assert main([*grid, "--dry-run", "--only", "sac_lag-*"]) == 0
    assert [line.split()[:2] for line in capsys.readouterr().out.splitlines()] == [["new", "sac_lag-seed0"]]
    assert main([*grid, "--only", "tssac-*"]) == 0
    assert "1 jobs: 1 finished, 0 to run" in capsys.readouterr().out
    assert not (results / "runs" / "sac_lag-seed0").exists()
    assert run(main, [*grid, "--only", "tssac-*", "--only", "sac-seed*"]) == 2
    err = capsys.readouterr().err.strip()
    assert (
        err == "error: --only 'sac-seed*' matches none of the jobs of experiments/smoke.yaml "
        "(see --dry-run for their names)"
    ), err
    assert not (results / "runs" / "sac_lag-seed0").exists()


def test_a_run_with_other_settings_is_refused(smoke, tmp_path, capsys):
    results = tmp_path / "r"
    run_dir = results / "runs" / "tssac-seed0"
    run_dir.mkdir(parents=True)
    config = json.loads((smoke / "runs" / "tssac-seed0" / "config.json").read_text())
    (run_dir / "config.json").write_text(json.dumps({**config, "epochs": 40}))
    assert run(main, ["--grid", "experiments/smoke.yaml", "--results", str(results)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "holds a run with other settings" in err and "epochs: 40" in err
    assert not (run_dir / LOG_NAME).exists()


def test_a_run_from_before_multiplier_signal_is_a_conflict(smoke, tmp_path, capsys):
    """Its multiplier measured Q^c; the grid's default is now the episode cost."""
    results = tmp_path / "r"
    run_dir = results / "runs" / "tssac-seed0"
    run_dir.mkdir(parents=True)
    config = json.loads((smoke / "runs" / "tssac-seed0" / "config.json").read_text())
    assert config["learner"].pop("multiplier_signal") == "episode_cost"
    (run_dir / "config.json").write_text(json.dumps(config))
    assert run(main, ["--grid", "experiments/smoke.yaml", "--results", str(results), "--dry-run"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "tssac-seed0" in x)
    assert line.startswith("conflict") and "'multiplier_signal': 'q_c'" in line


@pytest.mark.parametrize(
    "content, message",
    [
        ('{"algo": "tssac", "roles": ["decoy"], "warp_drive": 9}', "settings this TSSAC does not know: warp_drive"),
        ("[1, 2]", "not a training configuration"),
        ('{"algo": "tssac", "roles": "decoy"}', "roles: expected a list"),
    ],
)
def test_a_config_json_this_version_cannot_read_is_a_conflict_not_a_crash(tmp_path, capsys, content, message):
    results = tmp_path / "r"
    run_dir = results / "runs" / "tssac-seed0"
    run_dir.mkdir(parents=True)
    (run_dir / "config.json").write_text(content)
    assert run(main, ["--grid", "experiments/smoke.yaml", "--results", str(results), "--dry-run"]) == 0
    line = next(x for x in capsys.readouterr().out.splitlines() if "tssac-seed0" in x)
    assert line.startswith("conflict") and message in line
    assert run(main, ["--grid", "experiments/smoke.yaml", "--results", str(results)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err


# ------------------------------------------------------------------------- interruption and resume


@pytest.mark.slow
def test_sigterm_stops_the_job_and_the_next_run_resumes_it(tmp_path):
    """SIGTERM to the runner mid-job: the job's process is gone with it; the next run continues it with --resume."""
    # Two epochs per role: after the decoy's first one is saved, there is well over a second left to stop it.
    grid_path = write_grid(tmp_path / "one.yaml", smoke_text(("  - sac_lag\n", ""), ("  epochs: 1\n", "  epochs: 2\n")))
    results = tmp_path / "results"
    run_dir = results / "runs" / "tssac-seed0"
    runner = subprocess.Popen(
        [sys.executable, "-m", "tssac_core.experiments", "--grid", str(grid_path), "--results", str(results)],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    deadline = time.monotonic() + 60
    while time.monotonic() < deadline and not (run_dir / "resume" / "decoy.pt").is_file() and runner.poll() is None:
        time.sleep(0.02)
    runner.send_signal(signal.SIGTERM)
    out, err = runner.communicate(timeout=60)
    assert runner.returncode == 130, err
    pid = int(re.search(r"started tssac-seed0: pid (\d+)", out).group(1))
    with pytest.raises(ProcessLookupError):
        os.kill(pid, 0)  # stopped and reaped, not orphaned
    assert "stopping tssac-seed0" in out
    grid = load_grid(grid_path)
    assert job_state(grid.jobs(results)[0]).status is Status.PARTIAL, "the job finished before it could be stopped"

    launches = train(grid, results, 1, report=lambda line: None)
    assert len(launches) == 1 and launches[0].resumed and "--resume" in launches[0].command
    assert launches[0].returncode == 0 and job_state(grid.jobs(results)[0]).status is Status.FINISHED
    with (run_dir / "metrics.csv").open() as fh:
        epochs = [(r["role"], r["epoch"]) for r in csv.DictReader(fh)]
    assert epochs == [(role, e) for role in ("decoy", "detect", "strike") for e in ("1", "2")]  # nothing run twice
    log = (run_dir / LOG_NAME).read_text()
    assert log.count("runner: ") == 3 and len(re.findall(r"runner: stopped after \d+ s", log)) == 1, log
    stopped, finished = read_invocations(run_dir)  # the runner recorded the first, the training the second
    assert (stopped.ended, finished.ended) == (Ended.STOPPED, Ended.FINISHED)
    assert stopped.seconds == int(re.search(r"runner: stopped after (\d+) s", log).group(1))
    assert finished.seconds == int(re.search(r"trained .* in (\d+) s", log).group(1))
    assert training_wall_s(run_dir) == stopped.seconds + finished.seconds  # the stopped invocation counts


# ------------------------------------------------------------------------------------ --finish-by


def test_finish_by_reads_a_clock_time_or_a_date_and_refuses_the_past():
    from datetime import datetime

    from tssac_core.common.cli import UsageError
    from tssac_core.experiments.deadline import parse_finish_by

    now = datetime(2026, 11, 25, 9, 30)
    assert parse_finish_by("11:45", now) == datetime(2026, 11, 25, 11, 45).timestamp()
    assert parse_finish_by("2026-11-26 08:00", now) == datetime(2026, 11, 26, 8, 0).timestamp()
    for text, message in (("09:00", "has passed"), ("7pm", "expected HH:MM"), ("25:00", "expected HH:MM")):
        with pytest.raises(UsageError, match=message):
            parse_finish_by(text, now)


def took_600_s(run: Path) -> None:
    """Make the run's recorded wall time 600 s, in one invocation."""
    (run / WALL_TIME_FILE).unlink()
    record_invocation(run, 600.0, Ended.FINISHED)


def test_finish_by_starts_a_job_only_if_the_entrys_finished_runs_say_it_ends_in_time(smoke, tmp_path):
    """tssac-seed0 took 600 s: seed 1 (new) needs 600 s, seed 2 (a third of its epochs done) 400 s; sac_lag, with no
    finished run of its own, goes by its family's (tssac's); a PPO run, with none in its family, is started."""
    from tssac_core.experiments.deadline import deadline_filter

    grid = load_grid(
        write_grid(
            tmp_path / "three.yaml",
            smoke_text(("seeds: [0]", "seeds: [0, 1, 2]"), ("  - sac_lag\n", "  - sac_lag\n  - ppo\n")),
        )
    )
    results = tmp_path / "results"
    shutil.copytree(smoke / "runs" / "tssac-seed0", results / "runs" / "tssac-seed0")
    took_600_s(results / "runs" / "tssac-seed0")
    partial = results / "runs" / "tssac-seed2"
    write_metrics(partial, [("decoy", 1, 20, 0.0)])  # the decoy's epoch, one of the three roles' one each
    (partial / "config.json").write_text(
        (results / "runs" / "tssac-seed0" / "config.json").read_text().replace('"seed": 0', '"seed": 2')
    )
    states = [job_state(j) for j in grid.jobs(results)]
    jobs = {s.job.name: s.job for s in states}
    assert (
        job_state(jobs["tssac-seed0"]).status is Status.FINISHED
        and job_state(jobs["tssac-seed2"]).status is Status.PARTIAL
    )
    clock = lambda: 1000.0  # noqa: E731
    tight, loose = deadline_filter(states, 1500.0, clock), deadline_filter(states, 1700.0, clock)
    assert not tight(jobs["tssac-seed1"]) and loose(jobs["tssac-seed1"])  # 600 s from 1000 ends at 1600
    assert tight(jobs["tssac-seed2"]) and not deadline_filter(states, 1350.0, clock)(jobs["tssac-seed2"])  # 400 s left
    assert not tight(jobs["sac_lag-seed1"]) and loose(jobs["sac_lag-seed1"])  # as tssac's 600 s
    assert tight(jobs["ppo-seed1"])  # nothing to go by: started


def test_finish_by_goes_by_a_run_that_finished_after_the_invocation_began(smoke, tmp_path):
    """Nothing had finished when the runner started, so a SAC-family job could start; once tssac-seed0
    finishes (600 s), sac_lag-seed0 goes by it."""
    from tssac_core.experiments.deadline import deadline_filter

    grid = load_grid(write_grid(tmp_path / "two.yaml", smoke_text()))
    results = tmp_path / "results"
    states = [job_state(j) for j in grid.jobs(results)]
    jobs = {s.job.name: s.job for s in states}
    may_start = deadline_filter(states, 1500.0, lambda: 1000.0)
    assert may_start(jobs["sac_lag-seed0"])  # nothing to go by yet
    shutil.copytree(smoke / "runs" / "tssac-seed0", results / "runs" / "tssac-seed0")
    took_600_s(results / "runs" / "tssac-seed0")
    assert not may_start(jobs["sac_lag-seed0"])  # 600 s from 1000 ends after 1500


def test_a_job_the_deadline_refuses_is_reported_and_not_started(tmp_path):
    from tssac_core.train.jobs.runner import run_jobs

    grid = load_grid(write_grid(tmp_path / "one.yaml", smoke_text(("  - sac_lag\n", ""))))
    states = [job_state(job) for job in grid.jobs(tmp_path / "results")]
    lines: list[str] = []
    assert run_jobs(states, 2, lines.append, may_start=lambda job: False) == []
    assert lines == ["not started tssac-seed0: it would not finish in the time given"]
    assert not (tmp_path / "results" / "runs" / "tssac-seed0").exists()


# ---------------------------------------------------------------------------------- transfer speed-up


def write_metrics(path: Path, rows: list[tuple[str, int, int, float]]) -> None:
    path.mkdir(parents=True, exist_ok=True)
    with (path / "metrics.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=METRIC_FIELDS, restval="")
        writer.writeheader()
        for role, epoch, steps, task in rows:
            writer.writerow({"role": role, "epoch": epoch, "env_steps": steps, "task_success": task})


def test_transfer_speedup(tmp_path):
    grid = load_grid(write_grid(tmp_path / "g.yaml", smoke_text(("seeds: [0]", "seeds: [0, 1]"))))
    jobs = {j.name: j for j in grid.jobs(tmp_path)}
    detect = lambda tasks: [("detect", e + 1, 100 * (e + 1), t) for e, t in enumerate(tasks)]  # noqa: E731
    write_metrics(jobs["tssac-seed0"].out, detect([0.5, 0.95, 0.2]))  # reached at 200 (later dips do not count)
    write_metrics(jobs["tssac-seed1"].out, detect([0.9, 1.0, 1.0]))  # at 100
    write_metrics(jobs["sac_lag-seed0"].out, detect([0.1, 0.3, 0.92]))  # at 300
    write_metrics(jobs["sac_lag-seed1"].out, detect([0.1, 0.3, 0.5]))  # never: counts 300, a lower bound
    assert steps_to_threshold([], "detect", 0.9) == (None, 0)
    speedup = transfer_speedup(grid, list(jobs.values()))
    result, tssac, sac_lag = (
        speedup.roles["detect"],
        speedup.roles["detect"].with_transfer,
        speedup.roles["detect"].without_transfer,
    )
    assert tssac.entry == "tssac" and tssac.per_seed == {0: 200, 1: 100} and tssac.mean_steps == 150
    assert sac_lag.per_seed == {0: 300, 1: None} and sac_lag.reached == 1 and sac_lag.counted == {0: 300, 1: 300}
    assert sac_lag.mean_steps == 300 and sac_lag.mean_is_lower_bound
    assert result.speedup == pytest.approx(2.0) and result.speedup_is_lower_bound
    assert tssac.mean_task_success.per_seed == {0: pytest.approx(0.55), 1: pytest.approx(29 / 30)}
    assert sac_lag.mean_task_success.mean == pytest.approx((1.32 / 3 + 0.9 / 3) / 2)
    data = speedup.to_json()  # experiments.json: the sides by algorithm, the seeds as strings
    assert list(data) == ["threshold", "detect", "strike"] and data["threshold"] == 0.9
    assert list(data["detect"]) == ["tssac", "sac_lag", "speedup", "speedup_is_lower_bound"]
    assert data["detect"]["sac_lag"]["per_seed"] == {"0": 300, "1": None}


def test_error_bars_stop_where_the_quantity_does():
    """mean ± std of a cost (0.5 ± 1.8) must not reach below 0, nor a rate (94 ± 9) above 100%."""
    np.testing.assert_allclose(clipped_error([0.5, 4.0], [1.8, 1.0], 0.0), [[0.5, 1.0], [1.8, 1.0]])
    np.testing.assert_allclose(
        clipped_error([94.0, 6.0, np.nan], [9.0, 0.0, 0.0], 0.0, 100.0), [[9.0, 0.0, np.nan], [6.0, 0.0, np.nan]]
    )


def algorithm_row(
    name: str,
    algo: str,
    penalty: float = 0.0,
    generalization: EvalRow | None = None,
    tail: TailRow | None = None,
    tail_monitor: TailRow | None = None,
    generalization_tail: TailRow | None = None,
) -> AlgorithmSummary:
    """A row of experiments.json with no seeds (figures None), and the evaluations given."""
    nothing = OverSeeds(None, None, {})
    row = EvalRow(nothing, nothing, nothing, CostPool(0, None, None, 0, []))
    return AlgorithmSummary(
        name, algo, penalty, [], row, nothing, None, generalization, tail, tail_monitor, generalization_tail
    )


def test_figure_12_takes_plain_sac_as_penalty_0_unless_the_grid_trains_one():
    entry = algorithm_row
    done = [
        entry("tssac", "tssac"),
        entry("sac", "sac"),
        entry("ppo", "ppo"),
        entry("p50", "sac_penalty", -50.0),
        entry("p10", "sac_penalty", -10.0),
    ]
    bars = penalty_entries(done)
    assert [(a.name, a.penalty) for a in bars] == [("sac", 0.0), ("p10", -10.0), ("p50", -50.0), ("tssac", 0.0)]
    bars = penalty_entries([*done, entry("p0", "sac_penalty", 0.0)])
    assert [a.name for a in bars] == ["p0", "p10", "p50", "tssac"]


def test_an_algorithm_row_holds_only_the_evaluations_the_grid_flies():
    """experiments.json's row: the tail columns first, then the 50-layout evaluations, those the grid does not fly
    left out (not null); the paper's figures null where the paper has none."""
    assert list(algorithm_row("sac_pen10", "sac_penalty", -10.0).to_json()) == [
        "name",
        "algo",
        "penalty",
        "seeds",
        "random",
        "training_wall_s",
        "paper",
    ]
    nothing = OverSeeds(None, None, {})
    tail = TailRow(TailPool(0, 0, None, None), [], {})
    row = algorithm_row(
        "tssac",
        "tssac",
        generalization=EvalRow(nothing, nothing, nothing, CostPool(0, None, None, 0, [])),
        tail=tail,
        tail_monitor=tail,
        generalization_tail=tail,
    ).to_json()
    assert list(row) == [
        "name",
        "algo",
        "penalty",
        "seeds",
        "tail",
        "tail_monitor",
        "generalization_tail",
        "random",
        "generalization",
        "training_wall_s",
        "paper",
    ]
    assert row["tail"] == {"missions": 0, "seeds": 0, "flown_seeds": [], "per_seed": {}} and row["paper"] is None
    assert OverSeeds(1.0, None, {2: 1.0}).to_json() == {"mean": 1.0, "std": None, "per_seed": {"2": 1.0}}


def test_transfer_experiment_figures_and_table(tmp_path):
    from tssac_core.experiments.summary import transfer_experiment
    from tssac_core.experiments.table import transfer_experiment_markdown

    text = smoke_text(
        ("seeds: [0]", "seeds: [0, 1]"),
        ("evaluation:", "transfer: {teammates: models/tssac, with: tssac, without: sac_lag, epochs: 3}\nevaluation:"),
    )
    grid = load_grid(write_grid(tmp_path / "g.yaml", text))
    jobs = {j.name: j for j in grid.transfer_jobs(tmp_path)}
    assert len(jobs) == 8 and jobs["transfer-detect-tssac-seed1"].config.epochs == 3
    write_metrics(jobs["transfer-detect-tssac-seed0"].out, [("detect", 1, 20, 0.95)])  # stopped at its first epoch
    write_metrics(jobs["transfer-detect-tssac-seed1"].out, [("detect", 1, 20, 0.5), ("detect", 2, 40, 1.0)])
    write_metrics(
        jobs["transfer-detect-sac_lag-seed0"].out, [("detect", e, 20 * e, 0.1 * e) for e in (1, 2, 3)]
    )  # never: 60, a bound
    write_metrics(jobs["transfer-detect-sac_lag-seed1"].out, [("detect", 1, 20, 0.0), ("detect", 2, 40, 0.9)])
    runs = [jobs[n] for n in jobs if "detect" in n]
    x = transfer_experiment(grid, runs)
    assert x is not None
    detect = x.per_role["detect"]
    assert (
        detect.with_transfer.per_seed == {0: 20, 1: 40}
        and detect.with_transfer.mean_steps == 30
        and not detect.with_transfer.mean_is_lower_bound
    )
    assert detect.without_transfer.per_seed == {0: None, 1: 40} and detect.without_transfer.mean_steps == 50
    assert detect.speedup == pytest.approx(50 / 30) and detect.speedup_is_lower_bound
    strike = x.per_role["strike"]
    assert strike.with_transfer.seeds == 0 and strike.speedup is None  # nothing finished yet: no figure
    assert strike.with_transfer.entry is None  # nothing to name it by
    data = x.to_json()
    assert list(data) == ["threshold", "teammates", "epochs", "steps_per_epoch", "roles", "detect", "strike"]
    assert list(data["detect"]) == ["with", "without", "speedup", "speedup_is_lower_bound"]
    lines = transfer_experiment_markdown(x)
    assert "| detect | 20, 40 | 30 | not in 60, 40 | >= 50 | >= 1.7x |" in lines
    assert "| strike | — | — | — | — | — |" in lines
    assert transfer_experiment(load_grid(SMOKE), []) is None


def evaluation(cost_limit: float, **per_episode: list) -> TeamEvaluation:
    """A cached evaluation's figures: ``per_episode`` as a cache file holds it (success all True if not given)."""
    per_episode.setdefault("success", [True] * len(per_episode["cost"]))
    return TeamEvaluation(
        success_rate=float(np.mean(per_episode["success"])),
        mean_cost=float(np.mean(per_episode["cost"])),
        episodes=len(per_episode["cost"]),
        cost_limit=cost_limit,
        backup_time_fraction=None,
        per_episode=PerEpisode.from_record(per_episode),
        success_interval95=None,
        mean_cost_interval95=None,
    )


CACHE_RUN = {"controller": "guidance", "scenario": "scenarios/random.yaml", "seed": 1, "cost_limit": 3.0}
"""What every cache file says flew it, where."""


def test_within_limit_counts_uav_missions_at_or_under_the_limit():
    # 2 missions x 3 UAVs: one long stay inside a radar (812 steps) and one cost exactly at the limit
    assert within_limit(evaluation(3.0, cost=[[0.0, 3.0, 812.0], [0.0, 0.0, 4.0]])) == 4 / 6


def test_a_cached_evaluation_is_read_with_what_it_has():
    """A 50-layout cache from before evaluations had intervals reads without them; a tail cache flown with the monitor
    gives the time under the backup and the monitor's counts per UAV-mission."""
    old = {
        "success_rate": 0.5,
        "mean_cost": 1.5,
        "episodes": 2,
        **CACHE_RUN,
        "per_episode": {"success": [True, False], "cost": [[0, 3, 0], [0, 0, 6]], "return": [[1, 2, 3]] * 2},
    }
    e = TeamEvaluation.from_record(old)
    assert e.success_interval95 is None and e.backup_time_fraction is None and e.per_episode.monitor is None
    assert e.per_episode.cost.dtype == np.float64 and e.per_episode.returns.shape == (2, 3)
    assert e.per_episode.success.tolist() == [True, False] and e.per_episode.out_of_area is None
    tail = {
        **old,
        "success_interval95": [0.1, 0.9],
        "mean_cost_interval95": [0.0, 3.0],
        "shield": {
            "interventions_per_uav_mission": 1 / 3,
            "max_interventions_per_uav_mission": 1,
            "max_switches_per_uav_mission": 2,
            "backup_time_fraction": 0.25,
            "unprotected_time_fraction": 0.0,
            "uav_missions_with_cost": 2,
            "uavs_left_area": 0,
            "roles": {"decoy": {"interventions_per_mission": 1.0, "backup_time_fraction": 0.25}},
        },
    }
    tail["per_episode"] = {
        **old["per_episode"],
        "out_of_area": [[False] * 3] * 2,
        "backup_steps": [[1, 0, 0]] * 2,
        "flown_steps": [[4, 4, 4]] * 2,
        "interventions": [[1, 0, 0]] * 2,
    }
    del tail["per_episode"]["return"]
    t = TeamEvaluation.from_record(tail)
    assert t.success_interval95 == (0.1, 0.9) and t.mean_cost_interval95 == (0.0, 3.0)
    assert t.backup_time_fraction == 0.25 and t.per_episode.returns is None
    assert t.per_episode.monitor is not None and t.per_episode.monitor.flown_steps.sum() == 24


def test_a_damaged_cache_with_the_right_key_is_flown_again_not_a_crash(tmp_path):
    spec = EvalSpec(EvalLabel.RANDOM, ROOT / "scenarios" / "short.yaml", 2, 12345)
    cache = tmp_path / spec.cache_name()
    whole = {
        "success_rate": 0.5,
        "mean_cost": 0.0,
        "episodes": 2,
        **CACHE_RUN,
        "cache_key": cache_key(None, spec),
        "per_episode": {"success": [True, False], "cost": [[0.0] * 3] * 2},
    }
    cache.write_text(json.dumps(whole))
    assert cached(None, spec, cache) is not None
    for damage in ({"episodes": "two"}, {"success_interval95": [0.1]}, {"roles": {"decoy": {"speed": 1.0}}}):
        cache.write_text(json.dumps({**whole, **damage}))
        assert cached(None, spec, cache) is None, damage
    for lost in ("episodes", "controller"):  # a figure, or what flew it
        cache.write_text(json.dumps({k: v for k, v in whole.items() if k != lost}))
        assert cached(None, spec, cache) is None, lost


def test_pooled_cost_interval_spans_the_mean_and_counts_the_missions_over_the_limit():
    # two seeds of 50 missions: all at 0 but one UAV 812 steps inside a radar, and one at exactly the limit
    quiet = evaluation(3.0, cost=[[0.0, 0.0, 0.0]] * 50)
    tail = evaluation(3.0, cost=[[0.0, 0.0, 812.0], [0.0, 3.0, 0.0]] + [[0.0, 0.0, 0.0]] * 48)
    c = pooled_cost([quiet, tail])
    assert c.uav_missions == 300 and c.mean == pytest.approx(815 / 300)
    assert c.over_limit == 1 and c.largest == [812.0, 3.0, 0.0]
    assert c.ci95 is not None
    low, high = c.ci95
    assert low == 0.0 < 3.0 < c.mean * 2 < high  # one mission in a hundred: the interval reaches 0 and spans C
    assert pooled_cost([quiet]).ci95 == (0.0, 0.0) and pooled_cost([]).mean is None
    assert pooled_cost([]).to_json() == {"uav_missions": 0, "mean": None, "ci95": None, "over_limit": 0, "largest": []}


@pytest.mark.slow
def test_the_tail_is_flown_only_where_its_cache_is_missing_or_stale(smoke, tmp_path, capsys):
    """--cached-tail reports what is cached and says which rows lack it; a plain report flies what is missing, and an
    evaluation cached under another layout rule (before every mission had its own seed) is flown again."""
    results = tmp_path / "results"
    shutil.copytree(smoke, results)
    run_dir = results / "runs" / "tssac-seed0"
    for label in ("tail", "tail_monitor", "generalization_tail"):
        (run_dir / f"eval_{label}.json").unlink()
    other = results / "runs" / "sac_lag-seed0" / "eval_tail.json"
    stale = json.loads(other.read_text())
    del stale["cache_key"]["layouts"]
    other.write_text(json.dumps(stale))
    assert main(["--grid", "experiments/smoke.yaml", "--results", str(results), "--report-only", "--cached-tail"]) == 0
    out = capsys.readouterr().out
    assert "tssac-seed0: not cached, left out (--cached-tail)" in out and "sac_lag-seed0: not cached" in out
    assert not (run_dir / "eval_tail.json").exists() and json.loads(other.read_text()) == stale  # nothing flown
    assert not (run_dir / "eval_generalization_tail.json").exists()  # a tail too
    table = (results / "table4.md").read_text()
    gen_rows = table.split("## 3 layouts of the generalisation scenario")[1].splitlines()
    assert "| tssac | — | — | — | none | — | — | — | — | — | — |" in gen_rows and any(
        row.startswith("| sac_lag | ") and "| 0 | 0: " in row for row in gen_rows
    )
    rows = [line for line in (results / "table4.md").read_text().splitlines() if line.startswith("| tssac | ")]
    assert [cell.strip() for cell in rows[0].split("|")].count("—") >= 6 and rows[1].startswith(
        "| tssac | none | — |"
    )  # the columns, then the tail table
    data = json.loads((results / "experiments.json").read_text())
    assert data["algorithms"][0]["tail"]["missions"] == 0 and data["algorithms"][1]["tail_monitor"]["missions"] == 3
    assert [a["generalization_tail"]["missions"] for a in data["algorithms"]] == [0, 3]
    assert main(["--grid", "experiments/smoke.yaml", "--results", str(results), "--report-only"]) == 0
    assert "tssac-seed0: success " in capsys.readouterr().out
    assert "layouts" in json.loads(other.read_text())["cache_key"] and (run_dir / "eval_tail_monitor.json").is_file()
    assert (run_dir / "eval_generalization_tail.json").is_file()
    assert (
        "layouts" not in json.loads((run_dir / "eval_random.json").read_text())["cache_key"]
    )  # Table 4's: drawn in turn
    caches = {p: p.stat().st_mtime_ns for p in results.glob("runs/*/eval_*tail*.json")}
    assert main(["--grid", "experiments/smoke.yaml", "--results", str(results), "--report-only"]) == 0
    assert {p: p.stat().st_mtime_ns for p in caches} == caches and len(
        caches
    ) == 6  # all cached now: nothing flown again


def test_table4_keeps_its_layouts_and_the_tail_draws_each_mission_from_its_own_seed(random_path):
    from tssac_core.experiments.evaluations import layouts_in_turn
    from tssac_core.sim.missions import mission_layout
    from tssac_core.sim.scenario import load

    s = load(random_path)
    in_turn = layouts_in_turn(s, 3, 12345)  # the 50 layouts every earlier Table 4 flew: one generator, drawn in turn
    again = layouts_in_turn(s, 3, 12345)
    assert all(np.array_equal(a.sam_km, b.sam_km) for a, b in zip(in_turn, again))
    assert np.array_equal(
        in_turn[0].sam_km, mission_layout(s, 12345, 0).sam_km
    )  # the first layout is the same either way,
    assert not np.array_equal(in_turn[1].sam_km, mission_layout(s, 12345, 1).sam_km)  # the others are not


def test_pooled_tail_pools_the_seeds_missions_with_wilson_and_bootstrap_intervals():
    # two seeds of 4 missions: 7 of 8 hit the target; one UAV 812 steps inside a radar, one at exactly C = 3
    one = dict(
        success=[True] * 4,
        cost=[[0.0, 0.0, 0.0]] * 3 + [[0.0, 3.0, 0.0]],
        out_of_area=[[False] * 3] * 4,
    )
    two = dict(
        success=[True, True, True, False],
        cost=[[0.0, 0.0, 812.0]] + [[0.0] * 3] * 3,
        out_of_area=[[False] * 3] * 3 + [[False, False, True]],
    )
    pool = pooled_tail([evaluation(3.0, **one), evaluation(3.0, **two)])
    t = pool.to_json()
    assert (t["missions"], t["seeds"], t["success_rate"]) == (8, 2, 7 / 8)
    lo, hi = t["success_interval95"]  # Wilson, by hand: (p + z^2/2n -+ z sqrt(p(1-p)/n + z^2/4n^2)) / (1 + z^2/n)
    z = 1.959963984540054
    centre, half = (7 / 8 + z * z / 16) / (1 + z * z / 8), z * np.sqrt(7 / 8 / 8 / 8 + z * z / 256) / (1 + z * z / 8)
    assert (lo, hi) == (pytest.approx(centre - half), pytest.approx(centre + half)) and lo == pytest.approx(
        0.5291, abs=1e-4
    )
    assert (
        t["mean_cost"] == pytest.approx(815 / 24)
        and t["mean_cost_interval95"][0] == 0.0 < 3.0 < t["mean_cost_interval95"][1]
    )
    assert t["within_cost_limit"] == 23 / 24 and t["over_limit"] == 1 and t["largest"] == [812.0, 3.0, 0.0]
    assert t["within_cost_limit_per_role"] == {"decoy": 1.0, "detect": 1.0, "strike": 7 / 8}  # 3.0 is within C
    assert t["cvar95_cost"] == (812 + 3) / 2 and t["left_area"] == 1  # CVaR95: the mean of the worst ceil(5% of 24) = 2
    assert "backup_time_fraction" not in t and pool.monitor is None
    assert pooled_tail([]).to_json() == {"missions": 0, "seeds": 0} and _tail_rate(pooled_tail([]), 3) == "—"
    for e, backup in ((one, [[10, 0, 0]] * 4), (two, [[0, 0, 0]] * 4)):  # with the monitor: the time under the backup
        e.update(backup_steps=backup, flown_steps=[[100, 100, 100]] * 4, interventions=[[1, 0, 0]] * 4)
    pool = pooled_tail([evaluation(3.0, **one), evaluation(3.0, **two)])
    t = pool.to_json()
    assert t["backup_time_fraction"] == 40 / 2400 and t["interventions_per_uav_mission"] == 8 / 24
    assert list(t)[-2:] == ["backup_time_fraction", "interventions_per_uav_mission"]
    assert _tail_rate(pool, 3) == "87.5% (52.9-97.8) [2 of 3 seeds]" and _tail_rate(pool, 2) == "87.5% (52.9-97.8)"


def test_the_cascade_counts_each_roles_task_among_the_missions_the_role_before_it_finished():
    """A cache's per-role task rates come back as counts, pool over seeds, and each role's share is taken of the
    missions in which the role before it finished (the tasks nest, eq. 9), with its Wilson interval."""

    def cached(rates: tuple[float, float, float], success: list[bool]) -> TeamEvaluation:
        record = {
            "success_rate": float(np.mean(success)),
            "mean_cost": 0.0,
            "episodes": len(success),
            **CACHE_RUN,
            "roles": {role: {"task_success_rate": r} for role, r in zip(("decoy", "detect", "strike"), rates)},
            "per_episode": {"success": success, "cost": [[0.0] * 3] * len(success), "out_of_area": [[False] * 3] * 4},
        }
        return TeamEvaluation.from_record(record)

    one = cached((1.0, 0.75, 0.5), [True, True, False, False])  # 0.75 x 4 missions: 3, read back as a count
    two = cached((0.5, 0.25, 0.0), [False] * 4)
    assert one.tasks_finished == {"decoy": 4, "detect": 3, "strike": 2}
    pool = pooled_tail([one, two])
    assert pool.figures is not None and pool.figures.tasks_finished == {"decoy": 6, "detect": 4, "strike": 2}
    row = cascade_row("tssac", pool)
    w = wilson_interval(4, 6)  # the detect UAV's share: of the 6 missions whose decoy finished, not of all 8
    assert f"| {100 * w.value:.1f}% ({100 * w.low:.1f}-{100 * w.high:.1f}; 4 of 6) |" in row
    assert row.startswith("| tssac | 75.0% (") and "; 6 of 8) |" in row and "; 2 of 4) | 25.0% (" in row
    assert cascade_row("sac", pooled_tail([evaluation(3.0, cost=[[0.0] * 3], out_of_area=[[False] * 3])])) == (
        "| sac | — | — | — | — |"
    )  # a cache from before the per-role figures


def test_training_wall_time_sums_the_invocations_that_finished_or_the_runner_stopped(tmp_path):
    assert training_wall_s(tmp_path) is None  # nothing recorded
    (tmp_path / "train.log").write_text("trained decoy, detect, strike with tssac (seed 0) in 412 s; results in r\n")
    assert training_wall_s(tmp_path) is None  # a log is not read
    record_invocation(tmp_path, 99.5, Ended.STOPPED)  # whole seconds, as train.log prints them (99.5 -> 100)
    record_invocation(tmp_path, 412.4, Ended.FINISHED)
    record_invocation(tmp_path, 87.6, Ended.FINISHED)
    assert read_invocations(tmp_path) == [
        Invocation(100, Ended.STOPPED),
        Invocation(412, Ended.FINISHED),
        Invocation(88, Ended.FINISHED),
    ]
    assert training_wall_s(tmp_path) == 600.0
    assert json.loads((tmp_path / WALL_TIME_FILE).read_text())["invocations"][0] == {"seconds": 100, "ended": "stopped"}


def test_an_invocation_keeps_its_time_up_to_date_and_a_killed_one_still_counts(tmp_path):
    """A training invocation opens a running record and updates it every epoch; the next invocation finds it running
    (killed without a record of its end) and keeps its seconds as killed; a finish or the runner's stop closes the
    running record instead of adding one."""
    begin_invocation(tmp_path)
    record_invocation(tmp_path, 40.2, Ended.RUNNING)  # after an epoch
    record_invocation(tmp_path, 80.4, Ended.RUNNING)  # after the next; then a kill -9
    begin_invocation(tmp_path)
    assert read_invocations(tmp_path) == [Invocation(80, Ended.KILLED), Invocation(0, Ended.RUNNING)]
    record_invocation(tmp_path, 30.0, Ended.RUNNING)
    record_invocation(tmp_path, 55.0, Ended.STOPPED)  # the runner stops it, with its own count
    begin_invocation(tmp_path)
    record_invocation(tmp_path, 12.0, Ended.FINISHED)
    assert read_invocations(tmp_path) == [
        Invocation(80, Ended.KILLED),
        Invocation(55, Ended.STOPPED),
        Invocation(12, Ended.FINISHED),
    ]
    assert training_wall_s(tmp_path) == 147.0
