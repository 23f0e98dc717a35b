"""Tests of the learner (tssac_core.algos): losses by hand, multiplier, transfer, round trips."""

from __future__ import annotations

import copy
import io
import math

import numpy as np
import pytest
import torch

from tssac_core.algos import losses
from tssac_core.algos.budget import qc_limit
from tssac_core.algos.lagrange import CostSignal, DampedLagrangeMultiplier, SignalRule, choose_signal
from tssac_core.algos.networks import (
    LOG_STD_MAX,
    LOG_STD_MIN,
    Critic,
    SquashedGaussianActor,
    tanh_log_abs_det_jacobian,
)
from tssac_core.algos.onpolicy.ppo import OnPolicyAlgo, OnPolicyConfig, Ppo
from tssac_core.algos.replay import ReplayBuffer, ReplaySamples
from tssac_core.algos.sac_config import MultiplierSignal
from tssac_core.algos.sac_lagrangian import (
    TRANSFERRED_NETWORKS,
    SacConfig,
    SacLagrangian,
    Variant,
    cost_variance,
    transfer,
)

torch.set_num_threads(1)

OBS_DIM, ACT_DIM = 5, 2
SMALL = (32, 32)


def t(*values: float) -> torch.Tensor:
    return torch.tensor(values, dtype=torch.float64)


def small_config(**overrides: object) -> SacConfig:
    """A small learner whose multiplier measures Q^c on the update's batch (what ``update(batch)`` can measure)."""
    fields: dict[str, object] = dict(
        hidden_sizes=SMALL, episode_steps=100, multiplier_signal=MultiplierSignal.Q_C, multiplier_window=None
    )
    fields.update(overrides)
    return SacConfig(**fields)  # type: ignore[arg-type]


def random_batch(seed: int, n: int = 16, obs_dim: int = OBS_DIM) -> ReplaySamples:
    g = torch.Generator().manual_seed(seed)
    return ReplaySamples(
        observations=torch.randn(n, obs_dim, generator=g),
        actions=torch.rand(n, ACT_DIM, generator=g) * 2 - 1,
        rewards=torch.randn(n, generator=g),
        costs=(torch.rand(n, generator=g) < 0.5).float(),
        next_observations=torch.randn(n, obs_dim, generator=g),
        terminated=(torch.rand(n, generator=g) < 0.2).float(),
    )


def all_tensors(agent: SacLagrangian) -> dict[str, torch.Tensor]:
    out = {f"{name}.{key}": value for name, net in agent.networks().items() for key, value in net.state_dict().items()}
    out["alpha"] = agent.alpha.detach()
    out["beta"] = agent.multiplier.beta
    return out


def assert_same_tensors(a: dict[str, torch.Tensor], b: dict[str, torch.Tensor]) -> None:
    assert a.keys() == b.keys()
    for key in a:
        assert torch.equal(a[key], b[key]), key


# --- losses, against values computed by hand -------------------------------------------------


def test_soft_value_and_critic_target_by_hand() -> None:
    next_q_r = torch.tensor([[1.0, 4.0], [2.0, 3.0]], dtype=torch.float64)  # (members, batch)
    next_log_pi = t(0.5, -1.0)
    # min over members: [1, 3]; minus alpha * log_pi = 0.2 * [0.5, -1] -> [0.9, 3.2]
    v = losses.soft_value(next_q_r, next_log_pi, torch.tensor(0.2, dtype=torch.float64))
    torch.testing.assert_close(v, t(0.9, 3.2))
    # r + gamma (1 - terminated) V: [1 + 0.9 * 0.9, 0.5 + 0] = [1.81, 0.5]
    y = losses.critic_target(t(1.0, 0.5), t(0.0, 1.0), v, gamma=0.9)
    torch.testing.assert_close(y, t(1.81, 0.5))
    # A truncated (not terminated) transition bootstraps: terminated = 0 for both.
    y_trunc = losses.critic_target(t(1.0, 0.5), t(0.0, 0.0), v, gamma=0.9)
    torch.testing.assert_close(y_trunc, t(1.81, 0.5 + 0.9 * 3.2))
    # Cost critic: no entropy term, V_c = Q_c(s', a'): c + gamma (1 - d) Q_c' = [1 + 0.9*2, 0]
    y_c = losses.critic_target(t(1.0, 0.0), t(0.0, 1.0), t(2.0, 7.0), gamma=0.9)
    torch.testing.assert_close(y_c, t(2.8, 0.0))


def test_critic_loss_by_hand() -> None:
    q = torch.tensor([[1.0, 2.0], [4.0, 1.0]], dtype=torch.float64)
    target = t(2.0, 1.0)
    # member 0: 0.5 * mean(1, 1) = 0.5; member 1: 0.5 * mean(4, 0) = 1.0; sum 1.5
    expected = torch.tensor(1.5, dtype=torch.float64)
    torch.testing.assert_close(losses.critic_loss(q, target), expected)


def test_actor_loss_by_hand() -> None:
    log_pi = t(-1.0, 0.5)
    q_r = torch.tensor([[2.0, 1.0], [3.0, 0.0]], dtype=torch.float64)  # min: [2, 0]
    q_c = t(0.4, 1.0)
    alpha = torch.tensor(0.1, dtype=torch.float64)
    # eq. 12 with beta = 2: [-0.1 - 2 + 0.8, 0.05 - 0 + 2] = [-1.3, 2.05] -> mean 0.375
    loss = losses.actor_loss(log_pi, q_r, q_c, alpha, torch.tensor(2.0, dtype=torch.float64))
    torch.testing.assert_close(loss, torch.tensor(0.375, dtype=torch.float64))
    # eq. 16 with beta - xi = 2 - (-1) = 3: [-0.1 - 2 + 1.2, 0.05 + 3] = [-0.9, 3.05] -> 1.075
    loss16 = losses.actor_loss(log_pi, q_r, q_c, alpha, torch.tensor(3.0, dtype=torch.float64))
    torch.testing.assert_close(loss16, torch.tensor(1.075, dtype=torch.float64))


