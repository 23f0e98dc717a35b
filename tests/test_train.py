"""The training command: outputs, determinism, resume after kill -9, checkpoints and the policy face."""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch

from tssac_core.algos.lagrange import CostSignal, SignalRule
from tssac_core.deploy.numpy_actor import pilot_file
from tssac_core.deploy.policy import CheckpointError, Policy, load_team
from tssac_core.sim.scenario import Role
from tssac_core.train.cli import main
from tssac_core.train.wall_time import Ended, Invocation, read_invocations

# One test process runs this file: its module fixture is built once.
pytestmark = pytest.mark.xdist_group("test_train")

SHORT = str(Path(__file__).resolve().parent.parent / "scenarios" / "short.yaml")
"""A 600-step mission (the UAVs start in their rings): what these runs assert does not depend on the mission's
length, and their validation missions, flown to the end by untrained policies, cost a seventh of strike.yaml's."""

TINY = [
    "--scenario",
    SHORT,
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
    "--threads",
    "1",
    "--no-progress",
]


def rows(out: Path) -> list[dict[str, str]]:
    with (out / "metrics.csv").open() as fh:
        return list(csv.DictReader(fh))


@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("run") / "tssac"
    assert main(["--algo", "tssac", "--seed", "3", "--out", str(out), *TINY]) == 0
    return out


def test_outputs(trained):
    for name in (
        "config.json",
        "metrics.csv",
        "decoy.pt",
        "detect.pt",
        "strike.pt",
        "fig7_return_cost.png",
        "fig8_multiplier.png",
    ):
        assert (trained / name).is_file(), name
    r = rows(trained)
    assert [(x["role"], int(x["epoch"])) for x in r] == [
        (role, e) for role in ("decoy", "detect", "strike") for e in (1, 2)
    ]
    assert float(r[-1]["updates"]) > 0 and float(r[-1]["updates_per_s"]) > 0
    assert all(x["beta_minus_xi"] not in ("", "nan") for x in r[1:])
    for role in ("decoy", "detect", "strike"):  # each shipped role's actor, exported for the companion
        assert pilot_file(trained, Role(role)) == trained / f"{role}.npz"
    # The multiplier's measurement, left to its default on the command line, is recorded.
    assert json.loads((trained / "config.json").read_text())["learner"]["multiplier_signal"] == "episode_cost"


def test_runs_from_before_a_setting_resume_with_what_they_used():
    """A config.json without cost_margin_km trained on eq. 11 exactly; one of TSSAC or SAC-Lagrangian
    without multiplier_signal measured Q^c. The other algorithms have no multiplier to record."""
    from tssac_core.train.legacy import config_from_saved

    old = {"algo": "tssac", "roles": ["decoy"], "sac": {"gamma": 0.995}}
    cfg = config_from_saved(old)
    assert cfg.cost_margin_km == 0.0 and cfg.learner == {"gamma": 0.995, "multiplier_signal": "q_c"}
    assert config_from_saved({**old, "algo": "sac"}).learner == {"gamma": 0.995}
    new = {**old, "cost_margin_km": 1.0, "learner": {"multiplier_signal": "episode_cost"}}
    assert config_from_saved(new).learner == {"multiplier_signal": "episode_cost"}


def test_same_seed_same_run(trained, tmp_path):
    out = tmp_path / "again"
    assert main(["--algo", "tssac", "--seed", "3", "--out", str(out), "--roles", "decoy", *TINY]) == 0
    a = torch.load(trained / "decoy.pt", weights_only=False)["actor"]
    b = torch.load(out / "decoy.pt", weights_only=False)["actor"]
    assert all(torch.equal(a[k], b[k]) for k in a)


def no_update_run(hidden: str, *extra: str) -> list[str]:
    """Training flags for one epoch of 20 decisions and no update (it would start after 1,000): every network
    stays as it was initialised or transferred."""
    flags = "--epochs 1 --validation-episodes 0 --steps-per-epoch 20 --envs 2 --update-after 1000 --no-progress"
    return [*flags.split(), "--threads", "1", "--set", f"hidden_sizes={hidden}", *extra]


