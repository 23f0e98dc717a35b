"""Any policy (tssac_core.deploy.any_policy, sb3_policy, policy_export; evaluate_policy and evaluate --policy): what it
was trained on stated or read from its env or file, checked against the role's env before the first mission (one line
for each mismatch), the shipped team's figures when the policy is a shipped actor, and ONNX files that act as the
policy does."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import onnx
import pytest
import torch
from torch import nn

import tssac_core.sim.env  # noqa: F401  (registers tssac/<Role>-v0)
from tssac_core.common.cli import run
from tssac_core.deploy.any_policy import (
    PolicyError,
    PolicySpec,
    check_policy,
    from_callable,
    from_onnx,
    from_torch,
)
from tssac_core.deploy.manifest import check_command
from tssac_core.deploy.mlp_graph import mlp_model, torch_layers
from tssac_core.deploy.numpy_actor import load_policy
from tssac_core.deploy.onnx_actor import OnnxPolicy
from tssac_core.deploy.policy_export import export_team, write_onnx_actor
from tssac_core.deploy.sb3_policy import from_sb3
from tssac_core.evaluate import evaluate_policy
from tssac_core.evaluate import main as evaluate_main
from tssac_core.sim.observation import ObservationMode, observation_bounds
from tssac_core.sim.scenario import Role

REPO = Path(__file__).resolve().parent.parent
SHIPPED = REPO / "models" / "tssac"
STRIKE = REPO / "scenarios" / "strike.yaml"


def one_error_line(err: str) -> str:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1, err
    return lines[0]


def observations(mode: ObservationMode, n: int = 200, seed: int = 5) -> np.ndarray:
    low, high = observation_bounds(mode)
    return np.random.default_rng(seed).uniform(low, high, (n, low.size)).astype(np.float32)


def mlp(obs_dim: int = 24, squash: bool = False) -> nn.Sequential:
    torch.manual_seed(0)
    layers: list[nn.Module] = [nn.Linear(obs_dim, 16), nn.Tanh(), nn.Linear(16, 16), nn.ReLU(), nn.Linear(16, 2)]
    return nn.Sequential(*layers, *([nn.Tanh()] if squash else []))


def zeros(obs: np.ndarray) -> np.ndarray:
    return np.zeros((len(obs), 2))


# ------------------------------------------------------------------------------ what is stated, and by whom


def test_a_plain_callable_must_say_its_observation_and_interval():
    with pytest.raises(PolicyError) as err:
        from_callable(zeros)
    line = str(err.value)
    assert "\n" not in line and "observation=" in line and "decision_interval_s=" in line and "zeros" in line
    spec = from_callable(zeros, observation="route", decision_interval_s=1.0)
    assert (spec.observation_mode, spec.decision_interval_s, spec.role) == (ObservationMode.ROUTE, 1.0, None)


def test_the_env_it_was_trained_on_says_all_three():
    env = gym.make("tssac/Strike-v0", observation="extended", action_repeat=5, teammates="none")
    spec = from_callable(zeros, env=env)
    assert (spec.observation_mode, spec.decision_interval_s, spec.role) == (ObservationMode.EXTENDED, 0.5, Role.STRIKE)
    vec = gym.make_vec("tssac/Decoy-v0", num_envs=2)
    assert from_callable(zeros, env=vec).decision_interval_s == 1.0  # the env's defaults: route, 10 steps of 0.1 s
    with pytest.raises(PolicyError, match="you said observation 'route', the env it was trained on says 'extended'"):
        from_callable(zeros, observation="route", env=env)
    with pytest.raises(PolicyError, match="not a tssac/<Role>-v0 env"):
        from_callable(zeros, env=gym.make("Pendulum-v1"))


def test_a_shipped_actor_states_its_own():
    actor = load_policy(SHIPPED / "decoy.npz")
    spec = from_callable(actor)
    assert (spec.observation_mode, spec.decision_interval_s, spec.role) == (ObservationMode.ROUTE, 1.0, Role.DECOY)
    with pytest.raises(PolicyError, match="said decision interval 2 s, NumpyPolicy itself says 1 s"):
        from_callable(actor, decision_interval_s=2.0)


@pytest.mark.parametrize(
    ("spec_args", "role", "needle"),
    [
        ({"observation": "extended", "decision_interval_s": 1.0}, Role.DECOY, "fails on a batch of 4 'extended' "),
        ({"observation": "route", "decision_interval_s": 0.25}, Role.DECOY, "0.25 s is not a whole number"),
        ({"observation": "route", "decision_interval_s": 1.0, "role": "strike"}, Role.DECOY, "trained as the strike"),
    ],
)
def test_a_mismatch_with_the_env_is_one_line(spec_args: dict, role: Role, needle: str):
    actor = load_policy(SHIPPED / "decoy.npz")  # a 24-value network: on 22 values it raises inside

    def plain(obs: np.ndarray) -> np.ndarray:
        return actor(obs)

    spec = from_callable(plain, **spec_args)
    with pytest.raises(PolicyError) as err:
        check_policy(spec, role, 0.1)
    assert needle in str(err.value) and "\n" not in str(err.value)


@pytest.mark.parametrize(
    ("fn", "needle"),
    [
        (lambda obs: np.zeros(2), "returns shape (2,) for a batch of 4"),
        (lambda obs: np.full((len(obs), 2), np.nan), "not finite"),
        (lambda obs: np.zeros((len(obs), 3)), "returns shape (4, 3)"),
    ],
)
def test_what_a_callable_returns_is_checked(fn, needle: str):
    with pytest.raises(PolicyError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        check_policy(from_callable(fn, observation="route", decision_interval_s=1.0), Role.DECOY, 0.1)


def test_a_one_observation_callable_is_called_row_by_row():
    actor = load_policy(SHIPPED / "detect.npz")
    calls = []

    def one(obs: np.ndarray) -> np.ndarray:
        calls.append(obs.shape)
        return actor(obs)

    spec = from_callable(one, observation="route", decision_interval_s=1.0, batched=False)
    obs = observations(ObservationMode.ROUTE, 5)
    np.testing.assert_allclose(spec.act(obs), actor(obs), atol=1e-6)
    assert calls == [(24,)] * 5


# ------------------------------------------------------------------------------ the shipped team's figures


def test_a_shipped_actor_as_a_stated_callable_flies_the_shipped_teams_figures_at_its_interval(tmp_path: Path):
    """The same missions, figures, intervals and JSON keys as evaluate --models models/tssac, with the decoy given as a
    plain function (no attributes) whose observation and interval are stated: asked once per second, not per step."""
    actor = load_policy(SHIPPED / "decoy.pt")  # the actor --models flies (the .npz acts alike to 1e-6, not 0)
    batches: list[int] = []

    def decoy(obs: np.ndarray) -> np.ndarray:
        batches.append(len(obs))
        return actor(obs)

    spec = from_callable(decoy, observation="route", decision_interval_s=1.0)
    ours = evaluate_policy({"decoy": spec}, STRIKE, episodes=1, seed=3, team=SHIPPED, progress=False)
    out = tmp_path / "shipped.json"
    argv = ["--models", str(SHIPPED), "--scenario", str(STRIKE), "--episodes", "1", "--seed", "3", "--no-progress"]
    assert run(evaluate_main, [*argv, "--json", str(out)]) == 0
    shipped = json.loads(out.read_text())
    for key in ("success_rate", "success_interval95", "mean_cost", "mean_cost_interval95", "episodes", "roles"):
        assert ours[key] == shipped[key], key
    assert set(ours) == set(shipped) | {"policies"}
    assert ours["success_rate"] == 1.0
    steps = round(ours["mean_mission_time_s"] / 0.1)
    assert abs(len(batches) - 1 - steps / 10) <= 1  # the probe's call, then one per second of flight
    assert ours["policies"] == {"decoy": {"policy": "decoy", "observation": "route", "decision_interval_s": 1.0}}
    assert ours["controller"] == f"decoy=decoy, others={SHIPPED}"


# ------------------------------------------------------------------------------ torch and ONNX


def test_a_torch_sequential_evaluates_and_exports_to_an_onnx_actor_that_acts_alike(tmp_path: Path):
    module = mlp()
    with torch.no_grad():
        module[-1].weight.mul_(20.0)  # actions beyond [-1, 1], which the world clips
    spec = from_torch(module, observation="route", decision_interval_s=1.0, role="detect")
    assert spec.layers is not None and len(spec.layers) == 5
    path = write_onnx_actor(spec, "detect", tmp_path)
    actor = OnnxPolicy.load(path, "detect")
    assert (actor.observation_mode, actor.action_repeat) == (ObservationMode.ROUTE, 10)
    assert actor.meta["source"] == "Sequential"
    obs = observations(ObservationMode.ROUTE, 2000)
    with torch.no_grad():
        want = np.clip(module(torch.as_tensor(obs)).numpy(), -1, 1)  # the world clips an unsquashed action
    assert np.abs(want).max() == 1.0  # the clip is exercised
    np.testing.assert_allclose(actor.act(obs), want, atol=1e-5)
    assert "files match" in check_command(tmp_path)


def test_a_torch_module_that_returns_a_tuple_is_one_line():
    class MeanAndLogStd(nn.Module):  # CleanRL's SAC Actor.forward: (mean, log_std)
        def __init__(self) -> None:
            super().__init__()
            self.net = mlp()

        def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
            mean = self.net(x)
            return mean, torch.zeros_like(mean)

    spec = from_torch(MeanAndLogStd(), observation="route", decision_interval_s=1.0)
    assert spec.layers is None  # not a Sequential: evaluated, never exported
    with pytest.raises(PolicyError, match="returns 2 values, not the action tensor"):
        check_policy(spec, Role.DECOY, 0.1)


def test_an_onnx_graph_from_elsewhere_gets_its_metadata_stated(tmp_path: Path):
    foreign = tmp_path / "policy.onnx"
    layers = torch_layers(mlp(22, squash=True))
    assert layers is not None
    model = mlp_model(layers, {}, "foreign")  # no TSSAC metadata
    foreign.write_bytes(model.SerializeToString())
    with pytest.raises(PolicyError, match="say which role it flies"):
        from_onnx(foreign, "extended", 1.0)
    with pytest.raises(PolicyError, match="state the decision_interval_s="):
        from_onnx(foreign, "extended", role="strike")
    spec = from_onnx(foreign, "extended", 0.5, role="strike")
    written = write_onnx_actor(spec, "strike", tmp_path / "team")
    props = {p.key: p.value for p in onnx.load(str(written)).metadata_props}
    assert (props["role"], props["observation_mode"], props["action_repeat"]) == ("strike", "extended", "5")
    obs = observations(ObservationMode.EXTENDED, 300)
    np.testing.assert_allclose(OnnxPolicy.load(written).act(obs), spec.act(obs), atol=1e-6)
    # a TSSAC actor says its own, and a different word is refused
    with pytest.raises(PolicyError, match="you said observation 'route', its metadata says 'extended'"):
        from_onnx(written, observation="route")
    with pytest.raises(PolicyError, match="trained as the strike UAV, asked to fly the decoy"):
        check_policy(from_onnx(written), Role.DECOY, 0.1)


def test_a_plain_callable_has_no_network_to_export(tmp_path: Path):
    spec = from_callable(zeros, observation="route", decision_interval_s=1.0)
    with pytest.raises(PolicyError, match="no network to write as ONNX"):
        write_onnx_actor(spec, "decoy", tmp_path)
    assert not list(tmp_path.iterdir())  # nothing written


def test_a_graph_that_would_fly_another_controller_is_never_written(tmp_path: Path):
    module = mlp()
    spec = from_torch(module, observation="route", decision_interval_s=1.0)
    lying = PolicySpec(lambda obs: spec.act(obs) * 0.5, spec.observation_mode, 1.0, "lying", layers=spec.layers)
    with pytest.raises(PolicyError, match="its ONNX graph's actions differ from the policy's"):
        write_onnx_actor(lying, "decoy", tmp_path)
    assert not (tmp_path / "decoy.onnx").exists()


# ------------------------------------------------------------------------------ Stable-Baselines3


@pytest.fixture(scope="module")
def sb3_models(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Untrained SB3 models saved to files (the path does not depend on training): PPO and SAC on the decoy's route
    env, PPO on the extended one and on gymnasium's Pendulum."""
    from stable_baselines3 import PPO, SAC

    out = tmp_path_factory.mktemp("sb3")
    route = gym.make("tssac/Decoy-v0", teammates="none")
    extended = gym.make("tssac/Decoy-v0", teammates="none", observation="extended")
    models = {"ppo": PPO("MlpPolicy", route, seed=0), "sac": SAC("MlpPolicy", route, buffer_size=100, seed=0)}
    models["ppo_extended"] = PPO("MlpPolicy", extended, seed=0)
    models["pendulum"] = PPO("MlpPolicy", gym.make("Pendulum-v1"), seed=0)  # another env's spaces
    paths = {}
    for name, model in models.items():
        model.save(out / f"{name}.zip")
        paths[name] = out / f"{name}.zip"
    return paths


