"""Presets (tssac_core.train.preset): one recipe file for the training command and the grid."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tssac_core.common.cli import run
from tssac_core.experiments.grid import load_grid
from tssac_core.train.arguments import parse_args
from tssac_core.train.cli import main
from tssac_core.train.jobs.runner import config_difference

ROOT = Path(__file__).resolve().parent.parent


def test_a_preset_sets_the_defaults_and_the_command_line_wins(tmp_path: Path):
    preset = tmp_path / "p.yaml"
    preset.write_text(
        "epochs: 7\nenvs: 3\nroles: [decoy, detect]\nset: {gamma: 0.9}\n"
        "sac_set: {hidden_sizes: [8, 8], lr: 0.01}\nonpolicy_set: {hidden_sizes: [4, 4]}\n"
    )
    cfg, _, _, _ = parse_args(["--preset", str(preset), "--out", "x"])
    assert (cfg.epochs, cfg.envs, cfg.roles) == (7, 3, ("decoy", "detect"))
    assert cfg.learner == {"gamma": 0.9, "hidden_sizes": [8, 8], "lr": 0.01}
    cfg, _, _, _ = parse_args(
        ["--preset", str(preset), "--epochs", "2", "--set", "lr=0.5", "--algo", "ppo", "--out", "x"]
    )
    assert cfg.epochs == 2 and cfg.envs == 3
    assert cfg.learner == {"gamma": 0.9, "hidden_sizes": [4, 4], "lr": 0.5}  # the on-policy family's settings


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("epoch: 3\n", "epoch: unknown key"),
        ("epochs: three\n", "epochs: expected an integer"),
        ("sac_set: 3\n", "sac_set: expected a mapping"),
        ("[1, 2]\n", "expected a mapping of training settings"),
    ],
)
def test_a_bad_preset_is_one_line(tmp_path: Path, capsys, text: str, message: str):
    preset = tmp_path / "p.yaml"
    preset.write_text(text)
    assert run(main, ["--preset", str(preset), "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and message in err and str(preset) in err
    assert not (tmp_path / "run").exists()


def test_the_grid_reads_the_same_preset(tmp_path: Path, monkeypatch):
    """experiments/paper.yaml takes its recipe from configs/paper.yaml: a job's config is the single run's
    with that preset, and the grid file's own keys win over the preset's."""
    monkeypatch.chdir(ROOT)
    grid = load_grid(ROOT / "experiments" / "paper.yaml")
    job = next(j for j in grid.jobs(tmp_path) if j.entry.name == "sac_lag" and j.seed == 1)
    single, _, _, _ = parse_args(["--preset", "configs/paper.yaml", "--algo", "sac_lag", "--seed", "1", "--out", "x"])
    assert job.config == single
    ppo = next(j for j in grid.jobs(tmp_path) if j.entry.algo == "ppo")
    assert ppo.config.learner == {"hidden_sizes": [128, 128], "gamma": 0.995}
    text = (ROOT / "experiments" / "smoke.yaml").read_text()
    assert "preset" not in text  # a grid may still carry its whole recipe inline
    own = tmp_path / "g.yaml"
    own.write_text(
        (ROOT / "experiments" / "paper.yaml")
        .read_text()
        .replace("  preset: configs/paper.yaml", "  preset: configs/paper.yaml\n  epochs: 3")
    )
    assert load_grid(own).train.epochs == 3


@pytest.mark.parametrize(
    ("preset", "extra", "seed", "recorded"),
    [
        ("configs/grid-tssac-seed2.yaml", [], 2, "results/runs/tssac-seed2/config.json"),
        ("configs/safe.yaml", [], 1, "models/tssac/config.json"),
        *[("configs/safe.yaml", [], s, f"results/recipe-trials/hard50/seed{s}/config.json") for s in (0, 1, 2)],
        *[
            (
                "configs/safe.yaml",
                ["--hard-layouts", "0"],
                s,
                f"results/recipe-trials/layouts4x-tail995/seed{s}/config.json",
            )
            for s in (0, 1, 2)
        ],
    ],
)
def test_each_recipe_file_gives_the_configuration_of_the_runs_it_names(
    preset: str, extra: list[str], seed: int, recorded: str
):
    """A preset that drifted from the runs it documents (a default changed, a key dropped) would reproduce something
    else: the whole configuration must match what those runs recorded (the earlier trial: with its one flag)."""
    cfg, *_ = parse_args(["--preset", str(ROOT / preset), *extra, "--seed", str(seed), "--out", "r"])
    assert config_difference(json.loads((ROOT / recorded).read_text()), cfg) == ""


RECIPE_ROWS = [
    # (row of algos, its seed, the CLI's flags, a run that recorded this configuration)
    ("{preset: configs/paper.yaml, algo: sac_lag, name: r}", 1, ["--algo", "sac_lag"], "results/runs/sac_lag-seed1"),
    ("{preset: configs/paper.yaml, algo: ppo, name: r}", 0, ["--algo", "ppo"], "results/runs/ppo-seed0"),
    ("{preset: configs/safe.yaml, name: r}", 1, [], "models/tssac"),
    ("{preset: configs/safe.yaml, name: r, hard_layouts: 0}", 2, ["--hard-layouts", "0"], None),
    ("{preset: configs/grid-tssac-seed2.yaml, name: r}", 2, [], "results/runs/tssac-seed2"),
]


@pytest.mark.parametrize(("row", "seed", "flags", "recorded"), RECIPE_ROWS)
def test_any_preset_is_a_grid_row_whose_job_is_the_single_runs_config(
    tmp_path: Path, monkeypatch, row: str, seed: int, flags: list[str], recorded: str | None
):
    """A row naming a preset trains exactly ``train --preset P --seed N`` (the grid's ``train:`` does not leak
    in), which is what the committed runs of that recipe recorded; and the file the runner hands the job holds
    that configuration, read back as the run will."""
    from tssac_core.train.arguments import parse_cli
    from tssac_core.train.config import config_record, with_recorded_defaults
    from tssac_core.train.jobs.runner import JOB_CONFIG, command

    monkeypatch.chdir(ROOT)
    text = (ROOT / "experiments" / "smoke.yaml").read_text().replace("  - sac_lag\n", f"  - {row}\n")
    grid = load_grid(write(tmp_path / "g.yaml", text.replace("seeds: [0]", f"seeds: [{seed}]")))
    job = next(j for j in grid.jobs(tmp_path) if j.entry.name == "r")
    cli, *_ = parse_args(
        ["--preset", row.split("preset: ")[1].split(",")[0], *flags, "--seed", str(seed), "--out", "x"]
    )
    assert job.config == cli
    if recorded is not None:
        assert config_difference(json.loads((ROOT / recorded / "config.json").read_text()), job.config) == ""
    cmd = command(job, resume=False)
    assert cmd[3:] == ("--config", str(job.out / JOB_CONFIG), "--out", str(job.out), "--no-progress")
    job.out.mkdir(parents=True)
    (job.out / JOB_CONFIG).write_text(json.dumps(config_record(job.config)))
    child, out, resume, *_ = parse_cli(list(cmd[3:]))
    assert child == with_recorded_defaults(cli) and out == job.out and not resume


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


@pytest.mark.parametrize(
    ("row", "message"),
    [
        ("{preset: configs/nowhere.yaml}", "algos[1].preset: configs/nowhere.yaml: cannot read file"),
        ("{preset: configs/safe.yaml, seed: 3}", "algos[1].seed: a row's seeds are the grid's"),
        ("{preset: configs/safe.yaml, epochs: 0}", "algos[1].epochs: must be >= 1, got 0"),
        ("{algo: tssac, name: t2, hard_layouts: 2}", "algos[1].hard_layouts: expected a fraction in [0, 1], got 2"),
    ],
)
def test_a_bad_preset_row_is_one_line(tmp_path: Path, monkeypatch, capsys, row: str, message: str):
    from tssac_core.experiments.cli import main as grid_main

    monkeypatch.chdir(ROOT)
    text = (ROOT / "experiments" / "smoke.yaml").read_text().replace("  - sac_lag\n", f"  - {row}\n")
    grid = write(tmp_path / "g.yaml", text)
    assert run(grid_main, ["--grid", str(grid), "--results", str(tmp_path / "r"), "--dry-run"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith(f"error: {grid}: ") and message in err, err


@pytest.mark.parametrize(
    ("value", "problem"),
    [
        ("many", "expected an integer, got 'many'"),
        ("true", "expected an integer, got True"),
        ("2.5", "expected an integer, got 2.5"),
        ("10000000000", "out of range: 10000000000 (numbers are at most 1e+09 in size)"),
    ],
)
def test_scenario_preset_and_grid_word_a_bad_value_alike(tmp_path: Path, monkeypatch, value: str, problem: str):
    """One reader judges a value in all three file kinds (tssac_core.sim.yaml_file.typed_value): the same bad
    integer gets the same words in a scenario's ``episode_steps``, a preset's ``epochs`` and a grid's
    ``evaluation.episodes``."""
    from tssac_core.experiments.grid import GridError
    from tssac_core.sim.scenario import ScenarioError, load
    from tssac_core.train.preset import PresetError, load_preset

    monkeypatch.chdir(ROOT)
    scenario = (ROOT / "scenarios" / "strike.yaml").read_text()
    assert "episode_steps:" in scenario
    lines = [f"episode_steps: {value}" if ln.startswith("episode_steps:") else ln for ln in scenario.splitlines()]
    grid = (ROOT / "experiments" / "smoke.yaml").read_text()
    assert "  episodes: 2" in grid
    cases = [
        (ScenarioError, lambda: load(write(tmp_path / "s.yaml", "\n".join(lines) + "\n")), "episode_steps"),
        (PresetError, lambda: load_preset(write(tmp_path / "p.yaml", f"epochs: {value}\n")), "epochs"),
        (
            GridError,
            lambda: load_grid(write(tmp_path / "g.yaml", grid.replace("  episodes: 2", f"  episodes: {value}"))),
            "evaluation.episodes",
        ),
    ]
    for error, read, where in cases:
        with pytest.raises(error) as info:
            read()
        assert str(info.value).endswith(f"{where}: {problem}"), str(info.value)


def test_a_preset_number_must_be_finite(tmp_path: Path):
    from tssac_core.train.preset import PresetError, load_preset

    with pytest.raises(PresetError, match=r"route_margin_km: expected a finite number, got nan"):
        load_preset(write(tmp_path / "p.yaml", "route_margin_km: .nan\n"))
