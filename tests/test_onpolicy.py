"""Tests of the on-policy baselines: GAE, PPO's loss, log-probs of stored actions, CPO's solver and
step, the PPO-Lag multiplier, and the training loop's on-policy outputs and resume."""

from __future__ import annotations

import csv
import dataclasses
import math
import pickle
from pathlib import Path

import numpy as np
import pytest
import torch
from tqdm import tqdm

from tssac_core.algos.networks import SquashedGaussianActor
from tssac_core.algos.onpolicy.cpo import (
    FEASIBLE_ACTIVE,
    FEASIBLE_INTERIOR,
    INFEASIBLE,
    RECOVERABLE,
    Cpo,
    conjugate_gradient,
    constraint_value,
    cpo_step,
    fisher_vector_product,
    line_search_accepts,
)
from tssac_core.algos.onpolicy.gae import gae
from tssac_core.algos.onpolicy.ppo import (
    OnPolicyAlgo,
    OnPolicyBatch,
    OnPolicyConfig,
    Ppo,
    clipped_surrogate_loss,
    gaussian_kl,
    lagrangian_advantage,
    log_prob_of_actions,
    sample_actions,
    squashed_gaussian_log_prob,
)
from tssac_core.deploy.policy import Policy, read_checkpoint
from tssac_core.sim.scenario import Radar, Role, load
from tssac_core.train.config import TrainConfig, onpolicy_config
from tssac_core.train.learners import measured_episode_cost
from tssac_core.train.loop import train_role
from tssac_core.train.rundir import METRIC_FIELDS

torch.set_num_threads(1)

SMALL = (16, 16)


def t64(*values: float) -> torch.Tensor:
    return torch.tensor(values, dtype=torch.float64)


# --- GAE --------------------------------------------------------------------------------------------


def test_gae_by_hand_with_a_terminal_and_a_truncation_inside():
    """gamma = lam = 0.5, one world, 5 steps: terminal at t=1, truncation at t=3, bootstrap at t=4.

    delta = r + gamma (1 - term) V(s') - V(s):  [1 + 1 - 1, 1 - 2, 1 + 2 - 3, 1 + 5 - 4, 1 + 3 - 5]
          = [1, -1, 0, 2, -1]
    A_4 = -1;  A_3 = 2 (episode ended);  A_2 = 0 + 0.25 * 2 = 0.5;  A_1 = -1 (ended);
    A_0 = 1 + 0.25 * (-1) = 0.75;  R = A + V.
    """
    rewards = t64(1, 1, 1, 1, 1)[:, None]
    values = t64(1, 2, 3, 4, 5)[:, None]
    # V(s'_t): s'_0 = s_1; s'_1 terminal (its value 100 must be ignored); s'_2 = s_3;
    # s'_3 the final observation of the truncated episode (V = 10); s'_4 the bootstrap state (V = 6).
    next_values = t64(2, 100, 4, 10, 6)[:, None]
    terminated = torch.tensor([0, 1, 0, 0, 0], dtype=torch.bool)[:, None]
    ended = torch.tensor([0, 1, 0, 1, 0], dtype=torch.bool)[:, None]
    adv, ret = gae(rewards, values, next_values, terminated, ended, gamma=0.5, lam=0.5)
    torch.testing.assert_close(adv[:, 0], t64(0.75, -1, 0.5, 2, -1))
    torch.testing.assert_close(ret[:, 0], t64(1.75, 1, 3.5, 6, 4))


def test_gae_lambda_one_without_ends_is_the_bootstrapped_discounted_return():
    g = torch.Generator().manual_seed(0)
    T, N, gamma = 7, 3, 0.9
    rewards = torch.randn(T, N, generator=g, dtype=torch.float64)
    values = torch.randn(T, N, generator=g, dtype=torch.float64)
    bootstrap = torch.randn(N, generator=g, dtype=torch.float64)
    next_values = torch.cat([values[1:], bootstrap[None]])
    no = torch.zeros(T, N, dtype=torch.bool)
    _, ret = gae(rewards, values, next_values, no, no, gamma=gamma, lam=1.0)
    for t in range(T):
        naive = sum(gamma**k * rewards[t + k] for k in range(T - t)) + gamma ** (T - t) * bootstrap
        torch.testing.assert_close(ret[t], naive)


