"""K seeds of one SacConfig learned at once: `KSeedSacLagrangian`.

Every network holds the K seeds' copies stacked along a leading axis (`tssac_core.algos.stacked`),
so each layer of all K actors, or of all K x 3 critics, is one `torch.baddbmm`; alpha and the
multiplier's beta are K-vectors; one optimiser step moves all K seeds. Seed k's update is the one
`SacLagrangian.update` computes on seed k's batch (the losses are summed over the seeds only to
backpropagate once: seed k's parameters get the gradient of seed k's loss alone). Each seed draws
its noise from its own `torch.Generator`, in the order a single learner draws from the global one,
so a seed built by `from_seeds` follows the random stream of a single run with that torch seed.

`seed_state_dict(k)` / `load_seed_state_dict(k, state)` convert seed k to and from
`SacLagrangian.state_dict()`'s format: a seed's checkpoint is the file a single run writes.
"""

from __future__ import annotations

import copy
from collections import OrderedDict
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch

from tssac_core.algos import losses, optim_members
from tssac_core.algos.optim_members import LoadMember, ToMember
from tssac_core.algos.lagrange import DampedLagrangeMultiplier
from tssac_core.algos.replay import ReplaySamples
from tssac_core.algos.sac_lagrangian import (
    MULTIPLIER_VARIANTS,
    SacConfig,
    SacLagrangian,
    UpdateStats,
    Variant,
    TRANSFERRED_NETWORKS,
    fast_adam,
    measured_cost,
    multiplier_terms,
    step_actor_and_alpha,
    step_multiplier_and_targets,
)
from tssac_core.algos.stacked import StackedActor, StackedCritic


def stack_samples(batches: Sequence[ReplaySamples]) -> ReplaySamples:
    """K minibatches of equal size -> one with a leading seed axis (K, batch, ...)."""
    return ReplaySamples(*(torch.stack(field) for field in zip(*batches)))


