"""SAC, SAC with a hazard penalty, SAC-Lagrangian and TSSAC's learner (paper section 4, eq. 12-17).

One flat class, `SacLagrangian`, owns the networks, their targets, the optimisers, alpha and the
multiplier; `update` reads like the paper: targets (eq. 13) -> critic losses (eq. 13) -> actor loss
(eq. 12 / 16) -> alpha (eq. 14) -> multiplier (eq. 15, 17) -> Polyak averaging of the targets.
The four variants differ only in the multiplier of Q^c in the actor loss and in the reward:

| variant     | reward          | multiplier of Q^c in the actor loss             |
| ----------- | --------------- | ----------------------------------------------- |
| SAC         | r               | 0 (cost critic still trained, for logging)      |
| SAC_PENALTY | r + penalty * c | 0 (cost critic still trained, for logging)      |
| SAC_LAG     | r               | beta (eq. 12, 15)                               |
| TSSAC       | r               | beta - xi, xi = k_d (C - Q^c) (eq. 16, 17)      |

TSSAC's transfer (Algorithm 1, N1 -> N2 -> N3) is `transfer`.
"""

from __future__ import annotations

import copy
import logging
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, NotRequired, TypedDict

import numpy as np
import torch
from torch import nn
from torch.optim.optimizer import StateDict

from tssac_core.algos import losses
from tssac_core.algos.budget import qc_limit
from tssac_core.algos.lagrange import DampedLagrangeMultiplier, MultiplierState, SignalRule, choose_signal
from tssac_core.algos.networks import Critic, SquashedGaussianActor
from tssac_core.algos.replay import ReplaySamples
from tssac_core.algos.sac_config import MULTIPLIER_VARIANTS, SacConfig, Variant

logger = logging.getLogger(__name__)


def fast_adam(params: Sequence[torch.Tensor], lr: float) -> torch.optim.Adam:
    """Adam with torch's fused CPU kernel: one pass over each tensor instead of a chain of
    elementwise kernels (the step on Table 3's critics measured 2.4x faster). The same update
    rule; the rounding of the result can differ in the last bit from the default implementation."""
    try:
        return torch.optim.Adam(params, lr=lr, fused=True)
    except RuntimeError:  # a torch without the fused CPU kernel (< 2.4)
        return torch.optim.Adam(params, lr=lr, foreach=True)


NetworkName = Literal["actor", "q_r", "q_c", "q_r_target", "q_c_target", "q_c_var", "q_c_var_target"]
"""A network of the learner, as :meth:`SacLagrangian.networks` and :class:`SacState` name it."""


class _VarianceCritics(TypedDict, total=False):
    q_c_var: dict[str, torch.Tensor]
    q_c_var_target: dict[str, torch.Tensor]


class SacState(TypedDict):
    """What :meth:`SacLagrangian.state_dict` returns (and a role checkpoint's ``learner`` holds): each network's
    weights by name, in the order of :meth:`SacLagrangian.networks`, then the optimisers (torch's own state),
    alpha, the multiplier and the variant."""

    actor: dict[str, torch.Tensor]
    q_r: dict[str, torch.Tensor]
    q_c: dict[str, torch.Tensor]
    q_r_target: dict[str, torch.Tensor]
    q_c_target: dict[str, torch.Tensor]
    q_c_var: NotRequired[dict[str, torch.Tensor]]
    """With SacConfig.cost_cvar_level only."""
    q_c_var_target: NotRequired[dict[str, torch.Tensor]]
    actor_optim: StateDict
    critic_optim: StateDict
    alpha: torch.Tensor
    alpha_optim: StateDict
    multiplier: MultiplierState
    variant: str


def load_optimiser(optim: torch.optim.Optimizer, state: StateDict) -> None:
    """`optim.load_state_dict`, keeping optim's own implementation choice (fused / foreach):
    a loaded param group brings the flags it was saved with (None in older checkpoints)."""
    flags = {key: optim.param_groups[0].get(key) for key in ("fused", "foreach")}
    optim.load_state_dict(state)
    for group in optim.param_groups:
        group.update(flags)


