"""The gymnasium faces of a role (issue 42): gym.make with the shipped team's settings, a shipped actor flown in it,
the Safety-Gymnasium step, and gym.make_vec on the batched world, step for step equal to SyncVectorEnv."""

from __future__ import annotations

import json
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env, data_equivalence
from gymnasium.vector import AutoresetMode

import tssac_core.sim.env  # noqa: F401  (registers tssac/<Role>-v0)
from tssac_core.deploy.numpy_actor import load_policy, team_pilots
from tssac_core.sim.env import UavRoleEnv
from tssac_core.sim.missions import fly_missions
from tssac_core.sim.scenario import ROLES, load
from tssac_core.sim.vector_env import RoleVectorEnv

ROOT = Path(__file__).resolve().parent.parent
MODELS = ROOT / "models" / "tssac"


def test_defaults_are_the_shipped_teams():
    shipped = json.loads((MODELS / "config.json").read_text())
    env = gym.make("tssac/Decoy-v0")
    assert env.unwrapped.mode.value == shipped["observation"]
    assert env.unwrapped.action_repeat == shipped["action_repeat"]
    assert env.observation_space.shape == (load_policy(MODELS / "decoy.npz").obs_dim,)
    check_env(env.unwrapped, skip_render_check=True)


def test_a_step_holds_the_action_for_action_repeat_world_steps():
    held = gym.make("tssac/Detect-v0", action_repeat=5)
    fine = gym.make("tssac/Detect-v0", action_repeat=1)
    held.reset(seed=3)
    fine.reset(seed=3)
    action = np.array([0.3, -0.2], dtype=np.float32)
    for _ in range(4):
        obs, r, term, trunc, info = held.step(action)
        parts = [fine.step(action) for _ in range(5)]
        assert np.array_equal(obs, parts[-1][0])
        assert r == pytest.approx(sum(p[1] for p in parts))
        assert info["cost"] == sum(p[4]["cost"] for p in parts)
    with pytest.raises(ValueError, match="action_repeat"):
        gym.make("tssac/Detect-v0", action_repeat=0)


def test_safe_step_returns_the_cost_in_the_tuple():
    env = gym.make("tssac/Strike-v0", scenario=str(ROOT / "scenarios" / "strike.yaml")).unwrapped
    env.reset(seed=0)
    obs, reward, cost, terminated, truncated, info = env.safe_step(np.zeros(2, dtype=np.float32))
    assert cost == info["cost"] and isinstance(cost, float) and obs.shape == env.observation_space.shape


@pytest.mark.parametrize("role", ["Decoy", "Detect", "Strike"])
def test_the_safety_gymnasium_ids_step_with_the_cost_in_the_tuple(role):
    """tssac/Safe<Role>-v0 is the role's env, its step Safety-Gymnasium's 6-tuple: the plain env's items, cost third."""
    safe = gym.make(f"tssac/Safe{role}-v0", action_repeat=5)
    plain = gym.make(f"tssac/{role}-v0", action_repeat=5)
    assert isinstance(safe.unwrapped, UavRoleEnv) and safe.unwrapped.role.value == role.lower()
    assert safe.observation_space == plain.observation_space and safe.action_space == plain.action_space
    with pytest.raises(Exception, match="reset"):
        safe.step(np.zeros(2, dtype=np.float32))
    assert data_equivalence(safe.reset(seed=5), plain.reset(seed=5))
    rng = np.random.default_rng(1)
    for _ in range(60):
        action = rng.uniform(-1, 1, 2).astype(np.float32)
        obs, reward, cost, terminated, truncated, info = safe.step(action)
        assert data_equivalence((obs, reward, terminated, truncated, info), plain.step(action))
        assert cost == info["cost"] and isinstance(cost, float)
        if terminated or truncated:
            assert data_equivalence(safe.reset(seed=6), plain.reset(seed=6))