class KSeedSacLagrangian:
    """K `SacLagrangian` learners of one config in stacked networks (see the module docstring)."""

    def __init__(self, obs_dim: int, act_dim: int, config: SacConfig, n_seeds: int) -> None:
        if n_seeds < 1:
            raise ValueError(f"n_seeds must be >= 1, got {n_seeds}")
        self.obs_dim = obs_dim
        self.act_dim = act_dim
        self.config = config
        self.n_seeds = n_seeds
        hidden = config.hidden_sizes
        self.actor = StackedActor(n_seeds, obs_dim, act_dim, hidden)
        self.q_r = StackedCritic(n_seeds, obs_dim, act_dim, hidden, n_members=2)
        self.q_c = StackedCritic(n_seeds, obs_dim, act_dim, hidden, n_members=1)
        self.q_r_target = copy.deepcopy(self.q_r).requires_grad_(False)
        self.q_c_target = copy.deepcopy(self.q_c).requires_grad_(False)
        self.alpha = torch.full((n_seeds,), config.alpha_init, requires_grad=True)
        self.uses_multiplier = config.variant in MULTIPLIER_VARIANTS
        self.multiplier = DampedLagrangeMultiplier(
            cost_limit=config.qc_limit,
            k_d=config.k_d if config.variant is Variant.TSSAC else 0.0,
            beta_init=config.beta_init if self.uses_multiplier else 0.0,
            lr=config.beta_lr,
            clamp_effective=config.clamp_effective,
            upper=config.multiplier_max,
            n_seeds=n_seeds,
        )
        self.generators = [torch.Generator() for _ in range(n_seeds)]
        self._actor_params = list(self.actor.parameters())
        self._n_q_r = len(list(self.q_r.parameters()))
        self._critic_params = [*self.q_r.parameters(), *self.q_c.parameters()]
        self._targets = [*self.q_r_target.parameters(), *self.q_c_target.parameters()]
        self._onlines = [*self.q_r.parameters(), *self.q_c.parameters()]
        self.reset_optimisers()

    @classmethod
    def from_seeds(
        cls, obs_dim: int, act_dim: int, config: SacConfig, torch_seeds: Sequence[int]
    ) -> KSeedSacLagrangian:
        """Seed k starts as `SacLagrangian(obs_dim, act_dim, config)` built right after
        `torch.manual_seed(torch_seeds[k])`, and its generator goes on from there, as the global
        generator of such a single run would. The global generator is left as it was."""
        learner = cls(obs_dim, act_dim, config, len(torch_seeds))
        with torch.random.fork_rng(devices=[]):
            for k, seed in enumerate(torch_seeds):
                torch.manual_seed(seed)
                single = SacLagrangian(obs_dim, act_dim, config)
                learner.load_seed_state_dict(k, single.state_dict())
                learner.generators[k].set_state(torch.get_rng_state())
        return learner

    def reset_optimisers(self) -> None:
        """Fresh Adam optimisers (no moments) for the actors, the critics and alpha of all seeds."""
        self.actor_optim = fast_adam(self._actor_params, self.config.lr)
        self.critic_optim = fast_adam(self._critic_params, self.config.lr)
        self.alpha_optim = fast_adam([self.alpha], self.config.lr)

    def networks(self) -> dict[str, StackedActor | StackedCritic]:
        """The stacked networks by the names of `SacLagrangian.networks`."""
        return {
            "actor": self.actor,
            "q_r": self.q_r,
            "q_c": self.q_c,
            "q_r_target": self.q_r_target,
            "q_c_target": self.q_c_target,
        }

    @torch.no_grad()
    def act(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        """Actions in [-1, 1]: obs (K, n, obs_dim) -> (K, n, act_dim), seed k's from its actor."""
        obs_t = torch.as_tensor(obs, dtype=torch.float32)
        action, _ = self.actor(obs_t, None if deterministic else self.generators)
        return action.numpy()

    def update(
        self,
        batches: Sequence[ReplaySamples],
        recents: Sequence[ReplaySamples] | None = None,
        episode_costs: Sequence[float] | None = None,
    ) -> list[UpdateStats]:
        """One gradient step of every seed: seed k's is `SacLagrangian.update(batches[k],
        recents[k], episode_costs[k])` (the same equations, in the same order; eq. numbers as there)."""
        cfg = self.config
        gens = self.generators
        obs, actions, rewards, costs, next_obs, terminated = stack_samples(batches)
        if cfg.variant is Variant.SAC_PENALTY:
            rewards = rewards + cfg.penalty * costs
        alpha = self.alpha.detach().clone()  # (K,), the values used below, kept for the stats
        alpha_col = alpha.unsqueeze(1)  # (K, 1) against per-sample (K, batch)

        # Targets, eq. 13 (cost bootstrap clamped at >= 0, as in SacLagrangian.update).
        with torch.no_grad():
            next_actions, next_log_pi = self.actor(next_obs, gens)
            next_v_r = losses.soft_value(self.q_r_target(next_obs, next_actions), next_log_pi, alpha_col)
            y_r = losses.critic_target(rewards, terminated, next_v_r, cfg.gamma)
            next_v_c = self.q_c_target(next_obs, next_actions)[:, 0].clamp(min=0.0)
            y_c = losses.critic_target(costs, terminated, next_v_c, cfg.gamma)

        # Critic losses, eq. 13, one per seed; their sum gives each seed its own gradient.
        q_r_loss = losses.critic_loss(self.q_r(obs, actions), y_r.unsqueeze(1))
        q_c_loss = losses.critic_loss(self.q_c(obs, actions), y_c.unsqueeze(1))
        self.critic_optim.zero_grad()
        (q_r_loss + q_c_loss).sum().backward()
        self.critic_optim.step()

        # Actor loss, eq. 12 / 16, and alpha, eq. 14.
        pi_actions, log_pi = self.actor(obs, gens)
        q_r_pi = self.q_r(obs, pi_actions)
        with torch.set_grad_enabled(self.uses_multiplier):
            q_c_pi = self.q_c(obs, pi_actions)[:, 0]
        qc_mean = q_c_pi.detach().clamp(min=0.0).mean(dim=-1)

        def recent_qc_mean() -> torch.Tensor:
            assert recents is not None
            recent_obs = torch.stack([r.observations for r in recents])
            return self.q_c(recent_obs, self.actor(recent_obs, gens)[0])[:, 0].clamp(min=0.0).mean(dim=-1)

        measured = measured_cost(cfg, qc_mean, episode_costs, recent_qc_mean if recents is not None else None)
        beta, xi, multiplier = multiplier_terms(self.multiplier, self.uses_multiplier, measured)  # (K,) each
        actor_loss = losses.actor_loss(log_pi, q_r_pi, q_c_pi, alpha_col, multiplier.unsqueeze(1))
        alpha_loss = losses.alpha_loss(self.alpha, log_pi, cfg.target_entropy)
        step_actor_and_alpha(self.actor_optim, self.alpha_optim, self._actor_params, self.alpha, actor_loss, alpha_loss)
        beta_loss = step_multiplier_and_targets(  # one beta per seed, projected onto [0, upper] inside
            self.multiplier, self.uses_multiplier, measured, self._targets, self._onlines, cfg.polyak
        )

        columns = torch.stack(
            [
                q_r_loss.detach(),
                q_c_loss.detach(),
                actor_loss.detach(),
                alpha_loss.detach(),
                beta_loss,
                alpha,
                beta,
                xi,
                multiplier,
                q_r_pi.detach().min(dim=1).values.mean(dim=-1),
                qc_mean,
                measured,
                -log_pi.detach().mean(dim=-1),
            ],
            dim=1,
        ).tolist()  # (K, 13): one synchronisation for all statistics
        return [UpdateStats(*row) for row in columns]

    # --- seed k in SacLagrangian's format ---------------------------------------------------

    def _optimisers(self) -> dict[str, tuple[torch.optim.Optimizer, list[torch.Tensor], ToMember, LoadMember]]:
        """Each optimiser's parameters and how seed k's slice maps to a single learner's."""

        def critics_to(k: int, ts: Sequence[torch.Tensor]) -> list[torch.Tensor]:
            n = self._n_q_r
            return self.q_r.member_tensors(k, ts[:n]) + self.q_c.member_tensors(k, ts[n:])

        def critics_load(k: int, ts: Sequence[torch.Tensor], member: Sequence[torch.Tensor]) -> None:
            n, n_member = self._n_q_r, 2 * self.q_r.n_layers  # stacked q_r tensors; a single Critic's
            self.q_r.load_member(k, ts[:n], member[:n_member])
            self.q_c.load_member(k, ts[n:], member[n_member:])

        def alpha_to(k: int, ts: Sequence[torch.Tensor]) -> list[torch.Tensor]:
            return [ts[0].detach()[k].clone()]

        def alpha_load(k: int, ts: Sequence[torch.Tensor], member: Sequence[torch.Tensor]) -> None:
            with torch.no_grad():
                ts[0][k] = member[0]

        return {
            "actor_optim": (
                self.actor_optim, self._actor_params, self.actor.member_tensors, self.actor.load_member
            ),
            "critic_optim": (self.critic_optim, self._critic_params, critics_to, critics_load),
            "alpha_optim": (self.alpha_optim, [self.alpha], alpha_to, alpha_load),
        }

    def seed_state_dict(self, k: int) -> dict[str, Any]:
        """Seed k's state in exactly `SacLagrangian.state_dict()`'s format (copies)."""
        state: dict[str, Any] = {}
        for name, net in self.networks().items():
            keys = _single_keys(name, self.config)
            state[name] = OrderedDict(zip(keys, net.member_tensors(k, list(net.parameters())), strict=True))
        for name, (optim, params, to_member, _) in self._optimisers().items():
            state[name] = optim_members.member_state(optim, params, k, to_member)
        state.update(
            alpha=self.alpha.detach()[k].clone(),
            multiplier=self.multiplier.seed_state_dict(k),
            variant=self.config.variant.value,
        )
        return {key: state[key] for key in _STATE_ORDER}

    def load_seed_state_dict(self, k: int, state: dict[str, Any]) -> None:
        """Restore seed k from a `SacLagrangian.state_dict()` (same sizes and variant)."""
        if state.get("variant") != self.config.variant.value:
            raise ValueError(f"a {state.get('variant')} state cannot join a {self.config.variant.value} learner")
        for name, net in self.networks().items():
            keys = _single_keys(name, self.config)
            if set(state[name]) != set(keys):
                raise ValueError(f"{name}: state has keys {sorted(state[name])}, expected {keys}")
            net.load_member(k, list(net.parameters()), [state[name][key] for key in keys])
        for name, (optim, params, _, load_member) in self._optimisers().items():
            optim_members.load_member_state(optim, params, k, state[name], load_member)
        with torch.no_grad():
            self.alpha[k] = state["alpha"]
        self.multiplier.load_seed_state_dict(k, state["multiplier"])

    def transfer(self, source_states: Sequence[dict[str, Any]]) -> list[str]:
        """`sac_lagrangian.transfer` for every seed: seed k's networks from source_states[k];
        optimisers, alpha and beta reset. Returns the copied tensors' names (the same for all)."""
        nets = self.networks()
        for k, source in enumerate(source_states):
            for name in TRANSFERRED_NETWORKS:
                keys = _single_keys(name, self.config)
                if set(source[name]) != set(keys):
                    raise ValueError(f"{name}: source has keys {sorted(source[name])}, expected {keys}")
                nets[name].load_member(k, list(nets[name].parameters()), [source[name][key] for key in keys])
        copied = [f"{name}.{key}" for name in TRANSFERRED_NETWORKS for key in _single_keys(name, self.config)]
        with torch.no_grad():
            self.alpha.fill_(self.config.alpha_init)
        self.reset_optimisers()
        self.multiplier.reset()
        return copied


_STATE_ORDER = (
    "actor", "q_r", "q_c", "q_r_target", "q_c_target",
    "actor_optim", "critic_optim", "alpha", "alpha_optim", "multiplier", "variant",
)


def _single_keys(network: str, config: SacConfig) -> list[str]:
    """The `state_dict` keys of a single learner's network, in its `parameters()` order."""
    n_layers = len(config.hidden_sizes) + 1
    if network == "actor":
        return [f"net.{2 * i}.{kind}" for i in range(n_layers) for kind in ("weight", "bias")]
    return [f"weights.{i}" for i in range(n_layers)] + [f"biases.{i}" for i in range(n_layers)]