# --- PPO --------------------------------------------------------------------------------------------


def test_clipped_surrogate_by_hand_on_both_clip_sides():
    """clip 0.2, log pi_old = 0, ratios [1.5, 0.5, 1.1, 0.7, 1.5], advantages [1, -1, 2, 1, -1]:
    min(ratio A, clip(ratio) A) = [1.2 (upper clip), -0.8 (lower clip), 2.2, 0.7, -1.5 (not clipped:
    it hurts)], loss = -mean = -1.8 / 5 = -0.36; clipped samples pass no gradient."""
    ratio = t64(1.5, 0.5, 1.1, 0.7, 1.5)
    log_pi_new = ratio.log().requires_grad_(True)
    adv = t64(1, -1, 2, 1, -1)
    loss = clipped_surrogate_loss(log_pi_new, torch.zeros(5, dtype=torch.float64), adv, clip=0.2)
    torch.testing.assert_close(loss, torch.tensor(-0.36, dtype=torch.float64))
    loss.backward()
    # d loss / d log_pi = -ratio A / n where unclipped, 0 where clipped.
    torch.testing.assert_close(log_pi_new.grad, t64(0, 0, -2.2 / 5, -0.7 / 5, 1.5 / 5))


def test_lagrangian_advantage_by_hand():
    torch.testing.assert_close(lagrangian_advantage(t64(2.0, 0.0), t64(1.0, 3.0), 3.0), t64(-0.25, -2.25))
    torch.testing.assert_close(lagrangian_advantage(t64(2.0), t64(1.0), 0.0), t64(2.0))


def test_log_prob_of_stored_actions_equals_the_actors_log_prob():
    torch.manual_seed(0)
    actor = SquashedGaussianActor(5, 2, SMALL).double()
    obs = torch.randn(64, 5, dtype=torch.float64)
    actions, log_pi = actor(obs)
    torch.testing.assert_close(log_prob_of_actions(actor, obs, actions), log_pi, rtol=1e-7, atol=1e-7)
    # float32 too, for actions away from saturation (atanh loses precision next to +-1).
    actor32 = SquashedGaussianActor(5, 2, SMALL)
    obs32 = torch.randn(64, 5)
    a32, lp32 = actor32(obs32)
    inside = a32.abs().max(dim=-1).values < 0.99
    assert inside.sum() > 30
    torch.testing.assert_close(log_prob_of_actions(actor32, obs32, a32)[inside], lp32[inside], rtol=1e-4, atol=1e-4)


def test_saturated_actions_get_finite_log_probs_and_rollout_ratios_start_at_one():
    mean, log_std = torch.zeros(3, 2), torch.zeros(3, 2)
    actions = torch.tensor([[1.0, -1.0], [0.0, 1.0], [0.5, -0.5]])
    assert torch.isfinite(squashed_gaussian_log_prob(mean, log_std, actions)).all()
    torch.manual_seed(1)
    actor = SquashedGaussianActor(4, 2, SMALL)
    obs = torch.randn(32, 4) * 50  # large inputs: many saturated actions
    a, log_pi = sample_actions(actor, obs)
    torch.testing.assert_close(log_prob_of_actions(actor, obs, a), log_pi)


def random_batch(
    seed: int, n: int = 64, obs_dim: int = 4, cost_rate: float = 0.3
) -> tuple[SquashedGaussianActor, OnPolicyBatch]:
    """An actor and a batch of its own actions with random advantages and returns."""
    torch.manual_seed(seed)
    actor = SquashedGaussianActor(obs_dim, 2, SMALL)
    obs = torch.randn(n, obs_dim)
    actions, log_pi = sample_actions(actor, obs)
    g = torch.Generator().manual_seed(seed)
    adv_c = (torch.rand(n, generator=g) < cost_rate).float() * torch.randn(n, generator=g)
    batch = OnPolicyBatch(
        obs,
        actions,
        log_pi,
        torch.randn(n, generator=g),
        adv_c,
        torch.randn(n, generator=g),
        torch.rand(n, generator=g),
    )
    return actor, batch