@pytest.mark.parametrize("name", ["ppo", "sac"])
def test_an_sb3_model_acts_as_its_predict_and_exports_alike(sb3_models: dict[str, Path], name: str, tmp_path: Path):
    from stable_baselines3 import PPO, SAC

    model = (PPO if name == "ppo" else SAC).load(sb3_models[name], device="cpu")
    spec = from_sb3(sb3_models[name], decision_interval_s=1.0)
    assert spec.observation_mode is ObservationMode.ROUTE  # read from the saved observation space
    obs = observations(ObservationMode.ROUTE, 500)
    np.testing.assert_array_equal(spec.act(obs), model.predict(obs, deterministic=True)[0])
    path = write_onnx_actor(spec, "decoy", tmp_path)
    np.testing.assert_allclose(OnnxPolicy.load(path).act(obs), model.predict(obs, deterministic=True)[0], atol=1e-5)


def test_an_sb3_model_is_checked_against_the_env(sb3_models: dict[str, Path], tmp_path: Path):
    with pytest.raises(PolicyError, match="state the decision_interval_s="):
        from_sb3(sb3_models["ppo"])
    with pytest.raises(PolicyError, match="its saved observation space says 'extended'"):
        from_sb3(sb3_models["ppo_extended"], observation="route", decision_interval_s=1.0)
    env = gym.make("tssac/Strike-v0", action_repeat=5)
    said = "the env it was trained on said observation 'route', its saved observation space says 'extended'"
    with pytest.raises(PolicyError, match=said):
        from_sb3(sb3_models["ppo_extended"], env=env)
    bad = tmp_path / "not-a-model.zip"
    bad.write_bytes(b"PK\x03\x04 not really")
    with pytest.raises(PolicyError, match="not a readable Stable-Baselines3 model"):
        from_sb3(bad, decision_interval_s=1.0)