@dataclass(frozen=True)
class UpdateStats:
    """Scalars of one `update`. alpha, beta, xi and beta_minus_xi are the values *used* in this
    update's losses (before alpha's and beta's own steps)."""

    q_r_loss: float
    """Eq. 13 summed over the two reward critics."""
    q_c_loss: float
    """Eq. 13 of the cost critic (with SacConfig.cost_cvar_level: plus the variance critic's loss)."""
    actor_loss: float
    """Eq. 12 / 16."""
    alpha_loss: float
    """Eq. 14."""
    beta_loss: float
    """Eq. 15 (0 for SAC and SAC_PENALTY, whose beta is not learned)."""
    alpha: float
    """Entropy coefficient of eq. 12-14."""
    beta: float
    """Cost multiplier of eq. 12 / 15 (0 for SAC and SAC_PENALTY)."""
    xi: float
    """Eq. 17 (0 unless TSSAC)."""
    beta_minus_xi: float
    """The effective multiplier of Q^c in the actor loss, after the clamp if clamp_effective."""
    q_r_mean: float
    """Batch mean of min_i Q^r_i(s, a~pi)."""
    qc_mean: float
    """Batch mean of Q^c(s, a~pi), clamped at >= 0."""
    cost_signal: float
    """The measured cost fed to eq. 15 and 17, on Q^c's scale (SacConfig.multiplier_signal): the
    recent episodes' mean cost converted, or a mean Q^c."""
    entropy: float
    """Batch mean of -log pi(a|s), a ~ pi."""


