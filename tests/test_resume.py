"""Resume after damage (tssac_core.train.resume): a truncated resume state or best-epoch checkpoint costs at most
one epoch and never a traceback, nothing unreadable ships, and a damaged shipped file is not "finished"."""

from __future__ import annotations

import csv
import json
import shutil
from pathlib import Path

import pytest
from tiny_training import tiny_args

from tssac_core.common.cli import run
from tssac_core.deploy.policy import Policy, read_checkpoint
from tssac_core.train.cli import main

# One test process runs this file: its module fixture is built once.
pytestmark = pytest.mark.xdist_group("test_resume")

TINY = [*tiny_args(epochs=None, validation=2), "--seed", "2", "--action-repeat", "10"]


def epochs(out: Path) -> list[int]:
    with (out / "metrics.csv").open() as fh:
        return [int(r["epoch"]) for r in csv.DictReader(fh)]


def truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


@pytest.fixture(scope="module")
def two_epochs(tmp_path_factory) -> Path:
    """A finished 2-epoch run, with its resume states (epoch 2, and epoch 1 kept as the previous one)."""
    out = tmp_path_factory.mktemp("resume") / "run"
    assert main([*TINY, "--epochs", "2", "--out", str(out)]) == 0
    assert (out / "resume" / "decoy.pt").is_file() and (out / "resume" / "decoy.prev.pt").is_file()
    return out


def unfinished_copy(src: Path, dst: Path, epochs: int) -> Path:
    """``src`` as if killed after its last epoch, in a run that asks for ``epochs``."""
    shutil.copytree(src, dst)
    for name in ("decoy.pt", "decoy.npz"):
        (dst / name).unlink()
    config = json.loads((dst / "config.json").read_text())
    (dst / "config.json").write_text(json.dumps({**config, "epochs": epochs}))
    return dst


def test_a_truncated_resume_state_falls_back_one_epoch(two_epochs: Path, tmp_path: Path, caplog):
    out = unfinished_copy(two_epochs, tmp_path / "cut", epochs=3)
    truncate(out / "resume" / "decoy.pt")
    assert run(main, ["--out", str(out), "--resume", "--no-progress"]) == 0
    passed_over = [r.getMessage() for r in caplog.records if "not readable" in r.getMessage()]
    assert len(passed_over) == 1 and "decoy.pt: not readable" in passed_over[0]  # one line, once
    assert epochs(out) == [1, 2, 3]  # epoch 2 was trained again from epoch 1's state: one epoch lost
    Policy.load(out / "decoy.pt", "decoy")


def test_both_resume_states_damaged_stop_with_one_line_and_exit_2(two_epochs: Path, tmp_path: Path, capsys):
    """Never a silent restart from epoch 0: the run is left as it was, the user told what to remove."""
    out = unfinished_copy(two_epochs, tmp_path / "both", epochs=3)
    truncate(out / "resume" / "decoy.pt")
    (out / "resume" / "decoy.prev.pt").write_bytes(b"garbage")
    metrics = (out / "metrics.csv").read_text()
    capsys.readouterr()
    assert run(main, ["--out", str(out), "--resume", "--no-progress"]) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(err) == 1, err
    assert "no resume state of decoy loads (decoy.pt not readable" in err[0] and "decoy.prev.pt not readable" in err[0]
    assert "to train decoy again from epoch 0" in err[0]
    assert (out / "metrics.csv").read_text() == metrics and epochs(out) == [1, 2]
    assert not (out / "decoy.pt").exists()


def test_a_truncated_best_checkpoint_never_ships(two_epochs: Path, tmp_path: Path, caplog):
    """Killed after its last epoch, before shipping: the best epoch's file is damaged, so the last epoch ships."""
    out = unfinished_copy(two_epochs, tmp_path / "best", epochs=2)
    truncate(out / "resume" / "decoy-best.pt")
    assert run(main, ["--out", str(out), "--resume", "--no-progress"]) == 0
    assert "shipping the last epoch instead" in caplog.text
    assert read_checkpoint(out / "decoy.pt")["metrics"]["epoch"] == 2  # the last epoch, which loads
    Policy.load(out / "decoy.pt", "decoy")
    assert epochs(out) == [1, 2]


def test_a_damaged_shipped_checkpoint_is_not_finished(two_epochs: Path, tmp_path: Path, caplog):
    out = tmp_path / "shipped"
    shutil.copytree(two_epochs, out)
    truncate(out / "decoy.pt")
    assert run(main, ["--out", str(out), "--resume", "--no-progress"]) == 0
    assert "training decoy again" in caplog.text
    Policy.load(out / "decoy.pt", "decoy")
    assert epochs(out) == [1, 2]


def test_init_from_a_checkpoint_of_another_size_is_one_line(two_epochs: Path, tmp_path: Path, capsys):
    out = tmp_path / "bigger"
    argv = [
        *TINY,
        "--epochs",
        "1",
        "--set",
        "hidden_sizes=[32,32]",
        "--init-from",
        str(two_epochs / "decoy.pt"),
        "--out",
        str(out),
    ]
    assert run(main, argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "--init-from" in err and "[32, 32]" in err
    assert not (out / "config.json").exists()  # refused before any work


def test_resume_states_of_the_two_older_formats_are_read(tmp_path: Path):
    import numpy as np
    import torch

    from tssac_core.train.resume import load_state_file

    common = {
        "task": {"w": 1},
        "obs": np.zeros((2, 3)),
        "torch_rng": torch.get_rng_state(),
        "epoch": 4,
        "env_steps": 80,
        "updates": 30,
        "selector": {"best": None},
    }
    off = {**common, "learner": {"variant": "tssac"}, "buffer": {"n": 1}, "rng": {"state": 1}, "transferred": True}
    on = {**common, "algo": "cpo", "learner": {"pi": 1}, "ep_len": np.ones(2), "finished": [(1.0, 3)]}
    for name, data in (("off", off), ("on", on)):
        torch.save(data, tmp_path / f"{name}.pt")
    a, b = load_state_file(tmp_path / "off.pt"), load_state_file(tmp_path / "on.pt")
    assert (a.epoch, a.updates, a.learner["buffer"], a.learner["recent_costs"], a.learner["transferred"]) == (
        4,
        30,
        {"n": 1},
        [],
        True,
    )
    assert (b.algo, b.learner["finished"], b.learner["learner"]) == ("cpo", [(1.0, 3)], {"pi": 1})
    torch.save({"something": "else"}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a resume state"):
        load_state_file(tmp_path / "other.pt")