def test_ppo_lag_multiplier_rises_above_the_limit_falls_below_and_stays_non_negative():
    config = OnPolicyConfig(
        algo=OnPolicyAlgo.PPO_LAG, hidden_sizes=SMALL, epochs=1, minibatch=32, cost_limit=3.0, beta_lr=0.1
    )
    actor, batch = random_batch(2)
    learner = Ppo(4, 2, config)
    learner.actor.load_state_dict(actor.state_dict())
    lams = [learner.update(batch, episode_cost=10.0).multiplier for _ in range(5)]
    assert lams[0] > 0.0 and all(b > a for a, b in zip(lams, lams[1:]))
    assert learner.multiplier.beta.item() == pytest.approx(0.5, abs=0.05)  # Adam: ~beta_lr per step
    # Below the limit it falls (after Adam's momentum has turned) down to 0 and stays there.
    falling = [learner.update(batch, episode_cost=0.0).multiplier for _ in range(30)]
    assert falling[-1] == 0.0 and falling[-2] == 0.0 and min(falling) >= 0.0
    assert all(b <= a for a, b in zip(falling[5:], falling[6:]))
    plain = Ppo(4, 2, OnPolicyConfig(hidden_sizes=SMALL, epochs=1))
    assert math.isnan(plain.update(batch, episode_cost=10.0).multiplier)


def test_ppo_update_stops_at_target_kl_and_keeps_its_state_through_a_round_trip():
    actor, batch = random_batch(3)
    config = OnPolicyConfig(
        algo=OnPolicyAlgo.PPO_LAG, hidden_sizes=SMALL, epochs=50, minibatch=16, lr=1e-2, target_kl=0.01
    )
    learner = Ppo(4, 2, config)
    learner.actor.load_state_dict(actor.state_dict())
    stats = learner.update(batch, episode_cost=5.0)
    assert 0 < stats.policy_steps < 50 * 4  # stopped early
    assert stats.approx_kl > 0.01
    other = Ppo(4, 2, config)
    other.load_state_dict(learner.state_dict())
    obs = np.random.default_rng(0).normal(size=(5, 4)).astype(np.float32)
    np.testing.assert_array_equal(other.act(obs, deterministic=True), learner.act(obs, deterministic=True))
    assert other.multiplier.beta.item() == learner.multiplier.beta.item() > 0.0


# --- CPO --------------------------------------------------------------------------------------------


def test_conjugate_gradient_solves_an_spd_system():
    g = torch.Generator().manual_seed(4)
    m = torch.randn(6, 6, generator=g, dtype=torch.float64)
    A = m @ m.T + 0.5 * torch.eye(6, dtype=torch.float64)
    b = torch.randn(6, generator=g, dtype=torch.float64)
    x = conjugate_gradient(lambda v: A @ v, b, iters=6, tol=1e-12)  # exact in n steps
    torch.testing.assert_close(x, torch.linalg.solve(A, b))
    few = conjugate_gradient(lambda v: A @ v, b, iters=2)
    assert torch.linalg.norm(A @ few - b) < torch.linalg.norm(b)  # fewer iterations still reduce the residual


H = torch.tensor([[2.0, 0.5], [0.5, 1.0]], dtype=torch.float64)
DELTA = 0.01


