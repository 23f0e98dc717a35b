"""K seeds in one batched learner (tssac_core.algos.kseed): each seed is exactly a SacLagrangian."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import torch

from tssac_core.algos.kseed import KSeedSacLagrangian
from tssac_core.algos.replay import ReplaySamples
from tssac_core.algos.sac_lagrangian import SacConfig, SacLagrangian, UpdateStats, Variant, transfer

torch.set_num_threads(1)

OBS_DIM, ACT_DIM = 5, 2
SEEDS = (11, 12, 13)
TOL = dict(rtol=1e-5, atol=1e-5)


def config(**overrides: Any) -> SacConfig:
    fields: dict[str, Any] = dict(hidden_sizes=(32, 32), episode_steps=100, batch_size=16)
    fields.update(overrides)
    return SacConfig(**fields)


CONFIGS = {
    # cost_limit 0: Q^c is above the limit, so beta rises and the multiplier reaches the actor;
    # alpha_init 0.2: alpha moves from the first update (eq. 14).
    "tssac": config(cost_limit=0.0, alpha_init=0.2),
    "tssac_unclamped": config(cost_limit=0.5, k_d=10.0, clamp_effective=False, alpha_init=0.1),
    "sac_lag": config(variant=Variant.SAC_LAG, cost_limit=0.0, alpha_init=0.2),
    "sac": config(variant=Variant.SAC, alpha_init=0.2),
    "sac_penalty": config(variant=Variant.SAC_PENALTY, penalty=-5.0),
}


def random_batch(seed: int, n: int = 16) -> ReplaySamples:
    g = torch.Generator().manual_seed(seed)
    return ReplaySamples(
        observations=torch.randn(n, OBS_DIM, generator=g),
        actions=torch.rand(n, ACT_DIM, generator=g) * 2 - 1,
        rewards=torch.randn(n, generator=g),
        costs=(torch.rand(n, generator=g) < 0.5).float(),
        next_observations=torch.randn(n, OBS_DIM, generator=g),
        terminated=(torch.rand(n, generator=g) < 0.2).float(),
    )


def batches(k: int, i: int) -> tuple[ReplaySamples, ReplaySamples]:
    """Seed k's minibatch and recent batch of update i (different for every seed)."""
    return random_batch(1000 * k + 2 * i), random_batch(1000 * k + 2 * i + 1)


def episode_cost(k: int, i: int) -> float:
    """Seed k's measured cost per episode at update i: above C = 3 for some updates, below for others."""
    return float((3 * k + i) % 5) * 2.0


def run_single(cfg: SacConfig, seed: int, k: int, n_updates: int, costs: bool = False) -> tuple[SacLagrangian, list[UpdateStats], list[np.ndarray]]:
    torch.manual_seed(seed)
    learner = SacLagrangian(OBS_DIM, ACT_DIM, cfg)
    stats, actions = [], []
    for i in range(n_updates):
        actions.append(learner.act(random_batch(5000 + i).observations.numpy(), deterministic=False))
        stats.append(learner.update(*batches(k, i), episode_cost(k, i) if costs else None))
    return learner, stats, actions


def run_batched(cfg: SacConfig, n_updates: int, costs: bool = False) -> tuple[KSeedSacLagrangian, list[list[UpdateStats]], list[np.ndarray]]:
    learner = KSeedSacLagrangian.from_seeds(OBS_DIM, ACT_DIM, cfg, SEEDS)
    stats, actions = [], []
    obs = np.stack([random_batch(5000 + i).observations.numpy() for i in range(n_updates)])
    for i in range(n_updates):
        actions.append(learner.act(np.stack([obs[i]] * len(SEEDS)), deterministic=False))
        pairs = [batches(k, i) for k in range(len(SEEDS))]
        measured = [episode_cost(k, i) for k in range(len(SEEDS))] if costs else None
        stats.append(learner.update([p[0] for p in pairs], [p[1] for p in pairs], measured))
    return learner, stats, actions


def assert_states_close(a: Any, b: Any, path: str = "") -> None:
    """Same structure, keys, types, shapes and dtypes; tensors equal to float tolerance."""
    assert type(a) is type(b), path
    if isinstance(a, dict):
        assert list(a) == list(b), path
        for key in a:
            assert_states_close(a[key], b[key], f"{path}.{key}")
    elif isinstance(a, torch.Tensor):
        assert a.shape == b.shape and a.dtype == b.dtype, path
        torch.testing.assert_close(a, b, **TOL, msg=path)
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            assert_states_close(x, y, f"{path}[{i}]")
    else:
        assert a == b, path


