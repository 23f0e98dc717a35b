"""The OmniSafe cross-check's pure logic (benchmarks/crosscheck): the commands and OmniSafe's configuration, the
numpy actor, the checkpointed rows (skip on a rerun, refuse a mixed setting), the pooled table, the command's
one-line errors. Nothing here trains or imports OmniSafe (tests/test_crosscheck_omnisafe.py does, in OmniSafe's
environment: benchmarks/omnisafe_env.py builds it)."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))  # benchmarks/ is not an installed package: this checkout's

from benchmarks.crosscheck import driver  # noqa: E402
from benchmarks.crosscheck.actor_file import ActorFileError, OmniSafeActor, write_actor  # noqa: E402
from benchmarks.crosscheck.rows import RowsError, RowStore, figures, make_row, pool, setting, table  # noqa: E402
from benchmarks.crosscheck.settings import (  # noqa: E402
    PRESET,
    Budget,
    Job,
    SettingsError,
    omnisafe_cfgs,
    omnisafe_command,
    ours_command,
    parse_override,
    shared_settings,
)
from tssac_core.common.cli import run  # noqa: E402
from tssac_core.sim.observation import ObservationMode  # noqa: E402
from tssac_core.train.arguments import parse_cli  # noqa: E402

SHARED = shared_settings(yaml.safe_load(PRESET.read_text()), 3.0)
SETTING = setting(Budget(2, 10), 4, 2600001, 3.0)


def test_shared_settings_are_our_recipes_and_refuse_families_that_disagree():
    assert SHARED.gamma == 0.995 and SHARED.hidden_sizes == (128, 128) and SHARED.cost_margin_km == 1.0
    assert (SHARED.action_repeat, SHARED.update_every, SHARED.update_after, SHARED.cost_limit) == (10, 2, 1000, 3.0)
    preset = yaml.safe_load(PRESET.read_text())
    preset["sac_set"]["gamma"] = 0.99
    with pytest.raises(SettingsError, match="same gamma"):
        shared_settings(preset, 3.0)


def test_our_command_is_one_our_train_command_accepts_detect_beside_the_shipped_decoy():
    cmd = ours_command("python", Job("ours", "sac_lag", 2), Budget(3, 500), Path("/tmp/x"))
    cfg, out, resume, *_ = parse_cli(cmd[3:])
    assert cfg.algo == "sac_lag" and cfg.roles == ("detect",) and cfg.seed == 2 and not resume
    assert Path(cfg.teammates) == ROOT / "models" / "tssac" and (cfg.epochs, cfg.steps_per_epoch) == (3, 500)
    assert cfg.action_repeat == 10 and cfg.validation_episodes == 0 and out == Path("/tmp/x")
    again = ours_command("python", Job("ours", "sac_lag", 2), Budget(3, 500), Path("/tmp/x"), resume=True)
    assert again[-1] == "--resume"
    assert omnisafe_command("py", Path("c.json"), Path("d"))[:3] == ["py", "-m", "benchmarks.crosscheck.omnisafe_side"]


@pytest.mark.parametrize(
    "algo, limit_at", [("cpo", "algo_cfgs"), ("ppo_lag", "lagrange_cfgs"), ("sac_lag", "lagrange_cfgs")]
)
def test_omnisafe_cfgs_align_budget_limit_discount_and_networks(algo, limit_at):
    cfgs = omnisafe_cfgs(algo, Budget(50, 4000), 1, SHARED, Path("/tmp/log"))
    assert cfgs[limit_at]["cost_limit"] == 3.0 and cfgs["seed"] == 1
    assert cfgs["train_cfgs"]["total_steps"] == 200_000 and cfgs["algo_cfgs"]["steps_per_epoch"] == 4000
    assert cfgs["algo_cfgs"]["gamma"] == 0.995 and cfgs["model_cfgs"]["critic"]["hidden_sizes"] == [128, 128]
    assert cfgs["env_cfgs"]["teammate_roles"] == ["decoy"] and cfgs["env_cfgs"]["cost_margin_km"] == 1.0
    assert cfgs["logger_cfgs"]["save_model_freq"] == 50
    if algo == "sac_lag":
        assert cfgs["algo_cfgs"]["warmup_epochs"] == 10 and cfgs["algo_cfgs"]["update_cycle"] == 2
        assert cfgs["algo_cfgs"]["start_learning_steps"] == 1000 and "cost_gamma" not in cfgs["algo_cfgs"]
    else:
        assert cfgs["algo_cfgs"]["cost_gamma"] == 0.995


def test_overrides_are_dotted_and_parsed():
    assert parse_override("algo_cfgs.update_iters=10") == ("algo_cfgs.update_iters", 10)
    assert parse_override("model_cfgs.actor.activation=relu") == ("model_cfgs.actor.activation", "relu")
    cfgs = omnisafe_cfgs("ppo_lag", Budget(1, 10), 0, SHARED, Path("l"), {"algo_cfgs.update_iters": 10})
    assert cfgs["algo_cfgs"]["update_iters"] == 10 and cfgs["algo_cfgs"]["steps_per_epoch"] == 10
    for bad in ("update_iters", "=3"):
        with pytest.raises(SettingsError):
            parse_override(bad)
    with pytest.raises(SettingsError, match="not a section"):
        omnisafe_cfgs("cpo", Budget(1, 10), 0, SHARED, Path("l"), {"seed.x": 1})
    with pytest.raises(SettingsError):
        Budget(0, 10)
    with pytest.raises(SettingsError):
        Job("rllib", "cpo", 0)


def tiny_layers(rng, sizes):
    return [(rng.normal(size=(o, i)), rng.normal(size=o)) for i, o in zip(sizes[:-1], sizes[1:])]


@pytest.mark.parametrize("actor_type, activation", [("gaussian_learning", "tanh"), ("gaussian_sac", "relu")])
def test_numpy_actor_is_omnisafes_deterministic_mean(tmp_path, actor_type, activation):
    rng = np.random.default_rng(0)
    d = ObservationMode.ROUTE.size
    out_dim = 2 if actor_type == "gaussian_learning" else 4
    layers = tiny_layers(rng, [d, 5, out_dim])
    mean, std = rng.normal(size=d), rng.uniform(0.5, 2.0, size=d)
    path = tmp_path / "actor.npz"
    write_actor(
        path, {"algo": "X", "actor_type": actor_type, "activation": activation, "act_dim": 2}, layers, mean, std
    )
    actor = OmniSafeActor.load(path)
    obs = rng.normal(size=(7, d)) * 10
    x = np.clip((obs - mean) / std, -5, 5)
    h = x @ layers[0][0].T.astype(np.float32) + layers[0][1].astype(np.float32)
    h = np.tanh(h) if activation == "tanh" else np.maximum(h, 0)
    y = (h @ layers[1][0].T.astype(np.float32) + layers[1][1].astype(np.float32))[:, :2]
    expected = np.clip(np.tanh(y) if actor_type == "gaussian_sac" else y, -1, 1)
    np.testing.assert_allclose(actor(obs), expected, atol=1e-5)
    assert actor.action_repeat == 10 and actor.observation_mode is ObservationMode.ROUTE


def test_numpy_actor_refuses_what_it_cannot_fly(tmp_path):
    rng = np.random.default_rng(0)
    meta = {"algo": "X", "actor_type": "gaussian_learning", "activation": "tanh", "act_dim": 2}
    write_actor(tmp_path / "narrow.npz", meta, tiny_layers(rng, [3, 2]))
    with pytest.raises(ActorFileError, match="inputs"):
        OmniSafeActor.load(tmp_path / "narrow.npz")
    write_actor(tmp_path / "elu.npz", {**meta, "activation": "elu"}, tiny_layers(rng, [ObservationMode.ROUTE.size, 2]))
    with pytest.raises(ActorFileError, match="activation"):
        OmniSafeActor.load(tmp_path / "elu.npz")
    (tmp_path / "junk.npz").write_text("no")
    with pytest.raises(ActorFileError, match="cannot read"):
        OmniSafeActor.load(tmp_path / "junk.npz")


def test_figures_count_within_c_inclusively_and_give_intervals():
    f = figures([True, False, True, True], [0.0, 3.0, 4.0, 1.0], 3.0)
    assert f["missions"] == 4 and f["task_success"]["value"] == 0.75 and f["within_c"]["value"] == 0.75
    assert f["mean_cost"]["value"] == 2.0 and f["mean_cost"]["low"] <= 2.0 <= f["mean_cost"]["high"]
    assert 0 < f["task_success"]["low"] < 0.75 < f["task_success"]["high"] < 1
    with pytest.raises(RowsError):
        figures([True], [0.0, 1.0], 3.0)


def row(impl, algo, seed, task, cost, the_setting=SETTING):
    return make_row(Job(impl, algo, seed), the_setting, task, cost, 40.0, 1.0, [["cmd", str(seed)]], "runs/x")


def test_rows_are_written_at_once_skipped_after_and_never_mixed(tmp_path):
    path = tmp_path / "rows.json"
    store = RowStore(path)
    job = Job("ours", "cpo", 0)
    assert not store.done(job, SETTING)
    store.add(row("ours", "cpo", 0, [True] * 4, [0.0] * 4))
    again = RowStore(path)  # a later session
    assert again.done(job, SETTING) and not again.done(Job("omnisafe", "cpo", 0), SETTING)
    assert again.find(job)["ms_per_decision"] == pytest.approx(2000.0)  # 40 s over 2 x 10 decisions
    with pytest.raises(RowsError, match="another --rows"):
        again.done(job, {**SETTING, "epochs": 50})
    with pytest.raises(RowsError, match="already holds"):
        again.add(row("ours", "cpo", 0, [True] * 4, [0.0] * 4))
    side = RowStore(path)  # another command on the same file, opened before the next row lands
    again.add(row("ours", "ppo_lag", 0, [True] * 4, [0.0] * 4))
    side.add(row("omnisafe", "cpo", 0, [False] * 4, [9.0] * 4))
    assert {(r["impl"], r["algo"]) for r in RowStore(path).rows} == {
        ("ours", "cpo"),
        ("ours", "ppo_lag"),
        ("omnisafe", "cpo"),
    }
    path.write_text(json.dumps({"rows": []}))
    with pytest.raises(RowsError, match="not a cross-check"):
        RowStore(path)


def test_pool_takes_every_seeds_missions_and_the_table_shows_them():
    rows = [
        row("omnisafe", "ppo_lag", 1, [True, True, False, False], [0, 0, 9, 9]),
        row("omnisafe", "ppo_lag", 0, [True, True, True, True], [0, 0, 0, 1]),
        row("ours", "ppo_lag", 0, [False] * 4, [5.0] * 4),
        row("ours", "cpo", 0, [True] * 4, [0.0] * 4),
    ]
    pooled = pool(rows)
    assert [(p["algo"], p["impl"]) for p in pooled] == [("cpo", "ours"), ("ppo_lag", "ours"), ("ppo_lag", "omnisafe")]
    omni = pooled[2]
    assert omni["seeds"] == [0, 1] and omni["missions"] == 8 and omni["task_success"]["value"] == 0.75
    assert omni["mean_cost"]["value"] == pytest.approx(19 / 8) and omni["within_c"]["value"] == 0.75
    assert omni["per_seed_task_success"] == [1.0, 0.5]
    text = table(pooled)
    assert "| ppo_lag | omnisafe | 2 | 75.0% (" in text and "100%, 50%" in text and "2600001-2600004" in text
    assert text.rstrip().endswith("| 40 | n/a |")  # no CPU figure recorded
    rows[0]["cpu_ms_per_decision"], rows[1]["cpu_ms_per_decision"] = 3.0, None
    assert "| 40 | 3.0 |" in table(pool(rows))
    with pytest.raises(RowsError, match="different settings"):
        pool([*rows, row("ours", "cpo", 1, [True] * 4, [0.0] * 4, {**SETTING, "eval_seed": 1})])
    with pytest.raises(RowsError, match="no rows"):
        table([])


def test_a_rerun_skips_finished_rows_without_training(tmp_path, monkeypatch, capsys):
    rows = tmp_path / "rows.json"
    store = RowStore(rows)
    store.add(row("ours", "cpo", 0, [True] * 4, [0.0] * 4))

    def no_training(*args, **kwargs):
        raise AssertionError("a finished row was trained again")

    monkeypatch.setattr(driver, "train_ours", no_training)
    argv = ["--impls", "ours", "--algos", "cpo", "--seeds", "0", "--epochs", "2", "--steps-per-epoch", "10"]
    assert driver.main([*argv, "--episodes", "4", "--rows", str(rows), "--work", str(tmp_path)]) == 0
    assert "skipped" in capsys.readouterr().out
    # The same row at another budget is refused, not retrained or overwritten.
    assert run(driver.main, [*argv[:-1], "20", "--episodes", "4", "--rows", str(rows)]) == 2
    assert "another --rows" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--algos", "trpo"], "--algos"),
        (["--seeds", "0,0"], "--seeds"),
        (["--epochs", "0"], "epochs"),
        (["--impls", "omnisafe", "--omnisafe-python", "/no/python"], "--omnisafe-python"),
        (["--report", "--rows", "/no/rows.json"], "no such file"),
        (["--omnisafe-set", "oops"], "KEY=VALUE"),
    ],
)
def test_bad_input_is_one_line_and_exit_2(tmp_path, capsys, argv, message):
    assert run(driver.main, [*argv, "--work", str(tmp_path)] if "--report" not in argv else argv) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_report_writes_the_table(tmp_path, capsys):
    rows = tmp_path / "rows.json"
    RowStore(rows).add(row("ours", "sac_lag", 0, [True, False, True, True], [0.0, 1.0, 2.0, 10.0]))
    assert driver.main(["--report", "--rows", str(rows)]) == 0
    assert "| sac_lag | ours | 1 | 75.0% (" in (tmp_path / "rows.md").read_text()
