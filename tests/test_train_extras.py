"""The training command's extras: live TensorBoard scalars, and what Ctrl-C says."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import pytest

from tssac_core.common.cli import EXIT_INTERRUPTED, run
from tssac_core.sim.scenario import Role
from tssac_core.train import loop
from tssac_core.train.cli import main
from tssac_core.train.rundir import MetricsRow
from tssac_core.train.tensorboard import scalars

TINY = [
    "--roles",
    "decoy",
    "--epochs",
    "2",
    "--validation-episodes",
    "2",
    "--steps-per-epoch",
    "200",
    "--start-steps",
    "100",
    "--update-after",
    "100",
    "--envs",
    "2",
    "--set",
    "hidden_sizes=[32,32]",
    "--set",
    "batch_size=32",
    "--no-progress",
]


def test_scalars_name_the_role_and_leave_out_what_an_epoch_lacks():
    row = MetricsRow(Role.DETECT, {"epoch": 3, "return": -12.5, "beta": 0.4, "xi": math.nan, "val_cost": 1.0, "x": 2})
    assert scalars(row) == {"detect/return": -12.5, "detect/multiplier/beta": 0.4, "detect/validation/cost": 1.0}


def test_tensorboard_gets_every_epochs_row(tmp_path):
    """(tensorboard is in the dev extra: without it this fails rather than skips.)"""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    out, board = tmp_path / "run", tmp_path / "tb"
    # On scenarios/short.yaml with decisions of 1 s (as the shipped team): every world's 60-decision episode ends
    # within an epoch of 100 decisions each.
    short = str(Path(__file__).resolve().parent.parent / "scenarios" / "short.yaml")
    argv = ["--algo", "tssac", "--seed", "1", "--out", str(out), "--tensorboard", str(board), *TINY]
    assert main([*argv, "--scenario", short, "--action-repeat", "10", "--steps-per-epoch", "200"]) == 0
    events = EventAccumulator(str(board))
    events.Reload()
    tags = set(events.Tags()["scalars"])
    for tag in (
        "return",
        "cost",
        "multiplier/beta",
        "multiplier/xi",
        "multiplier/beta_minus_xi",
        "loss/q_r",
        "loss/actor",
        "validation/mission_success",
    ):
        assert f"decoy/{tag}" in tags
    with (out / "metrics.csv").open() as fh:
        rows = list(csv.DictReader(fh))
    logged = events.Scalars("decoy/return")
    assert [e.step for e in logged] == [1, 2]
    assert [e.value for e in logged] == pytest.approx([float(r["return"]) for r in rows], rel=1e-6)
    betas = [e.value for e in events.Scalars("decoy/multiplier/beta")]
    assert betas == pytest.approx([float(r["beta"]) for r in rows], rel=1e-6, abs=1e-7)


def test_tensorboard_missing_is_one_line(tmp_path, capsys, monkeypatch):
    import importlib.util

    real = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec", lambda name, *a: None if name == "tensorboard" else real(name, *a))
    code = run(main, ["--out", str(tmp_path / "r"), "--tensorboard", str(tmp_path / "tb")])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and "pip install -e '.[tensorboard]'" in err[0]


def test_ctrl_c_prints_the_command_that_resumes(tmp_path, capsys, monkeypatch):
    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(loop, "train_role", interrupted)
    out = tmp_path / "my run"
    assert run(main, ["--out", str(out), *TINY]) == EXIT_INTERRUPTED
    err = capsys.readouterr().err
    assert f"python -m tssac_core.train --out '{out}' --resume" in err
    assert (out / "config.json").is_file()  # what --resume reads


def test_ctrl_c_before_anything_was_saved(tmp_path, capsys, monkeypatch):
    from tssac_core.train import rundir

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(rundir, "prepare_run", interrupted)
    assert run(main, ["--out", str(tmp_path / "r"), *TINY]) == EXIT_INTERRUPTED
    assert "run the same command again" in capsys.readouterr().err
    assert not Path(tmp_path / "r" / "config.json").exists()
