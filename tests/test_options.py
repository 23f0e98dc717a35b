"""One schema per configuration (tssac_core.common.options): a training option's range, choices and rules are written
once, in TrainConfig, and every front end refuses the same bad value with the same problem, naming the option its own
way: the command line (``--flag: problem``), a preset file and a grid row (``where.field: problem``), a run's
config.json (``file: field: problem``)."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import pytest

from tssac_core.common.cli import run
from tssac_core.common.options import OptionError, add_flags, check_field, flag_name, options
from tssac_core.experiments.cli import main as grid_main
from tssac_core.train.cli import main as train_main
from tssac_core.train.config import TrainConfig, config_record

ROOT = Path(__file__).resolve().parent.parent

CASES = [
    # (settings as YAML/JSON values, the option that refuses them, its problem)
    ({"hard_layouts": 1.5}, "hard_layouts", "expected a fraction in [0, 1], got 1.5"),
    ({"epochs": 0}, "epochs", "must be >= 1, got 0"),
    ({"action_repeat": 20000}, "action_repeat", "expected a value in [1, 10000], got 20000"),
    ({"vary_turn_noise_deg_s": 91.0}, "vary_turn_noise_deg_s", "expected a value in [0, 90], got 91"),
    ({"vary_nominal_fraction": 1.5}, "vary_nominal_fraction", "expected a fraction in [0, 1], got 1.5"),
    ({"roles": ["strike", "foo"]}, "roles", "unknown role 'foo' (the roles: decoy, detect, strike)"),
    ({"roles": ["strike", "decoy"]}, "roles", "must follow the curriculum order decoy, detect, strike"),
    ({"observation": "pixels"}, "observation", "expected one of paper, extended, route, got 'pixels'"),
    # Rules between fields:
    ({"vary_wind_m_s": 5.0}, "vary_wind_m_s", "varies the airframes of airframe_response (--airframe-response)"),
    ({"vary_nominal_fraction": 0.5}, "vary_nominal_fraction", "varies the airframes of airframe_response"),
    ({"algo": "tssac", "penalty": -10.0}, "penalty", "only sac_penalty takes a penalty, not tssac"),
    ({"algo": "ppo", "init_from": "models/tssac/decoy.pt"}, "init_from", "ppo trains every role from scratch"),
]


def flags(settings: dict) -> list[str]:
    argv: list[str] = []
    for key, value in settings.items():
        argv += [flag_name(key), ",".join(value) if isinstance(value, list) else str(value)]
    return argv


def one_error_line(capsys) -> str:
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "Traceback" not in err, err
    return err


@pytest.mark.parametrize(("settings", "field", "problem"), CASES)
def test_every_front_end_refuses_a_bad_value_with_the_same_line(
    tmp_path: Path, monkeypatch, capsys, settings: dict, field: str, problem: str
) -> None:
    monkeypatch.chdir(ROOT)
    seen = []
    # The command line.
    if field != "observation":  # argparse refuses a word that is no choice itself (exit 2, its own line)
        assert run(train_main, ["--out", str(tmp_path / "run"), "--no-progress", *flags(settings)]) == 2
        seen.append(one_error_line(capsys))
        assert f"{flag_name(field)}: {problem}" in seen[-1]
    # A preset file, read by the command (a field's own problem is found reading the file; a rule between fields
    # when the command builds its configuration).
    preset = tmp_path / "p.yaml"
    preset.write_text(json.dumps(settings))
    assert run(train_main, ["--preset", str(preset), "--out", str(tmp_path / "run"), "--no-progress"]) == 2
    seen.append(one_error_line(capsys))
    assert f"{field}: {problem}" in seen[-1]
    # A grid row.
    text = (ROOT / "experiments" / "smoke.yaml").read_text()
    grid = tmp_path / "g.yaml"
    grid.write_text(text.replace("  - sac_lag\n", f"  - {json.dumps({'name': 'r', 'algo': 'sac', **settings})}\n"))
    assert run(grid_main, ["--grid", str(grid), "--results", str(tmp_path / "r"), "--dry-run"]) == 2
    seen.append(one_error_line(capsys))
    assert f"algos[1].{field}: {problem}" in seen[-1] or f"algos[1]: {field}: {problem}" in seen[-1], seen[-1]
    # A run's config.json, started as the grid starts its jobs.
    config = tmp_path / "config.json"
    config.write_text(json.dumps({**config_record(TrainConfig()), **settings}))
    assert run(train_main, ["--config", str(config), "--out", str(tmp_path / "job"), "--no-progress"]) == 2
    seen.append(one_error_line(capsys))
    assert f"{config}: {field}: {problem}" in seen[-1]
    assert not (tmp_path / "run").exists() and not (tmp_path / "job").exists()  # refused before any work


def test_the_issues_grid_row_is_refused_by_the_dry_run(tmp_path: Path, monkeypatch, capsys) -> None:
    """The grid that passed ``--dry-run`` with an unknown role (issue 60)."""
    monkeypatch.chdir(ROOT)
    text = (ROOT / "experiments" / "smoke.yaml").read_text()
    grid = tmp_path / "g.yaml"
    grid.write_text(text.replace("  - sac_lag\n", "  - {algo: sac_lag, roles: [strike, foo]}\n"))
    assert run(grid_main, ["--grid", str(grid), "--results", str(tmp_path / "r"), "--dry-run"]) == 2
    assert "algos[1].roles: unknown role 'foo'" in one_error_line(capsys)


def test_the_flags_are_the_fields_with_their_defaults_and_help() -> None:
    parser = argparse.ArgumentParser()
    add_flags(parser, TrainConfig, {"epochs": 25})
    parsed = parser.parse_args(["--roles", "detect,strike", "--hard-layouts", "0.5", "--scenario", "./scenarios/x"])
    assert parsed.roles == ("detect", "strike") and parsed.hard_layouts == 0.5 and parsed.scenario == "scenarios/x"
    assert parsed.epochs == 25 and parsed.seed == 0 and parsed.selection is None  # a preset's value, else the field's
    text = parser.format_help()
    assert "epochs per role (Table 3: 50) (default: 25)" in text.replace("\n", " ").replace("  ", " ")
    declared = set(options(TrainConfig))
    assert declared == {a.dest for a in parser._actions} - {"help"}
    assert declared == {f for f in TrainConfig.__dataclass_fields__} - {"learner"}


def test_a_value_outside_its_option_is_an_option_error_naming_the_field() -> None:
    assert check_field(TrainConfig, "hard_layouts", 1.0) == 1.0
    for name, value in (("hard_layouts", float("nan")), ("seed", -1), ("envs", True), ("epochs", "5")):
        with pytest.raises(OptionError) as caught:
            check_field(TrainConfig, name, value)
        assert caught.value.field == name
    with pytest.raises(OptionError, match="threads: must be >= 1"):
        TrainConfig(threads=0)