def best_in_trust_region(g: torch.Tensor, b: torch.Tensor, c: float) -> tuple[float | None, float]:
    """Brute force over the ellipse 1/2 x^T H x <= delta: the best g^T x with c + b^T x <= 0 (None if
    no point satisfies it), and the smallest c + b^T x."""
    L = torch.linalg.cholesky(H)
    theta = torch.linspace(0, 2 * math.pi, 2001, dtype=torch.float64)
    rho = torch.linspace(0, 1, 401, dtype=torch.float64)
    z = math.sqrt(2 * DELTA) * torch.stack([torch.outer(rho, theta.cos()), torch.outer(rho, theta.sin())], -1).reshape(
        -1, 2
    )
    x = torch.linalg.solve_triangular(L.T, z.T, upper=True).T  # H = L L^T, x = L^-T z
    constraint = x @ b + c
    feasible = constraint <= 0
    return ((x[feasible] @ g).max().item() if feasible.any() else None), constraint.min().item()


@pytest.mark.parametrize(
    "b, c, case, binds",
    [
        ((1.0, 1.0), -0.02, FEASIBLE_ACTIVE, True),  # feasible, the reward step would cross the constraint
        ((1.0, 1.0), 0.05, RECOVERABLE, True),  # infeasible now, part of the region is feasible
        ((-1.0, 2.0), 0.3, RECOVERABLE, True),  # r < 0: the reward step lowers the cost, but not enough
        ((1.0, 1.0), 0.0, RECOVERABLE, True),  # on the boundary
        ((1.0, 1.0), -0.3, FEASIBLE_INTERIOR, False),  # the whole trust region is feasible
        ((-1.0, 2.0), -0.02, FEASIBLE_ACTIVE, False),  # r < 0, feasible: the constraint stays slack
        ((-1.0, -0.2), 0.05, RECOVERABLE, False),  # infeasible, but the reward step itself recovers
    ],
)
def test_cpo_step_solves_the_constrained_problem(b, c, case, binds):
    """On max g^T x s.t. c + b^T x <= 0, 1/2 x^T H x <= delta, CPO's step is feasible and as good as a
    brute-force search; where the plain trust-region step would violate the constraint it differs from
    it, elsewhere it is that step (nu = 0)."""
    g = t64(1.0, 0.0)
    b_t = t64(*b)
    Hinv_g, Hinv_b = torch.linalg.solve(H, g), torch.linalg.solve(H, b_t)
    solution = cpo_step(g, b_t, Hinv_g, Hinv_b, c, DELTA)
    x = solution.step
    assert solution.case == case
    assert (c + b_t @ x).item() <= 1e-9
    assert (0.5 * x @ H @ x).item() <= DELTA * (1 + 1e-9)
    best, _ = best_in_trust_region(g, b_t, c)
    assert best is not None
    assert (g @ x).item() == pytest.approx(best, abs=2e-4)  # as good as the best feasible point found
    unconstrained = math.sqrt(2 * DELTA / (g @ Hinv_g).item()) * Hinv_g
    assert ((c + b_t @ unconstrained).item() > 0.0) == binds
    if binds:
        assert solution.nu > 0.0
    else:
        torch.testing.assert_close(x, unconstrained)
        assert solution.nu == 0.0


def test_cpo_infeasible_case_takes_the_recovery_step():
    g, b, c = t64(1.0, 0.0), t64(1.0, 1.0), 0.3
    Hinv_g, Hinv_b = torch.linalg.solve(H, g), torch.linalg.solve(H, b)
    best, min_constraint = best_in_trust_region(g, b, c)
    assert best is None and min_constraint > 0.0  # no point of the trust region is feasible
    solution = cpo_step(g, b, Hinv_g, Hinv_b, c, DELTA)
    assert solution.case == INFEASIBLE
    x = solution.step
    torch.testing.assert_close(x, -math.sqrt(2 * DELTA / (b @ Hinv_b).item()) * Hinv_b)
    assert (0.5 * x @ H @ x).item() == pytest.approx(DELTA)
    assert (c + b @ x).item() == pytest.approx(min_constraint, abs=1e-4)  # the largest cost decrease