def test_transfer_initialises_the_next_role(tmp_path):
    """With --epochs so short that no update happens, TSSAC's detect actor equals the decoy's (N1 -> N2)."""
    out = tmp_path / "t"
    args = no_update_run("[16]", "--roles", "decoy,detect")
    assert main(["--algo", "tssac", "--out", str(out), *args]) == 0
    a = torch.load(out / "decoy.pt", weights_only=False)["actor"]
    b = torch.load(out / "detect.pt", weights_only=False)["actor"]
    assert all(torch.equal(a[k], b[k]) for k in a)
    out2 = tmp_path / "s"
    assert main(["--algo", "sac_lag", "--out", str(out2), *args]) == 0
    c = torch.load(out2 / "decoy.pt", weights_only=False)["actor"]
    d = torch.load(out2 / "detect.pt", weights_only=False)["actor"]
    assert not all(torch.equal(c[k], d[k]) for k in c)  # sac_lag starts every role from scratch


def test_teammates_directory_flies_and_transfers_the_earlier_roles(trained, tmp_path, capsys):
    """--teammates DIR: the earlier roles come from DIR (not --out); TSSAC's strike starts as DIR's detect."""
    from tssac_core.common.cli import run

    out = tmp_path / "strike-only"
    args = no_update_run("[32,32]", "--roles", "strike")
    assert main(["--algo", "tssac", "--out", str(out), "--teammates", str(trained), *args]) == 0
    assert sorted(p.name for p in out.glob("*.pt")) == ["strike.pt"]  # nothing of the teammates copied in
    a = torch.load(trained / "detect.pt", weights_only=False)["actor"]
    b = torch.load(out / "strike.pt", weights_only=False)["actor"]
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert json.loads((out / "config.json").read_text())["teammates"] == str(trained)
    lonely = tmp_path / "lonely"  # a directory without the detect UAV: one line naming the missing file
    lonely.mkdir()
    shutil.copy(trained / "decoy.pt", lonely / "decoy.pt")
    assert run(main, ["--out", str(tmp_path / "x"), "--teammates", str(lonely), *args]) == 2
    assert f"needs {lonely / 'detect.pt'}" in capsys.readouterr().err


def test_stop_at_task_success_ends_the_role_at_the_first_epoch_that_reaches_it(tmp_path, capsys, caplog):
    """A trained strike UAV, flown (no update) beside its team, completes its task at once: with
    --stop-at-task-success the role ends after epoch 1 of 3 and ships; a value outside [0, 1] is one line."""
    from tssac_core.common.cli import run

    caplog.set_level("INFO")
    # The tail-selection team keeps its learner state (models/tssac holds actors only: it was compacted by the grid).
    models = Path(__file__).resolve().parent.parent / "results" / "shipped-team" / "tail-s2"
    args = [
        "--roles",
        "strike",
        "--teammates",
        str(models),
        "--init-from",
        str(models / "strike.pt"),
        "--epochs",
        "3",
        "--steps-per-epoch",
        "700",
        "--envs",
        "1",
        "--action-repeat",
        "10",
        "--update-after",
        "100000",
        "--start-steps",
        "0",
        "--validation-episodes",
        "0",
        "--set",
        "hidden_sizes=[128,128]",
        "--threads",
        "1",
        "--no-progress",
    ]
    out = tmp_path / "stopped"
    assert main(["--algo", "sac_lag", "--out", str(out), "--stop-at-task-success", "0.5", *args]) == 0
    r = rows(out)
    assert [int(x["epoch"]) for x in r] == [1] and float(r[0]["task_success"]) >= 0.5 and int(r[0]["episodes"]) >= 1
    assert (out / "strike.pt").is_file() and "reaches --stop-at-task-success" in caplog.text
    assert run(main, ["--out", str(tmp_path / "b"), "--stop-at-task-success", "1.5"]) == 2
    assert "--stop-at-task-success: expected a fraction in [0, 1], got 1.5" in capsys.readouterr().err


def test_init_from_a_teams_directory_starts_each_role_from_its_own_checkpoint(tmp_path, caplog):
    """--init-from DIR: the strike role starts from DIR/strike.pt (its actor, before any update, is that one's)."""
    caplog.set_level("INFO")
    models = Path(__file__).resolve().parent.parent / "results" / "shipped-team" / "tail-s2"
    out = tmp_path / "tuned"
    args = ["--roles", "strike", "--teammates", str(models), "--init-from", str(models), "--epochs", "1"]
    args += ["--steps-per-epoch", "50", "--envs", "1", "--update-after", "100000", "--validation-episodes", "0"]
    args += ["--set", "hidden_sizes=[128,128]", "--threads", "1", "--no-progress"]
    assert main(["--algo", "sac_lag", "--out", str(out), *args]) == 0
    assert "initialised" in caplog.text and str(models / "strike.pt") in caplog.text
    a = torch.load(models / "strike.pt", weights_only=False)["actor"]
    b = torch.load(out / "strike.pt", weights_only=False)["actor"]
    assert all(torch.equal(a[k], b[k]) for k in a)