def test_alpha_loss_by_hand() -> None:
    alpha = torch.tensor(0.3, dtype=torch.float64, requires_grad=True)
    log_pi = torch.tensor([-1.0, 0.5], dtype=torch.float64, requires_grad=True)
    # mean(-log_pi - H0) with H0 = -1: mean(2, 0.5) = 1.25; times 0.3 = 0.375
    loss = losses.alpha_loss(alpha, log_pi, target_entropy=-1.0)
    torch.testing.assert_close(loss, torch.tensor(0.375, dtype=torch.float64))
    loss.backward()
    # Entropy 0.25 above H0 -> positive gradient -> gradient descent lowers alpha.
    torch.testing.assert_close(alpha.grad, torch.tensor(1.25, dtype=torch.float64))
    assert log_pi.grad is None  # log_pi is a constant in eq. 14


def test_multiplier_loss_and_damping_by_hand() -> None:
    beta = torch.tensor(2.0, dtype=torch.float64)
    qc_mean = torch.tensor(0.5, dtype=torch.float64)
    # eq. 15: 2 * (0.3 - 0.5) = -0.4 ; eq. 17: 10 * (0.3 - 0.5) = -2
    torch.testing.assert_close(
        losses.multiplier_loss(beta, qc_mean, cost_limit=0.3),
        torch.tensor(-0.4, dtype=torch.float64),
    )
    torch.testing.assert_close(
        losses.damping(qc_mean, cost_limit=0.3, k_d=10.0), torch.tensor(-2.0, dtype=torch.float64)
    )


# --- networks --------------------------------------------------------------------------------


def test_tanh_correction_matches_naive_formula_and_stays_finite() -> None:
    u = torch.linspace(-4.0, 4.0, 81, dtype=torch.float64)
    naive = torch.log(1.0 - torch.tanh(u) ** 2 + 1e-15)
    torch.testing.assert_close(tanh_log_abs_det_jacobian(u), naive, atol=1e-9, rtol=1e-9)
    # Far in the tails the naive float32 formula saturates at log(eps); the identity does not.
    big = torch.tensor([-30.0, 20.0])
    exact = torch.tensor([2 * math.log(2) - 60.0, 2 * math.log(2) - 40.0])
    torch.testing.assert_close(tanh_log_abs_det_jacobian(big), exact)
    naive32 = torch.log(1.0 - torch.tanh(big) ** 2 + 1e-6)
    assert (naive32 - exact).abs().min() > 20.0


def test_actor_log_prob_is_change_of_variables_of_a_gaussian() -> None:
    torch.manual_seed(0)
    actor = SquashedGaussianActor(OBS_DIM, ACT_DIM, SMALL).double()
    obs = torch.randn(64, OBS_DIM, dtype=torch.float64)
    action, log_pi = actor(obs)
    mean, log_std = actor.mean_log_std(obs)
    u = torch.atanh(action)
    gaussian = torch.distributions.Normal(mean, log_std.exp())
    expected = gaussian.log_prob(u) - torch.log(1 - action**2)
    torch.testing.assert_close(log_pi, expected.sum(-1), atol=1e-6, rtol=1e-6)
    assert action.shape == (64, ACT_DIM) and log_pi.shape == (64,)
    det_action, _ = actor(obs, deterministic=True)
    torch.testing.assert_close(det_action, torch.tanh(mean))


def test_actor_log_std_is_clamped() -> None:
    actor = SquashedGaussianActor(OBS_DIM, ACT_DIM, SMALL)
    with torch.no_grad():
        actor.net[-1].bias[ACT_DIM:] = 100.0
    _, log_std = actor.mean_log_std(torch.zeros(3, OBS_DIM))
    assert torch.all(log_std == LOG_STD_MAX)
    with torch.no_grad():
        actor.net[-1].bias[ACT_DIM:] = -100.0
    _, log_std = actor.mean_log_std(torch.zeros(3, OBS_DIM))
    assert torch.all(log_std == LOG_STD_MIN)


def test_critic_members_are_independent_mlps() -> None:
    torch.manual_seed(0)
    critic = Critic(OBS_DIM, ACT_DIM, SMALL, n_members=2)
    obs, act = torch.randn(7, OBS_DIM), torch.rand(7, ACT_DIM)
    q = critic(obs, act)
    assert q.shape == (2, 7)
    for m in range(2):  # the same member computed with plain matmuls
        h = torch.cat([obs, act], -1)
        for i, (w, b) in enumerate(zip(critic.weights, critic.biases)):
            h = h @ w[m] + b[m]
            h = torch.relu(h) if i < len(critic.weights) - 1 else h
        torch.testing.assert_close(q[m], h.squeeze(-1))
    assert not torch.allclose(q[0], q[1])


# --- the multiplier ---------------------------------------------------------------------------


def test_beta_rises_above_limit_falls_below_and_never_goes_negative() -> None:
    rising = DampedLagrangeMultiplier(cost_limit=0.5, k_d=0.0, beta_init=1.0, lr=0.1)
    falling = DampedLagrangeMultiplier(cost_limit=0.5, k_d=0.0, beta_init=1.0, lr=0.1)
    up, down = [1.0], [1.0]
    for _ in range(10):
        rising.update(torch.tensor(0.9))  # Q^c above the limit
        falling.update(0.1)  # below it
        up.append(float(rising.beta))
        down.append(float(falling.beta))
    assert all(b2 > b1 for b1, b2 in zip(up, up[1:]))
    assert all(b2 < b1 for b1, b2 in zip(down, down[1:]))
    assert down[-1] == pytest.approx(0.0, abs=1e-6)  # reached 0 ...
    for _ in range(100):  # ... and stays there however long the constraint holds
        falling.update(0.1)
        assert float(falling.beta) >= 0.0
    assert float(falling.beta) == 0.0
    # After a long violation Adam's momentum carries beta up a little further, then it falls to 0.
    betas = []
    for _ in range(200):
        rising.update(0.1)
        betas.append(float(rising.beta))
    assert min(betas) == 0.0 and betas[-1] == 0.0