def test_line_search_conditions():
    assert line_search_accepts(kl=0.005, surr_r_gain=0.1, surr_c_rise=0.01, c=-0.02, max_kl=0.01, case=FEASIBLE_ACTIVE)
    assert not line_search_accepts(
        kl=0.02, surr_r_gain=0.1, surr_c_rise=0.0, c=-0.02, max_kl=0.01, case=FEASIBLE_ACTIVE
    )
    assert not line_search_accepts(
        kl=0.005, surr_r_gain=-0.1, surr_c_rise=0.0, c=-0.02, max_kl=0.01, case=FEASIBLE_ACTIVE
    )
    assert not line_search_accepts(
        kl=0.005, surr_r_gain=0.1, surr_c_rise=0.03, c=-0.02, max_kl=0.01, case=FEASIBLE_ACTIVE
    )
    # infeasible: the reward may fall, the cost may not rise
    assert line_search_accepts(kl=0.005, surr_r_gain=-0.1, surr_c_rise=-0.01, c=0.05, max_kl=0.01, case=INFEASIBLE)
    assert not line_search_accepts(kl=0.005, surr_r_gain=0.1, surr_c_rise=0.001, c=0.05, max_kl=0.01, case=RECOVERABLE)
    assert not line_search_accepts(
        kl=math.nan, surr_r_gain=0.1, surr_c_rise=0.0, c=-1.0, max_kl=0.01, case=FEASIBLE_INTERIOR
    )


def test_constraint_value_is_per_decision():
    assert constraint_value(episode_cost=13.0, cost_limit=3.0, episode_length=500.0) == pytest.approx(0.02)
    assert measured_episode_cost([(2.0, 100), (4.0, 300)], np.zeros((3, 2)), 4000) == (3.0, 200.0)
    # no finished episode: cost per decision x the cap
    assert measured_episode_cost([], np.array([[0.0, 1.0], [0.0, 0.0]]), 400) == (100.0, 400.0)


def test_fisher_vector_product_is_the_hessian_of_the_kl():
    torch.manual_seed(5)
    actor = SquashedGaussianActor(3, 2, (4,)).double()
    obs = torch.randn(10, 3, dtype=torch.float64)
    params = list(actor.parameters())
    shapes = [p.shape for p in params]
    theta0 = torch.cat([p.detach().reshape(-1) for p in params])
    with torch.no_grad():
        mean_old, log_std_old = actor.mean_log_std(obs)

    def kl_of(theta: torch.Tensor) -> torch.Tensor:
        tensors, offset = [], 0
        for shape in shapes:
            n = math.prod(shape)
            tensors.append(theta[offset : offset + n].reshape(shape))
            offset += n
        names = [name for name, _ in actor.net.named_parameters()]  # the actor's parameters are its MLP's
        mean, log_std = torch.func.functional_call(actor.net, dict(zip(names, tensors)), (obs,), strict=True).chunk(
            2, dim=-1
        )
        return gaussian_kl(mean_old, log_std_old, mean, log_std.clamp(-20, 2)).mean()

    hessian = torch.autograd.functional.hessian(kl_of, theta0)
    fvp = fisher_vector_product(actor, obs, damping=0.1)
    v = torch.randn(theta0.numel(), dtype=torch.float64)
    torch.testing.assert_close(fvp(v), hessian @ v + 0.1 * v)