def test_a_model_trained_behind_vecnormalize_is_refused(tmp_path: Path):
    from stable_baselines3 import PPO
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    venv = VecNormalize(DummyVecEnv([lambda: gym.make("tssac/Decoy-v0", teammates="none")]))
    model = PPO("MlpPolicy", venv, n_steps=8, batch_size=8, n_epochs=1, seed=0)
    model.learn(total_timesteps=8)
    model.save(tmp_path / "normalized.zip")
    with pytest.raises(PolicyError, match="trained behind VecNormalize"):
        from_sb3(tmp_path / "normalized.zip", decision_interval_s=1.0)


# ------------------------------------------------------------------------------ the command line


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--policy", "decoy=sb3:{ppo}"], "state the decision_interval_s="),
        (
            ["--policy", "decoy=sb3:{pendulum}", "--observation", "route", "--decision-interval-s", "1"],
            "trained on observations of shape (3,), the 'route' observation has (24,)",
        ),
        (["--policy", "pilot=sb3:{ppo}"], "'pilot' is not decoy, detect or strike"),
        (["--policy", "decoy=keras:{ppo}"], "expected [ROLE=]KIND:FILE"),
        (["--policy", "sb3:{ppo}", "--policy", "decoy=sb3:{ppo}"], "one policy per role"),
        (["--observation", "route"], "describe a --policy"),
        (["--policy", "decoy=sb3:{ppo}", "--decision-interval-s", "0.25"], "0.25 s is not a whole number"),
        (["--policy", "decoy=sb3:{ppo}", "--decision-interval-s", "nan"], "--decision-interval-s must be a positive"),
        (["--policy", "decoy=onnx:missing.onnx"], "missing.onnx: ONNX file not found"),
        (["--policy", "decoy=torch:{ppo}", "--decision-interval-s", "1"], "not a loadable torch module"),
    ],
)
def test_bad_policies_on_the_command_line_are_one_line(sb3_models: dict[str, Path], capsys, argv, needle: str):
    argv = [a.format(**{k: str(v) for k, v in sb3_models.items()}) for a in argv]
    assert run(evaluate_main, [*argv, "--models", str(SHIPPED), "--episodes", "1", "--no-progress"]) == 2
    captured = capsys.readouterr()
    assert needle in one_error_line(captured.err) and captured.out == ""


def test_the_team_directory_holds_the_policy_beside_the_shipped_roles(sb3_models: dict[str, Path], tmp_path: Path):
    spec = from_sb3(sb3_models["ppo"], decision_interval_s=1.0, role="decoy")
    written = export_team(tmp_path / "team", {"decoy": spec}, team=SHIPPED)
    assert sorted(p.name for p in written) == ["decoy.onnx", "detect.onnx", "strike.onnx"]
    assert OnnxPolicy.load(tmp_path / "team" / "decoy.onnx").meta["source"] == str(sb3_models["ppo"])
    assert OnnxPolicy.load(tmp_path / "team" / "strike.onnx").meta["source"] == "strike.npz"
    assert "files match" in check_command(tmp_path / "team")
    with pytest.raises(PolicyError, match="trained as the decoy UAV, asked to fly the strike"):
        export_team(tmp_path / "other", {"strike": spec}, team=SHIPPED)
    with pytest.raises(Exception, match="no policy for the detect UAV"):
        export_team(tmp_path / "alone", {"decoy": spec})