def test_multiplier_update_matches_its_docstring_rule() -> None:
    """First Adam step: step = lr * g / (|g| + eps) = lr * sign(g), g = C - qc_mean = -0.4."""
    m = DampedLagrangeMultiplier(cost_limit=0.5, k_d=0.0, beta_init=1.0, lr=0.1)
    loss = m.update(0.9)
    torch.testing.assert_close(loss, torch.tensor(1.0 * (0.5 - 0.9)))
    torch.testing.assert_close(m.beta, torch.tensor(1.1))


def test_xi_sign_and_magnitude() -> None:
    m = DampedLagrangeMultiplier(cost_limit=0.3, k_d=10.0)
    torch.testing.assert_close(m.damping(0.5), torch.tensor(-2.0))  # violated: xi < 0
    torch.testing.assert_close(m.damping(0.1), torch.tensor(2.0))  # satisfied: xi > 0
    torch.testing.assert_close(m.damping(0.3), torch.tensor(0.0))
    # violated -> effective multiplier beta - xi exceeds beta by k_d (Q^c - C)
    torch.testing.assert_close(m.effective(0.5), m.beta + 2.0)


def test_effective_multiplier_clamping() -> None:
    clamped = DampedLagrangeMultiplier(cost_limit=0.3, k_d=10.0, beta_init=0.5)
    raw = DampedLagrangeMultiplier(cost_limit=0.3, k_d=10.0, beta_init=0.5, clamp_effective=False)
    # Q^c = 0.1 < C: xi = 2, beta - xi = -1.5
    torch.testing.assert_close(raw.effective(0.1), torch.tensor(-1.5))
    torch.testing.assert_close(clamped.effective(0.1), torch.tensor(0.0))
    # above the limit the clamp changes nothing: 0.5 - 10 * (0.3 - 0.5) = 2.5
    torch.testing.assert_close(raw.effective(0.5), torch.tensor(2.5))
    torch.testing.assert_close(clamped.effective(0.5), torch.tensor(2.5))


def _toy_lagrangian_run(k_d: float, steps: int = 1500) -> np.ndarray:
    """max_x r(x) = x s.t. c(x) = x <= 0.5: gradient ascent on x - m c(x), m from eq. 15 (+17)."""
    m = DampedLagrangeMultiplier(cost_limit=0.5, k_d=k_d, beta_init=0.0, lr=0.05)
    x, xs = 0.0, []
    for _ in range(steps):
        x += 0.05 * (1.0 - float(m.effective(x)))  # d/dx [r(x) - m c(x)] = 1 - m
        m.update(x)  # the measured cost c(x) = x
        xs.append(x)
    return np.array(xs)