def test_cpo_update_keeps_the_trust_region_and_lowers_the_cost_surrogate_when_infeasible():
    actor, batch = random_batch(6, n=128, cost_rate=0.5)
    config = OnPolicyConfig(algo=OnPolicyAlgo.CPO, hidden_sizes=SMALL, epochs=1, max_kl=0.01)
    learner = Cpo(4, 2, config)
    learner.actor.load_state_dict(actor.state_dict())
    stats = learner.update(batch, episode_cost=20.0, episode_length=100.0)  # c = 0.17 per decision: infeasible
    assert stats.cpo_case in (INFEASIBLE, RECOVERABLE) and stats.step_fraction > 0.0
    assert 0.0 < stats.approx_kl <= 0.01
    with torch.no_grad():
        ratio = torch.exp(log_prob_of_actions(learner.actor, batch.observations, batch.actions) - batch.log_pi_old)
        adv_c = batch.adv_c - batch.adv_c.mean()
        assert (ratio * adv_c).mean().item() < 0.0  # the cost surrogate went down
        mean0, log_std0 = actor.mean_log_std(batch.observations)
        mean1, log_std1 = learner.actor.mean_log_std(batch.observations)
        assert gaussian_kl(mean0, log_std0, mean1, log_std1).mean().item() == pytest.approx(stats.approx_kl)
    feasible = Cpo(4, 2, config)
    feasible.actor.load_state_dict(actor.state_dict())
    stats = feasible.update(batch, episode_cost=0.0, episode_length=100.0)
    assert stats.cpo_case in (FEASIBLE_ACTIVE, FEASIBLE_INTERIOR) and stats.approx_kl <= 0.01


# --- training ---------------------------------------------------------------------------------------


def tiny_config(algo: str, epochs: int = 2) -> TrainConfig:
    root = Path(__file__).resolve().parent.parent
    return TrainConfig(
        algo=algo,
        scenario=str(root / "scenarios" / "strike.yaml"),
        seed=7,
        epochs=epochs,
        steps_per_epoch=200,
        roles=("decoy",),
        envs=2,
        threads=1,
        validation_episodes=2,
        learner={"hidden_sizes": [16, 16], "minibatch": 64, "epochs": 4},
    )


def rows(out: Path) -> list[dict[str, str]]:
    with (out / "metrics.csv").open() as fh:
        return list(csv.DictReader(fh))


@pytest.mark.parametrize("algo", ["ppo", "ppo_lag", "cpo"])
def test_tiny_run_writes_metrics_and_a_deployable_checkpoint(algo, tmp_path):
    # On scenarios/short.yaml: the validation missions, flown to the end by an untrained policy, are 600 steps there
    # (strike.yaml's are 4000), and what is checked does not depend on the mission.
    cfg = dataclasses.replace(tiny_config(algo), scenario=str(Path(tiny_config(algo).scenario).with_name("short.yaml")))
    scenario = load(cfg.scenario)
    train_role(cfg, scenario, Role.DECOY, tmp_path, resume=False, bar=tqdm(disable=True))
    r = rows(tmp_path)
    assert list(r[0]) == METRIC_FIELDS
    assert [(x["role"], int(x["epoch"]), int(x["env_steps"])) for x in r] == [("decoy", 1, 200), ("decoy", 2, 400)]
    for x in r:
        for key in ("q_r_loss", "q_c_loss", "actor_loss", "entropy", "q_r_mean", "qc_mean"):
            assert math.isfinite(float(x[key])), key
        assert x["alpha"] == "nan" and x["xi"] == "nan"
        assert (x["beta"] != "nan") == (algo == "ppo_lag")
    policy = Policy.load(tmp_path / "decoy.pt", "decoy")
    assert policy.info.algo == algo and policy.info.hidden_sizes == (16, 16) and policy.info.action_repeat == 1
    obs = np.random.default_rng(0).uniform(0, 1, (3, policy.info.obs_dim)).astype(np.float32)
    assert policy.act(obs).shape == (3, 2) and np.abs(policy.act(obs)).max() <= 1.0
    assert read_checkpoint(tmp_path / "decoy.pt")["learner"]["algo"] == algo
    assert (tmp_path / "resume" / "decoy.pt").is_file()