class SacLagrangian:
    """The learner of all four variants: actor, twin reward critics, cost critic, targets,
    optimisers, alpha and the multiplier. Deterministic given `torch.manual_seed` (construction
    and every `update` draw from torch's global generator)."""

    def __init__(self, obs_dim: int, act_dim: int, config: SacConfig) -> None:
        self.obs_dim = obs_dim
        self.act_dim = act_dim
        self.config = config
        hidden = config.hidden_sizes
        self.actor = SquashedGaussianActor(obs_dim, act_dim, hidden)
        self.q_r = Critic(obs_dim, act_dim, hidden, n_members=2)
        self.q_c = Critic(obs_dim, act_dim, hidden, n_members=1)
        self.q_r_target = copy.deepcopy(self.q_r).requires_grad_(False)
        self.q_c_target = copy.deepcopy(self.q_c).requires_grad_(False)
        self.alpha = torch.tensor(config.alpha_init, requires_grad=True)
        self.uses_multiplier = config.variant in MULTIPLIER_VARIANTS
        self.multiplier = DampedLagrangeMultiplier(
            cost_limit=config.qc_limit,
            k_d=config.k_d if config.variant is Variant.TSSAC else 0.0,
            beta_init=config.beta_init if self.uses_multiplier else 0.0,
            lr=config.beta_lr,
            clamp_effective=config.clamp_effective,
            upper=config.multiplier_max,
        )
        self.signal: SignalRule = choose_signal(
            config.multiplier_signal,
            self.uses_multiplier,
            config.multiplier_window,
            episode_scale=qc_limit(1.0, config.gamma, config.episode_steps),
        )
        """What the multiplier compares with C (``lagrange.choose_signal``); the caller passes its measurement."""
        self._actor_params: list[torch.Tensor] = list(self.actor.parameters())
        # WCSAC's variance critic (SacConfig.cost_cvar_level), made after everything else so that the learner
        # without it draws the same initial weights.
        self.q_c_var: Critic | None = None
        self.q_c_var_target: Critic | None = None
        if config.cost_cvar_level is not None:
            self.q_c_var = Critic(obs_dim, act_dim, hidden, n_members=1)
            self.q_c_var_target = copy.deepcopy(self.q_c_var).requires_grad_(False)
        variance = [] if self.q_c_var is None else [self.q_c_var]
        variance_target = [] if self.q_c_var_target is None else [self.q_c_var_target]
        self._critic_params: list[torch.Tensor] = [
            p for net in (self.q_r, self.q_c, *variance) for p in net.parameters()
        ]
        self._targets: list[torch.Tensor] = [
            p for net in (self.q_r_target, self.q_c_target, *variance_target) for p in net.parameters()
        ]
        self._onlines: list[torch.Tensor] = list(self._critic_params)
        self.reset_optimisers()

    def reset_optimisers(self) -> None:
        """Fresh Adam optimisers (no moments) for the actor, the critics and alpha."""
        # One optimiser for all three critics: Adam is elementwise, so this equals one per critic
        # with the summed loss, and costs one backward pass and one step.
        self.actor_optim = fast_adam(self._actor_params, self.config.lr)
        self.critic_optim = fast_adam(self._critic_params, self.config.lr)
        self.alpha_optim = fast_adam([self.alpha], self.config.lr)

    def networks(self) -> dict[NetworkName, nn.Module]:
        """The networks by name, as they appear in `state_dict` and `transfer`."""
        nets: dict[NetworkName, nn.Module] = {
            "actor": self.actor,
            "q_r": self.q_r,
            "q_c": self.q_c,
            "q_r_target": self.q_r_target,
            "q_c_target": self.q_c_target,
        }
        if self.q_c_var is not None and self.q_c_var_target is not None:
            nets["q_c_var"], nets["q_c_var_target"] = self.q_c_var, self.q_c_var_target
        return nets

    @torch.no_grad()
    def act(self, obs: np.ndarray, deterministic: bool) -> np.ndarray:
        """Actions in [-1, 1]: obs (n, obs_dim) -> (n, act_dim), or (obs_dim,) -> (act_dim,)."""
        obs_t = torch.as_tensor(obs, dtype=torch.float32)
        action, _ = self.actor(obs_t.unsqueeze(0) if obs_t.ndim == 1 else obs_t, deterministic)
        return action.squeeze(0).numpy() if obs_t.ndim == 1 else action.numpy()

    def _critic_step(
        self,
        obs: torch.Tensor,
        actions: torch.Tensor,
        rewards: torch.Tensor,
        costs: torch.Tensor,
        next_obs: torch.Tensor,
        terminated: torch.Tensor,
        alpha: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Eq. 13: the critics' targets and losses, one Adam step for them all; returns the reward and cost losses."""
        cfg = self.config
        # Eq. 13, targets: soft value with the min of the twin target critics; no entropy in the cost.
        with torch.no_grad():
            next_actions, next_log_pi = self.actor(next_obs)
            next_q_r = self.q_r_target(next_obs, next_actions)
            next_v_r = losses.soft_value(next_q_r, next_log_pi, alpha)
            y_r = losses.critic_target(rewards, terminated, next_v_r, cfg.gamma)
            # A cost-to-go is never negative (eq. 11 costs are 0 or 1): clamp the bootstrap so that the
            # critic's extrapolation below 0 does not feed on itself.
            next_v_c = self.q_c_target(next_obs, next_actions)[0].clamp(min=0.0)
            y_c = losses.critic_target(costs, terminated, next_v_c, cfg.gamma)

        # Eq. 13, critic losses: one backward pass and one Adam step for the three critics.
        q_r_loss = losses.critic_loss(self.q_r(obs, actions), y_r)
        q_c_sa = self.q_c(obs, actions)
        q_c_loss = losses.critic_loss(q_c_sa, y_c)
        if self.q_c_var is not None and self.q_c_var_target is not None:  # WCSAC's variance critic, same step
            with torch.no_grad():
                next_var = cost_variance(self.q_c_var_target, next_obs, next_actions)
                y_var = losses.cost_variance_target(costs, terminated, next_v_c, next_var, q_c_sa[0], cfg.gamma)
            q_c_loss = q_c_loss + losses.variance_loss(cost_variance(self.q_c_var, obs, actions), y_var)
        self.critic_optim.zero_grad()
        (q_r_loss + q_c_loss).backward()
        self.critic_optim.step()
        return q_r_loss, q_c_loss

    def _actor_alpha_step(
        self,
        log_pi: torch.Tensor,
        q_r_pi: torch.Tensor,
        cost_term: torch.Tensor,
        alpha: torch.Tensor,
        multiplier: torch.Tensor,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Eq. 12 / 16 and eq. 14: the actor's and alpha's losses and their steps; returns both losses."""
        actor_loss = losses.actor_loss(log_pi, q_r_pi, cost_term, alpha, multiplier)
        alpha_loss = losses.alpha_loss(self.alpha, log_pi, self.config.target_entropy)
        self.actor_optim.zero_grad()
        self.alpha_optim.zero_grad()
        torch.autograd.backward([actor_loss, alpha_loss], inputs=[*self._actor_params, self.alpha])
        self.actor_optim.step()
        self.alpha_optim.step()
        with torch.no_grad():
            self.alpha.clamp_(min=0.0)
        return actor_loss, alpha_loss

    def update(
        self, batch: ReplaySamples, recent: ReplaySamples | None = None, episode_cost: float | None = None
    ) -> UpdateStats:
        """One gradient step of every part (Algorithm 1, line 13).

        The measurements of the multiplier's signal (eq. 15, 17; ``self.signal``, chosen from the configuration by
        ``lagrange.choose_signal``): ``episode_cost``, the mean measured cost per recent episode, and ``recent``,
        transitions drawn from the last ``self.signal.recent_window`` added to the buffer; the signal's own one must
        be given (ValueError), the other is not read.
        """
        cfg = self.config
        obs, actions, rewards, costs, next_obs, terminated = batch
        if cfg.variant is Variant.SAC_PENALTY:
            rewards = rewards + cfg.penalty * costs
        alpha = self.alpha.detach().clone()  # the value used below, kept for the stats

        q_r_loss, q_c_loss = self._critic_step(obs, actions, rewards, costs, next_obs, terminated, alpha)

        # The policy's Q values at its own actions, the cost-to-go that eq. 4's g(pi) constrains (WCSAC's
        # saclag.py uses the replayed actions instead). Without a multiplier (SAC, SAC_PENALTY) Q^c is only
        # measured: no graph, no backward pass.
        pi_actions, log_pi = self.actor(obs)
        q_r_pi = self.q_r(obs, pi_actions)
        with torch.set_grad_enabled(self.uses_multiplier):
            q_c_pi = self.q_c(obs, pi_actions)[0]
        qc_mean = q_c_pi.detach().clamp(min=0.0).mean()
        cost_term = q_c_pi  # what the multiplier weighs in the actor loss: Q^c, or its CVaR (cost_cvar_level)
        if self.q_c_var is not None and cfg.cost_cvar_level is not None:
            with torch.set_grad_enabled(self.uses_multiplier):
                var_pi = cost_variance(self.q_c_var, obs, pi_actions)
                cost_term = losses.cost_cvar(q_c_pi, var_pi, cfg.cost_cvar_level)

        # What eq. 15 and 17 compare with C, on Q^c's scale: the signal lagrange.choose_signal chose.
        def q_c_recent() -> torch.Tensor:
            assert recent is not None
            with torch.no_grad():
                return self.q_c(recent.observations, self.actor(recent.observations)[0])[0].clamp(min=0.0).mean()

        measured = self.signal.measured(episode_cost, q_c_recent if recent is not None else None, qc_mean)

        # Eq. 17, the damping xi = k_d (C - measured), and the multiplier of Q^c in the actor loss: beta - xi
        # (eq. 16; k_d = 0 for SAC_LAG: beta, eq. 12), 0 without a multiplier.
        beta = self.multiplier.beta
        if self.uses_multiplier:
            xi, multiplier = self.multiplier.damping(measured), self.multiplier.effective(measured)
        else:
            xi, multiplier = torch.zeros_like(measured), torch.zeros_like(measured)

        # Eq. 12 / 16, the actor loss, and eq. 14, alpha's loss (log_pi a constant there): one backward pass for
        # both (they share no parameter: the actor loss uses a detached alpha); inputs= keeps the critics' weights
        # out of it. Alpha is projected onto >= 0 after its step (SacConfig.alpha_init).
        actor_loss, alpha_loss = self._actor_alpha_step(log_pi, q_r_pi, cost_term, alpha, multiplier)

        # Eq. 15, the multiplier's projected step (DampedLagrangeMultiplier.update), then Polyak averaging of the
        # targets: target <- polyak * target + (1 - polyak) * online.
        beta_loss = self.multiplier.update(measured) if self.uses_multiplier else torch.zeros_like(measured)
        with torch.no_grad():
            torch._foreach_lerp_(self._targets, self._onlines, 1.0 - cfg.polyak)

        scalars = torch.stack(
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
                q_r_pi.detach().min(dim=0).values.mean(),
                qc_mean,
                measured,
                -log_pi.detach().mean(),
            ]
        ).tolist()  # one synchronisation for all statistics
        return UpdateStats(*scalars)

    def state_dict(self) -> SacState:
        """All needed to resume: networks, targets, optimiser states, alpha, the multiplier.

        As with torch's own `state_dict`, the tensors share storage with the live learner: save it
        (`torch.save`) or `copy.deepcopy` it to keep a snapshot while training goes on.
        """
        variance: _VarianceCritics = {}
        if self.q_c_var is not None and self.q_c_var_target is not None:
            variance = {"q_c_var": self.q_c_var.state_dict(), "q_c_var_target": self.q_c_var_target.state_dict()}
        return {
            "actor": self.actor.state_dict(),
            "q_r": self.q_r.state_dict(),
            "q_c": self.q_c.state_dict(),
            "q_r_target": self.q_r_target.state_dict(),
            "q_c_target": self.q_c_target.state_dict(),
            **variance,
            "actor_optim": self.actor_optim.state_dict(),
            "critic_optim": self.critic_optim.state_dict(),
            "alpha": self.alpha.detach().clone(),
            "alpha_optim": self.alpha_optim.state_dict(),
            "multiplier": self.multiplier.state_dict(),
            "variant": self.config.variant.value,
        }

    def load_state_dict(self, state: SacState) -> None:
        """Restore what `state_dict` returned (same sizes; a different variant is logged)."""
        if state.get("variant") != self.config.variant.value:
            logger.warning(
                "loading a %s checkpoint into a %s learner",
                state.get("variant"),
                self.config.variant.value,
            )
        for name, net in self.networks().items():
            net.load_state_dict(state[name])
        # Optimiser.load_state_dict keeps the given moment tensors (no copy); copy them so that
        # two learners loaded from one in-memory state never share (and update) the same moments.
        load_optimiser(self.actor_optim, copy.deepcopy(state["actor_optim"]))
        load_optimiser(self.critic_optim, copy.deepcopy(state["critic_optim"]))
        with torch.no_grad():
            self.alpha.copy_(state["alpha"])
        load_optimiser(self.alpha_optim, copy.deepcopy(state["alpha_optim"]))
        self.multiplier.load_state_dict(state["multiplier"])


TRANSFERRED_NETWORKS: tuple[NetworkName, ...] = ("actor", "q_r", "q_c", "q_r_target", "q_c_target")
"""What `transfer` copies: all network weights. Everything else is reset."""
VARIANCE_NETWORKS: tuple[NetworkName, ...] = ("q_c_var", "q_c_var_target")
"""Also copied when both learners have them (SacConfig.cost_cvar_level); else the target's stay as they are."""
VARIANCE_FLOOR = 1e-6
"""Added to the variance critic's softplus, so that sqrt(V^c) has a finite gradient everywhere."""


def cost_variance(net: nn.Module, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
    """V^c(s, a) > 0 of WCSAC's variance critic, (batch,): the network's output through a softplus."""
    return nn.functional.softplus(net(obs, actions)[0]) + VARIANCE_FLOOR


def transfer(target: SacLagrangian, source_state: SacState) -> list[str]:
    """TSSAC's parameter transfer N_k -> N_k+1 (Algorithm 1, lines 17 and 19).

    Copied from `source_state` (a `SacLagrangian.state_dict()`): the weights of the actor, the
    reward critics, the cost critic and their targets (TRANSFERRED_NETWORKS), and the variance critic and its
    target when both learners have one (VARIANCE_NETWORKS).
    Reset to `target.config`: the optimiser states (fresh Adam moments), alpha (alpha_init) and
    beta (beta_init, with a fresh optimiser), since the new task has its own entropy and cost
    balance. Returns the names of the copied tensors, "<network>.<parameter>".
    """
    copied: list[str] = []
    nets = target.networks()
    names = [*TRANSFERRED_NETWORKS, *(n for n in VARIANCE_NETWORKS if n in nets and n in source_state)]
    for name in names:
        nets[name].load_state_dict(source_state[name])
        copied += [f"{name}.{key}" for key in source_state[name]]
    with torch.no_grad():
        target.alpha.fill_(target.config.alpha_init)
    target.reset_optimisers()
    target.multiplier.reset()
    logger.info("transferred %d tensors; optimisers, alpha and beta reset", len(copied))
    return copied
