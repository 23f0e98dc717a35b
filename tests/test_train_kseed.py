"""``python -m tssac_core.train --seeds``: K seeds in one process, each seed's directory a single run's."""

from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from tssac_core.algos.sac_lagrangian import SacConfig, SacLagrangian
from tssac_core.cli import run as run_cli
from tssac_core.policy import Policy, read_checkpoint
from tssac_core.scenario import Role
from tssac_core.train import SeedRole, main
from tssac_core.train_kseed import commit_marker, recover_resume_states, save_resume_states

TINY = ["--roles", "decoy", "--epochs", "2", "--validation-episodes", "2", "--steps-per-epoch", "120", "--start-steps", "60",
        "--update-after", "60", "--envs", "2", "--set", "hidden_sizes=[32,32]", "--set", "batch_size=32", "--threads", "1", "--no-progress"]
TIMING = {"env_steps_per_s", "updates_per_s"}


def rows(out: Path) -> list[dict[str, str]]:
    with (out / "metrics.csv").open() as fh:
        return [{k: v for k, v in r.items() if k not in TIMING} for r in csv.DictReader(fh)]


@pytest.fixture(scope="module")
def two_seeds(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("kseed") / "run"
    assert main(["--algo", "tssac", "--seeds", "4,7", "--out", str(out), *TINY]) == 0
    return out


def test_each_seed_directory_is_a_single_run(two_seeds):
    assert json.loads((two_seeds / "seeds.json").read_text()) == {"seeds": [4, 7]}
    for seed in (4, 7):
        d = two_seeds / f"seed{seed}"
        for name in ("config.json", "metrics.csv", "decoy.pt", "fig7_return_cost.png", "fig8_multiplier.png", "resume/decoy.pt"):
            assert (d / name).is_file(), (seed, name)
        assert json.loads((d / "config.json").read_text())["seed"] == seed
        r = rows(d)
        assert [int(x["epoch"]) for x in r] == [1, 2] and int(r[-1]["updates"]) > 0
        policy = Policy.load(d / "decoy.pt", "decoy")
        obs = np.random.default_rng(0).uniform(0, 1, (3, policy.info.obs_dim)).astype(np.float32)
        assert policy.act(obs).shape == (3, 2)
        # The learner state is SacLagrangian's: it loads into a single learner and resumes from there.
        learner = SacLagrangian(policy.info.obs_dim, 2, SacConfig(hidden_sizes=(32, 32), batch_size=32))
        learner.load_state_dict(read_checkpoint(d / "decoy.pt")["learner"])
    assert rows(two_seeds / "seed4") != rows(two_seeds / "seed7")


def test_two_identical_runs_give_identical_results(two_seeds, tmp_path):
    out = tmp_path / "again"
    assert main(["--algo", "tssac", "--seeds", "4,7", "--out", str(out), *TINY]) == 0
    for seed in (4, 7):
        assert rows(out / f"seed{seed}") == rows(two_seeds / f"seed{seed}")
        a = torch.load(out / f"seed{seed}" / "decoy.pt", weights_only=False)["actor"]
        b = torch.load(two_seeds / f"seed{seed}" / "decoy.pt", weights_only=False)["actor"]
        assert all(torch.equal(a[k], b[k]) for k in a)


def test_resume_after_an_interruption_continues_identically(tmp_path, monkeypatch):
    args = ["--algo", "sac_lag", "--seeds", "1,2", *TINY, "--epochs", "3"]
    whole = tmp_path / "whole"
    assert main([*args, "--out", str(whole)]) == 0
    cut = tmp_path / "cut"
    original = SeedRole.end_epoch

    def interrupted(self, log, iters, write_checkpoint):
        if self.epoch == 3:
            raise KeyboardInterrupt  # killed in epoch 3, after epoch 2's resume states
        return original(self, log, iters, write_checkpoint)

    monkeypatch.setattr(SeedRole, "end_epoch", interrupted)
    with pytest.raises(KeyboardInterrupt):
        main([*args, "--out", str(cut)])
    monkeypatch.setattr(SeedRole, "end_epoch", original)
    assert main(["--out", str(cut), "--resume", "--no-progress"]) == 0
    for seed in (1, 2):
        assert rows(cut / f"seed{seed}") == rows(whole / f"seed{seed}")
        a = torch.load(whole / f"seed{seed}" / "decoy.pt", weights_only=False)["actor"]
        b = torch.load(cut / f"seed{seed}" / "decoy.pt", weights_only=False)["actor"]
        assert all(torch.equal(a[k], b[k]) for k in a)


def test_resume_states_are_committed_together(tmp_path):
    paths = [tmp_path / f"seed{k}" / "resume" / "decoy.pt" for k in range(2)]
    marker = commit_marker(tmp_path, Role.DECOY)
    save_resume_states([(p, {"epoch": 1}) for p in paths], marker)
    assert not marker.exists() and all(torch.load(p)["epoch"] == 1 for p in paths)
    # Killed while writing the .next files (no marker): the old set stays.
    torch.save({"epoch": 2}, paths[0].with_name("decoy.pt.next"))
    recover_resume_states(paths, marker)
    assert all(torch.load(p)["epoch"] == 1 for p in paths) and not paths[0].with_name("decoy.pt.next").exists()
    # Killed after the marker, with one file moved: the resume moves the rest.
    torch.save({"epoch": 2}, paths[0])
    torch.save({"epoch": 2}, paths[1].with_name("decoy.pt.next"))
    marker.write_text("x")
    recover_resume_states(paths, marker)
    assert all(torch.load(p)["epoch"] == 2 for p in paths) and not marker.exists()


def test_bad_seed_arguments(tmp_path, capsys):
    assert run_cli(main, ["--algo", "ppo", "--seeds", "0,1", "--out", str(tmp_path / "a")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "SAC family only" in err[0]
    assert run_cli(main, ["--seeds", "0,x", "--out", str(tmp_path / "b")]) == 2
    assert run_cli(main, ["--seeds", "1,1", "--out", str(tmp_path / "c")]) == 2
    assert run_cli(main, ["--seeds", "0,1", "--out", str(tmp_path / "d"), "--resume"]) == 2
    assert "not found" in capsys.readouterr().err