@pytest.mark.parametrize("algo", ["ppo_lag", "cpo"])
def test_resume_continues_exactly_where_the_last_epoch_ended(algo, tmp_path):
    """Episodes capped at 70 steps: several end inside each 100-decision rollout, and one is running
    at every epoch boundary, so the resume state must carry the worlds mid-episode; a small radar at the
    decoy's start makes episode costs vary (and exceed C), so that the measured cost matters."""
    strike = load(tiny_config(algo).scenario)
    assert strike.layout is not None
    layout = dataclasses.replace(strike.layout, radars=(Radar((17.0, 13.0), 1.5), *strike.layout.radars))
    scenario = dataclasses.replace(strike, episode_steps=70, layout=layout)
    straight, split = tmp_path / "straight", tmp_path / "split"
    straight.mkdir()
    split.mkdir()
    train_role(tiny_config(algo, epochs=2), scenario, Role.DECOY, straight, resume=False, bar=tqdm(disable=True))
    train_role(tiny_config(algo, epochs=1), scenario, Role.DECOY, split, resume=False, bar=tqdm(disable=True))
    train_role(tiny_config(algo, epochs=2), scenario, Role.DECOY, split, resume=True, bar=tqdm(disable=True))
    a = read_checkpoint(straight / "decoy.pt")
    b = read_checkpoint(split / "decoy.pt")
    assert all(torch.equal(a["actor"][k], b["actor"][k]) for k in a["actor"])
    assert all(torch.equal(a["learner"]["v_c"][k], b["learner"]["v_c"][k]) for k in a["learner"]["v_c"])
    assert a["metrics"] == b["metrics"]
    timing = {"env_steps_per_s", "updates_per_s"}
    ra, rb = rows(straight), rows(split)
    assert len(ra) == len(rb) == 2
    assert all(int(x["episodes"]) >= 2 and math.isfinite(float(x["return"])) and float(x["cost"]) > 0.0 for x in ra)
    # The whole resume state matches too: worlds, episode lengths, the finished-episode window.
    sa = torch.load(straight / "resume" / "decoy.pt", weights_only=False)
    sb = torch.load(split / "resume" / "decoy.pt", weights_only=False)
    assert sa["learner"]["finished"] == sb["learner"]["finished"] and len(sa["learner"]["finished"]) > 2
    np.testing.assert_array_equal(sa["learner"]["ep_len"], sb["learner"]["ep_len"])
    assert sa["learner"]["ep_len"].max() > 0  # an episode was running at the boundary
    np.testing.assert_array_equal(sa["obs"], sb["obs"])
    (world_a, rng_a, ret_a, cost_a), (world_b, rng_b, ret_b, cost_b) = (
        pickle.loads(sa["task"]),
        pickle.loads(sb["task"]),
    )
    assert rng_a.bit_generator.state == rng_b.bit_generator.state
    np.testing.assert_array_equal(ret_a, ret_b)
    np.testing.assert_array_equal(cost_a, cost_b)
    arrays = [k for k, v in vars(world_a).items() if isinstance(v, np.ndarray)]
    assert arrays
    for k in arrays:
        np.testing.assert_array_equal(getattr(world_a, k), getattr(world_b, k), err_msg=k)
    if algo == "ppo_lag":
        assert (
            sa["learner"]["learner"]["multiplier"]["beta"].item()
            == sb["learner"]["learner"]["multiplier"]["beta"].item()
            > 0.0
        )
    for x, y in zip(ra, rb):
        assert {k: v for k, v in x.items() if k not in timing} == {k: v for k, v in y.items() if k not in timing}


def test_config_from_train_config():
    scenario = load(tiny_config("cpo").scenario)
    config = onpolicy_config(tiny_config("cpo"), scenario)
    assert (
        config.algo is OnPolicyAlgo.CPO and config.hidden_sizes == (16, 16) and config.cost_limit == scenario.cost_limit
    )
    assert config.episode_steps == scenario.episode_steps
    repeat = TrainConfig(algo="ppo", scenario=tiny_config("ppo").scenario, action_repeat=3)
    assert onpolicy_config(repeat, scenario).episode_steps == math.ceil(scenario.episode_steps / 3)
    with pytest.raises(ValueError, match="polyak"):
        onpolicy_config(TrainConfig(algo="ppo", learner={"polyak": 0.9}), scenario)
    with pytest.raises(ValueError, match="not an on-policy"):
        onpolicy_config(TrainConfig(algo="sac"), scenario)