def test_checkpoint_round_trip_and_team(trained):
    team = load_team(trained)
    obs = np.random.default_rng(0).uniform(0, 1, (5, team[0].info.obs_dim)).astype(np.float32)
    again = load_team(trained)
    for p, q in zip(team, again):
        np.testing.assert_array_equal(p.act(obs), q.act(obs))
        assert p.act(obs).shape == (5, 2) and np.abs(p.act(obs)).max() <= 1.0
        np.testing.assert_allclose(p.act(obs[0]), p.act(obs)[0], atol=1e-6)
    assert team[2].info.role.value == "strike" and team[2].info.algo == "tssac"
    assert team[0].info.versions["torch"] == torch.__version__


def test_bad_checkpoints_fail_with_one_line(trained, tmp_path):
    with pytest.raises(CheckpointError, match="checkpoint not found"):
        Policy.load(tmp_path / "missing.pt")
    junk = tmp_path / "junk.pt"
    junk.write_bytes(os.urandom(300))
    with pytest.raises(CheckpointError, match="not a readable checkpoint"):
        Policy.load(junk)
    with pytest.raises(CheckpointError, match="is for the decoy UAV, not the strike"):
        Policy.load(trained / "decoy.pt", "strike")
    data = torch.load(trained / "decoy.pt", weights_only=False)
    data["obs_dim"] = 5
    torch.save(data, tmp_path / "wrong.pt")
    with pytest.raises(CheckpointError, match="does not fit"):
        Policy.load(tmp_path / "wrong.pt")
    with pytest.raises(ValueError, match="observation has 5 values"):
        Policy.load(trained / "decoy.pt").act(np.zeros(5))
    proc = subprocess.run(
        [sys.executable, "-m", "tssac_core.evaluate", "--models", str(tmp_path), "--episodes", "1"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode == 2 and len(proc.stderr.strip().splitlines()) == 1 and "checkpoint not found" in proc.stderr


def test_evaluate_flies_trained_models(trained, tmp_path):
    from tssac_core.evaluate import main as evaluate

    assert (
        evaluate(
            [
                "--models",
                str(trained),
                "--scenario",
                "scenarios/strike.yaml",
                "--episodes",
                "2",
                "--json",
                str(tmp_path / "e.json"),
                "--no-progress",
            ]
        )
        == 0
    )
    assert (tmp_path / "e.json").is_file()


@pytest.mark.slow
def test_resume_after_kill_continues_identically(tmp_path):
    """kill -9 mid-run, then --resume: the result equals an uninterrupted run's, bit for bit."""
    args = [
        "--scenario",
        SHORT,
        "--algo",
        "sac_lag",
        "--seed",
        "5",
        "--roles",
        "decoy",
        "--epochs",
        "3",
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
        "--threads",
        "1",
        "--no-progress",
    ]
    whole = tmp_path / "whole"
    assert main([*args, "--out", str(whole)]) == 0
    cut = tmp_path / "cut"
    proc = subprocess.Popen(
        [sys.executable, "-m", "tssac_core.train", *args, "--out", str(cut)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    deadline = time.monotonic() + 120
    state = cut / "resume" / "decoy.pt"
    while time.monotonic() < deadline and not state.is_file():
        time.sleep(0.05)
    time.sleep(0.2)  # into the second epoch
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)
    assert not (cut / "decoy.pt").is_file(), "the run finished before it could be killed"
    (killed,) = read_invocations(cut)  # brought up to date after the first epoch, so the kill loses no more
    assert killed.ended is Ended.RUNNING
    assert main(["--out", str(cut), "--resume", "--no-progress"]) == 0
    assert [i.ended for i in read_invocations(cut)] == [Ended.KILLED, Ended.FINISHED]
    assert read_invocations(cut)[0] == Invocation(killed.seconds, Ended.KILLED)  # its seconds count
    assert [i.ended for i in read_invocations(whole)] == [Ended.FINISHED]
    a = torch.load(whole / "decoy.pt", weights_only=False)["actor"]
    b = torch.load(cut / "decoy.pt", weights_only=False)["actor"]
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert [r["epoch"] for r in rows(cut)] == ["1", "2", "3"]
    assert [r["return"] for r in rows(cut)] == [r["return"] for r in rows(whole)]


def test_bad_arguments(tmp_path, capsys):
    from tssac_core.common.cli import run

    assert run(main, ["--out", str(tmp_path / "x"), "--roles", "strike,decoy"]) == 2
    assert "curriculum order" in capsys.readouterr().err
    assert run(main, ["--out", str(tmp_path / "y"), "--resume"]) == 2
    assert run(main, ["--out", str(tmp_path / "z"), "--roles", "detect"]) == 2
    assert "train decoy first" in capsys.readouterr().err


@pytest.mark.parametrize(
    "algo, setting, message",
    [
        ("tssac", "hidden_sizes=128x", "hidden_sizes: expected a number, list or boolean, got '128x'"),
        ("tssac", "multiplier_signal=qc", "multiplier_signal must be one of episode_cost, q_c, got 'qc'"),
        ("tssac", "multiplier_signal=3", "multiplier_signal: expected a word, got 3"),
        ("ppo", "gamma=high", "gamma: expected a number, list or boolean, got 'high'"),
    ],
)
def test_a_bad_learner_setting_is_one_line_before_any_work(tmp_path, capsys, algo, setting, message):
    from tssac_core.common.cli import run

    assert run(main, ["--algo", algo, "--set", setting, "--out", str(tmp_path / "run")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize(
    "content, message",
    [
        ("{not json", "is not readable"),
        ('{"algo": "tssac", "roles": ["decoy"], "warp_drive": 9}', "settings this TSSAC does not know: warp_drive"),
    ],
)
def test_resume_with_a_damaged_config_json_is_one_line(tmp_path, capsys, content, message):
    from tssac_core.common.cli import run

    (tmp_path / "config.json").write_text(content)
    assert run(main, ["--out", str(tmp_path), "--resume"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err and "config.json" in err


def test_the_multiplier_measures_the_last_episodes_costs_and_resumes_with_them(tmp_path):
    """OffPolicyLearner.episode_cost: the mean learner cost of the last cost_window episodes, measured whatever the
    multiplier's signal (lagrange.choose_signal picks it); a resume state carries them, so a resumed run's multiplier
    sees what the uninterrupted one saw."""
    import dataclasses

    from tssac_core.sim.observation import ObservationMode
    from tssac_core.sim.scenario import load
    from tssac_core.train.config import TrainConfig
    from tssac_core.train.epoch import EpochLog, make_task
    from tssac_core.train.learners import OffPolicyLearner

    cfg = TrainConfig(
        algo="sac_lag",
        seed=4,
        roles=("decoy",),
        envs=2,
        action_repeat=10,
        validation_episodes=0,
        learner={"cost_window": 3},
    )
    scenario = load(cfg.scenario)
    mode = ObservationMode(cfg.observation)
    learner = OffPolicyLearner(cfg, scenario, Role.DECOY, mode)
    task = make_task(cfg, scenario, Role.DECOY, mode, {})
    obs = task.reset()
    assert learner.episode_cost() == 0.0  # no episode has ended yet
    log = EpochLog()
    rng = np.random.default_rng(0)
    for _ in range(2000):  # random flight: episodes end by the 400-decision cap at the latest
        action = rng.uniform(-1.0, 1.0, (2, 2))
        step = task.step(action, repeat=cfg.action_repeat)
        ended = step.terminated | step.truncated
        learner.store(obs, action, step, ended)
        obs = step.obs
        if ended.any():
            log.record_episodes(step, ended)
        if len(log.costs) >= 5:
            break
    assert len(log.costs) >= 5 and len(set(log.costs)) > 1, log.costs  # the window's choice matters
    assert learner.episode_cost() == pytest.approx(np.mean(log.costs[-3:]))
    assert learner.learner.signal.signal is CostSignal.EPISODE_COST
    assert OffPolicyLearner(dataclasses.replace(cfg, algo="sac"), scenario, Role.DECOY, mode).learner.signal == (
        SignalRule(CostSignal.Q_C_BATCH)
    )
    q_c = OffPolicyLearner(dataclasses.replace(cfg, learner={"multiplier_signal": "q_c"}), scenario, Role.DECOY, mode)
    assert q_c.learner.signal == SignalRule(CostSignal.Q_C_RECENT, recent_window=4000)
    resumed = OffPolicyLearner(cfg, scenario, Role.DECOY, mode)
    resumed.restore(learner.state())
    assert list(resumed.recent_costs) == log.costs[-3:] and resumed.recent_costs.maxlen == 3