@pytest.mark.parametrize("costs", [False, True], ids=["q_c", "episode_cost"])
@pytest.mark.parametrize("name", list(CONFIGS))
def test_each_seed_updates_like_a_separate_learner(name: str, costs: bool) -> None:
    """Also with the multiplier driven by each seed's own measured episode cost."""
    cfg = CONFIGS[name]
    n_updates = 6
    batched, batched_stats, batched_actions = run_batched(cfg, n_updates, costs)
    for k, seed in enumerate(SEEDS):
        single, stats, actions = run_single(cfg, seed, k, n_updates, costs)
        for i in range(n_updates):
            np.testing.assert_allclose(batched_actions[i][k], actions[i], **TOL)
            np.testing.assert_allclose(
                np.array(list(vars(batched_stats[i][k]).values())),
                np.array(list(vars(stats[i]).values())),
                **TOL,
                err_msg=f"seed {k} update {i}",
            )
        assert_states_close(batched.seed_state_dict(k), single.state_dict(), f"seed {k}")
        # Both random streams have advanced alike: the next draws agree.
        assert torch.equal(batched.generators[k].get_state(), torch.get_rng_state())


def test_the_test_exercises_alpha_beta_and_the_damping() -> None:
    _, stats, _ = run_batched(CONFIGS["tssac"], 6)
    last = stats[-1]
    # (A seed whose Q^c estimate is still below 0 everywhere measures 0 and keeps beta at 0.)
    assert sum(s.beta > 0.0 and s.xi < 0.0 and s.beta_minus_xi > s.beta for s in last) >= 2
    assert len({s.beta for s in last}) == len(SEEDS)  # the seeds are not copies of each other
    first_alpha = [s.alpha for s in stats[0]]
    assert all(s.alpha != a for s, a in zip(last, first_alpha))
    _, unclamped, _ = run_batched(CONFIGS["tssac_unclamped"], 6)
    assert any(s.beta_minus_xi < 0.0 for step in unclamped for s in step)  # eq. 16 unclamped


def test_seed_state_loads_into_a_single_learner_and_back() -> None:
    cfg = CONFIGS["tssac"]
    batched, _, _ = run_batched(cfg, 3)
    single = SacLagrangian(OBS_DIM, ACT_DIM, cfg)
    single.load_state_dict(batched.seed_state_dict(1))
    assert_states_close(single.state_dict(), batched.seed_state_dict(1))
    # Continue both: seed 1 of the stack and the single learner take the same next step.
    other = KSeedSacLagrangian(OBS_DIM, ACT_DIM, cfg, len(SEEDS))
    for k in range(len(SEEDS)):
        other.load_seed_state_dict(k, batched.seed_state_dict(k))
    pairs = [batches(k, 10) for k in range(len(SEEDS))]
    torch.manual_seed(0)
    single_stats = single.update(*pairs[1])
    other.generators[1].manual_seed(0)
    other_stats = other.update([p[0] for p in pairs], [p[1] for p in pairs])[1]
    np.testing.assert_allclose(list(vars(other_stats).values()), list(vars(single_stats).values()), **TOL)
    assert_states_close(other.seed_state_dict(1), single.state_dict())


def test_transfer_matches_the_single_transfer() -> None:
    cfg = CONFIGS["tssac"]
    source, _, _ = run_batched(cfg, 3)
    target = KSeedSacLagrangian.from_seeds(OBS_DIM, ACT_DIM, cfg, (1, 2, 3))
    sources = [source.seed_state_dict(k) for k in range(len(SEEDS))]
    copied = target.transfer(sources)
    for k in range(len(SEEDS)):
        single = SacLagrangian(OBS_DIM, ACT_DIM, cfg)
        assert copied == transfer(single, sources[k])
        assert_states_close(target.seed_state_dict(k), single.state_dict())


def test_a_fresh_optimiser_cannot_join_a_stack_at_a_later_step() -> None:
    cfg = CONFIGS["sac"]
    batched, _, _ = run_batched(cfg, 2)
    with pytest.raises(ValueError, match="later step"):
        batched.load_seed_state_dict(0, SacLagrangian(OBS_DIM, ACT_DIM, cfg).state_dict())