def test_damped_multiplier_oscillates_less_than_plain_one() -> None:
    plain = _toy_lagrangian_run(k_d=0.0)
    damped = _toy_lagrangian_run(k_d=10.0)
    tail = slice(len(plain) // 2, None)
    plain_amplitude = np.ptp(plain[tail])
    damped_amplitude = np.ptp(damped[tail])
    assert plain_amplitude > 1.0  # the plain multiplier really does oscillate around the limit
    assert damped_amplitude < 0.01 * plain_amplitude
    assert abs(damped[tail].mean() - 0.5) < 0.01  # and the damped one settles on it


def test_qc_limit() -> None:
    # 3 * (1 - 0.9^100) / (0.1 * 100)
    assert qc_limit(3.0, 0.9, 100) == pytest.approx(0.3 * (1 - 0.9**100), rel=1e-12)
    assert qc_limit(3.0, 0.99, 4000) == pytest.approx(0.075, rel=1e-9)
    # it is the discounted sum of the budget spent uniformly, C / T per step
    assert qc_limit(2.0, 0.95, 37) == pytest.approx(sum(0.95**k * 2.0 / 37 for k in range(37)))
    assert qc_limit(3.0, 0.0, 1) == pytest.approx(3.0)
    with pytest.raises(ValueError):
        qc_limit(3.0, 1.0, 10)


# --- the learner ----------------------------------------------------------------------------


def test_config_validation() -> None:
    with pytest.raises(ValueError, match="penalty"):
        SacConfig(variant=Variant.SAC, penalty=-10.0)
    with pytest.raises(ValueError, match="penalty"):
        SacConfig(variant=Variant.SAC_PENALTY, penalty=5.0)
    with pytest.raises(ValueError, match="gamma"):
        SacConfig(gamma=1.0)
    cfg = SacConfig()
    assert cfg.hidden_sizes == (256, 256) and cfg.lr == 1e-3 and cfg.polyak == 0.995
    assert cfg.alpha_init == 0.0 and cfg.beta_init == 0.0 and cfg.k_d == 10.0
    assert cfg.beta_lr > cfg.lr
    assert cfg.qc_limit == pytest.approx(qc_limit(3.0, 0.99, 4000))
    assert cfg.multiplier_signal == "episode_cost"
    with pytest.raises(ValueError, match="multiplier_signal"):
        SacConfig(multiplier_signal="q")
    with pytest.raises(ValueError, match="cost_window"):
        SacConfig(cost_window=0)


def test_act_shapes_and_bounds() -> None:
    torch.manual_seed(0)
    agent = SacLagrangian(OBS_DIM, ACT_DIM, small_config())
    obs = np.random.default_rng(0).normal(size=(4, OBS_DIM)) * 100
    for deterministic in (True, False):
        a = agent.act(obs, deterministic)
        assert a.shape == (4, ACT_DIM) and a.dtype == np.float32
        assert np.all(np.abs(a) <= 1.0)
    assert agent.act(obs[0], True).shape == (ACT_DIM,)
    np.testing.assert_array_equal(agent.act(obs, True), agent.act(obs, True))


def test_variants_multiplier_terms() -> None:
    batch = random_batch(0)
    stats = {}
    for variant in Variant:
        torch.manual_seed(0)
        agent = SacLagrangian(OBS_DIM, ACT_DIM, small_config(variant=variant, beta_init=0.5))
        stats[variant] = agent.update(batch)
    for variant in (Variant.SAC, Variant.SAC_PENALTY):
        s = stats[variant]
        assert s.beta == s.xi == s.beta_minus_xi == s.beta_loss == 0.0
    c = qc_limit(3.0, 0.99, 100)
    lag = stats[Variant.SAC_LAG]
    assert lag.beta == pytest.approx(0.5) and lag.xi == 0.0
    assert lag.beta_minus_xi == pytest.approx(0.5)
    ts = stats[Variant.TSSAC]
    assert ts.cost_signal == ts.qc_mean  # multiplier_signal q_c without a window: Q^c on the batch
    assert ts.xi == pytest.approx(10.0 * (c - ts.qc_mean), rel=1e-5)
    assert ts.beta_minus_xi == pytest.approx(max(0.0, 0.5 - ts.xi), rel=1e-5, abs=1e-7)


def test_sac_penalty_is_sac_on_shaped_rewards() -> None:
    batch = random_batch(1)
    shaped = batch._replace(rewards=batch.rewards + (-15.0) * batch.costs)
    torch.manual_seed(3)
    penalty_config = small_config(variant=Variant.SAC_PENALTY, penalty=-15.0)
    penalised = SacLagrangian(OBS_DIM, ACT_DIM, penalty_config)
    torch.manual_seed(3)
    plain = SacLagrangian(OBS_DIM, ACT_DIM, small_config(variant=Variant.SAC))
    torch.manual_seed(4)
    s_pen = penalised.update(batch)
    torch.manual_seed(4)
    s_plain = plain.update(shaped)
    assert s_pen == s_plain
    torch.manual_seed(4)
    s_unshaped = SacLagrangian(OBS_DIM, ACT_DIM, small_config(variant=Variant.SAC)).update(batch)
    assert s_unshaped.q_r_loss != s_pen.q_r_loss


def test_two_seeded_runs_are_identical() -> None:
    def run() -> tuple[list[object], dict[str, torch.Tensor]]:
        torch.manual_seed(7)
        agent = SacLagrangian(OBS_DIM, ACT_DIM, small_config())
        stats = [agent.update(random_batch(i)) for i in range(3)]
        return stats, all_tensors(agent)

    stats_a, tensors_a = run()
    stats_b, tensors_b = run()
    assert stats_a == stats_b
    assert_same_tensors(tensors_a, tensors_b)


def test_update_changes_what_it_should() -> None:
    torch.manual_seed(0)
    agent = SacLagrangian(OBS_DIM, ACT_DIM, small_config(alpha_init=0.1))
    before = {k: v.clone() for k, v in all_tensors(agent).items()}
    agent.update(random_batch(0))
    after = all_tensors(agent)
    for key in before:
        if key == "beta":
            continue  # may sit at its 0 projection
        assert not torch.equal(before[key], after[key]), key
    # Polyak: target <- 0.995 target + 0.005 online (the online weights after their step).
    for key in before:
        if "_target." not in key:
            continue
        online_key = key.replace("_target.", ".")
        assert torch.equal(before[key], before[online_key])  # targets start as copies
        expected = 0.995 * before[key].double() + 0.005 * after[online_key].double()
        torch.testing.assert_close(after[key].double(), expected, atol=1e-7, rtol=0)
        assert not torch.allclose(after[key], after[online_key])


def test_state_dict_round_trip_gives_same_actions_and_same_next_update() -> None:
    torch.manual_seed(0)
    agent = SacLagrangian(OBS_DIM, ACT_DIM, small_config(alpha_init=0.1, beta_init=0.3))
    for i in range(3):
        agent.update(random_batch(i))
    buffer = io.BytesIO()
    torch.save(agent.state_dict(), buffer)
    buffer.seek(0)
    state = torch.load(buffer, weights_only=True)

    torch.manual_seed(123)  # a differently initialised learner
    restored = SacLagrangian(OBS_DIM, ACT_DIM, small_config())
    assert float(agent.alpha.detach()) not in (0.0, 0.1)  # alpha and beta moved from their
    assert float(agent.multiplier.beta) not in (0.0, 0.3)  # initial values, which must not matter
    obs = np.random.default_rng(1).normal(size=(5, OBS_DIM))
    assert not np.array_equal(restored.act(obs, True), agent.act(obs, True))
    restored.load_state_dict(state)
    np.testing.assert_array_equal(restored.act(obs, True), agent.act(obs, True))
    assert_same_tensors(all_tensors(restored), all_tensors(agent))

    batch = random_batch(10)
    torch.manual_seed(5)
    s_agent = agent.update(batch)
    torch.manual_seed(5)
    s_restored = restored.update(batch)
    assert s_agent == s_restored
    assert_same_tensors(all_tensors(restored), all_tensors(agent))


def test_checkpoint_of_unfused_optimisers_loads_and_keeps_the_fast_step() -> None:
    """States saved before the learner used fused Adam (param groups with fused=None) still load,
    continue the same training, and do not switch the loading learner back to the slow step."""
    torch.manual_seed(0)
    old = SacLagrangian(OBS_DIM, ACT_DIM, small_config(alpha_init=0.1))
    old.actor_optim = torch.optim.Adam(old._actor_params, lr=old.config.lr)
    old.critic_optim = torch.optim.Adam(old._critic_params, lr=old.config.lr)
    old.alpha_optim = torch.optim.Adam([old.alpha], lr=old.config.lr)
    for i in range(2):
        old.update(random_batch(i))
    state = copy.deepcopy(old.state_dict())
    assert state["critic_optim"]["param_groups"][0]["fused"] is None

    new = SacLagrangian(OBS_DIM, ACT_DIM, small_config())
    flags = new.critic_optim.param_groups[0]["fused"], new.critic_optim.param_groups[0]["foreach"]
    new.load_state_dict(state)
    for optim in (new.actor_optim, new.critic_optim, new.alpha_optim):
        assert (optim.param_groups[0]["fused"], optim.param_groups[0]["foreach"]) == flags
    torch.manual_seed(5)
    s_old = old.update(random_batch(2))
    torch.manual_seed(5)
    s_new = new.update(random_batch(2))
    # the same Adam rule; a fused kernel may round the last bit differently
    assert s_new.q_r_loss == pytest.approx(s_old.q_r_loss, rel=1e-5)
    assert s_new.actor_loss == pytest.approx(s_old.actor_loss, rel=1e-5, abs=1e-7)
    for key, value in all_tensors(old).items():
        torch.testing.assert_close(all_tensors(new)[key], value, rtol=1e-5, atol=1e-6)


def test_in_memory_load_does_not_share_optimiser_moments() -> None:
    torch.manual_seed(0)
    a = SacLagrangian(OBS_DIM, ACT_DIM, small_config())
    a.update(random_batch(0))
    b = SacLagrangian(OBS_DIM, ACT_DIM, small_config())
    b.load_state_dict(copy.deepcopy(a.state_dict()))
    c = SacLagrangian(OBS_DIM, ACT_DIM, small_config())
    c.load_state_dict(a.state_dict())  # live references
    a.update(random_batch(1))  # must not move c's Adam moments
    assert_same_tensors(
        {str(i): v for i, v in enumerate(b.critic_optim.state_dict()["state"][0].values())},
        {str(i): v for i, v in enumerate(c.critic_optim.state_dict()["state"][0].values())},
    )


def test_transfer_copies_networks_and_resets_the_rest() -> None:
    torch.manual_seed(0)
    source = SacLagrangian(OBS_DIM, ACT_DIM, small_config(variant=Variant.SAC_LAG))
    for i in range(2):
        source.update(random_batch(i))
    source_state = copy.deepcopy(source.state_dict())

    torch.manual_seed(1)
    target = SacLagrangian(OBS_DIM, ACT_DIM, small_config(alpha_init=0.2, beta_init=0.5))
    for i in range(2):
        target.update(random_batch(10 + i))
    assert float(target.alpha.detach()) != 0.2 and float(target.multiplier.beta) != 0.5
    assert len(target.actor_optim.state) > 0

    copied = transfer(target, source_state)

    expected = {f"{name}.{key}" for name in TRANSFERRED_NETWORKS for key in source_state[name]}
    assert set(copied) == expected and len(copied) == len(expected)
    target_tensors = all_tensors(target)
    for name in copied:
        net, key = name.split(".", 1)
        assert torch.equal(target_tensors[name], source_state[net][key]), name
    assert float(target.alpha.detach()) == pytest.approx(0.2)
    assert float(target.multiplier.beta) == pytest.approx(0.5)
    for optim in (target.actor_optim, target.critic_optim, target.alpha_optim):
        assert len(optim.state) == 0
    assert target.multiplier.state_dict()["optim"]["state"] == {}
    # training continues from the transferred weights
    stats = target.update(random_batch(20))
    assert math.isfinite(stats.actor_loss)


def test_learns_a_constrained_bandit() -> None:
    """One-step task: reward a_0, cost (a_0 + 1) / 2, limit C = 0.25 (the constrained optimum
    spends it exactly). Terminated every step, so Q^c(s, a) = c(a) and qc_limit(C, gamma, 1) = C.
    SAC ignores the cost; SAC-Lagrangian meets the limit on average but oscillates around it; TSSAC
    settles on it."""
    rng = np.random.default_rng(0)
    n = 2048
    buf = ReplayBuffer(1, 1, n)
    actions = rng.uniform(-1, 1, size=(n, 1))
    obs = rng.normal(size=(n, 1))
    buf.add_batch(obs, actions, actions[:, 0], (actions[:, 0] + 1) / 2, obs, np.ones(n))
    qc_tail: dict[Variant, np.ndarray] = {}
    final_action: dict[Variant, float] = {}
    for variant in (Variant.SAC, Variant.SAC_LAG, Variant.TSSAC):
        torch.manual_seed(0)
        cfg = SacConfig(
            variant=variant,
            hidden_sizes=(32, 32),
            lr=3e-3,
            beta_lr=3e-2,
            cost_limit=0.25,
            episode_steps=1,
            alpha_init=0.05,
            multiplier_signal=MultiplierSignal.Q_C,  # eq. 15 literally: Q^c on the update's batch
            multiplier_window=None,
        )
        agent = SacLagrangian(1, 1, cfg)
        qc = [agent.update(buf.sample(128, rng)).qc_mean for _ in range(600)]
        qc_tail[variant] = np.array(qc[-200:])
        final_action[variant] = float(agent.act(np.zeros((1, 1)), deterministic=True)[0, 0])
    assert final_action[Variant.SAC] > 0.8 and qc_tail[Variant.SAC].mean() > 0.8
    assert final_action[Variant.TSSAC] < 0.0
    assert abs(qc_tail[Variant.TSSAC].mean() - 0.25) < 0.03
    assert qc_tail[Variant.SAC_LAG].mean() < 0.3
    assert qc_tail[Variant.TSSAC].std() < 0.5 * qc_tail[Variant.SAC_LAG].std()


# --- replay buffer ----------------------------------------------------------------------------


def _transitions(start: int, n: int) -> tuple[np.ndarray, ...]:
    idx = np.arange(start, start + n, dtype=np.float32)
    return (
        np.stack([idx, -idx], axis=1),  # obs
        np.stack([idx / 100, idx / 100], axis=1),  # actions
        idx,  # rewards
        idx % 2,  # costs
        np.stack([idx + 0.5, -idx], axis=1),  # next obs
        (idx % 3 == 0).astype(np.float32),  # terminated
    )


def test_replay_wraps_around() -> None:
    buf = ReplayBuffer(2, 2, capacity=5)
    buf.add_batch(*_transitions(0, 3))
    assert len(buf) == 3
    buf.add_batch(*_transitions(3, 4))  # 3, 4 at rows 3, 4; 5, 6 wrap to rows 0, 1
    assert len(buf) == 5
    state = buf.state_dict()
    np.testing.assert_array_equal(state["rewards"].numpy(), [5, 6, 2, 3, 4])
    np.testing.assert_array_equal(state["observations"].numpy()[:, 1], [-5, -6, -2, -3, -4])
    np.testing.assert_array_equal(state["costs"].numpy(), [1, 0, 0, 1, 0])
    np.testing.assert_array_equal(state["terminated"].numpy(), [0, 1, 0, 1, 0])
    assert state["ptr"] == 2
    buf.add_batch(*_transitions(100, 12))  # more than the capacity: the last 5 survive
    assert sorted(buf.state_dict()["rewards"].tolist()) == [107, 108, 109, 110, 111]


def test_replay_sample_types_and_consistency() -> None:
    buf = ReplayBuffer(2, 2, capacity=50)
    buf.add_batch(*_transitions(0, 20))
    s = buf.sample(64, np.random.default_rng(0))
    assert isinstance(s, ReplaySamples)
    assert s.observations.shape == (64, 2) and s.actions.shape == (64, 2)
    assert s.rewards.shape == s.costs.shape == s.terminated.shape == (64,)
    assert all(x.dtype == torch.float32 for x in s)
    # each row is one transition: every field is a function of the same index
    torch.testing.assert_close(s.observations[:, 0], s.rewards)
    torch.testing.assert_close(s.next_observations[:, 0], s.rewards + 0.5)
    torch.testing.assert_close(s.costs, s.rewards % 2)
    assert s.rewards.max() < 20


def test_replay_state_dict_round_trip() -> None:
    buf = ReplayBuffer(2, 2, capacity=8)
    buf.add_batch(*_transitions(0, 11))
    state = buf.state_dict()
    data = io.BytesIO()
    torch.save(state, data)
    data.seek(0)
    restored = ReplayBuffer(2, 2, capacity=8)
    restored.load_state_dict(torch.load(data, weights_only=True))
    assert len(restored) == len(buf)
    a = buf.sample(32, np.random.default_rng(3))
    b = restored.sample(32, np.random.default_rng(3))
    for x, y in zip(a, b):
        assert torch.equal(x, y)
    buf.add_batch(*_transitions(50, 3))
    restored.add_batch(*_transitions(50, 3))
    for key, value in buf.state_dict().items():
        if isinstance(value, torch.Tensor):
            assert torch.equal(value, restored.state_dict()[key]), key
    # a partly filled buffer saves only its filled rows and loads into a larger one
    part = ReplayBuffer(2, 2, capacity=100)
    part.add_batch(*_transitions(0, 4))
    assert len(part.state_dict()["rewards"]) == 4
    bigger = ReplayBuffer(2, 2, capacity=200)
    bigger.load_state_dict(part.state_dict())
    assert len(bigger) == 4
    with pytest.raises(ValueError):
        ReplayBuffer(2, 2, capacity=20).load_state_dict(state)  # was full at capacity 8


def test_sample_recent_draws_only_the_newest_rows() -> None:
    buf = ReplayBuffer(obs_dim=1, act_dim=1, capacity=10)
    for start in (0, 7):  # the second batch wraps around the end of the storage
        n = 7
        rows = np.arange(start, start + n, dtype=np.float32)[:, None]
        buf.add_batch(rows, rows, rows[:, 0], rows[:, 0], rows, np.zeros(n, np.float32))
    got = buf.sample_recent(200, window=4, rng=np.random.default_rng(0)).observations[:, 0].numpy()
    assert set(got.tolist()) == {10.0, 11.0, 12.0, 13.0}


def test_multiplier_measured_on_recent_batch() -> None:
    """With a recent batch, beta's step follows Q^c on that batch, not on the training batch."""
    torch.manual_seed(0)
    cfg = SacConfig(
        variant=Variant.SAC_LAG,
        hidden_sizes=(8,),
        cost_limit=3.0,
        episode_steps=100,
        multiplier_signal=MultiplierSignal.Q_C,
    )
    learner = SacLagrangian(2, 1, cfg)
    obs = torch.zeros(4, 2)
    batch = ReplaySamples(obs, torch.zeros(4, 1), torch.zeros(4), torch.zeros(4), obs, torch.zeros(4))
    q_c_everywhere(learner, 100.0)  # Q^c = 100 everywhere: far above the limit
    stats = learner.update(batch, recent=batch)
    assert stats.cost_signal == pytest.approx(100.0, rel=1e-3)
    assert learner.multiplier.beta.item() > 0.0


def q_c_everywhere(learner: SacLagrangian, value: float) -> None:
    with torch.no_grad():
        for p in learner.q_c.parameters():
            p.zero_()
        learner.q_c.biases[-1].fill_(value)


def test_episode_cost_drives_the_multiplier_whatever_q_c_says() -> None:
    """Given a measured episode cost, eq. 15 and 17 compare it (on Q^c's scale) with C; Q^c is ignored."""
    cfg = SacConfig(
        variant=Variant.TSSAC, hidden_sizes=(8,), cost_limit=3.0, episode_steps=100, gamma=0.99, beta_init=1.0
    )
    per_cost = qc_limit(1.0, 0.99, 100)
    signal = SacLagrangian(2, 1, cfg).signal
    assert signal == SignalRule(CostSignal.EPISODE_COST, episode_scale=per_cost)
    assert float(signal.measured(3.0)) == pytest.approx(cfg.qc_limit)  # C maps onto the Q^c limit
    obs = torch.zeros(4, 2)
    batch = ReplaySamples(obs, torch.zeros(4, 1), torch.zeros(4), torch.zeros(4), obs, torch.zeros(4))
    for q_c, measured, rises in ((100.0, 0.0, False), (0.0, 12.0, True)):
        torch.manual_seed(0)
        learner = SacLagrangian(2, 1, cfg)
        q_c_everywhere(learner, q_c)
        stats = learner.update(batch, recent=batch, episode_cost=measured)
        assert stats.cost_signal == pytest.approx(measured * per_cost, rel=1e-6)
        assert stats.qc_mean == pytest.approx(q_c, rel=1e-3)  # still reported
        assert stats.xi == pytest.approx(10.0 * (cfg.qc_limit - measured * per_cost), rel=1e-5)  # eq. 17
        assert (learner.multiplier.beta.item() > 1.0) is rises  # eq. 15: up above C, down below


def test_the_multiplier_module_chooses_every_learners_signal() -> None:
    """lagrange.choose_signal is the one choice: the SAC family's from its configuration, PPO-Lag's the episode cost
    on C's own scale, and Q^c on the batch (only reported) for a learner without a multiplier."""
    episode, q_c = MultiplierSignal.EPISODE_COST, MultiplierSignal.Q_C
    assert choose_signal(episode, True, 4000, 0.5) == SignalRule(CostSignal.EPISODE_COST, episode_scale=0.5)
    assert choose_signal(q_c, True, 4000, 0.5) == SignalRule(CostSignal.Q_C_RECENT, recent_window=4000)
    assert choose_signal(q_c, True, None, 0.5) == SignalRule(CostSignal.Q_C_BATCH)
    assert (
        choose_signal(episode, False, 4000, 0.5) == choose_signal(q_c, False, 4000) == SignalRule(CostSignal.Q_C_BATCH)
    )
    per_cost = qc_limit(1.0, 0.99, 100)
    for variant, setting, window, expected in (
        (Variant.TSSAC, episode, 4000, SignalRule(CostSignal.EPISODE_COST, episode_scale=per_cost)),
        (Variant.SAC_LAG, q_c, 4000, SignalRule(CostSignal.Q_C_RECENT, recent_window=4000)),
        (Variant.SAC, episode, 4000, SignalRule(CostSignal.Q_C_BATCH)),
        (Variant.SAC_PENALTY, q_c, 4000, SignalRule(CostSignal.Q_C_BATCH)),
    ):
        cfg = SacConfig(
            variant=variant,
            hidden_sizes=(8,),
            episode_steps=100,
            multiplier_signal=setting,
            multiplier_window=window,
            penalty=-1.0 if variant is Variant.SAC_PENALTY else 0.0,
        )
        assert SacLagrangian(2, 1, cfg).signal == expected, variant
    lag = Ppo(4, 2, OnPolicyConfig(algo=OnPolicyAlgo.PPO_LAG, hidden_sizes=(8,)))
    assert lag.signal == SignalRule(CostSignal.EPISODE_COST, episode_scale=1.0)
    assert Ppo(4, 2, OnPolicyConfig(hidden_sizes=(8,))).signal.signal is CostSignal.Q_C_BATCH


def test_a_signal_reads_only_its_own_measurement() -> None:
    """The Q^c of the recent transitions is computed (its actor sample drawn) only when it is the signal; a signal
    whose measurement is missing is an error, not a silent switch to another."""

    def never() -> torch.Tensor:
        raise AssertionError("computed although not the signal")

    episode = SignalRule(CostSignal.EPISODE_COST, episode_scale=0.25)
    assert float(episode.measured(8.0, never, torch.tensor(99.0))) == 2.0
    assert float(SignalRule(CostSignal.Q_C_BATCH).measured(8.0, never, torch.tensor(99.0))) == 99.0
    recent = SignalRule(CostSignal.Q_C_RECENT, recent_window=10)
    assert float(recent.measured(8.0, lambda: torch.tensor(7.0), torch.tensor(99.0))) == 7.0
    with pytest.raises(ValueError, match="episode cost"):
        episode.measured(None, never, torch.tensor(99.0))
    with pytest.raises(ValueError, match="recent"):
        recent.measured(8.0, None, torch.tensor(99.0))
    learner = SacLagrangian(OBS_DIM, ACT_DIM, small_config(multiplier_signal=MultiplierSignal.EPISODE_COST))
    with pytest.raises(ValueError, match="episode cost"):
        learner.update(random_batch(0))


def test_multiplier_upper_bound() -> None:
    """beta and beta - xi stay in [0, upper]; without a bound xi alone would ask for k_d * excess."""
    m = DampedLagrangeMultiplier(cost_limit=0.5, k_d=10.0, lr=1.0, upper=4.0)
    for _ in range(20):
        m.update(100.0)  # far above the limit: beta climbs by ~lr per step
    assert m.beta.item() == pytest.approx(4.0)
    assert m.effective(100.0).item() == pytest.approx(4.0)  # 4 + 10 * 99.5 unbounded
    unbounded = DampedLagrangeMultiplier(cost_limit=0.5, k_d=10.0, lr=1.0)
    assert unbounded.effective(100.0).item() == pytest.approx(995.0)


# --- WCSAC's worst-case cost critic (SacConfig.cost_cvar_level) ------------------------------------------------


def test_cost_variance_target_and_loss_by_hand() -> None:
    gamma = 0.9
    # A deterministic chain: c = 1, Q^c(s', a') = 2, V^c(s', a') = 0, so Q^c(s, a) = 1 + 0.9 * 2 and no variance.
    q = 1.0 + gamma * 2.0
    deterministic = losses.cost_variance_target(t(1.0), t(0.0), t(2.0), t(0.0), t(q), gamma)
    torch.testing.assert_close(deterministic, t(0.0), atol=1e-12, rtol=0)
    # The next state's variance comes through discounted twice: gamma^2 V^c(s', a').
    torch.testing.assert_close(losses.cost_variance_target(t(1.0), t(0.0), t(2.0), t(3.0), t(q), gamma), t(0.81 * 3.0))
    # Termination drops the next state: c^2 - Q^c(s, a)^2, clamped at 0.
    torch.testing.assert_close(
        losses.cost_variance_target(t(1.0, 0.0), t(1.0, 1.0), t(5.0, 5.0), t(9.0, 9.0), t(0.5, 0.5), gamma),
        t(0.75, 0.0),
    )
    # W2's variance part: (sqrt(var) - sqrt(target))^2, zero when they agree.
    assert float(losses.variance_loss(t(4.0, 1.0), t(1.0, 1.0))) == pytest.approx(0.5)


def test_cvar_of_a_gaussian_by_hand() -> None:
    assert losses.cvar_coefficient(1.0) == 0.0
    # Phi^-1(0.1) = -1.28155, phi(-1.28155) = 0.175498: the worst 10% of N(1, 4) average 1 + 1.75498 * 2.
    torch.testing.assert_close(losses.cost_cvar(t(1.0), t(4.0), 0.1), t(1.0 + 2 * 1.754983), atol=1e-5, rtol=0)
    with pytest.raises(ValueError, match="cost_cvar_level"):
        small_config(cost_cvar_level=1.0)


def test_the_variance_critic_is_an_addition_the_default_learner_does_not_have() -> None:
    torch.manual_seed(3)
    mean_only = SacLagrangian(OBS_DIM, ACT_DIM, small_config())
    torch.manual_seed(3)
    risk = SacLagrangian(OBS_DIM, ACT_DIM, small_config(cost_cvar_level=0.1))
    assert set(risk.networks()) - set(mean_only.networks()) == {"q_c_var", "q_c_var_target"}
    shared = {k: v for k, v in all_tensors(risk).items() if not k.startswith("q_c_var")}
    assert_same_tensors(shared, all_tensors(mean_only))  # the same initial weights for what both have
    before = {k: v.clone() for k, v in all_tensors(risk).items()}
    risk.update(random_batch(0))
    after = all_tensors(risk)
    assert not torch.equal(before["q_c_var.weights.0"], after["q_c_var.weights.0"])  # trained in the critics' step
    # A checkpoint round trip keeps it; a transfer between two such learners copies it.
    torch.manual_seed(9)
    other = SacLagrangian(OBS_DIM, ACT_DIM, small_config(cost_cvar_level=0.1))
    copied = transfer(other, copy.deepcopy(risk.state_dict()))
    assert {name.split(".")[0] for name in copied} == set(risk.networks())
    assert torch.equal(other.q_c_var.weights[0], risk.q_c_var.weights[0])  # type: ignore[union-attr]
    # From a learner without one, the target keeps its own variance critic.
    torch.manual_seed(9)
    fresh = SacLagrangian(OBS_DIM, ACT_DIM, small_config(cost_cvar_level=0.1))
    kept = fresh.q_c_var.weights[0].clone()  # type: ignore[union-attr]
    copied = transfer(fresh, copy.deepcopy(mean_only.state_dict()))
    assert {name.split(".")[0] for name in copied} == set(TRANSFERRED_NETWORKS)
    assert torch.equal(fresh.q_c_var.weights[0], kept)  # type: ignore[union-attr]


@pytest.mark.slow
def test_a_cvar_learner_avoids_the_risky_action_that_a_mean_learner_takes() -> None:
    """One-step task: reward 0.2 a_0, cost 0.5 +- a_0 / 2 (a fair coin): every action has mean cost 0.5, and the
    cost's spread grows with |a_0|. With the multiplier held at 1, the mean learner sees no reason not to take
    a_0 -> 1; the CVaR_0.1 learner pays for the spread and stays near 0."""
    rng = np.random.default_rng(0)
    n = 4096
    buf = ReplayBuffer(1, 1, n)
    actions = rng.uniform(-1, 1, size=(n, 1))
    obs = np.zeros((n, 1))
    coin = rng.choice([-1.0, 1.0], size=n)
    buf.add_batch(obs, actions, 0.2 * actions[:, 0], 0.5 + coin * actions[:, 0] / 2, obs, np.ones(n))
    final: dict[float | None, float] = {}
    for level in (None, 0.1):
        torch.manual_seed(0)
        cfg = SacConfig(
            variant=Variant.SAC_LAG,
            hidden_sizes=(32, 32),
            lr=3e-3,
            beta_init=1.0,
            beta_lr=1e-9,  # the multiplier held at 1
            cost_limit=0.5,
            episode_steps=1,
            alpha_init=0.01,
            cost_cvar_level=level,
            multiplier_signal=MultiplierSignal.Q_C,  # Q^c on the update's batch (the multiplier is held anyway)
            multiplier_window=None,
        )
        agent = SacLagrangian(1, 1, cfg)
        for _ in range(800):
            agent.update(buf.sample(256, rng))
        final[level] = float(agent.act(np.zeros((1, 1)), deterministic=True)[0, 0])
        if level is not None:
            zero, risky = torch.zeros(2, 1), torch.tensor([[0.0], [0.9]])
            with torch.no_grad():
                var = cost_variance(agent.q_c_var, zero, risky)  # type: ignore[arg-type]
            assert float(var[1]) > 4 * float(var[0])  # it learned where the spread is
    assert final[None] > 0.8
    assert abs(final[0.1]) < 0.3