def test_the_shipped_decoy_flies_in_gym_make_as_in_evaluate():
    """reset(seed=S + k) is mission k of seed S; the decoy's task comes out the same, mission for mission."""
    seed, missions = 800001, 6
    pilots = [load_policy(MODELS, role) for role in ROLES]
    evaluated = fly_missions(load(ROOT / "scenarios" / "random.yaml"), pilots, missions, seed)
    policy = load_policy(MODELS / "decoy.npz")
    env = gym.make("tssac/Decoy-v0", teammates=team_pilots(MODELS, ["detect", "strike"]))
    flown = []
    for k in range(missions):
        obs, info = env.reset(seed=seed + k)
        terminated = truncated = False
        while not (terminated or truncated):
            obs, reward, terminated, truncated, info = env.step(policy.predict(obs))
        flown.append(info["task_done"])
    assert flown == evaluated.task_done[:, 0].tolist()
    assert any(flown)


def test_load_policy_needs_a_role_for_a_directory():
    from tssac_core.common.errors import CheckpointError

    with pytest.raises(CheckpointError, match="which role"):
        load_policy(MODELS)
    assert load_policy(MODELS, "strike").role.value == "strike"


@pytest.mark.parametrize(
    "mode", [AutoresetMode.SAME_STEP, pytest.param(AutoresetMode.NEXT_STEP, marks=pytest.mark.slow)]
)
def test_make_vec_is_the_batched_world_and_equals_sync_vector_env(mode):
    n = 4
    # Guidance teammates: missions end (the target is hit), so autoreset is compared too.
    kwargs = {} if mode is AutoresetMode.SAME_STEP else {"autoreset_mode": mode}  # SAME_STEP: the default
    vec = gym.make_vec("tssac/Decoy-v0", num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    assert isinstance(vec, RoleVectorEnv) and vec.metadata["autoreset_mode"] is mode
    sync = gym.make_vec("tssac/Decoy-v0", num_envs=n, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode})
    assert vec.observation_space == sync.observation_space and vec.action_space == sync.action_space
    assert data_equivalence(vec.reset(seed=11), sync.reset(seed=11))
    rng = np.random.default_rng(0)
    ended = restarted = 0
    for _ in range(240):  # the first mission ends at step 224 (seed 11)
        actions = rng.uniform(-1, 1, (n, 2)).astype(np.float32)
        a, b = vec.step(actions), sync.step(actions)
        assert data_equivalence(a, b), "the vector env left SyncVectorEnv"
        restarted += int(ended and mode is AutoresetMode.NEXT_STEP and (a[1] == 0).any())
        ended += int((a[2] | a[3]).sum())
    assert ended >= 1  # autoreset was compared too
    assert restarted >= 1 or mode is AutoresetMode.SAME_STEP


def test_next_step_mode_takes_gymnasiums_stateful_wrappers():
    """NormalizeObservation (and NormalizeReward) refuse SAME_STEP; in NEXT_STEP mode they wrap the batched world."""
    from gymnasium.wrappers.vector import NormalizeObservation, NormalizeReward

    with pytest.raises(ValueError, match="NEXT_STEP"):
        NormalizeObservation(gym.make_vec("tssac/Detect-v0", num_envs=2, vectorization_mode="vector_entry_point"))
    vec = gym.make_vec(
        "tssac/Detect-v0",
        num_envs=2,
        vectorization_mode="vector_entry_point",
        autoreset_mode=AutoresetMode.NEXT_STEP,
    )
    env = NormalizeReward(NormalizeObservation(vec))
    env.reset(seed=0)
    for _ in range(5):
        obs, *_ = env.step(np.zeros((2, 2), dtype=np.float32))
    assert obs.shape == (2, 24) and np.isfinite(obs).all()
    with pytest.raises(ValueError, match="autoreset_mode"):
        RoleVectorEnv(num_envs=2, autoreset_mode=AutoresetMode.DISABLED)


def test_make_vec_bad_num_envs():
    with pytest.raises(ValueError, match="num_envs"):
        RoleVectorEnv(num_envs=0)
